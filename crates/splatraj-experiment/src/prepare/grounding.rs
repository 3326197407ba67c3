//! Grounding texts in a scene, as `splatraj run` ([`crate::Experiment::prepare`]) and
//! `splatraj query` ([`crate::picking::query::ConfigQuery`]) both do it: a config's `[targets]` built
//! into a source (the lifted field's memory checked first and its cache placed beside the
//! scene file), then a text, or a group shot's texts, made a target.

use anyhow::{Context, Result, anyhow};
use burn::tensor::Device;
use splatraj_scene::Scene;
use splatraj_semantic::{SelectionOptions, Target, TargetSource, find_target};

use crate::config::Config;
use crate::extensions::Extensions;

/// `config`'s `[targets]` built into a source with the sources of `extensions` (paths
/// relative to the config's folder, models on `device`), for a scene of `gaussians`
/// Gaussians. `key` turns a `[targets]` key (`phrases`) into the name errors use
/// (`targets.phrases` in a config file, `--phrases` on the command line).
pub fn build_source(
    config: &Config,
    gaussians: usize,
    device: &Device,
    extensions: &Extensions,
    key: &dyn Fn(&str) -> String,
) -> Result<Box<dyn TargetSource>> {
    crate::prepare::lifted::check_lifted_memory(config, gaussians)?;
    crate::prepare::lifted::with_lifted_cache(&config.targets, config.scene_file().as_deref())
        .build_named(&config.base_dir, device, &extensions.sources, key)
        .map_err(|e| anyhow!("{e}"))
}

/// The union of `objects`, each grounded like a query's text: every Gaussian of any of them,
/// centred on and spanning the box that holds each object's box (`shots::union_box`).
pub fn group_target(
    source: &dyn TargetSource,
    scene: &Scene,
    objects: &[String],
    selection: &SelectionOptions,
) -> Result<Target> {
    let mut parts = Vec::with_capacity(objects.len());
    for (k, text) in objects.iter().enumerate() {
        let part = find_target(source, scene, text, selection)
            .with_context(|| format!("object {k} ({text:?})"))?;
        parts.push(part);
    }
    let boxes: Vec<([f64; 3], [f64; 3])> = parts
        .iter()
        .map(|p| (p.centre.map(f64::from), p.extent.map(f64::from)))
        .collect();
    let (centre, extent) = splatraj_traj::shots::union_box(&boxes);
    let mut union = parts[0].clone();
    for part in &parts[1..] {
        for (u, m) in union.mask.iter_mut().zip(&part.mask) {
            *u = u.max(*m);
        }
        union.warnings.extend(part.warnings.iter().cloned());
        union.notes.extend(part.notes.iter().cloned());
    }
    union.count = union.mask.iter().filter(|&&m| m > 0.5).count();
    union.centre = centre.map(|v| v as f32);
    union.extent = extent.map(|v| v as f32);
    union.name = objects.join(" + ");
    Ok(union)
}
