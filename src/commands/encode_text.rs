//! `splatraj encode-text`: CLIP text embeddings of phrases, written as a phrase table (a cache
//! of what `--text-encoder` computes at run time, and a table for tools without the weights).
//!
//! The work is `splatraj_semantic::text_encoder::phrase_file` (one call: the weights read,
//! the canonical negatives added, the phrases encoded, the table written whole or not at all);
//! the table's forms are those `PhraseTable::read` takes (`.safetensors` with the phrases in
//! its metadata, or `.json`). This file checks the phrases, calls it and prints.

use std::path::PathBuf;
use std::str::FromStr;

use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use splatraj_render::backend::BackendKind;
use splatraj_semantic::text_encoder::phrase_file::{
    CanonicalNegatives, PhraseFileRequest, write_phrase_file,
};
use splatraj_semantic::{Activation, TextEncoderOptions};

/// Arguments of `splatraj encode-text`.
#[derive(Debug, Args)]
pub struct EncodeTextArgs {
    /// The phrases to encode.
    #[arg(required = true)]
    phrases: Vec<String>,
    /// CLIP text-tower weights (open_clip_model.safetensors, open_clip_pytorch_model.bin, or
    /// another safetensors or torch.save'd state dict of a CLIP model).
    #[arg(long, value_name = "FILE")]
    text_encoder: PathBuf,
    /// The tower's activation, gelu (open_clip) or quick-gelu (OpenAI) [default:
    /// open_clip_config.json beside the weights, else gelu].
    #[arg(long, value_name = "gelu|quick-gelu", value_parser = Activation::from_str)]
    text_activation: Option<Activation>,
    /// Also encode LERF's canonical negatives (object, things, stuff, texture), which a
    /// features query without an encoder looks up in the table.
    #[arg(long, value_enum, default_value_t = Negatives::Default)]
    negatives: Negatives,
    /// Output table: .safetensors (phrases in its metadata) or .json.
    #[arg(long, value_name = "TABLE")]
    out: PathBuf,
    /// Tensor backend: flex (CPU, default), ndarray or wgpu, among those compiled in.
    #[arg(long, default_value = "flex", value_parser = BackendKind::from_str)]
    backend: BackendKind,
}

/// Whether the canonical negatives join the table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Negatives {
    /// Add LERF's canonical negatives that are not among the phrases.
    Default,
    /// Only the phrases given.
    None,
}

/// Runs `splatraj encode-text`.
pub fn run(args: EncodeTextArgs) -> Result<()> {
    let mut phrases: Vec<String> = Vec::new();
    for p in &args.phrases {
        if p.trim().is_empty() {
            bail!("an empty phrase was given: every phrase needs at least one character");
        }
        phrases.push(p.trim().to_string());
    }
    let device = args.backend.device()?;
    let request = PhraseFileRequest {
        phrases: &phrases,
        negatives: match args.negatives {
            Negatives::Default => CanonicalNegatives::Added,
            Negatives::None => CanonicalNegatives::Left,
        },
        weights: &args.text_encoder,
        options: TextEncoderOptions {
            activation: args.text_activation,
            heads: None,
        },
        out: &args.out,
    };
    let written = write_phrase_file(&request, &device, |encoder| {
        eprintln!("{}", encoder.describe())
    })?;
    eprintln!(
        "wrote {} ({} phrases, {}-d)",
        args.out.display(),
        written.phrases,
        written.dim
    );
    Ok(())
}
