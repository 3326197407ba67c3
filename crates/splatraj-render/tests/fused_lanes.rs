//! The 8-lane f32 compositing kernels (AVX2 + FMA) against the scalar kernels: the same bits as
//! the scalar f32 kernels, and f32 rounding away from the f64 kernels (which `fused.rs` checks
//! against the tensor path): images, the saved state and the gradients of all four inputs,
//! every pixel and every row, on tiles that
//! hit every rule at lane granularity: partial tiles at the image's right and bottom edges, an
//! empty list, a one-Gaussian list, pixels of one half row stopping at different entries, α
//! clamped at 0.99, powers clamped at 0, footprints with no bounded box. Then: the same bits on
//! 1, 2 and 3 threads.

mod common;

use common::Rng;
use splatraj_render::fused::CompositePlan;
use splatraj_render::fused::cpu::{
    ForwardState, HostGradients, HostSplats, Kernels, backward_with, forward_with,
};
use splatraj_render::rows::PoseRows;
use splatraj_render::tiles::{TileGrid, TileWork};

/// Gaussians per pose.
const GAUSSIANS: usize = 120;

/// A batch of 2 poses on a 37 × 21 image (3 × 2 tiles, the last column and row partial), with
/// `channels` channels, and its plan: tile 0 of pose 0 composites nothing, tile 1 one
/// Gaussian, every other tile all Gaussians in a shuffled depth order.
fn case(channels: usize, stop_transmittance: f64) -> (HostSplats<f64>, CompositePlan) {
    let mut rng = Rng(0x5eed_1a9e);
    let batch = 2;
    let grid = TileGrid::new(37, 21);
    let mut splats = HostSplats {
        means: vec![],
        conics: vec![],
        opacities: vec![],
        values: vec![],
        channels,
    };
    for _ in 0..batch {
        for g in 0..GAUSSIANS {
            let mean = [rng.range(-4.0, 41.0), rng.range(-4.0, 25.0)];
            let (sx, sy) = (rng.range(0.6, 9.0), rng.range(0.6, 9.0));
            let rho = rng.range(-0.8, 0.8);
            let cov = [sx * sx, rho * sx * sy, sy * sy];
            let det = cov[0] * cov[2] - cov[1] * cov[1];
            let mut conic = [cov[2] / det, -cov[1] / det, cov[0] / det];
            // Opaque ones (α clamped at 0.99 at their centre), faint ones, the rest between.
            let mut opacity = match g % 5 {
                0 | 2 => rng.range(0.995, 1.0),
                1 => rng.range(0.001, 0.02),
                _ => rng.range(0.05, 0.95),
            };
            if g == 7 {
                // Indefinite conic: no bounded box, and the power goes above 0 (clamped).
                conic = [0.05, 0.3, 0.05];
                opacity = 0.4;
            }
            splats.means.extend(mean);
            splats.conics.extend(conic);
            splats.opacities.push(opacity);
            splats
                .values
                .extend((0..channels).map(|_| rng.range(-0.5, 1.5)));
        }
    }
    let mut work = vec![];
    for b in 0..batch {
        for tile in 0..grid.len() {
            let mut gaussians: Vec<u32> = (0..GAUSSIANS as u32).collect();
            for i in (1..gaussians.len()).rev() {
                gaussians.swap(i, (rng.next() * (i + 1) as f64) as usize);
            }
            match (b, tile) {
                (0, 0) => gaussians.clear(),
                (0, 1) => gaussians.truncate(1),
                _ => {}
            }
            work.push(TileWork {
                batch: b,
                tile,
                gaussians,
            });
        }
    }
    let plan = CompositePlan::new(&work, &PoseRows::dense(batch, GAUSSIANS), grid)
        .with_stop_transmittance(stop_transmittance);
    (splats, plan)
}

fn to_f32(splats: &HostSplats<f64>) -> HostSplats<f32> {
    let cast = |v: &[f64]| v.iter().map(|&x| x as f32).collect();
    HostSplats {
        means: cast(&splats.means),
        conics: cast(&splats.conics),
        opacities: cast(&splats.opacities),
        values: cast(&splats.values),
        channels: splats.channels,
    }
}

/// A random gradient of the packed image `[B, H, W, C + 1]`.
fn output_gradient(plan: &CompositePlan, channels: usize) -> Vec<f64> {
    let mut rng = Rng(0xc0ffee);
    let len = plan.batch() * plan.grid.height * plan.grid.width * (channels + 1);
    (0..len).map(|_| rng.range(-1.0, 1.0)).collect()
}

/// Image, state and gradients of one pass in f32.
type Pass = (Vec<f32>, ForwardState<f32>, HostGradients<f32>);

fn pass(splats: &HostSplats<f32>, plan: &CompositePlan, v: &[f64], kernels: Kernels) -> Pass {
    let (image, state) = forward_with(splats, plan, kernels);
    let v: Vec<f32> = v.iter().map(|&x| x as f32).collect();
    let gradients = backward_with(splats, plan, &state, &v, kernels);
    (image, state, gradients)
}

/// Every element of `got` within `absolute + relative·|want|` of `want`.
fn assert_close(what: &str, got: &[f32], want: &[f64], absolute: f64, relative: f64) {
    assert_eq!(got.len(), want.len(), "{what}: lengths");
    for (i, (&g, &w)) in got.iter().zip(want).enumerate() {
        let error = (g as f64 - w).abs();
        assert!(
            error <= absolute + relative * w.abs(),
            "{what}[{i}]: {g} against {w} (error {error:e})"
        );
    }
}

/// The lanes' pass against the scalar f32 pass (bit for bit) and the f64 pass (f32 rounding).
fn lanes_match_scalar(channels: usize, stop_transmittance: f64) {
    if Kernels::detect() != Kernels::Lanes8 {
        eprintln!("no AVX2 + FMA here: the lane kernels are not run");
        return;
    }
    let (splats64, plan) = case(channels, stop_transmittance);
    let splats = to_f32(&splats64);
    let v = output_gradient(&plan, channels);
    let lanes = pass(&splats, &plan, &v, Kernels::Lanes8);
    let scalar = pass(&splats, &plan, &v, Kernels::Scalar);
    let (image64, state64) = forward_with(&splats64, &plan, Kernels::Lanes8);
    let v64 = backward_with(&splats64, &plan, &state64, &v, Kernels::Lanes8);

    // The rules' decisions are the same: every pixel's last contributor, exactly.
    assert_eq!(
        lanes.1.last(),
        scalar.1.last(),
        "last contributors, lanes vs scalar"
    );
    assert_eq!(
        lanes.1.last(),
        state64.last(),
        "last contributors, lanes vs f64"
    );
    // The case reaches the rules it is meant to: early stops beside open pixels in one half
    // row, and an untouched tile.
    let stopped_beside_open = lanes.1.final_t().chunks(8).any(|half_row| {
        half_row
            .iter()
            .any(|&t| t < 2.0 * stop_transmittance as f32)
            && half_row.iter().any(|&t| t > 0.05)
    });
    assert!(
        stopped_beside_open,
        "no half row mixes stopped and open pixels"
    );
    assert!(
        lanes.1.last()[..256].iter().all(|&n| n == 0),
        "tile 0 is empty"
    );

    // The scalar f32 kernels' bits: every channel and alpha of every pixel, T, every gradient.
    assert_bits("image", &lanes.0, &scalar.0);
    assert_bits("final T", &lanes.1.final_t(), &scalar.1.final_t());
    let (g, s) = (&lanes.2, &scalar.2);
    assert_bits("v_means", &g.means, &s.means);
    assert_bits("v_conics", &g.conics, &s.conics);
    assert_bits("v_opacities", &g.opacities, &s.opacities);
    assert_bits("v_values", &g.values, &s.values);

    // f64 within f32 rounding: the image per value, the gradients relative to the largest of
    // their kind.
    assert_close("image vs f64", &lanes.0, &image64, 2e-5, 1e-4);
    let check = |what: &str, got: &[f32], f64s: &[f64]| {
        let scale = f64s.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(scale > 0.0, "{what}: all zero");
        assert_close(&format!("{what} vs f64"), got, f64s, 1e-4 * scale, 1e-3);
    };
    check("v_means", &g.means, &v64.means);
    check("v_conics", &g.conics, &v64.conics);
    check("v_opacities", &g.opacities, &v64.opacities);
    check("v_values", &g.values, &v64.values);
}

/// The same bits in every element (a lane computing anything else shows here).
fn assert_bits(what: &str, lanes: &[f32], scalar: &[f32]) {
    assert_eq!(lanes.len(), scalar.len(), "{what}: lengths");
    for (i, (a, b)) in lanes.iter().zip(scalar).enumerate() {
        assert_eq!(
            a.to_bits(),
            b.to_bits(),
            "{what}[{i}]: lanes {a} against scalar {b}"
        );
    }
}

#[test]
fn lanes_match_scalar_with_three_channels() {
    lanes_match_scalar(3, 1e-4);
}

#[test]
fn lanes_match_scalar_with_one_channel_and_a_larger_stop() {
    lanes_match_scalar(1, 0.02);
}

#[test]
fn lanes_match_scalar_with_five_channels() {
    lanes_match_scalar(5, 1e-4);
}

#[test]
fn lanes_give_the_same_bits_on_any_thread_count() {
    let (splats64, plan) = case(3, 1e-4);
    let splats = to_f32(&splats64);
    let v = output_gradient(&plan, 3);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| pass(&splats, &plan, &v, Kernels::detect()))
    };
    let one = run(1);
    for threads in [2, 3] {
        let other = run(threads);
        assert_eq!(one.0, other.0, "images with {threads} threads");
        assert_eq!(
            one.1.final_t(),
            other.1.final_t(),
            "final T with {threads} threads"
        );
        let (a, b) = (&one.2, &other.2);
        assert_eq!(a.means, b.means, "v_means with {threads} threads");
        assert_eq!(a.conics, b.conics, "v_conics with {threads} threads");
        assert_eq!(
            a.opacities, b.opacities,
            "v_opacities with {threads} threads"
        );
        assert_eq!(a.values, b.values, "v_values with {threads} threads");
    }
}
