//! `langsplat` source: LangSplat's per-Gaussian latents, decoded to text-embedding space by the
//! scene's own autoencoder decoder, then scored exactly as the `features` source.
//!
//! LangSplat (Qin et al., CVPR 2024) stores a 3-d latent per Gaussian and a scene-specific
//! autoencoder whose decoder maps latents back to 512-d CLIP space: Linear layers
//! 3→16→32→64→128→256→256→512 with ReLU between, the output L2-normalised. Its checkpoint
//! (`best_ckpt.pth`) is the `state_dict()` of the whole autoencoder. The decoder is an
//! `nn.ModuleList` of `[Linear, ReLU, Linear, ReLU, ..., Linear]`, so its weights sit under
//! `decoder.0`, `decoder.2`, ... (ReLU at the odd indices has none); the encoder's keys
//! (with BatchNorm) are in the same file and are not needed here.
//!
//! The widths are read from the checkpoint (LangSplat's are the default of its training
//! script; variants with other widths decode the same way), and every decoder key is checked:
//! a missing, unexpected or mis-shaped key is an error naming the file and the key.
//!
//! The latents are decoded once, when the source is built, on the caller's burn device, and
//! kept as an `[N, 512]` matrix (2 KiB per Gaussian): every later query is then as cheap as
//! with the `features` source, whose relevancy code scores them.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::module::{Module, Param};
use burn::nn::Linear;
use burn::store::pytorch_reader::{self, PytorchReader};
use burn::tensor::activation::relu;
use burn::tensor::{DType, Device, Tensor, TensorData};
use splatraj_scene::Scene;

use crate::embeddings::{Matrix, PhraseTable};
use crate::error::{Result, SemanticError};
use crate::sources::{FeatureInput, FeaturesSource, Relevancy, TargetSource};

/// The layer widths of LangSplat's decoder, latent first.
pub const LANGSPLAT_WIDTHS: [usize; 8] = [3, 16, 32, 64, 128, 256, 256, 512];

/// Prefix of the decoder's keys in a LangSplat autoencoder state dict.
pub const DECODER_PREFIX: &str = "decoder.";

/// Latents decoded per batch: bounds device memory to a few widest activations
/// (rows × 512 floats, 128 MiB at this size).
const DECODE_ROWS: usize = 65_536;

/// Norms below this are treated as zero when normalising, so that a dead output (all ReLUs
/// off and zero biases) stays a zero vector, reported by the scoring, rather than NaN.
const MIN_NORM: f64 = 1e-12;

/// The decoder's Linear layers, in order, as a burn module.
#[derive(Module, Debug)]
struct DecoderLayers {
    layers: Vec<Linear>,
}

/// LangSplat's autoencoder decoder, with weights from a checkpoint, on a burn device.
#[derive(Debug, Clone)]
pub struct LangsplatDecoder {
    module: DecoderLayers,
    widths: Vec<usize>,
    source: PathBuf,
}

/// One Linear layer's weights as PyTorch stores them, read to the host.
pub(crate) struct LinearWeights {
    /// `[out, input]`, row-major.
    pub weight: Vec<f32>,
    /// `[out]`.
    pub bias: Vec<f32>,
    /// Output width.
    pub out: usize,
    /// Input width.
    pub input: usize,
}

/// One decoder layer's tensors as found in the checkpoint.
#[derive(Default)]
struct LayerKeys<'a> {
    weight: Option<&'a pytorch_reader::Tensor>,
    bias: Option<&'a pytorch_reader::Tensor>,
}

impl LangsplatDecoder {
    /// Reads the decoder of a LangSplat autoencoder checkpoint (a PyTorch `state_dict()`
    /// saved with `torch.save`) onto `device`. The encoder's keys are ignored.
    pub fn from_checkpoint(path: &Path, device: &Device) -> Result<Self> {
        let reader = PytorchReader::new(path).map_err(|e| {
            SemanticError::file(path, format!("not a readable PyTorch checkpoint: {e}"))
        })?;
        let tensors = reader.tensors();
        let mut layers: BTreeMap<usize, LayerKeys> = BTreeMap::new();
        let expected = "LangSplat's decoder holds Linear layers (weight and bias) at the even \
                        indices decoder.0, decoder.2, ... with ReLU between";
        // Sorted, so that the key an error names does not depend on hash order.
        let mut sorted: Vec<(&String, &pytorch_reader::Tensor)> = tensors.iter().collect();
        sorted.sort_unstable_by_key(|(name, _)| name.as_str());
        for (name, tensor) in sorted {
            let Some(rest) = name.strip_prefix(DECODER_PREFIX) else {
                continue;
            };
            let parsed = rest
                .split_once('.')
                .and_then(|(i, p)| Some((i.parse::<usize>().ok()?, p)));
            let layer = match parsed {
                Some((i, "weight" | "bias")) if i % 2 == 0 => layers.entry(i / 2).or_default(),
                _ => {
                    return Err(SemanticError::file(
                        path,
                        format!("unexpected key {name:?}: {expected}"),
                    ));
                }
            };
            if name.ends_with(".weight") {
                layer.weight = Some(tensor);
            } else {
                layer.bias = Some(tensor);
            }
        }
        if layers.is_empty() {
            let mut keys: Vec<&str> = tensors.keys().map(String::as_str).collect();
            keys.sort_unstable();
            keys.truncate(8);
            return Err(SemanticError::file(
                path,
                format!(
                    "no key {DECODER_PREFIX}*: not a LangSplat autoencoder state dict (its first \
                     keys: {keys:?})"
                ),
            ));
        }

        let count = layers.keys().last().map_or(0, |&k| k + 1);
        let mut widths = Vec::with_capacity(count + 1);
        let mut linears = Vec::with_capacity(count);
        for k in 0..count {
            let index = 2 * k;
            let key = |p: &str| format!("{DECODER_PREFIX}{index}.{p}");
            let missing = |p: &str| {
                SemanticError::file(
                    path,
                    format!(
                        "missing key {:?}: {expected} ({count} layers found)",
                        key(p)
                    ),
                )
            };
            let found = layers.get(&k);
            let weight = found
                .and_then(|l| l.weight)
                .ok_or_else(|| missing("weight"))?;
            let bias = found.and_then(|l| l.bias).ok_or_else(|| missing("bias"))?;
            let [out, input] = weight.shape()[..] else {
                return Err(SemanticError::file(
                    path,
                    format!(
                        "key {:?} has shape {:?}: a Linear weight is [out, in]",
                        key("weight"),
                        weight.shape()
                    ),
                ));
            };
            if let Some(&previous) = widths.last()
                && input != previous
            {
                return Err(SemanticError::file(
                    path,
                    format!(
                        "key {:?} has shape [{out}, {input}] but the layer before outputs \
                         {previous} values",
                        key("weight")
                    ),
                ));
            }
            if bias.shape() != [out] {
                return Err(SemanticError::file(
                    path,
                    format!(
                        "key {:?} has shape {:?}: expected [{out}] to match {:?}",
                        key("bias"),
                        bias.shape(),
                        key("weight")
                    ),
                ));
            }
            if widths.is_empty() {
                widths.push(input);
            }
            widths.push(out);
            linears.push(LinearWeights {
                weight: read_f32(path, &key("weight"), weight)?,
                bias: read_f32(path, &key("bias"), bias)?,
                out,
                input,
            });
        }
        Ok(Self::from_linear_layers(linears, path, device))
    }

    /// A decoder of `layers` (chained: each layer's `input` is the previous one's `out`, as
    /// the caller checked), read from `source`, on `device`. Other checkpoints whose decoder
    /// is Linear layers (Feature 3DGS's 1×1 convolution is one) are built through this.
    pub(crate) fn from_linear_layers(
        layers: Vec<LinearWeights>,
        source: &Path,
        device: &Device,
    ) -> Self {
        let mut widths: Vec<usize> = layers.first().map(|l| l.input).into_iter().collect();
        let linears = layers
            .into_iter()
            .map(|l| {
                widths.push(l.out);
                let (out, input) = (l.out, l.input);
                // PyTorch keeps [out, in]; burn's Linear computes x·W with W as [in, out].
                let mut w_t = vec![0.0f32; l.weight.len()];
                for o in 0..out {
                    for i in 0..input {
                        w_t[i * out + o] = l.weight[o * input + i];
                    }
                }
                let weight = Tensor::<2>::from_data(
                    TensorData::new(w_t, [input, out]),
                    (device, DType::F32),
                );
                let bias =
                    Tensor::<1>::from_data(TensorData::new(l.bias, [out]), (device, DType::F32));
                Linear {
                    weight: Param::from_tensor(weight),
                    bias: Some(Param::from_tensor(bias)),
                }
            })
            .collect();
        LangsplatDecoder {
            module: DecoderLayers { layers: linears },
            widths,
            source: source.to_path_buf(),
        }
    }

    /// Widths from the latent to the output (LangSplat: [`LANGSPLAT_WIDTHS`]).
    pub fn widths(&self) -> &[usize] {
        &self.widths
    }

    /// Length of the latents the decoder takes.
    pub fn latent_dim(&self) -> usize {
        self.widths[0]
    }

    /// Length of the vectors it produces.
    pub fn output_dim(&self) -> usize {
        self.widths[self.widths.len() - 1]
    }

    /// The checkpoint the weights came from.
    pub fn source(&self) -> &Path {
        &self.source
    }

    /// The layers' raw output for `[rows, latent_dim]` inputs: Linear and ReLU in turn, none
    /// after the last Linear (logits, for decoders that end in a classifier).
    pub fn forward_raw(&self, latents: Tensor<2>) -> Tensor<2> {
        let layers = &self.module.layers;
        let mut x = latents;
        for (i, layer) in layers.iter().enumerate() {
            x = layer.forward(x);
            if i + 1 < layers.len() {
                x = relu(x);
            }
        }
        x
    }

    /// Decodes `[rows, latent_dim]` latents to unit `[rows, output_dim]` vectors, as LangSplat's
    /// `Autoencoder.decode`: [`LangsplatDecoder::forward_raw`], then L2 normalisation of each
    /// row.
    pub fn forward(&self, latents: Tensor<2>) -> Tensor<2> {
        let x = self.forward_raw(latents);
        let norm = (x.clone() * x.clone())
            .sum_dim(1)
            .sqrt()
            .clamp_min(MIN_NORM);
        x / norm
    }

    /// Decodes a latent matrix read from a file, in batches, back to the host. Latents of
    /// the wrong width or with a non-finite value are errors naming their file.
    pub fn decode(&self, latents: &Matrix) -> Result<Matrix> {
        if latents.dim != self.latent_dim() {
            return Err(SemanticError::Mismatch(format!(
                "{}: latents of width {} but the decoder of {} takes {} (LangSplat latents are \
                 [N, 3])",
                latents.source,
                latents.dim,
                self.source.display(),
                self.latent_dim()
            )));
        }
        if let Some(i) = latents.values.iter().position(|v| !v.is_finite()) {
            return Err(SemanticError::NonFinite {
                what: format!(
                    "latent {} of Gaussian {} in {}",
                    i % latents.dim,
                    i / latents.dim,
                    latents.source
                ),
                value: latents.values[i],
            });
        }
        self.map_rows(latents, self.output_dim(), "decoded", &|x| self.forward(x))
    }

    /// `head` applied, on the decoder's device, to batches of `inputs` (`[rows, latent_dim]`,
    /// checked by the caller), each batch's `[rows, out_dim]` result read back to the host:
    /// the batched loop every use of a decoder shares. `what` names the result in errors and
    /// in the matrix's source ("decoded", "classified").
    pub fn map_rows(
        &self,
        inputs: &Matrix,
        out_dim: usize,
        what: &str,
        head: &dyn Fn(Tensor<2>) -> Tensor<2>,
    ) -> Result<Matrix> {
        let device = self.module.devices().into_iter().next().ok_or_else(|| {
            SemanticError::Mismatch("the decoder holds no tensor (no device)".to_string())
        })?;
        let mut values = Vec::with_capacity(inputs.rows * out_dim);
        for chunk in inputs.values.chunks(DECODE_ROWS * inputs.dim) {
            let rows = chunk.len() / inputs.dim;
            let x = Tensor::<2>::from_data(
                TensorData::new(chunk.to_vec(), [rows, inputs.dim]),
                (&device, DType::F32),
            );
            let batch = head(x)
                .into_data()
                .convert::<f32>()
                .try_into_vec::<f32>()
                .map_err(|e| {
                    SemanticError::Mismatch(format!(
                        "reading the {what} rows of {} back from the device: {e:?}",
                        inputs.source
                    ))
                })?;
            values.extend(batch);
        }
        Ok(Matrix {
            source: format!("{} {what} by {}", inputs.source, self.source.display()),
            rows: inputs.rows,
            dim: out_dim,
            values,
        })
    }
}

/// A tensor's values as f32; float32 and float64 are accepted (LangSplat saves float32).
pub(crate) fn read_f32(
    path: &Path,
    key: &str,
    tensor: &pytorch_reader::Tensor,
) -> Result<Vec<f32>> {
    let bytes = tensor
        .read()
        .map_err(|e| SemanticError::file(path, format!("reading key {key:?}: {e}")))?;
    let values: Vec<f32> = match tensor.dtype() {
        pytorch_reader::DType::F32 => bytes
            .chunks_exact(4)
            .map(|b| f32::from_ne_bytes([b[0], b[1], b[2], b[3]]))
            .collect(),
        pytorch_reader::DType::F64 => bytes
            .chunks_exact(8)
            .map(|b| f64::from_ne_bytes(b.try_into().expect("8 bytes")) as f32)
            .collect(),
        other => {
            return Err(SemanticError::file(
                path,
                format!("key {key:?} has dtype {other:?}: expected float32 (or float64)"),
            ));
        }
    };
    if let Some(v) = values.iter().find(|v| !v.is_finite()) {
        return Err(SemanticError::file(
            path,
            format!("key {key:?} holds a non-finite value ({v})"),
        ));
    }
    Ok(values)
}

/// LangSplat latents decoded by the scene's decoder, scored as the `features` source.
#[derive(Debug, Clone)]
pub struct LangsplatSource {
    /// The decoded vectors with the phrase table, negatives and temperature that score them.
    pub features: FeaturesSource,
}

impl LangsplatSource {
    /// Decodes `latents` with `decoder` and scores them against `table` with the default
    /// negatives and temperature (change them through `features`).
    pub fn new(latents: &Matrix, decoder: &LangsplatDecoder, table: PhraseTable) -> Result<Self> {
        let decoded = decoder.decode(latents)?;
        Ok(LangsplatSource {
            features: FeaturesSource::new(FeatureInput::Sidecar(decoded), table),
        })
    }
}

impl TargetSource for LangsplatSource {
    fn kind(&self) -> &'static str {
        "langsplat"
    }

    fn relevancy(&self, scene: &Scene, query: &str) -> Result<Relevancy> {
        self.features.relevancy(scene, query)
    }
}
