#!/usr/bin/env python3
"""Writes the LEGaussians fixture of splatraj-semantic's tests.

LEGaussians (Shi et al., "Language Embedded 3D Gaussians for Open-Vocabulary Scene
Understanding", CVPR 2024; github.com/buaavrcg/LEGaussians) stores per Gaussian a short
`_semantic_features` vector, written by `scene/gaussian_model.py` as float properties
`clip_f_indices_0..` of the PLY. Its `scene/index_decoder.py` `IndexDecoder` (1x1 convolutions
`conv1` D->128, `conv2` 128->256, `conv3` 256->codebook size, ReLU between) maps the
L2-normalised vector to logits over a codebook; `train.py` saves it as
`index_decoder_chkpnt<iteration>.pth` (`torch.save(index_decoder.state_dict())`). The codebook
comes from `preprocess/quantize_features.py`: `torch.save(model.state_dict(),
'<prefix>_codebook.pt')` of `preprocess/quantizer.py`'s `VectorQuantizer`, whose only
parameter is `embedding` (`nn.Embedding(n_e, e_dim)`; the CLIP part is the first 512 columns,
DINO's 384 follow when both were quantised together). `render_mask.py` turns logits into a
CLIP feature (`--com_type argmax`: the codebook row of the argmax; `softmax`: the
softmax-weighted sum of rows) and scores it with `utils/lem_utils.py`'s
`CLIPRelevance.get_relevancy` (LERF's softmax against "object", "things", "stuff", "texture"
at `scale` 100, minimum over the negatives).

This script builds the same files at a small width with seeded weights. The CLIP part of the
codebook is the 16-d text space of the fixture text tower (crates/splatraj-semantic/tests/
fixtures/clip, made by open_clip): rows 0, 1, 2 are open_clip's embeddings of "red mug",
"green ball" and "potted plant" (from its phrases.json); 8 more columns (random) stand for
DINO. The other rows are a canonical negative's embedding plus noise (background). The decoder
is trained for a few hundred Adam steps so that three blobs of Gaussians decode to codes 0, 1,
2 and a background to the other codes, as a trained scene's would. The references apply
LEGaussians' own maths (copied formulas: normalise, decode, argmax or softmax, relevancy at
scale 100) to the features read back from the PLY.

Outputs, in crates/splatraj-semantic/tests/data/legaussians/ (or the folder given):
- point_cloud.ply            160 Gaussians as `save_lem_ply` writes them (see README)
- index_decoder_chkpnt.pth   IndexDecoder(8, 16) state dict (conv1..conv3 weight/bias)
- codebook.pt                VectorQuantizer(16, 24) state dict (`embedding.weight` [16, 24])
- expected_index.npy         [160] int64: argmax of the decoded logits
- expected_relevancy_argmax.npy, expected_relevancy_softmax.npy
                             [3, 160] float32: the relevancy of the three phrases (rows in
                             the order above) per Gaussian, with `--com_type` argmax/softmax
- bad_decoder_missing.pth    only `conv1` of the IndexDecoder (no `conv2.*`, `conv3.*`)
- bad_codebook_key.pt        the codebook under `weight` instead of `embedding.weight`
- bad_codebook_narrow.pt     a codebook [16, 8]: narrower than the 16-d text space

Usage: python scripts/make_legaussians_fixture.py [OUT_DIR]  (needs torch, numpy, plyfile)
"""

import json
import sys
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from plyfile import PlyData, PlyElement
from torch import nn

ROOT = Path(__file__).resolve().parent.parent
FEATURES = 8      # semantic_features_dim
CODES = 16        # codebook_size (n_e)
CLIP = 16         # the fixture tower's text width
DINO = 8
PLANTED = ["red mug", "green ball", "potted plant"]
PER_BLOB = 40
BACKGROUND = 40
SCALE = 100.0     # render_mask.py --scale default
NEGATIVES = ["object", "things", "stuff", "texture"]


class IndexDecoder(nn.Module):
    """LEGaussians' scene/index_decoder.py layout."""

    def __init__(self, input_channels, output_channels):
        super().__init__()
        self.conv1 = nn.Conv2d(in_channels=input_channels, out_channels=128, kernel_size=1)
        self.conv2 = nn.Conv2d(in_channels=128, out_channels=256, kernel_size=1)
        self.conv3 = nn.Conv2d(in_channels=256, out_channels=output_channels, kernel_size=1)

    def forward(self, x):
        x = torch.relu(self.conv1(x))
        x = torch.relu(self.conv2(x))
        return self.conv3(x)


class VectorQuantizer(nn.Module):
    """The parameters of LEGaussians' preprocess/quantizer.py VectorQuantizer."""

    def __init__(self, n_e, e_dim):
        super().__init__()
        self.embedding = nn.Embedding(n_e, e_dim)


def relevancy(embed, pos, negs, scale):
    """CLIPRelevance.get_relevancy of utils/lem_utils.py for one positive phrase."""
    p = torch.cat([pos[None], negs], dim=0)
    a_norm = torch.norm(embed, dim=-1)[..., None]
    b_norm = torch.norm(p, dim=-1)[None, ...]
    output = torch.matmul(embed, p.t()) / (torch.matmul(a_norm, b_norm) + 1e-6)
    positive_vals = output[..., :1]
    negative_vals = output[..., 1:]
    repeated_pos = positive_vals.repeat(1, len(NEGATIVES))
    sims = torch.stack((repeated_pos, negative_vals), dim=-1)
    softmax = torch.softmax(scale * sims, dim=-1)
    best_id = softmax[..., 0].argmin(dim=1)
    return softmax[torch.arange(len(embed)), best_id, 0]


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else (
        ROOT / "crates/splatraj-semantic/tests/data/legaussians")
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(20240618)
    rng = np.random.default_rng(20240618)

    phrases = json.loads((ROOT / "crates/splatraj-semantic/tests/fixtures/clip/phrases.json").read_text())
    text = {p["text"]: torch.tensor(p["gelu"], dtype=torch.float32) for p in phrases["phrases"]}

    quantizer = VectorQuantizer(CODES, CLIP + DINO)
    with torch.no_grad():
        weight = torch.empty(CODES, CLIP + DINO).uniform_(-1.0, 1.0)
        # The other codes are background ("stuff", "texture" and the like): a canonical
        # negative's embedding plus noise, so that the planted phrases do not match them.
        for k in range(CODES):
            base = text[PLANTED[k]] if k < len(PLANTED) else text[NEGATIVES[k % len(NEGATIVES)]]
            weight[k, :CLIP] = base + (0.0 if k < len(PLANTED) else 0.05) * torch.randn(CLIP)
        quantizer.embedding.weight.copy_(weight)
    codebook = quantizer.embedding.weight.detach()

    # Each code's direction in the Gaussians' feature space; the decoder learns to map it back.
    directions = F.normalize(torch.randn(CODES, FEATURES), dim=1)
    decoder = IndexDecoder(FEATURES, CODES)
    optimiser = torch.optim.Adam(decoder.parameters(), lr=1e-3)
    for _ in range(400):
        codes = torch.randint(0, CODES, (256,))
        x = F.normalize(directions[codes] + 0.2 * torch.randn(256, FEATURES), dim=1)
        logits = decoder(x[:, :, None, None])[:, :, 0, 0]
        loss = F.cross_entropy(logits, codes)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    decoder.eval()
    torch.save(decoder.state_dict(), out / "index_decoder_chkpnt.pth")
    torch.save(quantizer.state_dict(), out / "codebook.pt")

    centres = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]]
    xyz, feats = [], []
    for k, centre in enumerate(centres):
        for _ in range(PER_BLOB):
            xyz.append(np.array(centre) + rng.normal(0.0, 0.1, 3))
            # Rendering scales features freely (only their direction is decoded).
            feats.append(rng.uniform(0.5, 3.0) * (directions[k].numpy() + rng.normal(0.0, 0.1, FEATURES)))
    for _ in range(BACKGROUND):
        xyz.append(rng.uniform(-1.0, 3.0, 3))
        feats.append(directions[rng.integers(len(PLANTED), CODES)].numpy() + rng.normal(0.0, 0.1, FEATURES))
    n = len(xyz)

    # save_lem_ply: its names and its columns disagree after clip_f_indices (names opacity,
    # uncertainty, scale_0..2; data opacity, scale[0..2], uncertainty), kept as LEGaussians
    # writes them.
    n_rest = 3 * (3 + 1) ** 2 - 3
    names = ["x", "y", "z", "nx", "ny", "nz"] + [f"f_dc_{i}" for i in range(3)]
    names += [f"f_rest_{i}" for i in range(n_rest)] + [f"clip_f_indices_{i}" for i in range(FEATURES)]
    names += ["opacity", "uncertainty"] + [f"scale_{i}" for i in range(3)] + [f"rot_{i}" for i in range(4)]
    names += [f"lemcolor_{i}" for i in range(3)]
    columns = np.concatenate([
        np.array(xyz, np.float32),
        np.zeros((n, 3), np.float32),
        rng.normal(0.0, 0.5, (n, 3)).astype(np.float32),
        rng.normal(0.0, 0.05, (n, n_rest)).astype(np.float32),
        np.array(feats, np.float32),
        np.full((n, 1), 2.0, np.float32),                   # opacity (logit)
        np.full((n, 3), np.log(0.03), np.float32),          # scale (log)
        np.full((n, 1), -4.6, np.float32),                  # uncertainty (logit of 0.01)
        np.tile(np.array([[1.0, 0.0, 0.0, 0.0]], np.float32), (n, 1)),
        rng.uniform(0.0, 1.0, (n, 3)).astype(np.float32),   # lemcolor
    ], axis=1)
    elements = np.empty(n, dtype=[(a, "f4") for a in names])
    elements[:] = list(map(tuple, columns))
    PlyData([PlyElement.describe(elements, "vertex")]).write(str(out / "point_cloud.ply"))

    # The references, from the features as load_ply reads them back.
    ply = PlyData.read(str(out / "point_cloud.ply"))
    feature_names = sorted((p.name for p in ply.elements[0].properties if p.name.startswith("clip_f_indices_")),
                           key=lambda x: int(x.split("_")[-1]))
    semantic = torch.tensor(np.stack([np.asarray(ply.elements[0][a]) for a in feature_names], axis=1),
                            dtype=torch.float)
    with torch.no_grad():
        normed = F.normalize(semantic, p=2, dim=1)
        logits = decoder(normed[:, :, None, None])[:, :, 0, 0]  # [N, codes]
        index = torch.argmax(logits, dim=1)
        clip_argmax = F.embedding(index, codebook[:, :CLIP])
        clip_softmax = torch.softmax(logits, dim=1) @ codebook[:, :CLIP]
        negs = torch.stack([text[t] for t in NEGATIVES])
        negs = negs / negs.norm(dim=-1, keepdim=True)
        rel = {}
        for mode, embed in [("argmax", clip_argmax), ("softmax", clip_softmax)]:
            rows = []
            for phrase in PLANTED:
                pos = text[phrase] / text[phrase].norm()
                rows.append(relevancy(embed, pos, negs, SCALE))
            rel[mode] = torch.stack(rows).numpy().astype(np.float32)
    np.save(out / "expected_index.npy", index.numpy().astype(np.int64))
    for mode, values in rel.items():
        np.save(out / f"expected_relevancy_{mode}.npy", values)

    # Only conv1 (small): conv2.weight is the first key missing.
    broken = {k: v for k, v in decoder.state_dict().items() if k.startswith("conv1.")}
    torch.save(broken, out / "bad_decoder_missing.pth")
    torch.save({"weight": codebook.clone()}, out / "bad_codebook_key.pt")
    torch.save({"embedding.weight": codebook[:, :8].clone()}, out / "bad_codebook_narrow.pt")

    index = index.numpy()
    for k, phrase in enumerate(PLANTED):
        blob = slice(k * PER_BLOB, (k + 1) * PER_BLOB)
        print(f"{phrase}: code {k} for {(index[blob] == k).sum()}/{PER_BLOB}; relevancy argmax "
              f"in blob {rel['argmax'][k][blob].min():.3f}, elsewhere max "
              f"{np.delete(rel['argmax'][k], np.r_[blob]).max():.3f}; softmax in blob "
              f"{rel['softmax'][k][blob].min():.3f}, elsewhere max {np.delete(rel['softmax'][k], np.r_[blob]).max():.3f}")
    print("background codes:", sorted(set(index[len(PLANTED) * PER_BLOB:].tolist())))


if __name__ == "__main__":
    main()
