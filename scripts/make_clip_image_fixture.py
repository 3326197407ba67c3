#!/usr/bin/env python3
"""Writes the CLIP image-encoder fixtures of splatraj-semantic's tests
(tests/fixtures/clip_image/).

The reference is open_clip itself (pip install torch open_clip_torch safetensors numpy): its
`CLIP` model class built with small, seeded random vision towers (the ViT-B/16 architecture at
a smaller width and depth), saved the way open_clip saves models for the Hugging Face hub (the
whole model's `state_dict()` as `open_clip_model.safetensors` or `open_clip_pytorch_model.bin`,
beside `open_clip_config.json`), and:

- global embeddings: open_clip's own `encode_image(normalize=True)` at the tower's native size;
- dense features: ClearCLIP (Lan et al., "ClearCLIP: Decomposing CLIP Representations for
  Dense Vision-Language Inference", ECCV 2024, arXiv 2407.12442) written here in PyTorch on
  open_clip's own modules (`conv1`, `ln_pre`, the blocks, their `ln_1` and `attn` weights,
  `ln_post`, `proj`): the blocks but the last as trained; in the last block, self-self
  (query-query) attention on `ln_1(x)`, its output projection, and no residual connection
  and no feed-forward; then `ln_post` and `proj` on the patch tokens, L2-normalised. At the
  native size, and at larger and non-square inputs, where the patch position embeddings are
  resized with `F.interpolate(mode="bicubic", align_corners=False, antialias=False)` to the
  new grid (the interpolation ClearCLIP's and timm's code use; open_clip's `resize_pos_embed`
  is the same call with `antialias=True`, which changes the cubic kernel).

The hand-written embedding and block code is checked against open_clip's `encode_image`
(standard last block) before any dense feature is written.

Two towers, one per weight format and activation:
- gelu/       width 32, 4 heads (head_width 8), 2 layers, patch 8, image 32 (4x4 grid),
              nn.GELU, float32, open_clip_model.safetensors + open_clip_config.json
- quickgelu/  width 32, 2 heads (head_width 16), 2 layers, patch 16, image 48 (3x3 grid),
              QuickGELU, float16 (as open_clip's fp16 checkpoints), open_clip_pytorch_model.bin
              + open_clip_config.json
Each holds a tiny text tower too (real files hold one, and the image reader must skip it).
Layer-norm weights, all biases and the class embedding are perturbed from their initial
values so that a reader that ignored them would fail.

Also written:
- images.safetensors      the test images, uint8 [H, W, 3] (pixels in [0, 1] are value/255)
- expected.safetensors    float64 reference outputs, named "<case>"
- cases.json              each case: tower folder and file, kind (global/dense), images, input
                          size, grid
- vit_b_16_visual_shapes.json  key -> shape of the visual tensors of the full open_clip
                          ViT-B-16 state dict (randomly initialised, nothing downloaded)

Usage: python scripts/make_clip_image_fixture.py [OUT_DIR]
"""

import json
import sys
from pathlib import Path

import numpy as np
import open_clip
import safetensors.torch
import torch
import torch.nn.functional as F
from open_clip.constants import OPENAI_DATASET_MEAN, OPENAI_DATASET_STD
from open_clip.model import CLIP, CLIPTextCfg, CLIPVisionCfg
from open_clip.push_to_hf_hub import save_config_for_hf

SEED = 20260526
EMBED = 16
TEXT = {"context_length": 8, "vocab_size": 16, "width": 16, "heads": 2, "layers": 1}

TOWERS = [
    # folder, width, head_width, layers, patch, image, quick_gelu, format, dtype
    ("gelu", 32, 8, 2, 8, 32, False, "safetensors", torch.float32),
    ("quickgelu", 32, 16, 2, 16, 48, True, "bin", torch.float16),
]

# Images: name -> (height, width).
IMAGES = {
    "a32": (32, 32),
    "b32": (32, 32),
    "c64": (64, 64),
    "d32x64": (32, 64),
    "e48": (48, 48),
    "f48": (48, 48),
    "g96": (96, 96),
    "h80x48": (80, 48),
}

# name, tower, kind, images (each at its own size, which is the tower's input).
CASES = [
    ("gelu_global", "gelu", "global", ["a32", "b32"]),
    ("gelu_dense_native", "gelu", "dense", ["a32"]),
    ("gelu_dense_64", "gelu", "dense", ["c64"]),
    ("gelu_dense_32x64", "gelu", "dense", ["d32x64"]),
    ("quickgelu_global", "quickgelu", "global", ["e48", "f48"]),
    ("quickgelu_dense_native", "quickgelu", "dense", ["f48"]),
    ("quickgelu_dense_96", "quickgelu", "dense", ["g96"]),
    ("quickgelu_dense_80x48", "quickgelu", "dense", ["h80x48"]),
]


def build(width, head_width, layers, patch, image, quick_gelu, seed):
    torch.manual_seed(seed)
    vision = {
        "image_size": image,
        "layers": layers,
        "width": width,
        "head_width": head_width,
        "patch_size": patch,
    }
    model = CLIP(
        embed_dim=EMBED,
        vision_cfg=CLIPVisionCfg(**vision),
        text_cfg=CLIPTextCfg(**TEXT),
        quick_gelu=quick_gelu,
    )
    # What open_clip.create_model sets, and save_config_for_hf reads.
    model.visual.image_mean = OPENAI_DATASET_MEAN
    model.visual.image_std = OPENAI_DATASET_STD
    model_cfg = {
        "embed_dim": EMBED,
        "quick_gelu": quick_gelu,
        "vision_cfg": vision,
        "text_cfg": TEXT,
    }
    return model, model_cfg


def perturb(model, seed):
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for name, p in model.visual.named_parameters():
            if name.endswith("bias") or "ln_" in name or name == "class_embedding":
                p.add_(0.1 * torch.randn(p.shape, generator=g))


def save(model, model_cfg, folder, fmt, dtype):
    folder.mkdir(parents=True, exist_ok=True)
    state = {k: v.to(dtype).contiguous() for k, v in model.state_dict().items()}
    if fmt == "safetensors":
        safetensors.torch.save_file(state, folder / "open_clip_model.safetensors")
        file = "open_clip_model.safetensors"
    else:
        torch.save(state, folder / "open_clip_pytorch_model.bin")
        file = "open_clip_pytorch_model.bin"
    save_config_for_hf(model, folder / "open_clip_config.json", model_config=model_cfg)
    # The reference runs on exactly the saved values, in float64.
    model.load_state_dict({k: v.float() for k, v in state.items()})
    return file


def preprocess(images):
    """uint8 [B, H, W, 3] -> normalised float64 [B, 3, H, W], as CLIP's Normalize."""
    x = torch.from_numpy(images).double().permute(0, 3, 1, 2) / 255.0
    mean = torch.tensor(OPENAI_DATASET_MEAN, dtype=torch.float64).view(1, 3, 1, 1)
    std = torch.tensor(OPENAI_DATASET_STD, dtype=torch.float64).view(1, 3, 1, 1)
    return (x - mean) / std


def positions(visual, rows, cols):
    """Position embeddings [1 + rows*cols, W] for a rows x cols patch grid."""
    pos = visual.positional_embedding
    grid = visual.grid_size
    if (rows, cols) == tuple(grid):
        return pos
    width = pos.shape[1]
    patches = pos[1:].reshape(1, grid[0], grid[1], width).permute(0, 3, 1, 2)
    patches = F.interpolate(
        patches, size=(rows, cols), mode="bicubic", align_corners=False, antialias=False
    )
    patches = patches.permute(0, 2, 3, 1).reshape(rows * cols, width)
    return torch.cat([pos[:1], patches], dim=0)


def embed(visual, x):
    """Tokens [B, 1 + rows*cols, W] after ln_pre, as open_clip's `_embeds`."""
    patch = visual.patch_size[0]
    rows, cols = x.shape[2] // patch, x.shape[3] // patch
    t = visual.conv1(x).reshape(x.shape[0], visual.conv1.out_channels, -1).permute(0, 2, 1)
    cls = visual.class_embedding.view(1, 1, -1).expand(x.shape[0], 1, -1)
    t = torch.cat([cls, t], dim=1) + positions(visual, rows, cols)
    return visual.ln_pre(t), rows, cols


def clearclip_attention(block, x):
    """ClearCLIP's last-block output: Proj(softmax(q qᵀ/√d) v), q and v from ln_1(x)."""
    attn = block.attn
    b, n, w = x.shape
    heads = attn.num_heads
    d = w // heads
    q, _k, v = F.linear(block.ln_1(x), attn.in_proj_weight, attn.in_proj_bias).chunk(3, dim=-1)
    q = q.reshape(b, n, heads, d).transpose(1, 2)  # [B, H, N, d]
    v = v.reshape(b, n, heads, d).transpose(1, 2)
    weights = torch.softmax(q @ q.transpose(-1, -2) / d**0.5, dim=-1)
    out = (weights @ v).transpose(1, 2).reshape(b, n, w)
    return attn.out_proj(out)


def dense(model, x):
    """ClearCLIP dense features [rows, cols, EMBED] of one image x [1, 3, H, W]."""
    visual = model.visual
    assert visual.transformer.batch_first
    t, rows, cols = embed(visual, x)
    blocks = visual.transformer.resblocks
    for block in blocks[:-1]:
        t = block(t)
    t = clearclip_attention(blocks[-1], t)  # no residual, no FFN
    t = visual.ln_post(t[:, 1:]) @ visual.proj
    t = F.normalize(t, dim=-1)
    return t.reshape(rows, cols, -1)


def check_hand_written(model, x):
    """Our embedding and blocks reproduce open_clip's encode_image."""
    visual = model.visual
    t, _, _ = embed(visual, x)
    for block in visual.transformer.resblocks:
        t = block(t)
    ours = F.normalize(visual.ln_post(t[:, 0]) @ visual.proj, dim=-1)
    theirs = model.encode_image(x, normalize=True)
    assert torch.allclose(ours, theirs, atol=1e-12), (ours - theirs).abs().max()


def images():
    rng = np.random.default_rng(SEED)
    out = {}
    for name, (h, w) in IMAGES.items():
        # Smooth colour gradients plus noise: some structure for the attention to find.
        yy, xx = np.mgrid[0:h, 0:w]
        base = np.stack(
            [np.sin(xx / (3 + c) + yy / (5 + 2 * c) + rng.uniform(0, 6)) for c in range(3)], -1
        )
        img = 0.5 + 0.35 * base + 0.15 * rng.standard_normal((h, w, 3))
        out[name] = np.clip(np.round(img * 255), 0, 255).astype(np.uint8)
    return out


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else (
        Path(__file__).resolve().parent.parent
        / "crates/splatraj-semantic/tests/fixtures/clip_image"
    )
    out.mkdir(parents=True, exist_ok=True)
    pictures = images()
    towers = {}
    for i, (folder, width, hw, layers, patch, image, quick_gelu, fmt, dtype) in enumerate(TOWERS):
        model, cfg = build(width, hw, layers, patch, image, quick_gelu, SEED + i)
        perturb(model, SEED + 100 + i)
        file = save(model, cfg, out / folder, fmt, dtype)
        model = model.double().eval()
        towers[folder] = (model, file, patch, image)

    expected = {}
    cases = []
    with torch.no_grad():
        for name, folder, kind, names in CASES:
            model, file, patch, image = towers[folder]
            batch = np.stack([pictures[n] for n in names])
            x = preprocess(batch)
            h, w = batch.shape[1:3]
            if kind == "global":
                assert (h, w) == (image, image)
                check_hand_written(model, x)
                expected[name] = model.encode_image(x, normalize=True).contiguous()
                grid = [image // patch, image // patch]
            else:
                expected[name] = dense(model, x).contiguous()
                grid = list(expected[name].shape[:2])
            cases.append({
                "name": name,
                "tower": folder,
                "file": file,
                "kind": kind,
                "images": names,
                "height": h,
                "width": w,
                "grid": grid,
            })
    safetensors.torch.save_file(expected, out / "expected.safetensors")
    safetensors.torch.save_file(
        {k: torch.from_numpy(v) for k, v in pictures.items()}, out / "images.safetensors"
    )
    lines = [json.dumps(c) for c in cases]
    (out / "cases.json").write_text('{"cases": [\n%s\n]}\n' % ",\n".join(lines))
    full = open_clip.create_model("ViT-B-16", pretrained=None)
    visual = {k: list(v.shape) for k, v in full.state_dict().items() if k.startswith("visual.")}
    (out / "vit_b_16_visual_shapes.json").write_text(json.dumps(visual, indent=0) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
