//! INRIA 3DGS binary little-endian PLY writer, with splatraj's extras.
//!
//! The layout is the reference implementation's (`x y z nx ny nz f_dc_* f_rest_* opacity
//! scale_* rot_*`), so every 3DGS tool reads it. Extras follow: the label column (as `int`,
//! under its original name when that is one we read back, else `label`), feature columns
//! (under their original names, or `semantic_i`), and other float properties by name. Label
//! names go into header comments `comment label_name <id> <name>`, which the reader parses.

use std::io::Write;
use std::path::Path;

use super::inria_ply::{FEATURE_PREFIXES, LABEL_NAME_COMMENT, LABEL_PROPERTIES};
use crate::atomic::write_atomically;
use crate::error::{Result, SceneError};
use crate::scene::{Scene, logit};

/// Writes `scene` as an INRIA binary PLY (whole or not at all).
pub fn write_inria_ply(scene: &Scene, path: &Path) -> Result<()> {
    write_atomically(path, |out| write_ply_to(scene, out)).map_err(|e| SceneError::io(path, e))
}

/// Name under which the label column is written.
fn label_column_name(source: &str) -> &str {
    LABEL_PROPERTIES
        .iter()
        .find(|p| **p == source)
        .copied()
        .unwrap_or("label")
}

/// Names under which the feature columns are written: their own if we would read them back
/// as features, `semantic_i` otherwise.
fn feature_column_names(names: &[String], dim: usize) -> Vec<String> {
    let readable = names.len() == dim
        && FEATURE_PREFIXES.iter().any(|prefix| {
            names
                .iter()
                .enumerate()
                .all(|(i, n)| *n == format!("{prefix}{i}"))
        });
    if readable {
        names.to_vec()
    } else {
        (0..dim).map(|i| format!("semantic_{i}")).collect()
    }
}

/// Writes the PLY to any writer.
pub fn write_ply_to(scene: &Scene, out: &mut dyn Write) -> std::io::Result<()> {
    let n = scene.len();
    let coeffs = scene.sh_coeffs();
    let mut header =
        String::from("ply\nformat binary_little_endian 1.0\ncomment written by splatraj\n");
    if let Some(labels) = &scene.extras.labels {
        for (id, name) in &labels.names {
            // Names are single-line by construction of a header; newlines would break it.
            let name = name.replace(['\n', '\r'], " ");
            header += &format!("comment {LABEL_NAME_COMMENT} {id} {name}\n");
        }
    }
    header += &format!("element vertex {n}\n");
    let mut float_names: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .map(String::from)
    .to_vec();
    float_names.extend((0..3 * (coeffs - 1)).map(|j| format!("f_rest_{j}")));
    float_names.extend(
        [
            "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        ]
        .map(String::from),
    );
    for name in &float_names {
        header += &format!("property float {name}\n");
    }
    if let Some(labels) = &scene.extras.labels {
        header += &format!("property int {}\n", label_column_name(&labels.source));
    }
    if let Some(features) = &scene.extras.features {
        for name in feature_column_names(&features.names, features.dim) {
            header += &format!("property float {name}\n");
        }
    }
    for property in &scene.extras.properties {
        header += &format!("property float {}\n", property.name);
    }
    header += "end_header\n";
    out.write_all(header.as_bytes())?;

    let mut row: Vec<u8> = Vec::with_capacity(4 * (float_names.len() + 64));
    for i in 0..n {
        row.clear();
        let mut put = |v: f32| row.extend_from_slice(&v.to_le_bytes());
        scene.means[i].iter().for_each(|&v| put(v));
        [0.0; 3].iter().for_each(|&v| put(v));
        let sh = scene.sh_of(i);
        (0..3).for_each(|c| put(sh[c]));
        // INRIA groups f_rest by channel: all red coefficients, then green, then blue.
        for c in 0..3 {
            for k in 1..coeffs {
                put(sh[k * 3 + c]);
            }
        }
        put(logit(scene.opacities[i]));
        scene.scales[i].iter().for_each(|&s| put(s.ln()));
        scene.rotations[i].iter().for_each(|&q| put(q));
        if let Some(labels) = &scene.extras.labels {
            row.extend_from_slice(&labels.ids[i].to_le_bytes());
        }
        let mut put = |v: f32| row.extend_from_slice(&v.to_le_bytes());
        if let Some(features) = &scene.extras.features {
            features.row(i).iter().for_each(|&v| put(v));
        }
        for property in &scene.extras.properties {
            put(property.values[i]);
        }
        out.write_all(&row)?;
    }
    Ok(())
}
