//! Ground-truth label sidecars: per-Gaussian instance ids in a JSON file.
//!
//! Two forms are read:
//! - the Segments.ai point-cloud form that SuperSplat's examples ship
//!   (`dataset.samples[0].labels["ground-truth"].attributes.point_annotations`, one instance
//!   id per Gaussian, 0 = unlabelled; names from `annotations[].category_id` and
//!   `dataset.task_attributes.categories[]`);
//! - a plain array of integers, one per Gaussian (no names).
//!
//! [`write_label_sidecar`] writes the plain array when no label has a name, else the
//! Segments.ai form (each named id its own category, of the same id).

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::{Value, json};

use crate::atomic::write_atomically;
use crate::error::{Result, SceneError};
use crate::scene::Labels;

/// Reads a label sidecar for a scene of `expected_len` Gaussians.
pub fn read_label_sidecar(path: &Path, expected_len: usize) -> Result<Labels> {
    let text = crate::input::read_text(path).map_err(|e| SceneError::io(path, e))?;
    let json: Value = serde_json::from_str(&text)
        .map_err(|e| SceneError::sidecar(path, format!("not valid JSON: {e}")))?;
    let labels = labels_from_json(&json, path)?;
    if labels.ids.len() != expected_len {
        return Err(SceneError::sidecar(
            path,
            format!(
                "{} labels for a scene of {expected_len} Gaussians: the sidecar belongs to another scene",
                labels.ids.len()
            ),
        ));
    }
    Ok(labels)
}

/// Labels from either supported JSON form.
pub fn labels_from_json(json: &Value, path: &Path) -> Result<Labels> {
    if let Value::Array(values) = json {
        return Ok(Labels {
            source: path.display().to_string(),
            ids: ids_from_array(values, "the top-level array", path)?,
            names: BTreeMap::new(),
        });
    }
    const POINTS: &str = "dataset.samples[0].labels[\"ground-truth\"].attributes.point_annotations";
    let attributes = json
        .pointer("/dataset/samples/0/labels/ground-truth/attributes")
        .ok_or_else(|| {
            SceneError::sidecar(
                path,
                format!("expected a JSON array of label ids or a Segments.ai file with {POINTS}"),
            )
        })?;
    let points = attributes
        .get("point_annotations")
        .and_then(Value::as_array)
        .ok_or_else(|| SceneError::sidecar(path, format!("{POINTS} is missing or not an array")))?;
    let ids = ids_from_array(points, POINTS, path)?;

    let category_names: BTreeMap<i64, String> = json
        .pointer("/dataset/task_attributes/categories")
        .and_then(Value::as_array)
        .map(|categories| {
            categories
                .iter()
                .filter_map(|c| {
                    Some((c.get("id")?.as_i64()?, c.get("name")?.as_str()?.to_string()))
                })
                .collect()
        })
        .unwrap_or_default();
    let mut names = BTreeMap::new();
    for annotation in attributes
        .get("annotations")
        .and_then(Value::as_array)
        .into_iter()
        .flatten()
    {
        let (Some(id), Some(category)) = (
            annotation.get("id").and_then(Value::as_i64),
            annotation.get("category_id").and_then(Value::as_i64),
        ) else {
            continue;
        };
        if let (Ok(id), Some(name)) = (i32::try_from(id), category_names.get(&category)) {
            names.insert(id, name.clone());
        }
    }
    Ok(Labels {
        source: path.display().to_string(),
        ids,
        names,
    })
}

/// Whole-number ids from a JSON array (integers, or floats with no fractional part).
fn ids_from_array(values: &[Value], what: &str, path: &Path) -> Result<Vec<i32>> {
    values
        .iter()
        .enumerate()
        .map(|(i, v)| {
            v.as_f64()
                .filter(|x| x.fract() == 0.0 && x.abs() <= i32::MAX as f64)
                .map(|x| x as i32)
                .ok_or_else(|| {
                    SceneError::sidecar(
                        path,
                        format!("{what}[{i}] is {v}: expected a whole number"),
                    )
                })
        })
        .collect()
}

/// `labels` as sidecar JSON that [`labels_from_json`] reads back to the same ids and names.
pub fn label_sidecar_json(labels: &crate::scene::Labels) -> Value {
    if labels.names.is_empty() {
        return json!(labels.ids);
    }
    let annotations: Vec<Value> = labels
        .names
        .keys()
        .map(|&id| json!({ "id": id, "category_id": id }))
        .collect();
    let categories: Vec<Value> = labels
        .names
        .iter()
        .map(|(&id, name)| json!({ "id": id, "name": name }))
        .collect();
    json!({
        "dataset": {
            "task_attributes": { "format_version": "0.1", "categories": categories },
            "samples": [{
                "labels": {
                    "ground-truth": {
                        "attributes": {
                            "format_version": "0.2",
                            "annotations": annotations,
                            "point_annotations": labels.ids,
                        }
                    }
                }
            }]
        }
    })
}

/// Writes `labels` as a sidecar at `path` ([`label_sidecar_json`]), whole or not at all;
/// refuses to replace anything but a regular file (a folder, a device, a pipe).
pub fn write_label_sidecar(path: &Path, labels: &crate::scene::Labels) -> Result<()> {
    if let Ok(meta) = std::fs::metadata(path)
        && !meta.is_file()
    {
        return Err(SceneError::sidecar(
            path,
            "exists and is not a regular file: not replacing it",
        ));
    }
    let text = serde_json::to_string(&label_sidecar_json(labels))
        .map_err(|e| SceneError::sidecar(path, e.to_string()))?;
    write_atomically(path, |out| {
        out.write_all(text.as_bytes())?;
        out.write_all(b"\n")
    })
    .map_err(|e| SceneError::io(path, e))
}
