//! The tensors of a CLIP checkpoint, by name, from the files users have: open_clip's
//! `open_clip_model.safetensors` (or any safetensors state dict) and `torch.save`d state dicts
//! (`open_clip_pytorch_model.bin`, a non-TorchScript OpenAI state dict), read with burn's
//! PyTorch reader. OpenAI's original `ViT-B-16.pt` files are TorchScript archives, which that
//! reader cannot read: `docs/open-vocabulary.md` gives the one-line conversion.
//!
//! Only names, shapes and dtypes are read up front; values are read (and converted to f32
//! from float16, bfloat16, float32 or float64) for the tensors a tower uses.

use std::collections::BTreeMap;

/// The largest weight magnitude accepted: float16's range, in which CLIP checkpoints are
/// trained and shipped. A value beyond it overflows the towers' activations in f32 and would
/// surface later as a non-finite pixel of a rendered view, far from its cause.
const MAX_WEIGHT: f32 = 65_504.0;
use std::path::{Path, PathBuf};

use burn::store::pytorch_reader::{self, PytorchReader};
use safetensors::{Dtype, SafeTensors};

use crate::error::{Result, SemanticError};

/// Element types a checkpoint tensor may have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Element {
    F16,
    Bf16,
    F32,
    F64,
    Other,
}

/// Where the tensors come from.
enum Container {
    /// The whole file (safetensors is read into memory once).
    Safetensors(Vec<u8>),
    /// burn's lazy PyTorch reader.
    Pytorch(Box<PytorchReader>),
}

/// A checkpoint's tensors: name → shape, with values read on request.
pub struct StateDict {
    path: PathBuf,
    shapes: BTreeMap<String, Vec<usize>>,
    container: Container,
}

impl std::fmt::Debug for StateDict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "StateDict({}, {} tensors)",
            self.path.display(),
            self.shapes.len()
        )
    }
}

impl StateDict {
    /// Opens `path`: safetensors when the file starts like one (an 8-byte header length
    /// followed by `{`), else a PyTorch checkpoint.
    pub fn open(path: &Path) -> Result<Self> {
        let bytes =
            splatraj_scene::input::read_bytes(path).map_err(|e| SemanticError::io(path, e))?;
        if bytes.len() > 8 && bytes[8] == b'{' {
            let tensors = SafeTensors::deserialize(&bytes).map_err(|e| {
                SemanticError::file(path, format!("not a readable safetensors file: {e}"))
            })?;
            let shapes = tensors
                .iter()
                .map(|(name, view)| (name.to_string(), view.shape().to_vec()))
                .collect();
            return Ok(StateDict {
                path: path.to_path_buf(),
                shapes,
                container: Container::Safetensors(bytes),
            });
        }
        drop(bytes);
        let reader = PytorchReader::new(path).map_err(|e| {
            SemanticError::file(
                path,
                format!(
                    "neither a safetensors file nor a readable PyTorch state dict ({e}); an \
                     OpenAI TorchScript .pt must be converted first (see \
                     docs/open-vocabulary.md)"
                ),
            )
        })?;
        let shapes = reader
            .tensors()
            .iter()
            .map(|(name, t)| (name.clone(), t.shape().to_vec()))
            .collect();
        Ok(StateDict {
            path: path.to_path_buf(),
            shapes,
            container: Container::Pytorch(Box::new(reader)),
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Every tensor's name and shape.
    pub fn shapes(&self) -> &BTreeMap<String, Vec<usize>> {
        &self.shapes
    }

    /// The values of tensor `name` as f32 (row-major), checked to be finite.
    pub fn f32(&self, name: &str) -> Result<Vec<f32>> {
        let (element, bytes, little_endian) = match &self.container {
            Container::Safetensors(bytes) => {
                let tensors = SafeTensors::deserialize(bytes)
                    .map_err(|e| SemanticError::file(&self.path, e.to_string()))?;
                let view = tensors.tensor(name).map_err(|_| self.missing(name))?;
                let element = match view.dtype() {
                    Dtype::F16 => Element::F16,
                    Dtype::BF16 => Element::Bf16,
                    Dtype::F32 => Element::F32,
                    Dtype::F64 => Element::F64,
                    _ => Element::Other,
                };
                (element, view.data().to_vec(), true)
            }
            Container::Pytorch(reader) => {
                let tensor = reader.get(name).ok_or_else(|| self.missing(name))?;
                let element = match tensor.dtype() {
                    pytorch_reader::DType::F16 => Element::F16,
                    pytorch_reader::DType::BF16 => Element::Bf16,
                    pytorch_reader::DType::F32 => Element::F32,
                    pytorch_reader::DType::F64 => Element::F64,
                    _ => Element::Other,
                };
                let bytes = tensor.read().map_err(|e| {
                    SemanticError::file(&self.path, format!("reading tensor {name:?}: {e}"))
                })?;
                // The PyTorch reader hands values over in the machine's byte order.
                (element, bytes, cfg!(target_endian = "little"))
            }
        };
        let word = |b: &[u8]| -> [u8; 2] {
            let w = [b[0], b[1]];
            if little_endian { w } else { [w[1], w[0]] }
        };
        let values: Vec<f32> = match element {
            Element::F16 => bytes
                .chunks_exact(2)
                .map(|b| half::f16::from_le_bytes(word(b)).to_f32())
                .collect(),
            Element::Bf16 => bytes
                .chunks_exact(2)
                .map(|b| half::bf16::from_le_bytes(word(b)).to_f32())
                .collect(),
            Element::F32 => bytes
                .chunks_exact(4)
                .map(|b| {
                    let w = [b[0], b[1], b[2], b[3]];
                    if little_endian {
                        f32::from_le_bytes(w)
                    } else {
                        f32::from_be_bytes(w)
                    }
                })
                .collect(),
            Element::F64 => bytes
                .chunks_exact(8)
                .map(|b| {
                    let w: [u8; 8] = b.try_into().expect("8 bytes");
                    if little_endian {
                        f64::from_le_bytes(w) as f32
                    } else {
                        f64::from_be_bytes(w) as f32
                    }
                })
                .collect(),
            Element::Other => {
                return Err(SemanticError::file(
                    &self.path,
                    format!(
                        "tensor {name:?} is not a floating-point tensor (float16, bfloat16, \
                         float32 or float64)"
                    ),
                ));
            }
        };
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(SemanticError::file(
                &self.path,
                format!(
                    "tensor {name:?} holds a non-finite value ({}) at {i}",
                    values[i]
                ),
            ));
        }
        if let Some(i) = values.iter().position(|v| v.abs() > MAX_WEIGHT) {
            return Err(SemanticError::file(
                &self.path,
                format!(
                    "tensor {name:?} holds {:e} at {i}, beyond ±{MAX_WEIGHT}: not a trained \
                     weight (the activations would overflow)",
                    values[i]
                ),
            ));
        }
        Ok(values)
    }

    fn missing(&self, name: &str) -> SemanticError {
        SemanticError::file(&self.path, format!("no tensor {name:?}"))
    }
}
