//! `splatraj scene lift-masks`: lift a segmenter's 2D label masks onto the Gaussians and
//! write the label sidecar (the library's `lift_masks_to_sidecar`).

use std::path::PathBuf;
use std::str::FromStr;

use anyhow::Result;
use splatraj::experiment::prepare::scene_files::{MaskSidecarRequest, lift_masks_to_sidecar};
use splatraj::lift::MaskOptions;
use splatraj_render::backend::BackendKind;

use super::{stage_bar, warn_dropped};
use crate::cli::invalid_policy;

/// Arguments of `scene lift-masks`.
#[derive(Debug, clap::Args)]
pub struct LiftMasksArgs {
    /// Scene file (INRIA PLY, compressed PLY or SPZ).
    #[arg(long)]
    scene: PathBuf,
    /// The capture's cameras: INRIA cameras.json, COLMAP images.txt (cameras.txt beside it),
    /// nerfstudio transforms.json or camera_path.json.
    #[arg(long)]
    cameras: PathBuf,
    /// Folder of PNG masks named after the cameras' images (frame_0001.png for
    /// images/frame_0001.jpg): grey values are label ids, or colours are labels (black = none).
    #[arg(long)]
    masks: PathBuf,
    /// Label sidecar to write (JSON; written whole or not at all).
    #[arg(long)]
    out: PathBuf,
    /// The least share of a Gaussian's blending weight its object must hold, in (0, 1].
    #[arg(long, default_value_t = MaskOptions::default().min_share)]
    min_share: f32,
    /// Nearest Gaussians asked by one left without an object (0: no consensus pass).
    #[arg(long, default_value_t = MaskOptions::default().neighbours)]
    neighbours: usize,
    /// Drop Gaussians with invalid values with a warning, instead of stopping with an error.
    #[arg(long)]
    drop_invalid: bool,
    /// Tensor backend: flex (CPU), ndarray or wgpu, among those compiled in.
    #[arg(long, default_value = "flex", value_parser = BackendKind::from_str)]
    backend: BackendKind,
}

/// `scene lift-masks`: parses, lifts and writes with the library, prints a summary.
pub fn run(args: LiftMasksArgs) -> Result<()> {
    let device = args.backend.device()?;
    let request = MaskSidecarRequest {
        scene: args.scene,
        cameras: args.cameras,
        masks: args.masks,
        out: args.out,
        options: MaskOptions {
            min_share: args.min_share,
            neighbours: args.neighbours,
            ..MaskOptions::default()
        },
        invalid: invalid_policy(args.drop_invalid),
    };
    let (bar, progress) = stage_bar();
    let (lift, dropped) = lift_masks_to_sidecar(&request, &device, &progress)?;
    bar.finish_and_clear();
    warn_dropped(&request.scene, dropped);
    print!("{}", lift.summary_text());
    eprintln!(
        "wrote {} ({} Gaussians labelled)",
        request.out.display(),
        lift.labelled()
    );
    Ok(())
}
