#!/usr/bin/env python3
"""Reference checks of splatraj's SPZ and compressed-PLY writers, by the formats' own tools.

The writers (crates/splatraj-scene/src/formats/spz_writer.rs, compressed_ply_writer.rs) are
checked against the formats' reference implementations, not against our own readers only:

1. SPZ: 591 Gaussians (SH degree 3; every 8th of fruit_drops_minimal.ply, as for the SOG
   fixture) are written by `splatraj scene convert` as `fruit_sh3.spz`. Niantic's own library
   (github.com/nianticlabs/spz, built from source with scripts/spz_reference.cc) loads it in PLY
   axes; some Gaussians of its decoding go to `fruit_sh3_spz_reference.json`. The same library
   also writes the same Gaussians as version 3 (`fruit_sh3_niantic_v3.spz`), for a byte-level
   comparison of the quantisation.
2. Compressed PLY: the same Gaussians are written by `splatraj scene convert` as
   `fruit_sh3.compressed.ply`; PlayCanvas's splat-transform (npm `@playcanvas/splat-transform`)
   decodes it, and some of its Gaussians go to `fruit_sh3_compressed_ply_reference.json`.
   splat-transform also writes the same Gaussians as a compressed PLY
   (`fruit_sh3_splat_transform.compressed.ply`), for a comparison of chunk order and bits.

Values are stored activated, in splatraj's convention (see make_sog_fixture.py).

Usage (needs numpy, g++ with zlib and zstd headers, Node with splat-transform, and a release
build of splatraj):

    python3 scripts/make_writer_fixtures.py --splatraj target/release/splatraj \\
        --splat-transform DIR/node_modules/.bin/splat-transform --spz-source SPZ_CHECKOUT

Writes into crates/splatraj-scene/tests/data/ and prints how closely the tools agree.
"""

import argparse
import gzip
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from make_sog_fixture import activated, read_ply, run, version, write_ply  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "crates/splatraj-scene/tests/data"


def build_spz_reference(spz_source, tmp):
    """Compiles scripts/spz_reference.cc against Niantic's library sources."""
    exe = tmp / "spz_reference"
    src = Path(spz_source) / "src"
    subprocess.run(
        ["g++", "-O2", "-std=c++17", "-I", str(src), str(ROOT / "scripts/spz_reference.cc"),
         str(src / "cc/load-spz.cc"), str(src / "cc/splat-types.cc"), "-lz", "-lzstd",
         "-o", str(exe)],
        check=True,
    )
    return exe


def niantic_dump(exe, spz):
    """Niantic's decoding of an SPZ file (PLY axes) as a dict of arrays."""
    out = subprocess.run([str(exe), "dump", str(spz)], check=True, capture_output=True,
                         text=True).stdout
    # The library logs to standard output too, lines starting "[SPZ".
    text = [line for line in out.split("\n") if not line.startswith("[SPZ")]
    n, degree, _ = map(int, text[0].split())
    rows = np.array([[float(v) for v in line.split()] for line in text[1:1 + n]])
    return {
        "degree": degree,
        "mean": rows[:, 0:3],
        "log_scale": rows[:, 3:6],
        "xyzw": rows[:, 6:10],
        "logit": rows[:, 10],
        "dc": rows[:, 11:14],
        "rest": rows[:, 14:],
    }


def niantic_activated(g, indices):
    """Gaussians of a Niantic decoding, activated, in splatraj's JSON form."""
    out = []
    for i in indices:
        x, y, z, w = g["xyzw"][i]
        q = np.array([w, x, y, z])
        q /= np.linalg.norm(q)
        rest = g["rest"][i].reshape(-1, 3)  # coefficient-major, channel fastest
        out.append({
            "index": int(i),
            "mean": g["mean"][i].tolist(),
            "scale": np.exp(g["log_scale"][i]).tolist(),
            "rotation": q.tolist(),
            "opacity": float(1.0 / (1.0 + np.exp(-g["logit"][i]))),
            "sh": [g["dc"][i].tolist()] + rest.tolist(),
        })
    return out


def compare_spz(ours, theirs):
    """Byte differences between two SPZ version 3 files' contents, per array."""
    a, b = gzip.decompress(ours.read_bytes()), gzip.decompress(theirs.read_bytes())
    if a[:16] != b[:16] or len(a) != len(b):
        return f"headers or sizes differ: {a[:16].hex()} / {b[:16].hex()}, {len(a)} / {len(b)}"
    n, degree = int.from_bytes(a[8:12], "little"), a[12]
    sizes = [("positions", 9), ("alphas", 1), ("colours", 3), ("scales", 3), ("rotations", 4),
             ("sh", 3 * ((degree + 1) ** 2 - 1))]
    at, report = 16, []
    for name, per in sizes:
        x = np.frombuffer(a, np.uint8, n * per, at).astype(int)
        y = np.frombuffer(b, np.uint8, n * per, at).astype(int)
        at += n * per
        report.append(f"{name}: {int((x != y).sum())} of {n * per} bytes differ")
    return "; ".join(report)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--splatraj", required=True, help="splatraj binary (release build)")
    parser.add_argument("--splat-transform", required=True, help="the splat-transform CLI")
    parser.add_argument("--spz-source", required=True, help="checkout of nianticlabs/spz")
    args = parser.parse_args()
    tool = args.splat_transform
    generator = f"splat-transform {version(tool)}"

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        fruit = read_ply(OUT / "fruit_drops_minimal.ply")
        keep = np.arange(0, len(fruit["x"]), 8)[:600]
        names = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2"]
        names += [f"f_rest_{k}" for k in range(45)]
        names += ["opacity", "scale_0", "scale_1", "scale_2"] + [f"rot_{k}" for k in range(4)]
        write_ply(tmp / "fruit_sh3.ply", {k: fruit[k][keep] for k in names})
        n = len(keep)
        picks = sorted(set(range(0, n, 15)) | {n - 1})
        source = "591 Gaussians (every 8th) of fruit_drops_minimal.ply"

        # 1. SPZ.
        spz = OUT / "fruit_sh3.spz"
        subprocess.run([args.splatraj, "scene", "convert", tmp / "fruit_sh3.ply", spz],
                       check=True)
        exe = build_spz_reference(args.spz_source, tmp)
        niantic = niantic_dump(exe, spz)
        (OUT / "fruit_sh3_spz_reference.json").write_text(json.dumps({
            "source": f"{source}, written as SPZ version 3 by splatraj",
            "decoded_by": "nianticlabs/spz (loadSpz to RDF), scripts/spz_reference.cc",
            "count": n,
            "sh_degree": niantic["degree"],
            "gaussians": niantic_activated(niantic, picks),
        }, separators=(",", ":")) + "\n")
        theirs = OUT / "fruit_sh3_niantic_v3.spz"
        subprocess.run([str(exe), "write", tmp / "fruit_sh3.ply", theirs, "3"], check=True)
        print("SPZ, ours vs Niantic's writer:", compare_spz(spz, theirs))
        # splat-transform's SPZ reader, a second opinion (its axes may differ: printed only).
        run(tool, spz, tmp / "st_spz.ply")
        st = read_ply(tmp / "st_spz.ply")
        st_mean = np.stack([st[a] for a in "xyz"], 1)
        for label, flip in [("as stored", [1, 1, 1]), ("y, z flipped", [1, -1, -1])]:
            print(f"SPZ, splat-transform ({label}) vs Niantic: max position difference",
                  float(np.abs(st_mean * flip - niantic["mean"]).max()))

        # 2. Compressed PLY.
        compressed = OUT / "fruit_sh3.compressed.ply"
        subprocess.run([args.splatraj, "scene", "convert", tmp / "fruit_sh3.ply", compressed],
                       check=True)
        run(tool, compressed, tmp / "decoded.ply")
        decoded = read_ply(tmp / "decoded.ply")
        (OUT / "fruit_sh3_compressed_ply_reference.json").write_text(json.dumps({
            "source": f"{source}, written as compressed PLY by splatraj",
            "decoded_by": generator,
            "count": int(len(decoded["x"])),
            "sh_degree": 3,
            "gaussians": activated(decoded, picks),
        }, separators=(",", ":")) + "\n")
        reference = OUT / "fruit_sh3_splat_transform.compressed.ply"
        run(tool, tmp / "fruit_sh3.ply", reference)
        a, b = compressed.read_bytes(), reference.read_bytes()
        a, b = a[a.index(b"end_header\n") + 11:], b[b.index(b"end_header\n") + 11:]
        chunks = -(-n // 256)
        ra, rb = (np.frombuffer(x, "<f4", chunks * 18) for x in (a, b))
        va, vb = (np.frombuffer(x, "<u4", n * 4, chunks * 72) for x in (a, b))
        sa, sb = (np.frombuffer(x, np.uint8, n * 45, chunks * 72 + n * 16) for x in (a, b))
        print(f"compressed PLY, ours vs splat-transform's writer: {int((ra != rb).sum())} of "
              f"{ra.size} chunk floats differ (max {float(np.abs(ra - rb).max())}), "
              f"{int((va != vb).sum())} of {va.size} packed words, "
              f"{int((sa != sb).sum())} of {sa.size} SH bytes")
    print(f"wrote the writer fixtures into {OUT}")


if __name__ == "__main__":
    main()
