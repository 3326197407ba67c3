//! The lifted field against a brute-force lift: every pixel of every view, each Gaussian's
//! weight there from the independent f64 reference renderer, the patch features bilinearly
//! interpolated in f64 here, and the cosine of the weighted mean with a text vector.

use burn::tensor::{DType, Device};
use splatraj_lift::View;
use splatraj_lift::field::{FieldOptions, LiftedField};
use splatraj_lift::progress::silent;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::reference::{RefCamera, reference_weights};
use splatraj_render::render::DeviceScene;
use splatraj_scene::Scene;
use splatraj_semantic::image_encoder::DenseFeatures;

/// xorshift, so the test needs no rand dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f32 {
        (lo + (hi - lo) * self.next()) as f32
    }
}

/// 60 overlapping Gaussians in front of the cameras, some occluding others.
fn scene() -> Scene {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let mut scene = Scene::default();
    for _ in 0..60 {
        scene.means.push([
            rng.range(-1.0, 1.0),
            rng.range(-0.8, 0.8),
            rng.range(-0.5, 0.5),
        ]);
        scene.scales.push([
            rng.range(0.05, 0.3),
            rng.range(0.05, 0.3),
            rng.range(0.01, 0.1),
        ]);
        let q = [0; 4].map(|_| rng.range(-1.0, 1.0));
        let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
        scene.rotations.push(q.map(|v| v / n));
        scene.opacities.push(rng.range(0.3, 0.95));
        scene.sh.extend([0.5, 0.4, 0.3]);
    }
    scene
}

fn views() -> Vec<View> {
    let intrinsics = Intrinsics::from_fov_x(60.0, 40, 30).unwrap();
    [[0.0, 0.0, -4.0], [2.5, 0.5, -3.0]]
        .into_iter()
        .map(|eye| View {
            pose: Pose::look_at(eye.into(), glam::DVec3::ZERO, glam::DVec3::Y).unwrap(),
            intrinsics,
        })
        .collect()
}

/// Random unit features on a `rows × cols` grid.
fn grid(rng: &mut Rng, rows: usize, cols: usize, dim: usize) -> DenseFeatures {
    let mut values = Vec::new();
    for _ in 0..rows * cols {
        let v: Vec<f32> = (0..dim).map(|_| rng.range(-1.0, 1.0)).collect();
        let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        values.extend(v.iter().map(|x| x / n));
    }
    DenseFeatures {
        rows,
        cols,
        dim,
        values,
    }
}

/// The feature at pixel (x, y): bilinear between patch centres ((c + ½)·W/cols, (r + ½)·H/rows),
/// constant beyond the outer centres.
fn feature_at(g: &DenseFeatures, x: usize, y: usize, w: usize, h: usize) -> Vec<f64> {
    let axis = |p: usize, pixels: usize, cells: usize| {
        let centre = |i: usize| (i as f64 + 0.5) * pixels as f64 / cells as f64;
        let at = p as f64 + 0.5;
        if at <= centre(0) {
            return (0, 0, 0.0);
        }
        if at >= centre(cells - 1) {
            return (cells - 1, cells - 1, 0.0);
        }
        let i = (0..cells - 1).find(|&i| at < centre(i + 1)).unwrap();
        (i, i + 1, (at - centre(i)) / (centre(i + 1) - centre(i)))
    };
    let (r0, r1, fy) = axis(y, h, g.rows);
    let (c0, c1, fx) = axis(x, w, g.cols);
    let v = |r: usize, c: usize, d: usize| f64::from(g.values[(r * g.cols + c) * g.dim + d]);
    (0..g.dim)
        .map(|d| {
            let top = v(r0, c0, d) * (1.0 - fx) + v(r0, c1, d) * fx;
            let bottom = v(r1, c0, d) * (1.0 - fx) + v(r1, c1, d) * fx;
            top * (1.0 - fy) + bottom * fy
        })
        .collect()
}

#[test]
fn lifted_cosines_equal_a_brute_force_lift_of_the_features() {
    let scene = scene();
    let views = views();
    let mut rng = Rng(77);
    let dim = 5;
    let dense: Vec<DenseFeatures> = views.iter().map(|_| grid(&mut rng, 3, 4, dim)).collect();
    // All components kept: the subspace is the whole space and the field must be exact.
    let options = FieldOptions {
        render_size: 40,
        lift_size: 40,
        components: dim,
    };
    let device = Device::default().autodiff();
    let device_scene = DeviceScene::new(&scene, &device, DType::F32);
    let field = LiftedField::lift(&device_scene, &views, &dense, &options, &silent).unwrap();
    assert!((field.explained() - 1.0).abs() < 1e-6);

    let n = scene.len();
    let mut weighted = vec![0f64; n * dim];
    let mut weights = vec![0f64; n];
    for (view, g) in views.iter().zip(&dense) {
        let k = view.intrinsics;
        let pixels = reference_weights(
            &scene,
            &RefCamera::from_pose(&view.pose, &k, splatraj_render::project::NEAR_PLANE),
        );
        for (p, pairs) in pixels.iter().enumerate() {
            let f = feature_at(g, p % k.width, p / k.width, k.width, k.height);
            for &(i, w) in pairs {
                weights[i] += w;
                for d in 0..dim {
                    weighted[i * dim + d] += w * f[d];
                }
            }
        }
    }
    let seen = weights.iter().filter(|&&w| w > 0.01).count();
    assert!(seen > 30, "the views show {seen} of 60 Gaussians");
    for trial in 0..3 {
        let t: Vec<f32> = {
            let v: Vec<f32> = (0..dim).map(|_| rng.range(-1.0, 1.0)).collect();
            let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
            v.iter().map(|x| x / n).collect()
        };
        let ours = field.cosines(&t);
        for i in 0..n {
            if weights[i] < 0.01 {
                continue; // too faint for an f32 mean to be compared tightly
            }
            let mean: Vec<f64> = (0..dim)
                .map(|d| weighted[i * dim + d] / weights[i])
                .collect();
            let norm = mean.iter().map(|x| x * x).sum::<f64>().sqrt();
            let want = mean
                .iter()
                .zip(&t)
                .map(|(a, &b)| a * f64::from(b))
                .sum::<f64>()
                / norm;
            let got = f64::from(ours[i].expect("a seen Gaussian has a vote"));
            assert!(
                (got - want).abs() < 2e-4,
                "trial {trial}, Gaussian {i} (Σw {:.3}): {got} vs brute force {want}",
                weights[i]
            );
        }
        for i in (0..n).filter(|&i| weights[i] == 0.0) {
            assert_eq!(ours[i], None, "Gaussian {i} was never seen");
        }
    }
}

#[test]
fn a_smaller_subspace_keeps_most_of_low_rank_features() {
    // Features that vary in two directions only: two components hold all of it.
    let scene = scene();
    let views = views();
    let mut rng = Rng(5);
    let (a, b) = ([0.6f32, 0.0, 0.8, 0.0, 0.0], [0.0f32, 1.0, 0.0, 0.0, 0.0]);
    let dense: Vec<DenseFeatures> = views
        .iter()
        .map(|_| {
            let mut g = grid(&mut rng, 3, 4, 5);
            for f in g.values.chunks_exact_mut(5) {
                let (s, c) = (rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
                for d in 0..5 {
                    f[d] = 0.3 + s * a[d] + c * b[d];
                }
            }
            g
        })
        .collect();
    let device = Device::default().autodiff();
    let device_scene = DeviceScene::new(&scene, &device, DType::F32);
    let full = FieldOptions {
        render_size: 40,
        lift_size: 40,
        components: 5,
    };
    let small = FieldOptions {
        components: 2,
        ..full
    };
    let exact = LiftedField::lift(&device_scene, &views, &dense, &full, &silent).unwrap();
    let compressed = LiftedField::lift(&device_scene, &views, &dense, &small, &silent).unwrap();
    assert!(compressed.explained() > 0.999, "{}", compressed.explained());
    let t = [0.5f32, 0.5, 0.5, 0.5, 0.0];
    for (e, c) in exact.cosines(&t).iter().zip(compressed.cosines(&t)) {
        match (e, c) {
            (Some(e), Some(c)) => assert!((e - c).abs() < 1e-3, "{e} vs {c}"),
            (e, c) => assert_eq!(e.is_some(), c.is_some()),
        }
    }
}
