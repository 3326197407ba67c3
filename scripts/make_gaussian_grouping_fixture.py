#!/usr/bin/env python3
"""Writes the Gaussian Grouping fixture of splatraj-semantic's tests.

Gaussian Grouping (Ye et al., ECCV 2024; github.com/lkeab/gaussian-grouping) gives each
Gaussian a 16-d identity encoding, `_objects_dc` of shape [N, 1, 16], which
`scene/gaussian_model.py`'s `save_ply` writes as float properties `obj_dc_0..obj_dc_15` after
`rot_*` (the layout `construct_list_of_attributes` builds, written with plyfile). `train.py`
trains `classifier = torch.nn.Conv2d(gaussians.num_objects, num_classes, kernel_size=1)` on
`.cuda()` and saves `torch.save(classifier.state_dict(), .../classifier.pth)`. Its editing
scripts (`edit_object_removal.py`) classify the Gaussians themselves with
`logits3d = classifier(gaussians._objects_dc.permute(2, 0, 1))` and
`prob_obj3d = torch.softmax(logits3d, dim=0)`.

This script builds the same things with seeded random weights: a `GaussianModel`-layout PLY
(SH degree 3, 16 identity dims) whose Gaussians sit in four blobs, each blob's encodings
pointing at one class, plus a scatter of Gaussians with weak encodings (no confident class);
the classifier's state dict, saved with its storages tagged `cuda:0` as a GPU-trained
`train.py` writes them; and PyTorch's own classification of the PLY's encodings (read back
with plyfile, exactly as `load_ply` does) as the reference.

Outputs, in crates/splatraj-semantic/tests/data/gaussian_grouping/ (or the folder given):
- point_cloud.ply        220 Gaussians in Gaussian Grouping's layout (binary little endian)
- classifier.pth         Conv2d(16, 32, kernel_size=1) state dict (`weight`, `bias`), cuda:0
- expected_ids.npy       [220] int64: argmax over classes of the softmax (PyTorch)
- expected_prob.npy      [220] float32: that class's softmax probability (PyTorch)
- bad_kernel.pth         Conv2d(16, 32, kernel_size=3): weight [32, 16, 3, 3]
- bad_no_bias.pth        Conv2d(16, 32, 1, bias=False): no `bias`
- bad_width.pth          Conv2d(8, 32, 1): takes 8 dims, the PLY has 16

Usage: python scripts/make_gaussian_grouping_fixture.py [OUT_DIR]  (needs torch, numpy, plyfile)
"""

import sys
from pathlib import Path

import numpy as np
import torch
from plyfile import PlyData, PlyElement

NUM_OBJECTS = 16  # GaussianModel.num_objects
NUM_CLASSES = 32
SH_DEGREE = 3
BLOB_CLASSES = [3, 7, 12, 25]  # the instance ids the blobs are built for
PER_BLOB = 50
SCATTERED = 20


def tag_as_cuda():
    """Makes torch.save record every storage's location as `cuda:0`, as train.py's
    `classifier.cuda()` does, without a GPU (the bytes are the same; only the tag differs)."""
    torch.serialization.register_package(
        1, lambda storage: "cuda:0", lambda storage, location: storage if location == "cuda:0" else None)


def attributes(n_rest, n_obj):
    """GaussianModel.construct_list_of_attributes of Gaussian Grouping."""
    names = ["x", "y", "z", "nx", "ny", "nz"]
    names += [f"f_dc_{i}" for i in range(3)]
    names += [f"f_rest_{i}" for i in range(n_rest)]
    names += ["opacity"]
    names += [f"scale_{i}" for i in range(3)]
    names += [f"rot_{i}" for i in range(4)]
    names += [f"obj_dc_{i}" for i in range(n_obj)]
    return names


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else (
        Path(__file__).resolve().parent.parent / "crates/splatraj-semantic/tests/data/gaussian_grouping")
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(20240817)
    rng = np.random.default_rng(20240817)

    classifier = torch.nn.Conv2d(NUM_OBJECTS, NUM_CLASSES, kernel_size=1)
    with torch.no_grad():
        # A trained classifier separates the ids it has seen: unit-scale weights give that
        # contrast (PyTorch's default init, uniform within ±1/4, gives near-uniform softmax).
        classifier.weight.normal_(0.0, 1.0)
        classifier.bias.normal_(0.0, 0.1)

    # Identity encodings: along the blob class's weight row (its logit grows fastest), with
    # noise; the scattered Gaussians get weak random encodings.
    w = classifier.weight.detach()[:, :, 0, 0].numpy()  # [classes, 16]
    centres = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [2.0, 2.0, 1.0]]
    xyz, obj = [], []
    for centre, k in zip(centres, BLOB_CLASSES):
        direction = w[k] / np.linalg.norm(w[k])
        for _ in range(PER_BLOB):
            xyz.append(np.array(centre) + rng.normal(0.0, 0.1, 3))
            obj.append(1.5 * direction + rng.normal(0.0, 0.15, NUM_OBJECTS))
    for _ in range(SCATTERED):
        xyz.append(rng.uniform(-1.0, 3.0, 3))
        obj.append(rng.normal(0.0, 0.05, NUM_OBJECTS))
    n = len(xyz)
    xyz = np.array(xyz, dtype=np.float32)
    obj = np.array(obj, dtype=np.float32)

    # The other properties as a trained scene has them: small scales, unit quaternions.
    n_rest = 3 * (SH_DEGREE + 1) ** 2 - 3
    columns = np.concatenate([
        xyz,
        np.zeros((n, 3), np.float32),                         # normals
        rng.normal(0.0, 0.5, (n, 3)).astype(np.float32),      # f_dc
        rng.normal(0.0, 0.05, (n, n_rest)).astype(np.float32),  # f_rest
        np.full((n, 1), 2.0, np.float32),                     # opacity (logit)
        np.full((n, 3), np.log(0.03), np.float32),            # scale (log)
        np.tile(np.array([[1.0, 0.0, 0.0, 0.0]], np.float32), (n, 1)),  # rot
        obj,                                                  # obj_dc
    ], axis=1)
    names = attributes(n_rest, NUM_OBJECTS)
    elements = np.empty(n, dtype=[(a, "f4") for a in names])
    elements[:] = list(map(tuple, columns))
    PlyData([PlyElement.describe(elements, "vertex")]).write(str(out / "point_cloud.ply"))

    # The reference: the encodings as load_ply reads them, classified as the editing scripts do.
    ply = PlyData.read(str(out / "point_cloud.ply"))
    objects_dc = np.zeros((n, NUM_OBJECTS, 1))
    for idx in range(NUM_OBJECTS):
        objects_dc[:, idx, 0] = np.asarray(ply.elements[0]["obj_dc_" + str(idx)])
    objects_dc = torch.tensor(objects_dc, dtype=torch.float).transpose(1, 2).contiguous()  # [N, 1, 16]
    with torch.no_grad():
        logits3d = classifier(objects_dc.permute(2, 0, 1))  # [classes, N, 1]
        prob_obj3d = torch.softmax(logits3d, dim=0)
        prob, ids = prob_obj3d[:, :, 0].max(dim=0)
    np.save(out / "expected_ids.npy", ids.numpy().astype(np.int64))
    np.save(out / "expected_prob.npy", prob.numpy().astype(np.float32))

    tag_as_cuda()
    torch.save(classifier.state_dict(), out / "classifier.pth")
    torch.save(torch.nn.Conv2d(NUM_OBJECTS, NUM_CLASSES, kernel_size=3).state_dict(), out / "bad_kernel.pth")
    torch.save(torch.nn.Conv2d(NUM_OBJECTS, NUM_CLASSES, 1, bias=False).state_dict(), out / "bad_no_bias.pth")
    torch.save(torch.nn.Conv2d(8, NUM_CLASSES, kernel_size=1).state_dict(), out / "bad_width.pth")

    ids = ids.numpy()
    prob = prob.numpy()
    for b, k in enumerate(BLOB_CLASSES):
        blob = slice(b * PER_BLOB, (b + 1) * PER_BLOB)
        print(f"blob {b} (class {k}): argmax = {k} for {(ids[blob] == k).sum()}/{PER_BLOB}, "
              f"probability {prob[blob].min():.3f}..{prob[blob].max():.3f}")
    rest = slice(len(BLOB_CLASSES) * PER_BLOB, n)
    print(f"scattered: probability {prob[rest].min():.3f}..{prob[rest].max():.3f}")


if __name__ == "__main__":
    main()
