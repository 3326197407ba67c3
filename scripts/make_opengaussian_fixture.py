#!/usr/bin/env python3
"""Writes the OpenGaussian fixture of splatraj-semantic's tests.

`cluster_lang.npz` is written as OpenGaussian's train.py writes it (`np.savez` with keys
leaf_feat [k1*k2, 512] float32, leaf_score [k1*k2] float32, occu_count [k1*k2], leaf_ind
[num_pts] int64), at a small width: 9 leaves of 16-d features for the 4721 Gaussians of the
scene crate's fruit_drops_minimal fixture, leaf_ind[i] = (7 i) mod 9. Leaf 8 was never matched
to a view (occu_count 0, zero feature), as OpenGaussian leaves unmatched leaves.

Outputs, in crates/splatraj-semantic/tests/data/opengaussian/ (or the folder given):
- cluster_lang.npz          the language clusters
- cluster_lang_compressed.npz  the same with np.savez_compressed (deflate entries)
- phrases.json              "leaf 0".."leaf 7" = leaf_feat row + N(0, 0.01²), and four random
                            negatives ("object", "things", "stuff", "texture")
- bad_no_leaf_ind.npz       without leaf_ind
- bad_leaf_range.npz        one leaf_ind equal to 9 (out of range)
- bad_feat_1d.npz           leaf_feat flattened to 1-D

Usage: python scripts/make_opengaussian_fixture.py [OUT_DIR]   (needs numpy)
"""

import json
import sys
from pathlib import Path

import numpy as np

LEAVES, DIM, GAUSSIANS = 9, 16, 4721


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else (
        Path(__file__).resolve().parent.parent / "crates/splatraj-semantic/tests/data/opengaussian")
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(20240603)
    # Orthonormal leaf features (QR of a Gaussian draw): distinct instances, distinct concepts.
    q, _ = np.linalg.qr(rng.standard_normal((DIM, DIM)))
    leaf_feat = q[:LEAVES].astype(np.float32)
    leaf_feat[8] = 0.0
    occu_count = np.array([3, 5, 2, 7, 4, 1, 6, 3, 0], dtype=np.int64)
    leaf_score = rng.uniform(0.2, 0.9, LEAVES).astype(np.float32)
    leaf_ind = (np.arange(GAUSSIANS, dtype=np.int64) * 7) % LEAVES
    data = dict(leaf_feat=leaf_feat, leaf_score=leaf_score, occu_count=occu_count, leaf_ind=leaf_ind)
    np.savez(out / "cluster_lang.npz", **data)
    np.savez_compressed(out / "cluster_lang_compressed.npz", **data)

    phrases = {f"leaf {k}": (leaf_feat[k] + 0.01 * rng.standard_normal(DIM)).tolist() for k in range(8)}
    for n, v in zip(["object", "things", "stuff", "texture"], q[LEAVES:LEAVES + 4]):
        phrases[n] = v.tolist()
    (out / "phrases.json").write_text(json.dumps(phrases))

    np.savez(out / "bad_no_leaf_ind.npz", **{k: v for k, v in data.items() if k != "leaf_ind"})
    bad = leaf_ind.copy()
    bad[100] = LEAVES
    np.savez(out / "bad_leaf_range.npz", **{**data, "leaf_ind": bad})
    np.savez(out / "bad_feat_1d.npz", **{**data, "leaf_feat": leaf_feat.reshape(-1)})


if __name__ == "__main__":
    main()
