#!/usr/bin/env python3
"""Writes the Feature 3DGS decoder fixture of splatraj-semantic's tests.

The checkpoint is what Feature 3DGS's `train.py --speedup` writes
(`torch.save(cnn_decoder.state_dict())` of `models/networks.py`'s `CNN_decoder`: one
`nn.Conv2d(in, out, kernel_size=1)` under `conv`), with seeded random weights; the reference
outputs come from PyTorch's own convolution applied to a feature map, the way Feature 3DGS
applies the decoder to a rendered feature map.

Outputs, in crates/splatraj-semantic/tests/data/feature3dgs/ (or the folder given):
- decoder_chkpnt.pth     CNN_decoder(8, 32) state dict, float32
- features.npy           [12, 8] float32 inputs: the 8 basis vectors, then 4 random ones
- decoded.npy            [12, 32] float32: the conv applied by PyTorch to `features` laid out
                         as an [8, 12, 1] feature map (one pixel per row), not normalised
- bad_kernel.pth         CNN_decoder with kernel_size=3 (weight [32, 8, 3, 3])
- bad_missing_bias.pth   Conv2d(8, 32, 1, bias=False) under `conv`
- bad_not_decoder.pth    a Linear under `fc` (no `conv.*` keys)

Usage: python scripts/make_feature3dgs_fixture.py [OUT_DIR]   (needs torch and numpy)
"""

import sys
from pathlib import Path

import numpy as np
import torch
from torch import nn

IN, OUT = 8, 32


class CNN_decoder(nn.Module):
    """Feature 3DGS's decoder module layout (models/networks.py)."""

    def __init__(self, input_dim, output_dim, kernel_size=1, bias=True):
        super().__init__()
        self.conv = nn.Conv2d(input_dim, output_dim, kernel_size=kernel_size, bias=bias)

    def forward(self, x):
        return self.conv(x)


class Other(nn.Module):
    def __init__(self):
        super().__init__()
        self.fc = nn.Linear(IN, OUT)


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else (
        Path(__file__).resolve().parent.parent / "crates/splatraj-semantic/tests/data/feature3dgs")
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(20240602)
    decoder = CNN_decoder(IN, OUT)
    with torch.no_grad():
        # Unit-scale weights and a small bias: the decoded basis vectors point in clearly
        # different directions, as distinct concepts of a trained field do.
        decoder.conv.weight.normal_(0.0, 1.0)
        decoder.conv.bias.normal_(0.0, 0.05)
    torch.save(decoder.state_dict(), out / "decoder_chkpnt.pth")

    features = torch.cat([torch.eye(IN), torch.randn(4, IN)]).float()  # [12, 8]
    with torch.no_grad():
        feature_map = features.T.reshape(IN, features.shape[0], 1)  # [C, H, W]
        decoded = decoder(feature_map.unsqueeze(0))[0]  # [OUT, 12, 1]
    np.save(out / "features.npy", features.numpy().astype(np.float32))
    np.save(out / "decoded.npy", decoded[:, :, 0].T.contiguous().numpy().astype(np.float32))

    torch.save(CNN_decoder(IN, OUT, kernel_size=3).state_dict(), out / "bad_kernel.pth")
    torch.save(CNN_decoder(IN, OUT, bias=False).state_dict(), out / "bad_missing_bias.pth")
    torch.save(Other().state_dict(), out / "bad_not_decoder.pth")


if __name__ == "__main__":
    main()
