//! `splatraj encode-text` as one call: phrases encoded by CLIP text-tower weights, LERF's
//! canonical negatives added when asked, written as a phrase table (`.safetensors` or
//! `.json`, whole or not at all).

use std::path::Path;

use burn::tensor::Device;

use super::{TextEncoder, TextEncoderOptions};
use crate::error::Result;
use crate::vectors::DEFAULT_NEGATIVES;

/// Whether LERF's canonical negatives (object, things, stuff, texture) join the table: a
/// features query without an encoder looks them up there.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CanonicalNegatives {
    /// Added after the phrases, those not among them already.
    Added,
    /// Only the phrases given.
    Left,
}

/// What a phrase file holds and where it goes.
#[derive(Debug, Clone)]
pub struct PhraseFileRequest<'a> {
    /// The phrases, in order.
    pub phrases: &'a [String],
    /// Whether the canonical negatives join them.
    pub negatives: CanonicalNegatives,
    /// The CLIP text-tower weights.
    pub weights: &'a Path,
    /// Heads and activation, where the weights cannot tell.
    pub options: TextEncoderOptions,
    /// The table file (`.safetensors` or `.json`).
    pub out: &'a Path,
}

/// What was written.
#[derive(Debug, Clone, PartialEq)]
pub struct PhraseFile {
    /// Phrases in the table.
    pub phrases: usize,
    /// Their embedding width.
    pub dim: usize,
}

/// Encodes the request's phrases on `device` and writes the table; `loaded` hears the
/// encoder once its weights are read (before the encoding, which takes the time).
pub fn write_phrase_file(
    request: &PhraseFileRequest<'_>,
    device: &Device,
    loaded: impl FnOnce(&TextEncoder),
) -> Result<PhraseFile> {
    let mut phrases = request.phrases.to_vec();
    if request.negatives == CanonicalNegatives::Added {
        for n in DEFAULT_NEGATIVES {
            if !phrases.iter().any(|p| p.eq_ignore_ascii_case(n)) {
                phrases.push(n.to_string());
            }
        }
    }
    let encoder = TextEncoder::from_file(request.weights, request.options, device)?;
    loaded(&encoder);
    let table = encoder.table(&phrases)?;
    table.write(request.out)?;
    Ok(PhraseFile {
        phrases: phrases.len(),
        dim: table.dim(),
    })
}
