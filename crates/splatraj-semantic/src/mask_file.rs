//! Per-Gaussian mask files: a `.npy` array with one value in [0, 1] per Gaussian (uint8, bool,
//! int32/64 or float32/64; shape `[N]` or `[N, 1]`), the object given directly instead of by a
//! query (`--mask` of `splatraj render`, `mask = "…"` of a config's query).

use std::io::BufReader;
use std::path::Path;

use crate::error::{Result, SemanticError};

/// Reads a per-Gaussian mask for a scene of `gaussians` Gaussians; errors name the file and
/// what is wrong (dtype, shape, count, a value outside [0, 1]).
pub fn read_mask_file(path: &Path, gaussians: usize) -> Result<Vec<f32>> {
    let fail = |detail: String| SemanticError::File {
        path: path.to_path_buf(),
        detail,
    };
    let file = splatraj_scene::input::open(path)
        .map(|(file, _)| file)
        .map_err(|e| SemanticError::io(path, e))?;
    crate::npy_size::check_shape_product_file(path).map_err(fail)?;
    let npy = npyz::NpyFile::new(BufReader::new(file))
        .map_err(|e| fail(format!("not a readable .npy file: {e}")))?;
    let shape = npy.shape().to_vec();
    if !(shape.len() == 1 || (shape.len() == 2 && shape[1] == 1)) {
        return Err(fail(format!(
            "shape {shape:?} must be [N] or [N, 1], one value per Gaussian"
        )));
    }
    crate::npy_size::check_npy_file(path, npy.header()).map_err(fail)?;
    let dtype = npy.dtype().descr();
    let values = read_values(npy)
        .map_err(|e| fail(e.to_string()))?
        .ok_or_else(|| {
            fail(format!(
                "dtype {dtype} is not supported (use uint8, bool, int32, int64, float32 or \
                 float64)"
            ))
        })?;
    if values.len() != gaussians {
        return Err(fail(format!(
            "holds {} values but the scene has {gaussians} Gaussians (one value per Gaussian \
             is needed)",
            values.len()
        )));
    }
    if let Some(i) = values
        .iter()
        .position(|v| !(v.is_finite() && (0.0..=1.0).contains(v)))
    {
        return Err(fail(format!(
            "value {} at index {i} is not in [0, 1]",
            values[i]
        )));
    }
    Ok(values.into_iter().map(|v| v as f32).collect())
}

/// Every value as f64, trying each supported dtype in turn (`try_data` hands the file back
/// when the dtype differs); None for an unsupported dtype.
fn read_values<R: std::io::Read>(npy: npyz::NpyFile<R>) -> std::io::Result<Option<Vec<f64>>> {
    let npy = match npy.try_data::<u8>() {
        Ok(data) => return collect(data, f64::from),
        Err(npy) => npy,
    };
    let npy = match npy.try_data::<bool>() {
        Ok(data) => return collect(data, |b| if b { 1.0 } else { 0.0 }),
        Err(npy) => npy,
    };
    let npy = match npy.try_data::<f32>() {
        Ok(data) => return collect(data, f64::from),
        Err(npy) => npy,
    };
    let npy = match npy.try_data::<f64>() {
        Ok(data) => return collect(data, |v| v),
        Err(npy) => npy,
    };
    let npy = match npy.try_data::<i64>() {
        Ok(data) => return collect(data, |v| v as f64),
        Err(npy) => npy,
    };
    match npy.try_data::<i32>() {
        Ok(data) => collect(data, f64::from),
        Err(_) => Ok(None),
    }
}

fn collect<T: npyz::Deserialize, R: std::io::Read>(
    data: npyz::NpyReader<T, R>,
    convert: impl Fn(T) -> f64,
) -> std::io::Result<Option<Vec<f64>>> {
    data.map(|v| v.map(&convert))
        .collect::<std::io::Result<Vec<f64>>>()
        .map(Some)
}
