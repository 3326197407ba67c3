#!/usr/bin/env python3
"""Write a degree-3 copy of a degree-1 INRIA PLY (as `splatraj scene demo` writes it).

Real captures mostly hold SH degree 3 (45 `f_rest_*` values a Gaussian); the demo scene holds
degree 1 (9). The copy keeps every Gaussian, its degree-1 coefficients and everything else,
and adds the 12 higher-order coefficients a channel as small pseudo-random values (±0.1, a
fixed seed), so benchmarks can time what degree 3 costs on the same geometry:

    splatraj scene demo --out /tmp/demo1m.ply --gaussians 1000000
    python3 scripts/sh_degree3_copy.py /tmp/demo1m.ply /tmp/demo1m_sh3.ply
    splatraj bench frames --scene /tmp/demo1m_sh3.ply --gaussians 0 --sizes 720p

Standard library only. Every property must be a 4-byte float or int (as splatraj writes them).
"""

import argparse
import array
import random
import sys

LOW = 3  # degree-1 coefficients a channel
HIGH = 15  # degree-3 coefficients a channel


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source", help="binary little-endian INRIA PLY of SH degree 1")
    parser.add_argument("target", help="the degree-3 copy to write")
    args = parser.parse_args()

    data = open(args.source, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    properties = [line.split() for line in header if line.startswith("property")]
    names = [p[2] for p in properties]
    if any(p[1] not in ("float", "int", "uint") for p in properties):
        sys.exit(f"{args.source}: every property must be a 4-byte float or int")
    rest = [n for n in names if n.startswith("f_rest_")]
    if len(rest) != 3 * LOW:
        sys.exit(f"{args.source}: {len(rest)} f_rest values, expected {3 * LOW} (degree 1)")
    first = names.index("f_rest_0")
    width = len(names)
    count = next(int(l.split()[2]) for l in header if l.startswith("element vertex"))

    # Raw 4-byte words: ints travel untouched.
    words = array.array("I")
    words.frombytes(data[end : end + count * width * 4])
    rng = random.Random(1)
    noise = array.array("f", [rng.uniform(-0.1, 0.1) for _ in range(100_003)])
    noise_words = array.array("I", noise.tobytes())
    out = array.array("I")
    k = 0
    for row in range(count):
        values = words[row * width : (row + 1) * width]
        out.extend(values[:first])
        # f_rest is grouped by channel: all red coefficients, then green, then blue.
        for channel in range(3):
            out.extend(values[first + channel * LOW : first + (channel + 1) * LOW])
            for _ in range(HIGH - LOW):
                out.append(noise_words[k % len(noise_words)])
                k += 1
        out.extend(values[first + 3 * LOW :])

    lines = []
    for line in header:
        if line.startswith("property") and line.split()[2].startswith("f_rest_"):
            if line.split()[2] == "f_rest_0":
                lines += [f"property float f_rest_{i}" for i in range(3 * HIGH)]
            continue
        lines.append(line)
    with open(args.target, "wb") as f:
        f.write(("\n".join(lines) + "\n").encode())
        f.write(out.tobytes())
    print(f"wrote {count} Gaussians of SH degree 3 to {args.target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
