//! The scene files `splatraj scene` writes: a scene converted to another format, the demo
//! scene, and label masks lifted onto a scene as a label sidecar. Each is one call that reads,
//! checks and writes (whole or not at all); the command prints what it returns.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use burn::tensor::Device;
use splatraj_lift::MaskOptions;
use splatraj_lift::Progress;
use splatraj_lift::mask_files::{MaskLift, lift_mask_files};
use splatraj_scene::demo::{DemoConfig, demo_scene};
use splatraj_scene::formats::{LoadedScene, check_output_target, write_label_sidecar};
use splatraj_scene::{
    InvalidPolicy, ReadOptions, Scene, SceneFormat, read_scene, write_inria_ply, write_scene,
};

/// Reads `path` for a command that renders it: a scene without Gaussians (none in the file,
/// or all dropped as invalid) is refused, naming the file.
pub fn read_scene_to_render(path: &Path, options: &ReadOptions) -> Result<LoadedScene> {
    let loaded = read_scene(path, options)?;
    if loaded.scene.is_empty() {
        let why = if loaded.dropped > 0 {
            format!(
                "all {} of its Gaussians are invalid (dropped by --drop-invalid)",
                loaded.dropped
            )
        } else {
            "it holds no Gaussians".to_string()
        };
        bail!("{}: nothing to render: {why}", path.display());
    }
    Ok(loaded)
}

/// Most neighbours the consensus pass of [`lift_masks_to_sidecar`] may ask.
pub const MAX_NEIGHBOURS: usize = 64;

/// What [`convert_scene`] wrote.
#[derive(Debug, Clone)]
pub struct Converted {
    /// The format written.
    pub format: SceneFormat,
    /// The scene read (with how many invalid Gaussians were dropped).
    pub loaded: LoadedScene,
    /// The extras the format has no place for, not written ([`SceneFormat::dropped_extras`]).
    pub dropped_extras: Vec<String>,
}

impl Converted {
    /// What `scene convert` says after writing `output`: the extras the format could not hold
    /// (a warning), then what it wrote.
    pub fn summary(&self, output: &Path) -> Vec<String> {
        let (scene, format) = (&self.loaded.scene, self.format);
        let mut lines = Vec::with_capacity(2);
        if !self.dropped_extras.is_empty() {
            lines.push(format!(
                "warning: {} cannot hold {}; they are not written (INRIA .ply keeps them)",
                format.name(),
                self.dropped_extras.join(", ")
            ));
        }
        lines.push(format!(
            "wrote {} Gaussians (SH degree {}) to {} ({})",
            scene.len(),
            scene.sh_degree,
            output.display(),
            format.name()
        ));
        lines
    }
}

/// Reads `input` and writes it to `output` in `format` (else the one its name asks for), with
/// SH of `sh_degree` where given (0 to 3; [`Scene::with_sh_degree`]): the format and the
/// target are checked before the scene is read.
pub fn convert_scene(
    input: &Path,
    output: &Path,
    format: Option<SceneFormat>,
    sh_degree: Option<u8>,
    options: &ReadOptions,
) -> Result<Converted> {
    // Decided before reading, so a wrong name fails at once.
    let format = SceneFormat::for_output_as(output, format)?;
    check_output_target(output)?;
    if let Some(degree) = sh_degree.filter(|&d| d > 3) {
        bail!("--sh-degree {degree}: SH degrees are 0 to 3");
    }
    let mut loaded = read_scene(input, options)?;
    if let Some(degree) = sh_degree {
        loaded.scene = loaded.scene.with_sh_degree(degree);
    }
    let dropped_extras = format.dropped_extras(&loaded.scene);
    write_scene(&loaded.scene, output, format)?;
    Ok(Converted {
        format,
        loaded,
        dropped_extras,
    })
}

/// Builds the demo scene of `config` and writes it to `out` as INRIA PLY; returns it.
pub fn write_demo_scene(config: &DemoConfig, out: &Path) -> Result<Scene> {
    let scene = demo_scene(config)?;
    write_inria_ply(&scene, out)?;
    Ok(scene)
}

/// What `scene lift-masks` asks for.
#[derive(Debug, Clone)]
pub struct MaskSidecarRequest {
    /// The scene file.
    pub scene: PathBuf,
    /// The capture's camera file.
    pub cameras: PathBuf,
    /// The folder of label masks.
    pub masks: PathBuf,
    /// The label sidecar to write.
    pub out: PathBuf,
    /// How the masks are lifted.
    pub options: MaskOptions,
    /// What to do with Gaussians holding invalid values.
    pub invalid: InvalidPolicy,
}

/// Reads the scene, lifts the masks onto it on `device` and writes the labels as a sidecar
/// (refusing an `out` that is the scene file itself, before minutes of work); returns the lift
/// and how many invalid Gaussians were dropped.
pub fn lift_masks_to_sidecar(
    request: &MaskSidecarRequest,
    device: &Device,
    progress: &Progress,
) -> Result<(MaskLift, usize)> {
    let options = &request.options;
    if !(options.min_share > 0.0 && options.min_share <= 1.0) {
        bail!("--min-share {} must be in (0, 1]", options.min_share);
    }
    if options.neighbours > MAX_NEIGHBOURS {
        bail!(
            "--neighbours {} must be at most {MAX_NEIGHBOURS}",
            options.neighbours
        );
    }
    if let (Ok(out), Ok(scene)) = (request.out.canonicalize(), request.scene.canonicalize())
        && out == scene
    {
        bail!("--out {} is the scene file itself", request.out.display());
    }
    let loaded = read_scene(
        &request.scene,
        &ReadOptions {
            invalid: request.invalid,
            labels: None,
        },
    )?;
    // The labels come from the masks' content: bound what their votes take by the memory
    // limit before lifting.
    let limit = crate::resources::MemoryLimit::new(None)?;
    let options = MaskOptions {
        max_bytes: Some(limit.bytes as u64),
        ..request.options
    };
    let lift = lift_mask_files(
        &loaded.scene,
        &request.cameras,
        &request.masks,
        &options,
        device,
        progress,
    )?;
    let labels = lift.scene_labels(request.out.display().to_string());
    write_label_sidecar(&request.out, &labels)
        .with_context(|| format!("cannot write the labels to {}", request.out.display()))?;
    Ok((lift, loaded.dropped))
}
