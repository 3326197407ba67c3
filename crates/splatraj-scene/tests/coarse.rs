//! Coarse copies: closed forms of a two-Gaussian merge, the budget, classes kept apart, and
//! the first and second moments of the scene kept.

use splatraj_scene::Scene;
use splatraj_scene::coarse::{CoarseError, coarsen};

fn scene(gaussians: &[([f32; 3], [f32; 3], f32)]) -> Scene {
    let n = gaussians.len();
    Scene {
        means: gaussians.iter().map(|g| g.0).collect(),
        scales: gaussians.iter().map(|g| g.1).collect(),
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacities: gaussians.iter().map(|g| g.2).collect(),
        sh_degree: 0,
        sh: (0..3 * n).map(|k| (k % 7) as f32 * 0.1).collect(),
        extras: Default::default(),
    }
}

fn xorshift(state: &mut u64) -> f32 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    (*state >> 40) as f32 / (1u64 << 24) as f32
}

#[test]
fn two_equal_spheres_merge_into_the_moment_matched_ellipsoid() {
    // Two spheres of σ = s, opacity α, at ±d/2 on x, plus a far third one so that the budget
    // (2) forces exactly this merge.
    let (s, d, alpha) = (0.01f32, 0.02f32, 0.3f32);
    let far = ([10.0, 10.0, 10.0], [s, s, s], alpha);
    let input = scene(&[
        ([-d / 2.0, 0.0, 0.0], [s, s, s], alpha),
        ([d / 2.0, 0.0, 0.0], [s, s, s], alpha),
        far,
    ]);
    let coarse = coarsen(&input, &[0, 0, 0], 2).unwrap();
    assert_eq!(coarse.scene.len(), 2);
    assert_eq!(coarse.coarse_from_fine[0], coarse.coarse_from_fine[1]);
    let j = coarse.coarse_from_fine[0] as usize;
    let mean = coarse.scene.means[j];
    assert!(mean.iter().all(|m| m.abs() < 1e-7), "{mean:?}");
    // Covariance: s² on every axis plus (d/2)² along x.
    let long = (s * s + d * d / 4.0).sqrt();
    let mut scales = coarse.scene.scales[j];
    scales.sort_by(f32::total_cmp);
    for (got, want) in scales.iter().zip([s, s, long]) {
        assert!((got - want).abs() < 1e-6 * want.max(1.0), "{scales:?}");
    }
    // The long axis is x: the rotation maps the long local axis onto ±x.
    let [w, x, y, z] = coarse.scene.rotations[j];
    let q = glam::Quat::from_xyzw(x, y, z, w);
    let k = coarse.scene.scales[j]
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .unwrap()
        .0;
    let axis = q * glam::Vec3::AXES[k];
    assert!(axis.x.abs() > 1.0 - 1e-5, "{axis}");
    // Opacity: Σ αs² spread over s·long, below 1 − (1 − α)².
    let spread = 2.0 * alpha * s * s / (s * long);
    let want = spread.min(1.0 - (1.0 - alpha).powi(2));
    assert!((coarse.scene.opacities[j] - want).abs() < 1e-6);
    // SH: the mean of the two members'.
    for c in 0..3 {
        let want = 0.5 * (input.sh[c] + input.sh[3 + c]);
        assert!((coarse.scene.sh[3 * j + c] - want).abs() < 1e-6);
    }
    // The far Gaussian is kept as it was.
    let f = coarse.coarse_from_fine[2] as usize;
    assert_eq!(coarse.scene.means[f], far.0);
    assert_eq!(coarse.scene.opacities[f], far.2);
}

#[test]
fn a_scene_within_the_budget_comes_back_unchanged() {
    let input = scene(&[
        ([0.0, 0.0, 0.0], [0.01, 0.02, 0.03], 0.5),
        ([0.001, 0.0, 0.0], [0.01, 0.01, 0.01], 0.9),
    ]);
    let coarse = coarsen(&input, &[0, 0], 2).unwrap();
    assert_eq!(coarse.scene.means, input.means);
    assert_eq!(coarse.scene.scales, input.scales);
    assert_eq!(coarse.scene.opacities, input.opacities);
    assert_eq!(coarse.scene.sh, input.sh);
    assert_eq!(coarse.coarse_from_fine, vec![0, 1]);
}

#[test]
fn the_budget_holds_classes_stay_apart_and_the_moments_are_kept() {
    let mut rng = 0x5EED_u64;
    let mut r = || xorshift(&mut rng);
    let n = 20_000;
    let gaussians: Vec<([f32; 3], [f32; 3], f32)> = (0..n)
        .map(|_| {
            let size = 0.002 + 0.004 * r();
            (
                [r(), r(), 0.3 * r()],
                [size, size * 0.5, size * 0.2],
                0.2 + 0.7 * r(),
            )
        })
        .collect();
    let input = scene(&gaussians);
    // Class 1: a box in the middle (an object), class 0 the rest.
    let classes: Vec<u32> = input
        .means
        .iter()
        .map(|m| u32::from(m[0] > 0.4 && m[0] < 0.6 && m[1] > 0.4 && m[1] < 0.6))
        .collect();
    for budget in [5_000, 1_000] {
        let coarse = coarsen(&input, &classes, budget).unwrap();
        let m = coarse.scene.len();
        assert!(
            m <= budget && m > budget / 8,
            "{m} Gaussians for a budget of {budget}"
        );
        let mut class_of = vec![None; m];
        for (i, &g) in coarse.coarse_from_fine.iter().enumerate() {
            let c = class_of[g as usize].get_or_insert(classes[i]);
            assert_eq!(*c, classes[i], "merged Gaussian {g} mixes classes");
        }
        // The object's mask carried over is 0/1 (no mixing) and as heavy as before.
        let mask: Vec<f32> = classes.iter().map(|&c| c as f32).collect();
        let carried = coarse.carry(&input, &mask);
        assert!(carried.iter().all(|&v| v == 0.0 || v == 1.0));
        // Weighted first moment (weights αᵢ·aᵢ, what the merge conserves unless capped).
        let moment = |s: &Scene| {
            let mut sum = [0.0f64; 4];
            for i in 0..s.len() {
                let mut sc = s.scales[i].map(f64::from);
                sc.sort_by(f64::total_cmp);
                let w = f64::from(s.opacities[i]) * sc[1] * sc[2];
                for (total, &m) in sum.iter_mut().zip(&s.means[i]) {
                    *total += w * f64::from(m);
                }
                sum[3] += w;
            }
            [sum[0] / sum[3], sum[1] / sum[3], sum[2] / sum[3]]
        };
        let (a, b) = (moment(&input), moment(&coarse.scene));
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() < 0.02, "centre of mass {a:?} → {b:?}");
        }
        // Every merged Gaussian lies within its members' bounds (the cell).
        for (i, &g) in coarse.coarse_from_fine.iter().enumerate() {
            let d: f32 = (0..3)
                .map(|k| (coarse.scene.means[g as usize][k] - input.means[i][k]).powi(2))
                .sum::<f32>()
                .sqrt();
            assert!(
                d <= 3f32.sqrt() * coarse.cell + 1e-6,
                "member {i} {d} from its merge"
            );
        }
    }
}

#[test]
fn bad_classes_are_refused() {
    let input = scene(&[([0.0; 3], [0.01; 3], 0.5)]);
    assert!(matches!(
        coarsen(&input, &[], 1),
        Err(CoarseError::ClassCount { .. })
    ));
    assert!(matches!(
        coarsen(&input, &[5000], 1),
        Err(CoarseError::TooManyClasses(_))
    ));
}

#[test]
fn a_saturated_merge_keeps_the_stacked_opacity_and_grows_its_cross_section() {
    // Four coincident opaque discs (α = 0.9, flat along z): spread over one disc their
    // weight gives α = 3.6, far above what they give stacked, 1 − 0.1⁴; the cross-section
    // grows by the most allowed, twice the area (√2 on each of its two axes).
    let (s, alpha) = (0.01f32, 0.9f32);
    let disc = ([0.0, 0.0, 0.0], [s, s, 0.1 * s], alpha);
    let far = ([10.0, 10.0, 10.0], [s, s, s], alpha);
    let input = scene(&[disc, disc, disc, disc, far]);
    let coarse = coarsen(&input, &[0; 5], 2).unwrap();
    let j = coarse.coarse_from_fine[0] as usize;
    assert!(
        coarse.coarse_from_fine[..4]
            .iter()
            .all(|&g| g as usize == j)
    );
    let want = 1.0 - (1.0 - alpha).powi(4);
    assert!((coarse.scene.opacities[j] - want).abs() < 1e-6);
    let mut scales = coarse.scene.scales[j];
    scales.sort_by(f32::total_cmp);
    for (got, want) in scales
        .iter()
        .zip([0.1 * s, s * 2f32.sqrt(), s * 2f32.sqrt()])
    {
        assert!((got - want).abs() < 1e-6, "{scales:?}");
    }
}
