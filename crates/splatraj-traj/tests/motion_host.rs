//! The motion cost computed on the host (value and hand-written gradient, joined to the graph
//! by its first-order expansion) against the tensor formulation it replaced, kept here as the
//! yardstick: every term as burn ops on the joined path, differentiated by autodiff. f64 on
//! flex, several stretches with their own time steps and object centres, one too short to be
//! charged, every limit active somewhere.

mod common;

use common::{host, poses_tensor};

use burn::tensor::{DType, Device, Tensor, TensorData};
use splatraj_traj::costs::{
    Cost, CostInputs, HostPoses, MotionCost, PathSamples, PathStretch, QueryContext,
};

/// Fewest poses a stretch needs for its motion to be charged.
const MIN_POSES: usize = 3;

fn context(object_centre: [f64; 3], prior_radius: f64) -> QueryContext {
    QueryContext {
        object_centre,
        prior_radius,
        world_up: [0.0, 0.0, 1.0],
        target_ratio: 0.15,
    }
}

/// max(0, x/limit² − 1), averaged per stretch `[W]`. A product with 1/limit², not a quotient:
/// burn's backward of `div_scalar` is off by ~10⁻⁸ relative in f64 (measured: d(x/9)/dx came
/// out 1/9 + 8·10⁻¹⁰), which would hide a real error at the tolerance this test keeps.
fn over_limit(path: &PathSamples, squared_rate: Tensor<1>, lag: usize, limit: f64) -> Tensor<1> {
    let charge = squared_rate
        .mul_scalar(1.0 / (limit * limit))
        .sub_scalar(1.0)
        .clamp_min(0.0);
    path.stretch_means(charge, lag, MIN_POSES)
}

/// The motion cost `[W]` as tensor ops (the formulas of `costs/motion.rs`).
fn tensor_motion(cost: &MotionCost, path: &PathSamples) -> Tensor<1> {
    let poses = path.poses.clone(); // [ΣP, 6]
    let [count, _] = poses.dims();
    let seconds = path.seconds.unwrap();
    let of_dt = |lag: usize, f: fn(f64) -> f64| path.per_row(lag, |s| f(s.time_step * seconds));
    let centres = poses.clone().narrow(1, 3, 3);
    let steps = centres.clone().narrow(0, 1, count - 1) - centres.clone().narrow(0, 0, count - 1);
    let squared_speed =
        of_dt(1, |dt| dt * dt).divide(steps.clone().square().sum_dim(1).reshape([count - 1]));
    let mut total = path.per_stretch(poses.clone().narrow(1, 0, 1).sum().mul_scalar(0.0));
    if let Some(limit) = cost.max_speed.and_then(|s| s.value()) {
        total = total + over_limit(path, squared_speed.clone(), 1, limit);
    }
    if let Some(limit) = cost.max_acceleration {
        let second = steps.clone().narrow(0, 1, count - 2) - steps.narrow(0, 0, count - 2);
        let squared =
            of_dt(2, |dt| dt.powi(4)).divide(second.square().sum_dim(1).reshape([count - 2]));
        total = total + over_limit(path, squared, 2, limit);
    }
    if let Some(limit) = cost.max_angular_speed {
        let rotations = splatraj_render::camera::rotation_matrices(poses.clone().narrow(1, 0, 3));
        let turns = rotations.clone().narrow(0, 1, count - 1) - rotations.narrow(0, 0, count - 1);
        let squared_angle = of_dt(1, |dt| 2.0 * dt * dt)
            .divide(turns.square().sum_dim(2).sum_dim(1).reshape([count - 1]));
        total = total + over_limit(path, squared_angle, 1, limit.to_radians());
    }
    if let Some(limit) = cost.max_orbit_speed {
        let floor_sq = path.per_row(0, |s| (1e-6 * s.context.prior_radius).powi(2));
        let offsets = centres - path.context_rows(|c| c.object_centre);
        let lengths = floor_sq.floor(offsets.clone().square().sum_dim(1)).sqrt();
        let directions = offsets / lengths.expand([count, 3]);
        let chords =
            directions.clone().narrow(0, 1, count - 1) - directions.narrow(0, 0, count - 1);
        let squared_angle =
            of_dt(1, |dt| dt * dt).divide(chords.square().sum_dim(1).reshape([count - 1]));
        total = total + over_limit(path, squared_angle, 1, limit.to_radians());
    }
    if cost.even_speed > 0.0 {
        let mean = path
            .stretch_means(squared_speed.clone(), 1, MIN_POSES)
            .add_scalar(1e-12);
        let ratio = (squared_speed / path.spread(mean, 1)).sub_scalar(1.0);
        let spread = path.stretch_means(ratio.square(), 1, MIN_POSES);
        total = total + spread.mul_scalar(cost.even_speed);
    }
    total
}

fn xorshift(state: &mut u64) -> f64 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

/// Three windows' stretches: a fast turning orbit, a short stretch (2 poses: not charged) and
/// an accelerating, uneven one passing near its object centre.
fn joined_path() -> (Vec<[f64; 6]>, Vec<PathStretch>) {
    let mut rng = 0x5EED_u64;
    let mut poses = Vec::new();
    for k in 0..9 {
        let phase = 0.35 * k as f64;
        poses.push([
            0.1 + 0.3 * phase,
            -0.2 + 0.05 * xorshift(&mut rng),
            0.3 - 0.2 * phase,
            1.0 + 1.5 * phase.cos(),
            -2.0 + 1.5 * phase.sin(),
            0.5 + 0.1 * xorshift(&mut rng),
        ]);
    }
    poses.push([0.2, 0.1, 0.0, 0.3, 0.3, 0.3]);
    poses.push([0.25, 0.1, 0.05, 0.5, 0.2, 0.3]);
    for k in 0..12 {
        let t = k as f64 * 0.1;
        poses.push([
            2.5 + 0.4 * t * t,
            0.1 * xorshift(&mut rng),
            -0.1,
            -1.0 + 2.0 * t + 0.8 * t * t + 0.05 * xorshift(&mut rng),
            0.01 + 0.02 * xorshift(&mut rng),
            0.02 * xorshift(&mut rng),
        ]);
    }
    let stretches = vec![
        PathStretch {
            rows: 9,
            time_step: 0.02,
            context: context([1.0, -2.0, 0.5], 0.7),
        },
        PathStretch {
            rows: 2,
            time_step: 0.05,
            context: context([0.0; 3], 0.5),
        },
        PathStretch {
            rows: 12,
            time_step: 0.01,
            context: context([0.0, 0.0, 0.0], 1.2),
        },
    ];
    (poses, stretches)
}

/// Distinct weights w + 1 of the windows' values `[W]`, so a gradient landing in the wrong
/// window shows.
fn window_weights(windows: usize, device: &Device) -> Tensor<1> {
    Tensor::<1>::from_data(
        TensorData::new((1..=windows).map(|w| w as f64).collect(), [windows]),
        (device, DType::F64),
    )
}

/// Per-window values and the gradient of Σ_w (w + 1)·value_w in the poses.
fn value_and_gradient(
    poses: &[[f64; 6]],
    evaluate: impl Fn(Tensor<2>) -> Tensor<1>,
) -> (Vec<f64>, Vec<f64>) {
    let device = Device::flex().autodiff();
    let tensor = poses_tensor(poses, &device).require_grad();
    let values = evaluate(tensor.clone());
    let [windows] = values.dims();
    let grads = (values.clone() * window_weights(windows, &device))
        .sum()
        .backward();
    (host(values), host(tensor.grad(&grads).unwrap()))
}

fn assert_close(what: &str, got: &[f64], want: &[f64], tolerance: f64) {
    assert_eq!(got.len(), want.len(), "{what}: lengths");
    let scale = want.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (g - w).abs() <= tolerance * scale,
            "{what}[{k}]: host {g}, tensor {w} (scale {scale})"
        );
    }
}

#[test]
fn host_motion_cost_matches_the_tensor_formulation_on_a_joined_path() {
    let (poses, stretches) = joined_path();
    let seconds = Some(4.0);
    let path_of = |t: Tensor<2>| PathSamples::joined(t, stretches.clone(), seconds).unwrap();
    let costs = [
        MotionCost {
            weight: 1.0,
            max_speed: Some(0.8.into()),
            max_acceleration: Some(3.0),
            max_angular_speed: Some(20.0),
            max_orbit_speed: Some(15.0),
            even_speed: 0.7,
        },
        MotionCost {
            max_angular_speed: Some(36.0),
            max_orbit_speed: Some(36.0),
            max_speed: Some(5.9.into()),
            ..MotionCost::default()
        },
        MotionCost {
            even_speed: 1.0,
            ..MotionCost::default()
        },
    ];
    for cost in &costs {
        let reference = value_and_gradient(&poses, |t| tensor_motion(cost, &path_of(t)));
        // The host cost as a step calls it (its host poses given) and as anything else does
        // (read back here).
        for given in [true, false] {
            let got = value_and_gradient(&poses, |t| {
                let mut inputs = CostInputs::new(t.clone(), None, 0, stretches[0].context)
                    .unwrap()
                    .with_path(path_of(t));
                if given {
                    inputs = inputs.with_host_poses(HostPoses {
                        samples: poses.clone(),
                        path: Some(poses.clone()),
                    });
                }
                cost.evaluate(&inputs).unwrap()
            });
            assert!(reference.0.iter().any(|&v| v > 1e-3), "{cost:?}: charges");
            assert_eq!(reference.0[1], 0.0, "the short stretch is not charged");
            assert_close("values", &got.0, &reference.0, 1e-10);
            assert_close("gradient", &got.1, &reference.1, 1e-10);
        }
    }
}

#[test]
fn host_motion_cost_carries_its_gradient_back_through_what_made_the_poses() {
    // The poses as a function of parameters θ (Φ = 2θ + 1): the gradient reaches θ doubled.
    let (poses, stretches) = joined_path();
    let cost = MotionCost {
        max_speed: Some(0.5.into()),
        max_angular_speed: Some(10.0),
        ..MotionCost::default()
    };
    let device = Device::flex().autodiff();
    let parameters: Vec<[f64; 6]> = poses.iter().map(|p| p.map(|v| (v - 1.0) / 2.0)).collect();
    let theta = poses_tensor(&parameters, &device).require_grad();
    let made = theta.clone().mul_scalar(2.0).add_scalar(1.0);
    let path = PathSamples::joined(made.clone(), stretches.clone(), Some(4.0)).unwrap();
    let inputs = CostInputs::new(made, None, 0, stretches[0].context)
        .unwrap()
        .with_path(path);
    let values = cost.evaluate(&inputs).unwrap();
    let [windows] = values.dims();
    let grads = (values * window_weights(windows, &device)).sum().backward();
    let via_theta = host(theta.grad(&grads).unwrap());
    let (_, direct) = value_and_gradient(&poses, |t| {
        let path = PathSamples::joined(t.clone(), stretches.clone(), Some(4.0)).unwrap();
        let inputs = CostInputs::new(t, None, 0, stretches[0].context)
            .unwrap()
            .with_path(path);
        cost.evaluate(&inputs).unwrap()
    });
    let doubled: Vec<f64> = direct.iter().map(|g| 2.0 * g).collect();
    assert!(doubled.iter().any(|g| g.abs() > 1e-3));
    assert_close("∂L/∂θ", &via_theta, &doubled, 1e-12);
}
