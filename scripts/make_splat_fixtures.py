#!/usr/bin/env python3
"""Small antimatter15 `.splat` and GaussianSplats3D `.ksplat` files, written by the formats'
own reference writers, with reference values decoded by PlayCanvas's splat-transform.

- `tiny.splat`: antimatter15/splat's `convert.py` (the reference writer; it needs `plyfile`),
  from 200 Gaussians of `fruit_drops_minimal.ply`.
- `tiny_l0.ksplat`, `tiny_l1.ksplat`, `tiny_l2.ksplat`: GaussianSplats3D's generator
  (`scripts/ksplat_write.mjs`, the calls of its `util/create-ksplat.js`) at compression levels
  0, 1 and 2, SH degree 2, blocks of 0.2 and buckets of 16 so that positions use both full
  and partially filled buckets.
- `tiny_splat_reference.json`: for every file, the Gaussians that splat-transform (another
  implementation than both writers and than ours) decodes from it (every 7th Gaussian and the
  last), activated in splatraj's convention. (The .ksplat generator drops Gaussians with alpha
  below 1/255, 4 of the 200 here, so its files hold 196.)

Usage:
    python3 scripts/make_splat_fixtures.py --splat-transform PATH --convert-py PATH \
        --gs3d-dir DIR [--data /work/shared/data]

`--convert-py`: antimatter15/splat's convert.py; `--gs3d-dir`: a folder whose node_modules holds
`@mkkellogg/gaussian-splats-3d` and `three` (`npm install @mkkellogg/gaussian-splats-3d three`).
Writes into crates/splatraj-scene/tests/data/.
"""

import argparse
import json
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from make_sog_fixture import OUT, activated, read_ply, run, version, write_ply

COUNT = 200
KSPLAT_LEVELS = [0, 1, 2]
KSPLAT_SH_DEGREE = 2


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--splat-transform", required=True)
    parser.add_argument("--convert-py", required=True)
    parser.add_argument("--gs3d-dir", required=True)
    parser.add_argument("--data", default="/work/shared/data")
    args = parser.parse_args()
    tool, data = args.splat_transform, Path(args.data)

    fruit = read_ply(data / "fruit_drops_minimal.ply")
    keep = np.arange(0, len(fruit["x"]), len(fruit["x"]) // COUNT)[:COUNT]
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    names += [f"f_rest_{k}" for k in range(45)]
    names += ["opacity", "scale_0", "scale_1", "scale_2"] + [f"rot_{k}" for k in range(4)]
    reference = {
        "decoded_by": f"splat-transform {version(tool)}",
        "source_ply": f"{COUNT} Gaussians of fruit_drops_minimal.ply (every "
        f"{len(fruit['x']) // COUNT}th), SH degree 3",
        "files": {},
    }
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        source = tmp / "tiny.ply"
        write_ply(source, {k: fruit[k][keep] for k in names})

        # antimatter15's writer sorts by size × opacity, so the source order is not kept.
        splat = OUT / "tiny.splat"
        subprocess.run(
            ["python3", args.convert_py, str(source), "--output", str(splat)], check=True
        )
        files = [("tiny.splat", splat)]

        script = Path(args.gs3d_dir) / "ksplat_write.mjs"
        shutil.copy(Path(__file__).with_name("ksplat_write.mjs"), script)
        for level in KSPLAT_LEVELS:
            out = OUT / f"tiny_l{level}.ksplat"
            subprocess.run(
                ["node", str(script), str(source), str(out), str(level),
                 str(KSPLAT_SH_DEGREE), "0.2", "16"],
                check=True,
            )
            files.append((out.name, out))

        for name, path in files:
            ply_path = tmp / (name + ".ply")
            run(tool, path, ply_path)
            table = read_ply(ply_path)
            n = len(table["x"])
            reference["files"][name] = {
                "count": n,
                "gaussians": activated(table, sorted(set(range(0, n, 7)) | {n - 1})),
            }

    (OUT / "tiny_splat_reference.json").write_text(
        json.dumps(reference, separators=(",", ":")) + "\n"
    )
    print(f"wrote the .splat/.ksplat fixtures into {OUT}")


if __name__ == "__main__":
    main()
