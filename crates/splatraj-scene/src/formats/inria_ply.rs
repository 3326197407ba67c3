//! INRIA 3DGS PLY (the layout of the reference implementation, nerfstudio, gsplat, Brush):
//! `x y z [nx ny nz] f_dc_0..2 [f_rest_*] opacity scale_0..2 rot_0..3` plus any extras.

use std::collections::BTreeMap;
use std::path::Path;

use super::ply_table::{Column, PlyFile, Table};
use crate::error::{Result, SceneError};
use crate::scene::{Extras, Features, Labels, NamedProperty, Scene, sh_degree_for_coeffs, sigmoid};

/// Property names read as integer labels, in order of preference.
pub const LABEL_PROPERTIES: [&str; 3] = ["label", "obj_id", "instance"];
/// Property name prefixes read as feature vectors (`semantic_0`, `f_lang_0`, …).
pub const FEATURE_PREFIXES: [&str; 2] = ["semantic_", "f_lang_"];
/// Header comment prefix that carries a label's name (`comment label_name 3 apple`).
pub const LABEL_NAME_COMMENT: &str = "label_name";
/// Properties with a fixed meaning in the INRIA layout.
const CORE: [&str; 14] = [
    "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
    "rot_0", "rot_1", "rot_2", "rot_3",
];
/// Normals that 3DGS trainers write as zeros; they carry nothing and are not kept.
const IGNORED: [&str; 3] = ["nx", "ny", "nz"];

/// Columns whose name is `prefix` followed by 0, 1, 2, … (all of them, sorted by index).
/// A gap in the numbering is an error.
pub fn numbered_columns<'a>(
    table: &'a Table,
    prefix: &str,
    path: &Path,
) -> Result<Vec<&'a Column>> {
    let mut numbered: Vec<(usize, &Column)> = table
        .columns
        .iter()
        .filter_map(|c| Some((c.name.strip_prefix(prefix)?.parse().ok()?, c)))
        .collect();
    numbered.sort_by_key(|(k, _)| *k);
    for (expected, (k, _)) in numbered.iter().enumerate() {
        if *k != expected {
            return Err(SceneError::malformed(
                path,
                format!(
                    "element '{}' has {prefix}{k} but no {prefix}{expected}",
                    table.name
                ),
            ));
        }
    }
    Ok(numbered.into_iter().map(|(_, c)| c).collect())
}

/// Builds a scene (not yet validated) from the `vertex` element of an INRIA-layout PLY.
pub fn scene_from_tables(ply: &PlyFile, path: &Path) -> Result<Scene> {
    let vertex = ply
        .table("vertex")
        .ok_or_else(|| SceneError::malformed(path, "no 'vertex' element"))?;
    if vertex.column("f_dc_0").is_none() && vertex.column("red").is_some() {
        return Err(SceneError::malformed(
            path,
            "this PLY has red/green/blue but no f_dc_0: it looks like a point cloud, not a \
             Gaussian splat scene",
        ));
    }
    let col = |name: &str| vertex.require(name, path);
    let n = vertex.count;
    let [x, y, z] = [col("x")?, col("y")?, col("z")?];
    let dc = [col("f_dc_0")?, col("f_dc_1")?, col("f_dc_2")?];
    let opacity = col("opacity")?;
    let scale = [col("scale_0")?, col("scale_1")?, col("scale_2")?];
    let rot = [col("rot_0")?, col("rot_1")?, col("rot_2")?, col("rot_3")?];

    let rest = numbered_columns(vertex, "f_rest_", path)?;
    if rest.len() % 3 != 0 {
        return Err(SceneError::malformed(
            path,
            format!(
                "{} f_rest_* properties: not a multiple of 3 channels",
                rest.len()
            ),
        ));
    }
    let coeffs = rest.len() / 3 + 1;
    let sh_degree = sh_degree_for_coeffs(coeffs).ok_or_else(|| {
        SceneError::malformed(
            path,
            format!(
                "{} f_rest_* properties do not make an SH degree 0-3 (expected 0, 9, 24 or 45)",
                rest.len()
            ),
        )
    })?;

    let mut sh = vec![0.0f32; n * coeffs * 3];
    for (i, gaussian) in sh.chunks_exact_mut(coeffs * 3).enumerate() {
        for c in 0..3 {
            gaussian[c] = dc[c].f32(i);
        }
        // f_rest_j is grouped by channel: j = channel · (coeffs − 1) + (coefficient − 1).
        for (j, column) in rest.iter().enumerate() {
            let (channel, k) = (j / (coeffs - 1), j % (coeffs - 1) + 1);
            gaussian[k * 3 + channel] = column.f32(i);
        }
    }

    let mut scene = Scene {
        means: (0..n).map(|i| [x.f32(i), y.f32(i), z.f32(i)]).collect(),
        scales: (0..n)
            .map(|i| std::array::from_fn(|k| scale[k].f32(i).exp()))
            .collect(),
        rotations: (0..n)
            .map(|i| std::array::from_fn(|k| rot[k].f32(i)))
            .collect(),
        opacities: (0..n).map(|i| sigmoid(opacity.f32(i))).collect(),
        sh_degree,
        sh,
        extras: extras_from_table(vertex, path)?,
    };
    if let Some(labels) = &mut scene.extras.labels {
        labels.names = label_names_from_comments(&ply.comments);
    }
    Ok(scene)
}

/// Label names from `comment label_name <id> <name>` header lines (written by splatraj).
fn label_names_from_comments(comments: &[String]) -> BTreeMap<i32, String> {
    comments
        .iter()
        .filter_map(|c| {
            let rest = c.strip_prefix(LABEL_NAME_COMMENT)?.trim_start();
            let (id, name) = rest.split_once(' ')?;
            Some((id.parse().ok()?, name.trim().to_string()))
        })
        .collect()
}

/// Labels, features and other properties of the `vertex` element.
fn extras_from_table(vertex: &Table, path: &Path) -> Result<Extras> {
    let mut extras = Extras::default();
    let mut used: Vec<&str> = CORE.iter().chain(&IGNORED).copied().collect();
    let rest_names: Vec<String> = numbered_columns(vertex, "f_rest_", path)?
        .iter()
        .map(|c| c.name.clone())
        .collect();
    used.extend(rest_names.iter().map(String::as_str));

    if let Some(column) = LABEL_PROPERTIES.iter().find_map(|name| vertex.column(name)) {
        extras.labels = Some(labels_from_column(column, path)?);
        used.push(&column.name);
    }

    for prefix in FEATURE_PREFIXES {
        let columns = numbered_columns(vertex, prefix, path)?;
        if columns.is_empty() {
            continue;
        }
        if extras.features.is_some() {
            return Err(SceneError::malformed(
                path,
                format!("two feature groups ({:?}): keep one", FEATURE_PREFIXES),
            ));
        }
        let dim = columns.len();
        let mut values = vec![0.0f32; vertex.count * dim];
        for (d, column) in columns.iter().enumerate() {
            for i in 0..vertex.count {
                values[i * dim + d] = column.f32(i);
            }
        }
        extras.features = Some(Features {
            names: columns.iter().map(|c| c.name.clone()).collect(),
            dim,
            values,
        });
    }
    let feature_names: Vec<String> = extras
        .features
        .as_ref()
        .map(|f| f.names.clone())
        .unwrap_or_default();
    used.extend(feature_names.iter().map(String::as_str));

    extras.properties = vertex
        .columns
        .iter()
        .filter(|c| !used.contains(&c.name.as_str()))
        .map(|c| NamedProperty {
            name: c.name.clone(),
            values: c.to_f32_vec(),
        })
        .collect();
    Ok(extras)
}

/// Integer labels from a PLY column; float columns must hold whole numbers.
fn labels_from_column(column: &Column, path: &Path) -> Result<Labels> {
    let n = column.len();
    let mut ids = Vec::with_capacity(n);
    for i in 0..n {
        let v = column.f64(i);
        if v.fract() != 0.0 || !v.is_finite() || v.abs() > i32::MAX as f64 {
            return Err(SceneError::malformed(
                path,
                format!(
                    "property '{}' of Gaussian {i} is {v}: a label must be a whole number",
                    column.name
                ),
            ));
        }
        ids.push(v as i32);
    }
    Ok(Labels {
        source: column.name.clone(),
        ids,
        names: BTreeMap::new(),
    })
}
