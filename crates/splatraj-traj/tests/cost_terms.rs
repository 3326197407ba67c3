//! The cost terms behind the `Cost` trait: upright (both modes) and prior against hand-computed
//! values and f64 finite differences, the prior's decay and default radius, IoU, config parsing
//! and validation, and the weighted sum; the host forms the costs evaluate against the tensor
//! forms (autodiff, f64).

mod common;

use common::{host, poses_tensor};

use burn::tensor::{DType, Device, Tensor, TensorData};
use glam::{DMat3, DVec3};
use splatraj_render::camera::Pose;
use splatraj_traj::costs::{
    Cost, CostError, CostInputs, CostsConfig, PriorCost, QueryContext, TceCost, TreCost,
    UprightCost, UprightMode, WeightedCosts, bbox_iou, bbox_iou_batch, box_from_hits, clearance,
    clearance_on_host, default_prior_radius, mask_box, mask_hits, prior, prior_on_host, tce, tre,
    upright, upright_on_host,
};

const Z_UP: [f64; 3] = [0.0, 0.0, 1.0];

fn context(object_centre: [f64; 3], prior_radius: f64, world_up: [f64; 3]) -> QueryContext {
    QueryContext {
        object_centre,
        prior_radius,
        world_up,
        target_ratio: 0.15,
    }
}

/// Unweighted cost values `[B]` of `cost` at `poses`, no masks, step 0, f64 on flex.
fn values(cost: &dyn Cost, poses: &[[f64; 6]], query: QueryContext) -> Vec<f64> {
    let device = Device::flex();
    let inputs = CostInputs::new(poses_tensor(poses, &device), None, 0, query).unwrap();
    host(cost.evaluate(&inputs).unwrap())
}

fn look_at(eye: [f64; 3], target: [f64; 3], up: [f64; 3]) -> [f64; 6] {
    Pose::look_at(DVec3::from(eye), DVec3::from(target), DVec3::from(up))
        .unwrap()
        .0
}

/// `pose` rolled by `angle` about its own optical axis: R_wc ← R_wc·R_z(angle).
fn rolled(pose: [f64; 6], angle: f64) -> [f64; 6] {
    let p = Pose(pose);
    Pose::from_rotation_and_centre(p.rotation_wc() * DMat3::from_rotation_z(angle), p.centre()).0
}

fn close(got: &[f64], want: &[f64], tolerance: f64) {
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() <= tolerance, "got {got:?}, want {want:?}");
    }
}

#[test]
fn up_vector_is_0_upright_2_upside_down_1_rolled_90_degrees() {
    let cost = UprightCost {
        weight: 1.0,
        mode: UprightMode::UpVector,
    };
    for up in [Z_UP, [0.0, -1.0, 0.0], [0.0, 0.0, 5.0]] {
        let u = DVec3::from(up);
        // A level camera: eye and target at the same height along `up`.
        let side = if u.z != 0.0 { DVec3::X } else { DVec3::Z };
        let eye = (side * 4.0 + u.normalize() * 0.5).to_array();
        let target = (u.normalize() * 0.5).to_array();
        let upright = look_at(eye, target, up);
        let upside_down = look_at(eye, target, (-u).to_array());
        let rolled_90 = rolled(upright, std::f64::consts::FRAC_PI_2);
        let got = values(
            &cost,
            &[upright, upside_down, rolled_90, rolled(upright, -1.0)],
            context([0.0; 3], 1.0, up),
        );
        close(&got, &[0.0, 2.0, 1.0, 1.0 - 1f64.cos()], 1e-12);
    }
}

#[test]
fn roll_mode_ignores_pitch_and_measures_horizon_tilt() {
    let roll = UprightCost {
        weight: 1.0,
        mode: UprightMode::Roll,
    };
    let up_vector = UprightCost {
        weight: 1.0,
        mode: UprightMode::UpVector,
    };
    // Pitched down 60°: the target is below the eye at 60° from the horizontal.
    let angle = 60f64.to_radians();
    let eye = [0.0, 0.0, 2.0];
    let pitched = look_at(eye, [angle.cos(), 0.0, 2.0 - angle.sin()], Z_UP);
    let query = context([0.0; 3], 1.0, Z_UP);
    close(&values(&roll, &[pitched], query), &[0.0], 1e-12);
    // The paper's form does penalise it: 1 − cos 60°.
    close(&values(&up_vector, &[pitched], query), &[0.5], 1e-12);

    let level = look_at(eye, [3.0, 1.0, 2.0], Z_UP);
    let thetas = [0.0, 0.3, -0.7, 1.2, std::f64::consts::FRAC_PI_2];
    let poses: Vec<_> = thetas.iter().map(|&t| rolled(level, t)).collect();
    let want: Vec<f64> = thetas.iter().map(|t| t.sin().powi(2)).collect();
    close(&values(&roll, &poses, query), &want, 1e-12);
    // Rolling the pitched camera by θ: x' = cos θ·x + sin θ·y with x level and
    // ⟨y, up⟩ = −cos 60°, so the cost is (sin θ·cos 60°)².
    let got = values(&roll, &[rolled(pitched, 0.5)], query);
    close(&got, &[(0.5f64.sin() * 0.5).powi(2)], 1e-12);
}

#[test]
fn prior_hand_values() {
    let o = [1.0, 2.0, 3.0];
    let r = 1.0;
    let cost = PriorCost {
        alpha0: 1.0,
        gamma: 0.9,
        radius: None,
    };
    let query = context(o, r, Z_UP);
    let from = |offset: [f64; 3]| [o[0] + offset[0], o[1] + offset[1], o[2] + offset[2]];
    let looking_at = look_at(from([3.0, 0.0, 0.0]), o, Z_UP); // d = 3 > r, facing o
    let looking_away = look_at(from([3.0, 0.0, 0.0]), from([6.0, 0.0, 0.0]), Z_UP);
    let sideways = look_at(from([0.0, 3.0, 0.0]), from([1.0, 3.0, 0.0]), Z_UP);
    let inside = look_at(from([0.0, -0.5, 0.0]), o, Z_UP); // d = 0.5 < r
    let got = values(&cost, &[looking_at, looking_away, sideways, inside], query);
    // The guard moves values by ≤ 5e-7·(r + 1) (prior module docs).
    close(&got, &[3.0, 5.0, 4.0, 1.0], 1e-5);

    // A configured radius overrides the query's.
    let wide = PriorCost {
        radius: Some(5.0),
        ..cost.clone()
    };
    close(&values(&wide, &[looking_at], query), &[5.0], 1e-5);
}

#[test]
fn prior_at_the_object_centre_is_finite_with_finite_gradient() {
    let ad = Device::flex().autodiff();
    let o = [0.5, -1.0, 2.0];
    let cost = PriorCost::default();
    let pose = [
        [0.3, -0.2, 0.1, o[0], o[1], o[2]],
        [0.0, 0.0, 0.0, o[0], o[1], o[2]],
    ];
    let poses = poses_tensor(&pose, &ad).require_grad();
    let inputs = CostInputs::new(poses.clone(), None, 0, context(o, 2.0, Z_UP)).unwrap();
    let value = cost.evaluate(&inputs).unwrap();
    let grads = value.clone().sum().backward();
    // No direction to align with: alignment term 0, distance term clamped at r.
    close(&host(value), &[3.0, 3.0], 1e-12);
    let grad = host(poses.grad(&grads).unwrap());
    assert!(grad.iter().all(|g| g.is_finite()), "{grad:?}");
}

#[test]
fn prior_weight_decays_geometrically() {
    let cost = PriorCost {
        alpha0: 2.0,
        gamma: 0.5,
        radius: None,
    };
    let got: Vec<f64> = [0, 1, 3, 10].iter().map(|&k| cost.weight(k)).collect();
    close(&got, &[2.0, 1.0, 0.25, 2.0 / 1024.0], 1e-15);
    let constant = PriorCost { gamma: 1.0, ..cost };
    assert_eq!(constant.weight(1_000_000), 2.0);
    // The image costs' weights do not decay.
    assert_eq!(TceCost { weight: 0.7 }.weight(50), 0.7);
}

#[test]
fn default_prior_radius_frames_the_target_ratio() {
    // Unit cube: mean silhouette area 1.5; 60° × 60°: frame 4·tan²30° = 4/3 → r = √(1.5/0.2).
    let fov = 60f64.to_radians();
    let r = default_prior_radius([1.0, 1.0, 1.0], fov, fov, 0.15).unwrap();
    assert!((r - 7.5f64.sqrt()).abs() < 1e-12, "{r}");
    // Coverage at that distance is the target ratio, for a box and another fov.
    let (fx, fy) = (70f64.to_radians(), 45f64.to_radians());
    let (a, b, c) = (0.4, 1.3, 0.2);
    let r = default_prior_radius([a, b, c], fx, fy, 0.3).unwrap();
    let area = 0.5 * (a * b + b * c + c * a);
    let coverage = area / (r * r) / (4.0 * (fx / 2.0).tan() * (fy / 2.0).tan());
    assert!((coverage - 0.3).abs() < 1e-12, "{coverage}");
    // Farther for a smaller target share.
    assert!(default_prior_radius([a, b, c], fx, fy, 0.1).unwrap() > r);
    // Degenerate inputs name the argument.
    for (extent, fov, ratio, field) in [
        ([0.0; 3], fov, 0.15, "extent"),
        ([1.0, -1.0, 1.0], fov, 0.15, "extent"),
        ([1.0; 3], 0.0, 0.15, "fov_x"),
        ([1.0; 3], fov, 0.0, "target_ratio"),
    ] {
        match default_prior_radius(extent, fov, fov, ratio) {
            Err(CostError::InvalidContext { field: f, .. }) => assert_eq!(f, field),
            other => panic!("{extent:?} {fov} {ratio}: {other:?}"),
        }
    }
    // A segment still gets a radius.
    assert!(default_prior_radius([2.0, 0.0, 0.0], fov, fov, 0.15).unwrap() > 0.0);
}

/// Small deterministic generator (xorshift), uniform in [−1, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        2.0 * ((self.0 >> 11) as f64 / (1u64 << 53) as f64) - 1.0
    }
}

/// Autodiff gradient of Σ_b cost_b w.r.t. Φ `[B, 6]` against central finite differences.
fn check_gradient(cost: &dyn Cost, poses: &[[f64; 6]], query: QueryContext) {
    let ad = Device::flex().autodiff();
    let x = poses_tensor(poses, &ad).require_grad();
    let inputs = CostInputs::new(x.clone(), None, 0, query).unwrap();
    let grads = cost.evaluate(&inputs).unwrap().sum().backward();
    let grad = host(x.grad(&grads).unwrap());
    let total = |p: &[[f64; 6]]| values(cost, p, query).iter().sum::<f64>();
    let step = 1e-6;
    for b in 0..poses.len() {
        for k in 0..6 {
            let (mut plus, mut minus) = (poses.to_vec(), poses.to_vec());
            plus[b][k] += step;
            minus[b][k] -= step;
            let fd = (total(&plus) - total(&minus)) / (2.0 * step);
            let g = grad[b * 6 + k];
            assert!(
                (g - fd).abs() <= 1e-7 * fd.abs().max(1.0),
                "{}: sample {b}, Φ[{k}]: autodiff {g} vs finite differences {fd}",
                cost.name()
            );
        }
    }
    assert!(
        grad.iter().any(|g| g.abs() > 1e-2),
        "{}: trivial",
        cost.name()
    );
}

#[test]
fn upright_and_prior_gradients_match_finite_differences() {
    let mut rng = Rng(0xc057);
    let o = [0.4, -0.3, 1.1];
    let mut poses = Vec::new();
    for b in 0..6 {
        // ω of norm ≈ 0.05 (Rodrigues' series branch) for the first sample, up to ≈ 2.5 after.
        let scale = if b == 0 { 0.03 } else { 1.4 };
        let mut p = [0.0; 6];
        for (k, v) in p.iter_mut().enumerate() {
            *v = rng.next() * if k < 3 { scale } else { 3.0 };
        }
        poses.push(p);
    }
    // One camera inside the radius (d ≈ 0.3 < r = 1): only the alignment term moves it.
    poses.push([0.2, 1.0, -0.4, o[0] + 0.2, o[1] - 0.2, o[2] + 0.1]);
    let query = context(o, 1.0, [0.2, -0.9, 0.3]);
    for mode in [UprightMode::UpVector, UprightMode::Roll] {
        check_gradient(&UprightCost { weight: 1.0, mode }, &poses, query);
    }
    check_gradient(&PriorCost::default(), &poses, query);
}

/// A host form: one pose's value and its gradient in the pose.
type HostForm<'a> = &'a dyn Fn(&[f64; 6]) -> (f64, [f64; 6]);

/// Values `[B]` of a tensor form `f(rotations, centres)` at `poses` and the gradient of their
/// sum in the poses, by autodiff in f64 (Rodrigues as tensor ops).
fn tensor_form(
    poses: &[[f64; 6]],
    f: impl Fn(Tensor<3>, Tensor<2>) -> Tensor<1>,
) -> (Vec<f64>, Vec<f64>) {
    let ad = Device::flex().autodiff();
    let x = poses_tensor(poses, &ad).require_grad();
    let rotations = splatraj_render::camera::rotation_matrices(x.clone().narrow(1, 0, 3));
    let values = f(rotations, x.clone().narrow(1, 3, 3));
    let grads = values.clone().sum().backward();
    (host(values), host(x.grad(&grads).unwrap()))
}

#[test]
fn host_forms_of_upright_and_prior_match_their_tensor_forms() {
    let mut rng = Rng(0x7e57);
    let o = [0.4, -0.3, 1.1];
    let radius = 1.0;
    let epsilon = 0.1; // large, so the guard's terms count in the comparison
    let mut poses = Vec::new();
    for b in 0..8 {
        // Both branches of Rodrigues: |ω| ≈ 0.05 for the first two samples, up to ≈ 2.5 after.
        let scale = if b < 2 { 0.03 } else { 1.4 };
        poses.push(std::array::from_fn(|k| {
            rng.next() * if k < 3 { scale } else { 3.0 }
        }));
    }
    poses.push([0.2, 1.0, -0.4, o[0] + 0.2, o[1] - 0.2, o[2] + 0.1]); // inside the radius
    let up = {
        let u = DVec3::new(0.2, -0.9, 0.3).normalize();
        [u.x, u.y, u.z]
    };
    let device = Device::flex().autodiff();
    let row =
        |v: [f64; 3]| poses_tensor(&[[v[0], v[1], v[2], 0.0, 0.0, 0.0]], &device).narrow(1, 0, 3);
    let compare = |name: &str, host_form: HostForm, want: (Vec<f64>, Vec<f64>)| {
        for (b, pose) in poses.iter().enumerate() {
            let (value, gradient) = host_form(pose);
            assert!(
                (value - want.0[b]).abs() <= 1e-12 * want.0[b].abs().max(1.0),
                "{name}, sample {b}: value {value} vs {}",
                want.0[b]
            );
            for (k, (g, w)) in gradient.iter().zip(&want.1[b * 6..b * 6 + 6]).enumerate() {
                assert!(
                    (g - w).abs() <= 1e-10 * w.abs().max(1.0),
                    "{name}, sample {b}, Φ[{k}]: {g} vs {w}"
                );
            }
        }
    };
    for mode in [UprightMode::UpVector, UprightMode::Roll] {
        let want = tensor_form(&poses, |r, _| upright(r, row(up), mode));
        compare(
            &format!("upright {mode:?}"),
            &|p| upright_on_host(p, up, mode),
            want,
        );
    }
    let want = tensor_form(&poses, |r, c| prior(r, c, row(o), radius, epsilon));
    compare("prior", &|p| prior_on_host(p, o, radius, epsilon), want);
}

#[test]
fn host_form_of_clearance_matches_its_tensor_form() {
    let mut rng = Rng(0xc1ea);
    let margin = 0.4;
    let mut centres = Vec::new();
    let (mut points, mut normals) = (Vec::new(), Vec::new());
    for b in 0..12 {
        let c = DVec3::new(rng.next(), rng.next(), rng.next()) * 2.0;
        let n = DVec3::new(rng.next(), rng.next(), rng.next()).normalize();
        // Distances from inside the geometry (−0.3) to beyond the margin (0.6).
        let d = -0.3 + 0.9 * b as f64 / 11.0;
        centres.push(c);
        points.push(c - n * d);
        normals.push(n);
    }
    let poses: Vec<[f64; 6]> = centres
        .iter()
        .map(|c| [0.1, 0.2, 0.3, c.x, c.y, c.z])
        .collect();
    let device = Device::flex().autodiff();
    let rows = |v: &[DVec3]| {
        let rows: Vec<[f64; 6]> = v.iter().map(|p| [p.x, p.y, p.z, 0.0, 0.0, 0.0]).collect();
        poses_tensor(&rows, &device).narrow(1, 0, 3)
    };
    let want = tensor_form(&poses, |_, c| {
        clearance(c, rows(&points), rows(&normals), margin)
    });
    for b in 0..poses.len() {
        let (value, gradient) = clearance_on_host(centres[b], points[b], normals[b], margin);
        assert!(
            (value - want.0[b]).abs() <= 1e-12,
            "sample {b}: {value} vs {}",
            want.0[b]
        );
        for (k, g) in gradient.iter().enumerate() {
            let w = want.1[b * 6 + 3 + k];
            assert!(
                (g - w).abs() <= 1e-10 * w.abs().max(1.0),
                "sample {b}, c[{k}]: {g} vs {w}"
            );
        }
    }
    assert!(want.0.iter().any(|&v| v > 0.5) && want.0.contains(&0.0));
}

/// Row-major H×W mask with 1 inside columns `xs` and rows `ys`.
fn rect(
    width: usize,
    height: usize,
    xs: std::ops::Range<usize>,
    ys: std::ops::Range<usize>,
) -> Vec<f64> {
    let mut m = vec![0.0; width * height];
    for j in ys {
        for i in xs.clone() {
            m[j * width + i] = 1.0;
        }
    }
    m
}

#[test]
fn iou_of_boxes() {
    let (w, h) = (16, 12);
    let alone = rect(w, h, 2..10, 3..7);
    assert_eq!(bbox_iou(&alone, &alone, w, h), 1.0);
    // The right half hidden: visible box 4×4 of the alone box's 8×4.
    let half = rect(w, h, 2..6, 3..7);
    assert_eq!(bbox_iou(&half, &alone, w, h), 0.5);
    // A quarter hidden along the bottom (row 6 gone): 8×3 / 8×4.
    assert_eq!(bbox_iou(&rect(w, h, 2..10, 3..6), &alone, w, h), 0.75);
    // Disjoint boxes, and one empty box.
    let elsewhere = rect(w, h, 11..14, 8..11);
    assert_eq!(bbox_iou(&elsewhere, &alone, w, h), 0.0);
    let empty = vec![0.0; w * h];
    assert_eq!(bbox_iou(&empty, &alone, w, h), 0.0);
    // Both empty (object out of view): defined as 0 (iou module docs), never NaN.
    assert_eq!(bbox_iou(&empty, &empty, w, h), 0.0);
    // Threshold 0.5: a pixel at 0.49 is outside, at 0.5 inside.
    let mut faint = alone.clone();
    faint[5 * w + 12] = 0.49;
    assert_eq!(bbox_iou(&faint, &alone, w, h), 1.0);
    faint[5 * w + 12] = 0.5;
    assert!((bbox_iou(&faint, &alone, w, h) - 32.0 / 44.0).abs() < 1e-15);
    // The batched tensor version agrees.
    let device = Device::flex();
    let batch = |ms: Vec<Vec<f64>>| {
        let n = ms.len();
        Tensor::<3>::from_data(
            TensorData::new(ms.concat(), [n, h, w]),
            (&device, DType::F32),
        )
    };
    let got = bbox_iou_batch(
        batch(vec![alone.clone(), half, empty.clone()]),
        batch(vec![alone.clone(), alone, empty]),
    );
    assert_eq!(got, vec![1.0, 0.5, 0.0]);
}

/// The boxes found from row and column hits on the device are the boxes of the host's scan
/// of every pixel (`mask_box`), on random masks from empty to dense, with values at and just
/// below the threshold.
#[test]
fn boxes_from_device_hits_match_the_pixel_scan() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let (batch, h, w) = (40, 9, 13);
    let masks: Vec<Vec<f64>> = (0..batch)
        .map(|b| {
            let density = b as f64 / batch as f64 * 0.2;
            (0..h * w)
                .map(|_| match rng.random::<f64>() {
                    x if x < density / 2.0 => 0.5,
                    x if x < density => 0.9,
                    x if x < 2.0 * density => 0.499_999,
                    _ => 0.1 * rng.random::<f64>(),
                })
                .collect()
        })
        .collect();
    let device = Device::flex();
    let tensor = Tensor::<3>::from_data(
        TensorData::new(masks.concat(), [batch, h, w]),
        (&device, DType::F64),
    );
    let (rows, columns) = mask_hits(tensor, 0.5);
    let (rows, columns) = (host(rows), host(columns));
    let mut empty = 0;
    for (b, mask) in masks.iter().enumerate() {
        let expected = mask_box(mask, w, h, 0.5);
        empty += usize::from(expected.is_none());
        let got = box_from_hits(&rows[b * h..(b + 1) * h], &columns[b * w..(b + 1) * w]);
        assert_eq!(got, expected, "mask {b}");
    }
    assert!(
        empty > 0 && empty < batch,
        "{empty} empty masks: both cases must occur"
    );
}

#[test]
fn config_parses_and_rejects_unknown_keys_naming_them() {
    let config: CostsConfig = toml::from_str(
        r#"
        [tce]
        weight = 2.0
        [upright]
        mode = "roll"
        [prior]
        alpha0 = 3.0
        gamma = 0.95
        radius = 1.5
        "#,
    )
    .unwrap();
    assert_eq!(config.tce, Some(TceCost { weight: 2.0 }));
    assert_eq!(config.tre, None, "a cost without a table is off");
    assert_eq!(
        config.upright,
        Some(UprightCost {
            weight: 1.0,
            mode: UprightMode::Roll
        })
    );
    assert_eq!(
        config.prior,
        Some(PriorCost {
            alpha0: 3.0,
            gamma: 0.95,
            radius: Some(1.5)
        })
    );
    assert_eq!(config.build().unwrap().names(), ["tce", "upright", "prior"]);
    let mode: UprightCost = toml::from_str("mode = \"up-vector\"").unwrap();
    assert_eq!(mode.mode, UprightMode::UpVector);
    assert_eq!(
        CostsConfig::default().build().unwrap().names(),
        ["tce", "tre", "upright", "prior"]
    );

    for (text, key) in [
        ("[tcee]\nweight = 1.0", "tcee"),
        ("[prior]\ngama = 0.9", "gama"),
        ("[upright]\nweight = 1.0\nroll = true", "roll"),
        ("[upright]\nmode = \"pitch\"", "pitch"),
    ] {
        let err = toml::from_str::<CostsConfig>(text).unwrap_err().to_string();
        assert!(err.contains(key), "{text:?}: {err}");
    }

    for (text, key) in [
        ("[tce]\nweight = -1.0", "costs.tce.weight"),
        ("[tre]\nweight = nan", "costs.tre.weight"),
        ("[upright]\nweight = inf", "costs.upright.weight"),
        ("[prior]\nalpha0 = -0.5", "costs.prior.alpha0"),
        ("[prior]\ngamma = 0.0", "costs.prior.gamma"),
        ("[prior]\ngamma = 1.5", "costs.prior.gamma"),
        ("[prior]\nradius = -2.0", "costs.prior.radius"),
    ] {
        let config: CostsConfig = toml::from_str(text).unwrap();
        match config.build() {
            Err(e @ CostError::InvalidConfig(..)) => {
                assert!(e.to_string().contains(key), "{text:?}: {e}")
            }
            other => panic!("{text:?}: {other:?}"),
        }
    }
    // An empty [costs] table turns everything off, which is an error.
    assert!(matches!(
        toml::from_str::<CostsConfig>("").unwrap().build(),
        Err(CostError::Set(_))
    ));
}

#[test]
fn weighted_sum_equals_hand_weighted_terms() {
    let device = Device::flex();
    let (b, h, w) = (3, 6, 8);
    let mut rng = Rng(0xfeed);
    let masks: Vec<f64> = (0..b * h * w).map(|_| 0.5 + 0.5 * rng.next()).collect();
    let masks = Tensor::<3>::from_data(TensorData::new(masks, [b, h, w]), (&device, DType::F64));
    let poses: Vec<[f64; 6]> = (0..b)
        .map(|_| std::array::from_fn(|k| rng.next() * if k < 3 { 1.0 } else { 3.0 }))
        .collect();
    let query = QueryContext {
        object_centre: [0.1, 0.2, -0.3],
        prior_radius: 0.8,
        world_up: Z_UP,
        target_ratio: 0.25,
    };
    let config = CostsConfig {
        tce: Some(TceCost { weight: 0.7 }),
        tre: Some(TreCost { weight: 1.3 }),
        upright: Some(UprightCost {
            weight: 0.4,
            mode: UprightMode::Roll,
        }),
        prior: Some(PriorCost {
            alpha0: 2.0,
            gamma: 0.9,
            radius: None,
        }),
        clearance: None,
        motion: None,
        visibility: None,
        custom: Default::default(),
    };
    let costs = config.build().unwrap();
    assert!(costs.needs_mask());
    let step = 3;
    let inputs = CostInputs::new(
        poses_tensor(&poses, &device),
        Some(masks.clone()),
        step,
        query,
    )
    .unwrap();
    let terms = costs.evaluate(&inputs).unwrap();

    // Each term independently: the image costs from the plain functions, the pose costs alone.
    let tce_v = host(tce(masks.clone()));
    let tre_v = host(tre(masks, 0.25));
    let pose_only = |c: &dyn Cost| values(c, &poses, query);
    let up_v = pose_only(config.upright.as_ref().unwrap());
    let prior_v = pose_only(config.prior.as_ref().unwrap());
    let alpha = 2.0 * 0.9f64.powi(3);
    let want: Vec<f64> = (0..b)
        .map(|i| 0.7 * tce_v[i] + 1.3 * tre_v[i] + 0.4 * up_v[i] + alpha * prior_v[i])
        .collect();
    close(&host(terms.total.clone()), &want, 1e-12);
    let names: Vec<_> = terms.terms.iter().map(|t| t.name).collect();
    assert_eq!(names, ["tce", "tre", "upright", "prior"]);
    let weights: Vec<_> = terms.terms.iter().map(|t| t.weight).collect();
    close(&weights, &[0.7, 1.3, 0.4, alpha], 1e-15);
    close(&host(terms.terms[0].value.clone()), &tce_v, 1e-15);
    close(&host(terms.terms[3].value.clone()), &prior_v, 1e-15);
    let means = terms.means();
    assert!((means[1].2 - tre_v.iter().sum::<f64>() / b as f64).abs() < 1e-12);
    assert!((terms.total_mean() - want.iter().sum::<f64>() / b as f64).abs() < 1e-12);
    // Every term contributes (guards against a test that passes with a term dropped).
    assert!(
        tce_v
            .iter()
            .chain(&tre_v)
            .chain(&up_v)
            .chain(&prior_v)
            .all(|v| *v > 1e-6)
    );

    // Without a render, mask costs say so; pose-only costs need none.
    let no_mask = CostInputs::new(poses_tensor(&poses, &device), None, 0, query).unwrap();
    match costs.evaluate(&no_mask) {
        Err(CostError::MissingMask { cost }) => assert_eq!(cost, "tce"),
        other => panic!("{other:?}"),
    }
    let pose_costs = WeightedCosts::new(vec![
        Box::new(UprightCost::default()),
        Box::new(PriorCost::default()),
    ])
    .unwrap();
    assert!(!pose_costs.needs_mask());
    assert_eq!(host(pose_costs.evaluate(&no_mask).unwrap().total).len(), b);
    // Duplicate names are refused (their history columns would collide).
    assert!(matches!(
        WeightedCosts::new(vec![
            Box::new(TceCost::default()),
            Box::new(TceCost::default())
        ]),
        Err(CostError::Set(_))
    ));
}

#[test]
fn inputs_reject_bad_shapes_and_contexts() {
    let device = Device::flex();
    let poses = poses_tensor(&[[0.0; 6]; 2], &device);
    let query = context([0.0; 3], 1.0, Z_UP);
    let f32_masks = Tensor::<3>::zeros([2, 4, 4], &device);
    assert!(matches!(
        CostInputs::new(poses.clone(), Some(f32_masks), 0, query),
        Err(CostError::Shape(_))
    ));
    let wrong_batch = Tensor::<3>::from_data(
        TensorData::new(vec![0.0f64; 16], [1, 4, 4]),
        (&device, DType::F64),
    );
    assert!(matches!(
        CostInputs::new(poses.clone(), Some(wrong_batch), 0, query),
        Err(CostError::Shape(_))
    ));
    for (bad, field) in [
        (context([0.0; 3], 0.0, Z_UP), "prior_radius"),
        (context([0.0; 3], 1.0, [0.0; 3]), "world_up"),
        (context([f64::NAN, 0.0, 0.0], 1.0, Z_UP), "object_centre"),
    ] {
        match CostInputs::new(poses.clone(), None, 0, bad) {
            Err(CostError::InvalidContext { field: f, .. }) => assert_eq!(f, field),
            other => panic!("{field}: {other:?}"),
        }
    }
}
