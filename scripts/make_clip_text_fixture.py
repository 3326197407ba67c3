#!/usr/bin/env python3
"""Writes the CLIP text-encoder fixtures of splatraj-semantic's tests (tests/fixtures/clip/).

The reference is open_clip itself (pip install torch open_clip_torch safetensors numpy): its
`CLIP` model class built with small, seeded random text towers (the ViT-B/16 architecture at a
smaller width and depth), saved the way open_clip saves models for the Hugging Face hub
(`open_clip.push_to_hf_hub`: the whole model's `state_dict()` as `open_clip_model.safetensors`
or `open_clip_pytorch_model.bin`, beside `open_clip_config.json`), and its own tokenizer and
`encode_text(normalize=True)` applied to a list of phrases.

Two towers, one per weight format and activation:
- gelu/       width 32, 4 heads, 2 layers, nn.GELU (as open_clip's laion2b_s34b_b88k ViT-B/16),
              open_clip_model.safetensors + open_clip_config.json
- quickgelu/  width 32, 2 heads, 2 layers, QuickGELU (as OpenAI's towers),
              open_clip_pytorch_model.bin (torch.save of the state dict) + open_clip_config.json

Each keeps a tiny vision tower too (real files hold one, and the reader must skip it). Layer
norm weights and all biases are perturbed from their initial 1/0 so that a reader that ignored
them would fail. Rows of the token embedding that no fixture phrase uses are zeroed: the file
keeps the real vocabulary's shape ([49408, width]) yet packs to a few kilobytes in git, and a
lookup of a wrong row still lands on a zero row and changes the result.

Also written:
- phrases.json            the phrases, open_clip's token ids (77 per phrase), and each tower's
                          unit embeddings computed in float64 from the saved float32 weights
- vit_b_16_shapes.json    key -> shape of the full open_clip ViT-B-16 state dict (randomly
                          initialised, nothing downloaded): the shapes the reader must accept
- vit_b_32_shapes.json    the same for ViT-B-32 (OpenAI's B/32 shares the text tower)

Usage: python scripts/make_clip_text_fixture.py [OUT_DIR]
"""

import json
import sys
from pathlib import Path

import numpy as np
import open_clip
import safetensors.torch
import torch
from open_clip.constants import OPENAI_DATASET_MEAN, OPENAI_DATASET_STD
from open_clip.model import CLIP, CLIPTextCfg, CLIPVisionCfg
from open_clip.push_to_hf_hub import save_config_for_hf

SEED = 20260522
CONTEXT = 77
VOCAB = 49408
EMBED = 16

PHRASES = [
    # The canonical negatives and the planted objects of the end-to-end query test.
    "object",
    "things",
    "stuff",
    "texture",
    "red mug",
    "green ball",
    "potted plant",
    # Case, spacing and punctuation.
    "A photo of a CAT.",
    "  glass   of\twater \n",
    "napkins, please!!!",
    "the bear's nose (left)",
    "i've seen it; we'd go",
    # HTML entities (open_clip unescapes twice), curly quotes, ligatures, full-width letters.
    "fish &amp;amp; chips",
    "it\u2019s a \u201cdog\u201d",
    "\ufb01sh \ufb02ower",
    "\uff52\uff45\uff44 \uff4d\uff55\uff47",
    # Non-ASCII letters, composed and decomposed, other scripts, emoji, digits.
    "caf\u00e9 cr\u00e8me",
    "cafe\u0301 cre\u0300me",
    "Stra\u00dfe",
    "\u65e5\u672c\u306e\u732b",
    "\U0001f34e apple",
    "room 101",
    # Longer than the context: truncated to 76 tokens then <end_of_text>.
    " ".join(["a very long description of a wooden chair with four legs"] * 12),
]


def tower(width, heads, layers, quick_gelu, seed):
    torch.manual_seed(seed)
    text_cfg = CLIPTextCfg(
        context_length=CONTEXT, vocab_size=VOCAB, width=width, heads=heads, layers=layers
    )
    vision_cfg = CLIPVisionCfg(layers=1, width=16, head_width=8, patch_size=8, image_size=16)
    model = CLIP(
        embed_dim=EMBED, vision_cfg=vision_cfg, text_cfg=text_cfg, quick_gelu=quick_gelu
    )
    # What open_clip.create_model sets, and save_config_for_hf reads.
    model.visual.image_mean = OPENAI_DATASET_MEAN
    model.visual.image_std = OPENAI_DATASET_STD
    model_cfg = {
        "embed_dim": EMBED,
        "quick_gelu": quick_gelu,
        "vision_cfg": {"image_size": 16, "layers": 1, "width": 16, "head_width": 8, "patch_size": 8},
        "text_cfg": {
            "context_length": CONTEXT,
            "vocab_size": VOCAB,
            "width": width,
            "heads": heads,
            "layers": layers,
        },
    }
    return model, model_cfg


def perturb_and_prune(model, used_tokens, seed):
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for name, p in model.named_parameters():
            if name.endswith("bias") or ".ln_" in name or name.startswith("ln_final"):
                p.add_(0.1 * torch.randn(p.shape, generator=g))
        keep = torch.zeros(VOCAB, dtype=torch.bool)
        keep[used_tokens] = True
        model.token_embedding.weight[~keep] = 0.0


def save_tower(model, model_cfg, folder, fmt):
    folder.mkdir(parents=True, exist_ok=True)
    state = {k: v.contiguous() for k, v in model.state_dict().items()}
    if fmt == "safetensors":
        safetensors.torch.save_file(state, folder / "open_clip_model.safetensors")
    else:
        torch.save(state, folder / "open_clip_pytorch_model.bin")
    save_config_for_hf(model, folder / "open_clip_config.json", model_config=model_cfg)


def embeddings(model, tokens):
    reference = model.double().eval()
    with torch.no_grad():
        return reference.encode_text(tokens, normalize=True).numpy()


def shapes(name):
    model = open_clip.create_model(name, pretrained=None)
    return {k: list(v.shape) for k, v in model.state_dict().items()}


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else (
        Path(__file__).resolve().parent.parent
        / "crates/splatraj-semantic/tests/fixtures/clip"
    )
    tokenizer = open_clip.get_tokenizer("ViT-B-16")
    tokens = tokenizer(PHRASES)
    assert tokens.shape == (len(PHRASES), CONTEXT)
    used = torch.unique(tokens)

    record = {"phrases": []}
    towers = {}
    for i, (folder, width, heads, layers, quick_gelu, fmt) in enumerate([
        ("gelu", 32, 4, 2, False, "safetensors"),
        ("quickgelu", 32, 2, 2, True, "bin"),
    ]):
        model, cfg = tower(width, heads, layers, quick_gelu, SEED + i)
        perturb_and_prune(model, used, SEED + 100 + i)
        save_tower(model, cfg, out / folder, fmt)
        towers[folder] = embeddings(model, tokens)

    for k, phrase in enumerate(PHRASES):
        entry = {"text": phrase, "tokens": tokens[k].tolist()}
        for folder, e in towers.items():
            entry[folder] = [float(x) for x in e[k]]
        record["phrases"].append(entry)
    # One phrase a line: readable diffs when the fixture is made anew.
    lines = [json.dumps(e, ensure_ascii=False) for e in record["phrases"]]
    (out / "phrases.json").write_text(
        '{"context_length": %d, "phrases": [\n%s\n]}\n' % (CONTEXT, ",\n".join(lines))
    )
    for name, file in [("ViT-B-16", "vit_b_16_shapes.json"), ("ViT-B-32", "vit_b_32_shapes.json")]:
        (out / file).write_text(json.dumps(shapes(name), indent=0) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
