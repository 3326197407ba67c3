//! Times `lift_views` on a real scene: one view and a batch of four at 256×256, dim 2, with a
//! forward-only render of the same views beside it and the per-stage split.
//!
//! `cargo run -p splatraj-render --release --example lift_timing [scene.ply] [rasterizer]`
//! (default: /work/shared/data/biker.compressed.ply, fused; biker's up is −y).

use std::path::PathBuf;
use std::time::Instant;

use burn::tensor::{DType, Device};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::host::OnDevice;
use splatraj_render::lift::lift_views;
use splatraj_render::render::{Channel, DeviceScene, Rasterizer, RenderRequest, render};
use splatraj_render::stages;
use splatraj_scene::{ReadOptions, read_scene};

const SIZE: usize = 256;
const DIM: usize = 2;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/work/shared/data/biker.compressed.ply"));
    let rasterizer: Rasterizer = args.next().as_deref().unwrap_or("fused").parse()?;
    let scene = read_scene(&path, &ReadOptions::default())?.scene;
    let bounds = scene.robust_bounds(0.02).ok_or("empty scene")?;
    let centre = DVec3::from(bounds.center().map(f64::from));
    let extent = bounds.size().into_iter().fold(0.0f32, f32::max) as f64;
    let up = DVec3::new(0.0, -1.0, 0.0);
    // Four views around the centre, level with it, at 1.2 extents (the object fills the frame).
    let poses: Vec<Pose> = (0..4)
        .map(|k| {
            let angle = k as f64 * std::f64::consts::FRAC_PI_2 + 0.3;
            let eye = centre + 1.2 * extent * DVec3::new(angle.cos(), 0.0, angle.sin());
            Pose::look_at(eye, centre, up)
        })
        .collect::<Result<_, _>>()?;
    let f = 0.9 * SIZE as f64;
    let k = Intrinsics::new(f, f, 0.5 * SIZE as f64, 0.5 * SIZE as f64, SIZE, SIZE)?;
    println!(
        "{}: {} Gaussians, {SIZE}×{SIZE}, dim {DIM}, {rasterizer:?}, {} threads",
        path.display(),
        scene.len(),
        rayon::current_num_threads()
    );

    let plain = DeviceScene::new(&scene, &Device::flex(), DType::F32);
    let request = RenderRequest {
        rasterizer,
        ..RenderRequest::new(
            k,
            vec![Channel::Features {
                dim: DIM + 1,
                values: vec![0.0; scene.len() * (DIM + 1)],
            }],
        )
    };
    let ad = DeviceScene::new(&scene, &Device::flex().autodiff(), DType::F32);
    for views in [1, 4] {
        let poses = &poses[..views];
        let pixels: Vec<f32> = (0..views * SIZE * SIZE * DIM)
            .map(|i| ((i * 7919) % 101) as f32 / 101.0)
            .collect();
        for run in 0..2 {
            let started = Instant::now();
            let out = render(&plain, plain.poses(poses), &request)?;
            let _ = out.images.into_data();
            let forward = started.elapsed().as_secs_f64();

            stages::reset();
            let started = Instant::now();
            let sums = lift_views(&ad, poses, &k, &pixels, DIM, rasterizer)?;
            let lift = started.elapsed().as_secs_f64();
            let voted = sums.weights.iter().filter(|&&w| w > 1e-6).count();
            let split: Vec<String> = stages::totals()
                .iter()
                .map(|(s, d)| format!("{} {:.0} ms", s.name(), d.as_secs_f64() * 1e3))
                .collect();
            println!(
                "{views} view(s), run {run}: lift {:.0} ms ({:.0} ms/view; forward-only render {:.0} ms), {voted} Gaussians voted; {}",
                lift * 1e3,
                lift * 1e3 / views as f64,
                forward * 1e3,
                split.join(", ")
            );
        }
    }
    Ok(())
}
