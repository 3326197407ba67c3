//! The lifted field on disk, so that the second query on a scene is fast.
//!
//! One safetensors file per (scene, views, options, weights file): tensors `mean` `[dim]`,
//! `basis` `[k, dim]`, `codes` `[N, k]`, `weights` `[N]`, and in the metadata the key and the
//! explained variance. The key hashes what the field depends on: the scene's Gaussians (their
//! bytes, so a renamed file still hits and an edited one misses), the view and field options,
//! the given cameras, and the weights file's path, length and modification time (hashing a
//! 600 MB checkpoint on every query would cost more than it saves). Files are written
//! atomically, with a hash of their tensors' bytes in the metadata (`content`): a cache is
//! trusted only when its tensors still hash to it and hold what a field can (finite values,
//! weights ≥ 0, no zero basis vector); one that cannot be read, or fails these, is ignored with
//! a warning and rebuilt.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use safetensors::tensor::{Dtype, TensorView};
use splatraj_scene::Scene;

use crate::error::{LiftError, Result};
use crate::field::LiftedField;
use crate::pca::Subspace;

/// A stable 64-bit FNV-1a hash (std's hasher may change between Rust versions, which would
/// silently invalidate every cache).
#[derive(Debug, Clone, Copy)]
pub struct Fnv(u64);

impl Default for Fnv {
    fn default() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv {
    /// Adds bytes.
    pub fn bytes(&mut self, bytes: &[u8]) -> &mut Self {
        for &b in bytes {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
        self
    }

    /// Adds f32 values by their bits, a word per step (the key is hashed on every query, over
    /// about 60 floats per Gaussian: bytewise was a second per 6 M Gaussians).
    pub fn floats(&mut self, values: &[f32]) -> &mut Self {
        for v in values {
            self.0 ^= u64::from(v.to_bits());
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
        self
    }

    /// The hash as 16 hex digits.
    pub fn hex(&self) -> String {
        format!("{:016x}", self.0)
    }
}

/// Adds what rendering the scene depends on.
pub fn hash_scene(hash: &mut Fnv, scene: &Scene) {
    hash.bytes(&(scene.len() as u64).to_le_bytes());
    hash.floats(scene.means.as_flattened());
    hash.floats(scene.scales.as_flattened());
    hash.floats(scene.rotations.as_flattened());
    hash.floats(&scene.opacities);
    hash.bytes(&[scene.sh_degree]);
    hash.floats(&scene.sh);
}

/// Adds a file's identity: canonical path, length and modification time.
pub fn hash_file_identity(hash: &mut Fnv, path: &Path) -> Result<()> {
    let meta = std::fs::metadata(path).map_err(|e| LiftError::file(path, e))?;
    let canonical = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    hash.bytes(canonical.to_string_lossy().as_bytes());
    hash.bytes(&meta.len().to_le_bytes());
    if let Ok(modified) = meta.modified()
        && let Ok(since) = modified.duration_since(std::time::UNIX_EPOCH)
    {
        hash.bytes(&since.as_nanos().to_le_bytes());
    }
    Ok(())
}

/// The cache file of `key` in `dir`.
pub fn cache_path(dir: &Path, key: &str) -> PathBuf {
    dir.join(format!("lifted-{key}.safetensors"))
}

/// The hash of a cache's tensors, in the order mean, basis, codes, weights.
fn content_hash(tensors: &[&[u8]]) -> String {
    let mut hash = Fnv::default();
    for bytes in tensors {
        hash.bytes(&(bytes.len() as u64).to_le_bytes()).bytes(bytes);
    }
    hash.hex()
}

/// Writes `field` under `key` (atomically).
pub fn write(path: &Path, key: &str, field: &LiftedField) -> Result<()> {
    let sub = &field.subspace;
    let k = sub.components();
    let n = field.len();
    let bytes = |v: &[f32]| -> Vec<u8> { v.iter().flat_map(|x| x.to_le_bytes()).collect() };
    let (mean, basis, codes, weights) = (
        bytes(&sub.mean),
        bytes(&sub.basis),
        bytes(&field.codes),
        bytes(&field.weights),
    );
    fn view<'a>(path: &Path, data: &'a [u8], shape: Vec<usize>) -> Result<TensorView<'a>> {
        TensorView::new(Dtype::F32, shape, data).map_err(|e| LiftError::file(path, e))
    }
    let tensors = vec![
        ("mean", view(path, &mean, vec![sub.dim])?),
        ("basis", view(path, &basis, vec![k, sub.dim])?),
        ("codes", view(path, &codes, vec![n, k])?),
        ("weights", view(path, &weights, vec![n])?),
    ];
    let metadata = HashMap::from([
        ("key".to_string(), key.to_string()),
        ("explained".to_string(), sub.explained.to_string()),
        (
            "content".to_string(),
            content_hash(&[&mean, &basis, &codes, &weights]),
        ),
    ]);
    let data =
        safetensors::serialize(tensors, Some(metadata)).map_err(|e| LiftError::file(path, e))?;
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| LiftError::file(dir, e))?;
    }
    splatraj_scene::atomic::write_atomically(path, |out| out.write_all(&data))
        .map_err(|e| LiftError::file(path, e))
}

/// Reads the field stored under `key` for a scene of `n` Gaussians; `Ok(None)` when there is
/// no such file, an error when it exists but does not hold that field.
pub fn read(path: &Path, key: &str, n: usize) -> Result<Option<LiftedField>> {
    let data = match splatraj_scene::input::read_bytes(path) {
        Ok(data) => data,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(LiftError::file(path, e)),
    };
    let bad =
        |why: String| LiftError::file(path, format!("not a lifted field of this scene: {why}"));
    let (_, meta) =
        safetensors::SafeTensors::read_metadata(&data).map_err(|e| bad(e.to_string()))?;
    let metadata = meta.metadata().clone().unwrap_or_default();
    if metadata.get("key").map(String::as_str) != Some(key) {
        return Err(bad("its key differs".into()));
    }
    let explained: f64 = metadata
        .get("explained")
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| bad("no explained variance".into()))?;
    let tensors = safetensors::SafeTensors::deserialize(&data).map_err(|e| bad(e.to_string()))?;
    let written = metadata
        .get("content")
        .ok_or_else(|| bad("no content hash (written by another version)".into()))?;
    let raw = |name: &str| {
        tensors
            .tensor(name)
            .map(|t| t.data().to_vec())
            .unwrap_or_default()
    };
    let content: Vec<Vec<u8>> = ["mean", "basis", "codes", "weights"].map(raw).to_vec();
    let refs: Vec<&[u8]> = content.iter().map(Vec::as_slice).collect();
    if content_hash(&refs) != *written {
        return Err(bad(
            "its tensors do not hash to the content hash written with them (edited or damaged)"
                .into(),
        ));
    }
    let get = |name: &str| -> Result<(Vec<usize>, Vec<f32>)> {
        let t = tensors
            .tensor(name)
            .map_err(|e| bad(format!("{name}: {e}")))?;
        if t.dtype() != Dtype::F32 {
            return Err(bad(format!("{name} is not f32")));
        }
        let values: Vec<f32> = t
            .data()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        if values.iter().any(|v| !v.is_finite()) {
            return Err(bad(format!("{name} holds a non-finite value")));
        }
        Ok((t.shape().to_vec(), values))
    };
    let (mean_shape, mean) = get("mean")?;
    let (basis_shape, basis) = get("basis")?;
    let (codes_shape, codes) = get("codes")?;
    let (weights_shape, weights) = get("weights")?;
    let dim = mean_shape.first().copied().unwrap_or(0);
    let k = basis_shape.first().copied().unwrap_or(0);
    if mean_shape != [dim]
        || basis_shape != [k, dim]
        || codes_shape != [n, k]
        || weights_shape != [n]
        || dim == 0
        || k == 0
    {
        return Err(bad(format!(
            "shapes mean {mean_shape:?}, basis {basis_shape:?}, codes {codes_shape:?}, weights \
             {weights_shape:?} do not fit a scene of {n} Gaussians"
        )));
    }
    // What a field built here holds: blending weights are sums of α·T ≥ 0, basis vectors are
    // unit principal directions, and nothing is near f32's range.
    if let Some(w) = weights.iter().find(|w| **w < 0.0) {
        return Err(bad(format!("a weight is negative ({w})")));
    }
    if basis
        .chunks_exact(dim)
        .any(|row| row.iter().map(|v| v * v).sum::<f32>() < 1e-6)
    {
        return Err(bad("a basis vector is zero".into()));
    }
    let huge = 1e15f32;
    if mean
        .iter()
        .chain(&basis)
        .chain(&codes)
        .chain(&weights)
        .any(|v| v.abs() > huge)
    {
        return Err(bad(format!("a value is beyond {huge:e}")));
    }
    Ok(Some(LiftedField {
        subspace: Subspace {
            dim,
            mean,
            basis,
            explained,
        },
        codes,
        weights,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A field of 3 Gaussians, 2 components of 4 dimensions.
    fn field() -> LiftedField {
        LiftedField {
            subspace: Subspace {
                dim: 4,
                mean: vec![0.1, 0.2, 0.3, 0.4],
                basis: vec![1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
                explained: 0.9,
            },
            codes: vec![0.5, -0.5, 0.25, 0.0, 1.0, 2.0],
            weights: vec![1.0, 0.5, 2.0],
        }
    }

    fn error(path: &Path) -> String {
        match read(path, "k", 3) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("a lying cache was trusted"),
        }
    }

    #[test]
    fn a_cache_is_trusted_only_intact_and_plausible() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("lifted-k.safetensors");
        write(&path, "k", &field()).unwrap();
        let back = read(&path, "k", 3).unwrap().expect("the cache is there");
        assert_eq!(back.weights, field().weights);

        // A weight edited in place (its bytes changed, the hash not): found by the hash.
        let mut bytes = std::fs::read(&path).unwrap();
        let at = bytes
            .windows(4)
            .rposition(|w| w == 2.0f32.to_le_bytes())
            .unwrap();
        bytes[at..at + 4].copy_from_slice(&(-2.0f32).to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        assert!(error(&path).contains("do not hash"), "{}", error(&path));

        // Written with a matching hash but holding what no field holds.
        type Edit = fn(&mut LiftedField);
        let cases: [(Edit, &str); 3] = [
            (|f| f.weights[1] = -0.5, "negative"),
            (|f| f.subspace.basis[4..].fill(0.0), "basis vector is zero"),
            (|f| f.codes[2] = 1e38, "beyond"),
        ];
        for (edit, mentions) in cases {
            let mut lying = field();
            edit(&mut lying);
            write(&path, "k", &lying).unwrap();
            let e = error(&path);
            assert!(e.contains(mentions), "{e}");
        }
    }
}
