#!/usr/bin/env python3
"""Writes the LangSplat decoder fixture of splatraj-semantic's tests.

The checkpoint is what LangSplat's autoencoder training writes (`torch.save(model.state_dict())`
of its `Autoencoder`, encoder and decoder together), with seeded random weights instead of
trained ones: the Rust reader must find the decoder's tensors among the encoder's, and its
decoded vectors must match PyTorch's on the same latents.

Outputs, in crates/splatraj-semantic/tests/data/langsplat/ (or the folder given):
- best_ckpt.pth          state dict of the full autoencoder (512→256→128→64→32→3 encoder with
                         BatchNorm, 3→16→32→64→128→256→256→512 decoder), float32
- latents.npy            [32, 3] float32 latents, drawn from N(0, 1) then L2-normalised (as
                         LangSplat's encoder output is)
- decoded.npy            [32, 512] float32: the checkpoint's decoder applied by PyTorch to the
                         latents (Linear/ReLU in turn, then L2 normalisation)
- bad_missing_bias.pth   a decoder-only state dict (3→4→5) without decoder.2.bias
- bad_shape.pth          a decoder-only state dict whose decoder.2.weight does not chain
- bad_odd_key.pth        a decoder with a BatchNorm at decoder.1 (a layout splatraj refuses)
- encoder_only.pth       a small encoder's keys only (no decoder)

Usage: python scripts/make_langsplat_fixture.py [OUT_DIR]   (needs torch and numpy)
"""

import sys
from pathlib import Path

import numpy as np
import torch
from torch import nn

SEED = 20240601
ENCODER_DIMS = [256, 128, 64, 32, 3]
DECODER_DIMS = [16, 32, 64, 128, 256, 256, 512]
CLIP_DIM = 512
LATENTS = 32


def mlp(widths, batch_norm):
    """Linear layers through `widths` as an nn.ModuleList, with (BatchNorm and) ReLU between:
    the module layout, and so the state-dict keys, of LangSplat's autoencoder halves."""
    layers = [nn.Linear(widths[0], widths[1])]
    for a, b in zip(widths[1:-1], widths[2:]):
        if batch_norm:
            layers.append(nn.BatchNorm1d(a))
        layers.append(nn.ReLU())
        layers.append(nn.Linear(a, b))
    return nn.ModuleList(layers)


class Autoencoder(nn.Module):
    """LangSplat's autoencoder layout. Its decoder has no BatchNorm: LangSplat's constructor
    appends the decoder's BatchNorm layers to the encoder's Python list after that list was
    turned into a ModuleList, so they never become part of the model."""

    def __init__(self):
        super().__init__()
        self.encoder = mlp([CLIP_DIM] + ENCODER_DIMS, batch_norm=True)
        self.decoder = mlp([ENCODER_DIMS[-1]] + DECODER_DIMS, batch_norm=False)

    def decode(self, x):
        for m in self.decoder:
            x = m(x)
        return x / x.norm(dim=-1, keepdim=True)


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else (
        Path(__file__).resolve().parent.parent
        / "crates/splatraj-semantic/tests/data/langsplat"
    )
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(SEED)
    model = Autoencoder().eval()
    with torch.no_grad():
        # Non-default BatchNorm statistics, so that the encoder's keys look trained.
        for m in model.encoder:
            if isinstance(m, nn.BatchNorm1d):
                m.running_mean.normal_()
                m.running_var.uniform_(0.5, 2.0)
        # He-scaled weights and small biases: with PyTorch's default initialisation the
        # biases dominate and every latent decodes to nearly the same direction (cosines
        # above 0.999), which would make a weak test of the decoder.
        for m in model.decoder:
            if isinstance(m, nn.Linear):
                m.weight.normal_(0.0, (2.0 / m.in_features) ** 0.5)
                m.bias.normal_(0.0, 0.05)
    torch.save(model.state_dict(), out / "best_ckpt.pth")

    latents = torch.randn(LATENTS, ENCODER_DIMS[-1])
    latents = latents / latents.norm(dim=-1, keepdim=True)
    with torch.no_grad():
        decoded = model.decode(latents)
    np.save(out / "latents.npy", latents.numpy().astype(np.float32))
    np.save(out / "decoded.npy", decoded.numpy().astype(np.float32))

    small = nn.Module()
    small.decoder = mlp([3, 4, 5], batch_norm=False)
    state = small.state_dict()
    del state["decoder.2.bias"]
    torch.save(state, out / "bad_missing_bias.pth")

    state = small.state_dict()
    state["decoder.2.weight"] = torch.randn(5, 7)
    torch.save(state, out / "bad_shape.pth")

    odd = nn.Module()
    odd.decoder = mlp([3, 4, 5], batch_norm=True)
    torch.save(odd.state_dict(), out / "bad_odd_key.pth")

    encoder = nn.Module()
    encoder.encoder = mlp([8, 4, 3], batch_norm=True)
    torch.save(encoder.state_dict(), out / "encoder_only.pth")
    print(f"torch {torch.__version__}, numpy {np.__version__}, seed {SEED}: wrote {out}")


if __name__ == "__main__":
    main()
