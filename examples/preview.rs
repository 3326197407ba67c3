//! Renders a quick CPU preview of a scene with the f64 reference renderer.
//!
//! ```text
//! cargo run --release --example preview -- SCENE.ply OUT.png [--width 320 --height 240]
//!     [--azimuth 30 --elevation 25 --fov 60 --distance 1.0 --up X,Y,Z]
//! ```
//!
//! The camera looks at the centre of the scene's robust bounds (2 %–98 % quantiles of the
//! centres, which ignores stray far-away splats) from outside them: it sits on the sphere
//! around that box, at `--azimuth` degrees around the up axis and `--elevation` degrees above
//! the horizontal plane, far enough for the sphere to fit the narrower field of view
//! (`--distance` scales that). Up is `--up` if given, else the scene crate's guess, else +z.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Parser;
use splatraj_render::camera::Intrinsics;
use splatraj_render::reference::{RefCamera, RefChannels, render_reference};
use splatraj_scene::{ReadOptions, guess_up_axis, read_scene};

/// Preview a Gaussian Splatting scene as a PNG (CPU reference renderer).
#[derive(Debug, Parser)]
struct Args {
    /// Scene file (INRIA PLY, compressed PLY, SPZ).
    scene: PathBuf,
    /// Output PNG.
    out: PathBuf,
    /// Image width in pixels.
    #[arg(long, default_value_t = 320)]
    width: usize,
    /// Image height in pixels.
    #[arg(long, default_value_t = 240)]
    height: usize,
    /// Camera angle around the up axis, degrees.
    #[arg(long, default_value_t = 30.0)]
    azimuth: f64,
    /// Camera angle above the horizontal plane, degrees.
    #[arg(long, default_value_t = 25.0)]
    elevation: f64,
    /// Horizontal field of view, degrees.
    #[arg(long, default_value_t = 60.0)]
    fov: f64,
    /// Multiplies the distance at which the scene's bounding sphere just fits.
    #[arg(long, default_value_t = 1.0)]
    distance: f64,
    /// World up as `x,y,z` (default: guessed from the scene, else +z).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    up: Option<[f64; 3]>,
}

fn parse_vec3(s: &str) -> Result<[f64; 3], String> {
    let parts: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>().map_err(|e| format!("{p:?}: {e}")))
        .collect::<Result<_, _>>()?;
    let v: [f64; 3] = parts
        .try_into()
        .map_err(|_| "expected three comma-separated numbers".to_string())?;
    if v.iter().map(|c| c * c).sum::<f64>() == 0.0 {
        return Err("the up vector must not be zero".into());
    }
    Ok(v)
}

fn main() -> Result<()> {
    let args = Args::parse();
    if args.width == 0 || args.height == 0 {
        bail!("--width and --height must be positive");
    }

    let t0 = Instant::now();
    let loaded = read_scene(&args.scene, &ReadOptions::default())
        .with_context(|| format!("reading {}", args.scene.display()))?;
    let scene = loaded.scene;
    let load_s = t0.elapsed().as_secs_f64();
    let Some(bounds) = scene.robust_bounds(0.02) else {
        bail!("{} holds no Gaussian", args.scene.display());
    };

    let up = match args.up {
        Some(up) => up,
        None => guess_up_axis(&scene).map_or([0.0, 0.0, 1.0], |g| g.up.map(f64::from)),
    };
    let up = normalize(up);
    let center = bounds.center().map(f64::from);
    let size = bounds.size().map(f64::from);
    // Half the box diagonal, floored so a single point or a flat scene still gets a camera.
    let radius = (0.5 * norm(size)).max(1e-3);

    let fx = 0.5 * args.width as f64 / (0.5 * args.fov.to_radians()).tan();
    let fy = fx; // square pixels
    let half_fov_min = (0.5 * args.width.min(args.height) as f64 / fx).atan();
    let dist = args.distance * radius / half_fov_min.sin();

    // Horizontal basis perpendicular to up: the world axis least aligned with up, made
    // orthogonal, then up × that.
    let k = (0..3)
        .min_by(|&a, &b| up[a].abs().total_cmp(&up[b].abs()))
        .unwrap_or(0);
    let mut e1 = [0.0; 3];
    e1[k] = 1.0;
    let d = dot(e1, up);
    let e1 = normalize([e1[0] - d * up[0], e1[1] - d * up[1], e1[2] - d * up[2]]);
    let e2 = cross(up, e1);
    let (az, el) = (args.azimuth.to_radians(), args.elevation.to_radians());
    let dir: [f64; 3] = std::array::from_fn(|i| {
        el.cos() * (az.cos() * e1[i] + az.sin() * e2[i]) + el.sin() * up[i]
    });
    let eye: [f64; 3] = std::array::from_fn(|i| center[i] + dist * dir[i]);

    let k = Intrinsics::new(
        fx,
        fy,
        0.5 * args.width as f64,
        0.5 * args.height as f64,
        args.width,
        args.height,
    )?;
    let mut camera = RefCamera::look_at(eye, center, up, k);
    // Scale the near plane with the scene so tiny or huge scenes behave alike.
    camera.near = (1e-3 * radius).min(0.01);

    let t1 = Instant::now();
    let channels = RefChannels {
        rgb: true,
        ..Default::default()
    };
    let image = render_reference(&scene, &camera, &channels);
    let render_s = t1.elapsed().as_secs_f64();
    image
        .save_png(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;

    let covered = image.alpha.iter().filter(|&&a| a > 0.5).count() as f64;
    println!(
        "{} Gaussians (SH degree {}), {}x{}: load {:.2}s, render {:.3}s; up {:?}, eye {:?}, \
         target {:?}; {:.0}% of pixels covered -> {}",
        scene.len(),
        scene.sh_degree,
        args.width,
        args.height,
        load_s,
        render_s,
        up.map(|c| (c * 1000.0).round() / 1000.0),
        eye.map(|c| (c * 1000.0).round() / 1000.0),
        center.map(|c| (c * 1000.0).round() / 1000.0),
        100.0 * covered / (args.width * args.height) as f64,
        args.out.display()
    );
    Ok(())
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = norm(a);
    a.map(|c| c / n)
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
