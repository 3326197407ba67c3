#!/usr/bin/env python3
"""Reference values for splatraj's SOG reader, decoded by PlayCanvas's own tool.

The SOG reader (crates/splatraj-scene/src/formats/sog.rs) is checked against what
splat-transform (the format's reference implementation, npm `@playcanvas/splat-transform`)
decodes from the same files, not against our own understanding of the layout:

1. `narcissus.sog` (a real SuperSplat export, shared data): splat-transform converts it to an
   INRIA PLY; a few Gaussians of it are stored as `narcissus_sog_reference.json`.
2. A small scene *with* an SH palette (shN, degree 3), which narcissus lacks: 600 Gaussians of
   `fruit_drops_minimal.ply` are written as SOG by splat-transform, bundled (`fruit_sh3.sog`)
   and unbundled (`fruit_sh3_sog/meta.json` + WebP files), then decoded by it again; some are
   stored in `fruit_sh3_sog_reference.json` (every 15th Gaussian and the last).

Values are stored activated, in splatraj's convention: scales exp'd, opacity sigmoid'd,
quaternions (w, x, y, z), SH `[coefficient][channel]` with the DC term first.

Usage (needs numpy and Node with splat-transform, e.g. `npm install @playcanvas/splat-transform`
in DIR, then pass `--splat-transform DIR/node_modules/.bin/splat-transform`):

    python3 scripts/make_sog_fixture.py --splat-transform PATH [--data /work/shared/data]

Writes into crates/splatraj-scene/tests/data/.
"""

import argparse
import json
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "crates/splatraj-scene/tests/data"

# Gaussians of narcissus.sog whose reference values are kept: both ends, texel-row boundaries
# of its 320-wide images, and a spread in between.
NARCISSUS_INDICES = [0, 1, 2, 319, 320, 321, 4096, 12345, 50000, 65535, 65536, 99999, 101274]


def read_ply(path):
    """A binary little-endian PLY's vertex element as a dict of float32/other arrays."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    types = {"float": "<f4", "double": "<f8", "uchar": "u1", "int": "<i4", "uint": "<u4"}
    count, fields, in_vertex = 0, [], False
    for line in header:
        parts = line.split()
        if parts[:1] == ["format"] and parts[1] != "binary_little_endian":
            raise SystemExit(f"{path}: only binary_little_endian PLY is supported here")
        if parts[:1] == ["element"]:
            in_vertex = parts[1] == "vertex"
            if in_vertex:
                count = int(parts[2])
        elif parts[:1] == ["property"] and in_vertex:
            fields.append((parts[2], types[parts[1]]))
    table = np.frombuffer(data, dtype=np.dtype(fields), count=count, offset=end)
    return {name: table[name] for name, _ in fields}


def write_ply(path, columns):
    """Writes float32 columns as a binary little-endian INRIA-style PLY."""
    names = list(columns)
    n = len(columns[names[0]])
    header = "ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % n
    header += "".join(f"property float {name}\n" for name in names)
    header += "end_header\n"
    table = np.empty(n, dtype=[(name, "<f4") for name in names])
    for name in names:
        table[name] = columns[name]
    Path(path).write_bytes(header.encode("ascii") + table.tobytes())


def activated(ply, indices):
    """Gaussians `indices` of a PLY table, activated, as JSON-ready dicts."""
    rest = sorted(
        (k for k in ply if k.startswith("f_rest_")), key=lambda k: int(k.split("_")[-1])
    )
    per_channel = len(rest) // 3
    out = []
    for i in indices:
        i = int(i)
        q = np.array([ply[f"rot_{k}"][i] for k in range(4)], dtype=np.float64)
        q /= np.linalg.norm(q)
        sh = [[float(ply[f"f_dc_{c}"][i]) for c in range(3)]]
        # INRIA groups f_rest by channel: coefficient j of channel c is f_rest_{c*per_channel+j}.
        for j in range(per_channel):
            sh.append([float(ply[rest[c * per_channel + j]][i]) for c in range(3)])
        out.append(
            {
                "index": i,
                "mean": [float(ply[a][i]) for a in "xyz"],
                "scale": [float(np.exp(np.float64(ply[f"scale_{k}"][i]))) for k in range(3)],
                "rotation": q.tolist(),
                "opacity": float(1.0 / (1.0 + np.exp(-np.float64(ply["opacity"][i])))),
                "sh": sh,
            }
        )
    return out


def run(tool, *args):
    """Runs splat-transform, failing loudly."""
    subprocess.run([tool, "-q", "-w", *map(str, args)], check=True)


def version(tool):
    return subprocess.run([tool, "--version"], capture_output=True, text=True).stdout.strip()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--splat-transform", required=True, help="the splat-transform CLI")
    parser.add_argument("--data", default="/work/shared/data", help="shared data folder")
    args = parser.parse_args()
    tool, data = args.splat_transform, Path(args.data)
    generator = f"splat-transform {version(tool)}"

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)

        # 1. The real capture, decoded by the reference reader.
        run(tool, data / "narcissus.sog", tmp / "narcissus.ply")
        ply = read_ply(tmp / "narcissus.ply")
        (OUT / "narcissus_sog_reference.json").write_text(
            json.dumps(
                {
                    "source": "shared data narcissus.sog (see tests/data/README.md)",
                    "decoded_by": generator,
                    "count": int(len(ply["x"])),
                    "sh_degree": 0,
                    "gaussians": activated(ply, NARCISSUS_INDICES),
                },
                indent=1,
            )
            + "\n"
        )

        # 2. A small degree-3 scene through the SOG writer (palette), bundled and not.
        fruit = read_ply(data / "fruit_drops_minimal.ply")
        keep = np.arange(0, len(fruit["x"]), 8)[:600]
        names = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2"]
        names += [f"f_rest_{k}" for k in range(45)]
        names += ["opacity", "scale_0", "scale_1", "scale_2"] + [f"rot_{k}" for k in range(4)]
        write_ply(tmp / "fruit_sh3.ply", {k: fruit[k][keep] for k in names})
        run(tool, "-g", "cpu", tmp / "fruit_sh3.ply", OUT / "fruit_sh3.sog")
        folder = OUT / "fruit_sh3_sog"
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir()
        run(tool, "-g", "cpu", tmp / "fruit_sh3.ply", folder / "meta.json")
        run(tool, OUT / "fruit_sh3.sog", tmp / "fruit_bundle.ply")
        run(tool, folder / "meta.json", tmp / "fruit_folder.ply")
        bundle = read_ply(tmp / "fruit_bundle.ply")
        unbundled = read_ply(tmp / "fruit_folder.ply")
        n = len(bundle["x"])
        picks = sorted(set(range(0, n, 15)) | {n - 1})
        (OUT / "fruit_sh3_sog_reference.json").write_text(
            json.dumps(
                {
                    "source": "600 Gaussians (every 8th) of fruit_drops_minimal.ply, written "
                    f"as SOG by {generator}",
                    "decoded_by": generator,
                    "count": n,
                    "sh_degree": 3,
                    "bundle": activated(bundle, picks),
                    "folder": activated(unbundled, picks),
                },
                separators=(",", ":"),
            )
            + "\n"
        )
    print(f"wrote the SOG fixtures into {OUT}")


if __name__ == "__main__":
    main()
