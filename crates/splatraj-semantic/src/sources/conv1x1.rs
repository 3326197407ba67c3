//! Chains of PyTorch 1×1 `Conv2d` layers read from a `state_dict` checkpoint, as Linear layers.
//!
//! Several language fields ship a small network of 1×1 convolutions that their code applies
//! to rendered feature maps: Feature 3DGS's `CNN_decoder` (one layer under `conv`), Gaussian
//! Grouping's identity classifier (one bare `Conv2d`), LEGaussians' `IndexDecoder` (`conv1`,
//! `conv2`, `conv3` with ReLU between). A 1×1 convolution is the same Linear map applied to
//! each pixel's vector, so each becomes a [`LangsplatDecoder`] (Linear layers with ReLU between
//! and none after the last) that runs on the caller's burn device. Every key is checked: a
//! missing key, a kernel other than 1×1 or widths that do not chain are errors naming the file
//! and the key.

use std::path::Path;

use burn::store::pytorch_reader::PytorchReader;
use burn::tensor::Device;

use crate::error::{Result, SemanticError};
use crate::sources::LangsplatDecoder;
use crate::sources::langsplat::{LinearWeights, read_f32};

/// Reads the 1×1 convolutions whose keys start with `prefixes` (in order: `"conv."`, or `""`
/// for a bare `Conv2d`), each with `weight` `[out, in, 1, 1]` and `bias` `[out]`, onto
/// `device`. `module` says what the file should hold, for errors ("a Gaussian Grouping
/// classifier.pth: torch.nn.Conv2d(num_objects, num_classes, kernel_size=1)").
pub fn read_conv1x1_layers(
    path: &Path,
    prefixes: &[&str],
    module: &str,
    device: &Device,
) -> Result<LangsplatDecoder> {
    let reader = PytorchReader::new(path).map_err(|e| {
        SemanticError::file(path, format!("not a readable PyTorch checkpoint: {e}"))
    })?;
    let tensors = reader.tensors();
    let get = |key: &str| {
        tensors.get(key).ok_or_else(|| {
            let mut keys: Vec<&str> = tensors.keys().map(String::as_str).collect();
            keys.sort_unstable();
            keys.truncate(8);
            SemanticError::file(
                path,
                format!("missing key {key:?}: not {module} (its keys: {keys:?})"),
            )
        })
    };
    let mut layers: Vec<LinearWeights> = Vec::with_capacity(prefixes.len());
    for prefix in prefixes {
        let (weight_key, bias_key) = (format!("{prefix}weight"), format!("{prefix}bias"));
        let (weight, bias) = (get(&weight_key)?, get(&bias_key)?);
        let [out, input, 1, 1] = weight.shape()[..] else {
            return Err(SemanticError::file(
                path,
                format!(
                    "key {weight_key:?} has shape {:?}: a 1×1 convolution's weight is \
                     [out, in, 1, 1] ({module})",
                    weight.shape()
                ),
            ));
        };
        if let Some(previous) = layers.last()
            && previous.out != input
        {
            return Err(SemanticError::file(
                path,
                format!(
                    "key {weight_key:?} takes {input} channels but the layer before outputs {}",
                    previous.out
                ),
            ));
        }
        if bias.shape() != [out] {
            return Err(SemanticError::file(
                path,
                format!(
                    "key {bias_key:?} has shape {:?}: expected [{out}] to match {weight_key:?}",
                    bias.shape()
                ),
            ));
        }
        layers.push(LinearWeights {
            weight: read_f32(path, &weight_key, weight)?,
            bias: read_f32(path, &bias_key, bias)?,
            out,
            input,
        });
    }
    Ok(LangsplatDecoder::from_linear_layers(layers, path, device))
}
