//! Trajectory models against hand-computed bases, exact fits of poses in each model's span, the
//! tensor forward against the host evaluation, and the weight gradient against its closed form.

use burn::tensor::{DType, Device, Tensor, TensorData};
use splatraj_traj::trajectory::{
    Basis, LensPath, POSE_DIM, Polynomial, Pose, Rbf, RbfNormalisation, Trajectory,
    TrajectoryError, TrajectoryModel, TrajectoryRecord, Waypoint, ZoomRange, uniform_times,
};

fn host<const D: usize>(t: Tensor<D>) -> Vec<f64> {
    t.into_data().try_into_vec_as::<f64>().unwrap()
}

fn times_tensor(times: &[f64], device: &Device, dtype: DType) -> Tensor<1> {
    Tensor::from_data(
        TensorData::new(times.to_vec(), [times.len()]),
        (device, dtype),
    )
}

/// Deterministic, irregular weights `[K][6]` (no RNG dependency; values in about [−2, 2]).
fn weights(k: usize) -> Vec<Pose> {
    (0..k)
        .map(|i| std::array::from_fn(|j| ((i * 7 + j * 13) as f64 * 0.37).sin() * 2.0))
        .collect()
}

/// Irregular times in [0, 1], none on a 1/100 boundary (0.5 is irrational-ish away from one).
fn odd_times(count: usize) -> Vec<f64> {
    (0..count)
        .map(|i| ((i as f64 + 0.5) * 0.618_033_988_75).fract())
        .collect()
}

fn models() -> Vec<TrajectoryModel> {
    vec![
        TrajectoryModel::Rbf(Rbf::new(3, 2, None)),
        TrajectoryModel::Rbf(normalised(3, 2, None)),
        TrajectoryModel::Waypoint(Waypoint::default()),
        TrajectoryModel::Polynomial(Polynomial::default()),
    ]
}

fn normalised(windows: usize, centres: usize, sigma: Option<f64>) -> Rbf {
    Rbf {
        normalisation: RbfNormalisation::PartitionOfUnity,
        ..Rbf::new(windows, centres, sigma)
    }
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn rbf_basis_matches_hand_values() {
    // 2 windows × 2 centres: window [0, ½] split into cells [0, ¼], [¼, ½] with middles ⅛, ⅜;
    // window [½, 1] likewise ⅝, ⅞. σ = 0.1, so 2σ² = 0.02.
    let rbf = Rbf::new(2, 2, Some(0.1));
    assert_eq!(rbf.centres(), vec![0.125, 0.375, 0.625, 0.875]);
    let mut row = [0.0; 4];
    rbf.eval_into(0.3, &mut row);
    // (0.3 − t_k)² / 0.02 = 0.030625/0.02, 0.005625/0.02, 0.105625/0.02, 0.330625/0.02.
    let want = [
        (-1.53125f64).exp(),
        (-0.28125f64).exp(),
        (-5.28125f64).exp(),
        (-16.53125f64).exp(),
    ];
    assert!(max_abs_diff(&row, &want) < 1e-15, "{row:?} vs {want:?}");
    // At a centre the basis is exactly 1.
    rbf.eval_into(0.625, &mut row);
    assert_eq!(row[2], 1.0);

    // One centre per window (the paper): the windows' middles 1/6, 1/2, 5/6, σ = spacing = 1/3.
    let paper = Rbf::new(3, 1, None);
    let centres = paper.centres();
    assert!(max_abs_diff(&centres, &[1.0 / 6.0, 0.5, 5.0 / 6.0]) < 1e-15);
    assert!((paper.effective_sigma() - 1.0 / 3.0).abs() < 1e-15);
    let mut row = [0.0; 3];
    paper.eval_into(0.0, &mut row);
    // (1/6)²/(2/9) = 1/8, (1/2)²/(2/9) = 9/8, (5/6)²/(2/9) = 25/8.
    let want = [(-0.125f64).exp(), (-1.125f64).exp(), (-3.125f64).exp()];
    assert!(max_abs_diff(&row, &want) < 1e-15, "{row:?} vs {want:?}");
}

#[test]
fn waypoint_basis_is_one_hot_of_100_segments() {
    let waypoint = Waypoint::default();
    assert_eq!(waypoint.count(), 100);
    let cases = [
        (0.0, 0),
        (0.005, 0),
        (0.0099, 0),
        (0.01, 1),
        (0.505, 50),
        (0.999, 99),
        (1.0, 99), // The last segment is closed.
        (-0.5, 0), // Outside [0, 1] the end segments extend.
        (1.5, 99),
    ];
    let mut row = vec![0.0; 100];
    for (t, segment) in cases {
        waypoint.eval_into(t, &mut row);
        let ones: Vec<usize> = (0..100).filter(|&k| row[k] == 1.0).collect();
        assert_eq!(ones, vec![segment], "t = {t}");
        assert_eq!(row.iter().sum::<f64>(), 1.0, "t = {t}");
    }

    // Piecewise constant: with weight row j = j, every time inside segment j gives pose j.
    let w: Vec<Pose> = (0..100).map(|j| [j as f64; POSE_DIM]).collect();
    let device = Device::flex();
    let traj =
        Trajectory::from_weights(TrajectoryModel::Waypoint(waypoint), &w, &device, DType::F64)
            .unwrap();
    let times: Vec<f64> = (0..100)
        .flat_map(|j| [0.001, 0.004, 0.0095].map(|d| j as f64 / 100.0 + d))
        .collect();
    for (t, pose) in times.iter().zip(traj.poses_at(&times)) {
        let j = (t * 100.0).floor();
        assert_eq!(pose, [j; POSE_DIM], "t = {t}");
    }
    // Exactly 100 distinct values over a dense grid.
    let mut seen: Vec<f64> = traj
        .poses_at(&uniform_times(10_001))
        .iter()
        .map(|p| p[0])
        .collect();
    seen.dedup();
    assert_eq!(seen.len(), 100);
}

#[test]
fn polynomial_basis_is_exact() {
    let poly = Polynomial::default();
    assert_eq!(poly.count(), 6);
    let mut row = [0.0; 6];
    for (t, want) in [
        (0.5, [1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125]),
        (2.0, [1.0, 2.0, 4.0, 8.0, 16.0, 32.0]),
        (-1.0, [1.0, -1.0, 1.0, -1.0, 1.0, -1.0]),
        (0.0, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
    ] {
        poly.eval_into(t, &mut row);
        assert_eq!(row, want, "t = {t}");
    }
}

/// The normalised bases sum to 1 at every t (so a held pose is one weight vector, exactly),
/// equal the paper's bases over their sum, and stay finite in f32 with a σ so narrow that the
/// paper's bases all underflow between centres.
#[test]
fn normalised_rbf_bases_are_a_partition_of_unity() {
    let plain = Rbf::new(3, 4, None);
    let unit = normalised(3, 4, None);
    let times = odd_times(41);
    let (p, u) = (plain.matrix(&times), unit.matrix(&times));
    for (row_p, row_u) in p.chunks(12).zip(u.chunks(12)) {
        let sum: f64 = row_p.iter().sum();
        assert!((row_u.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        for (a, b) in row_p.iter().zip(row_u) {
            assert!((a / sum - b).abs() < 1e-12, "{a} / {sum} against {b}");
        }
    }
    let held = [[0.1, -0.2, 0.3, 1.5, -2.5, 0.7]; 12];
    let device = Device::flex();
    let trajectory =
        Trajectory::from_weights(TrajectoryModel::Rbf(unit), &held, &device, DType::F64).unwrap();
    for pose in trajectory.poses_at(&[0.0, 0.37, 1.0]) {
        assert!(max_abs_diff(&pose, &held[0]) < 1e-12, "{pose:?}");
    }
    // σ = spacing / 40: exp(−d²/2σ²) is 0 in f32 halfway between centres.
    let narrow = normalised(3, 4, Some(1.0 / 12.0 / 40.0));
    let got = host(narrow.tensor(times_tensor(&times, &device, DType::F32)));
    assert!(got.iter().all(|v| v.is_finite()), "NaN in the f32 bases");
    let want = narrow.matrix(&times);
    assert!(max_abs_diff(&got, &want) < 1e-5);
}

#[test]
fn tensor_basis_equals_host_basis() {
    let device = Device::flex();
    let mut times = odd_times(57);
    times.extend([0.0, 0.01, 0.5, 1.0]); // Waypoint boundaries: f64 floors agree exactly.
    for model in models() {
        let got = host(model.tensor(times_tensor(&times, &device, DType::F64)));
        let want = model.matrix(&times);
        assert!(
            max_abs_diff(&got, &want) < 1e-15,
            "{}: basis differs",
            model.name()
        );
    }
}

#[test]
fn fit_reproduces_a_quadratic_with_the_polynomial_model() {
    // c_j(t) = a_j + b_j t + q_j t²: in the span of [1, t, …, t⁵], so the fit is exact.
    let (a, b, q) = (
        [0.1, -0.2, 0.3, 1.0, -2.0, 3.5],
        [0.5, 0.0, -1.5, 2.0, 0.25, -4.0],
        [-0.3, 0.7, 0.2, -1.0, 3.0, 0.5],
    );
    let truth = |t: f64| -> Pose { std::array::from_fn(|j| a[j] + b[j] * t + q[j] * t * t) };
    let times = uniform_times(40);
    let poses: Vec<Pose> = times.iter().map(|&t| truth(t)).collect();
    let device = Device::flex();
    let traj = Trajectory::fit(
        TrajectoryModel::Polynomial(Polynomial::default()),
        &times,
        &poses,
        &device,
        DType::F64,
    )
    .unwrap();
    let check = [0.0, 0.123, 0.5, 0.77, 1.0, 1.3];
    for (t, got) in check.iter().zip(traj.poses_at(&check)) {
        let want = truth(*t);
        assert!(
            max_abs_diff(&got, &want) < 1e-9,
            "t = {t}: {got:?} vs {want:?}"
        );
    }
    let w = traj.host_weights();
    for j in 0..POSE_DIM {
        let got = [w[0][j], w[1][j], w[2][j], w[3][j], w[4][j], w[5][j]];
        let want = [a[j], b[j], q[j], 0.0, 0.0, 0.0];
        assert!(max_abs_diff(&got, &want) < 1e-8, "component {j}: {got:?}");
    }
}

#[test]
fn fit_recovers_weights_of_poses_in_each_models_span() {
    let device = Device::flex();
    // Dense enough that every waypoint segment holds samples.
    let times = uniform_times(401);
    for model in models() {
        let w0 = weights(model.count());
        let source = Trajectory::from_weights(model.clone(), &w0, &device, DType::F64).unwrap();
        let poses = source.poses_at(&times);
        let fitted = Trajectory::fit(model.clone(), &times, &poses, &device, DType::F64).unwrap();
        let got: Vec<f64> = fitted.poses_at(&odd_times(77)).concat();
        let want: Vec<f64> = source.poses_at(&odd_times(77)).concat();
        assert!(
            max_abs_diff(&got, &want) < 1e-9,
            "{}: poses differ by {}",
            model.name(),
            max_abs_diff(&got, &want)
        );
        let w = fitted.host_weights();
        assert!(
            max_abs_diff(&w.concat(), &w0.concat()) < 1e-6,
            "{}: weights differ",
            model.name()
        );
    }
}

#[test]
fn fit_gives_unreached_waypoint_segments_zero_weight() {
    // Samples only in the first half: the ridge keeps the second half's weights at 0 (finite).
    let device = Device::flex();
    let times: Vec<f64> = (0..500).map(|i| i as f64 / 1000.0).collect();
    let poses: Vec<Pose> = times.iter().map(|_| [1.0; POSE_DIM]).collect();
    let traj = Trajectory::fit(
        TrajectoryModel::Waypoint(Waypoint::default()),
        &times,
        &poses,
        &device,
        DType::F64,
    )
    .unwrap();
    let w = traj.host_weights();
    assert!(w[..50].iter().flatten().all(|v| (v - 1.0).abs() < 1e-12));
    assert!(w[50..].iter().flatten().all(|v| *v == 0.0));
}

#[test]
fn fit_rejects_bad_data() {
    let device = Device::flex();
    let model = TrajectoryModel::Polynomial(Polynomial::default());
    let fit = |times: &[f64], poses: &[Pose]| {
        Trajectory::fit(model.clone(), times, poses, &device, DType::F64).map(|_| ())
    };
    assert!(matches!(
        fit(&[0.0, 1.0], &[[0.0; 6]]),
        Err(TrajectoryError::FitData(_))
    ));
    assert!(matches!(fit(&[], &[]), Err(TrajectoryError::FitData(_))));
    assert!(matches!(
        fit(&[0.0, f64::NAN], &[[0.0; 6]; 2]),
        Err(TrajectoryError::FitData(_))
    ));
    assert!(matches!(
        Trajectory::from_weights(model.clone(), &[[0.0; 6]; 5], &device, DType::F64),
        Err(TrajectoryError::WeightRows {
            expected: 6,
            got: 5
        })
    ));
}

#[test]
fn tensor_forward_equals_host_poses() {
    let device = Device::flex();
    let times = odd_times(64);
    for model in models() {
        let w = weights(model.count());
        for (dtype, tolerance) in [(DType::F64, 1e-12), (DType::F32, 2e-5)] {
            let traj = Trajectory::from_weights(model.clone(), &w, &device, dtype).unwrap();
            let out = traj.forward(times_tensor(&times, &device, dtype));
            assert_eq!(out.dims(), [64, POSE_DIM]);
            let got = host(out);
            let want: Vec<f64> = traj.poses_at(&times).concat();
            let scale = want.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            assert!(
                max_abs_diff(&got, &want) <= tolerance * scale,
                "{} {dtype:?}: {}",
                model.name(),
                max_abs_diff(&got, &want)
            );
        }
        // f32 times against f64 weights: the basis is evaluated in the weights' dtype.
        let traj = Trajectory::from_weights(model.clone(), &w, &device, DType::F64).unwrap();
        let out = traj.forward(times_tensor(&times, &device, DType::F32));
        assert_eq!(out.dtype(), DType::F64);
    }
}

#[test]
fn weight_gradient_equals_closed_form() {
    // L = Σ_bj c_bj Φ_bj²  ⇒  ∂L/∂Φ = 2 c ⊙ Φ  ⇒  ∂L/∂W = Ψᵀ (2 c ⊙ Φ), Ψ = basis [B, K].
    let device = Device::flex().autodiff();
    let times = odd_times(23);
    let batch = times.len();
    let c: Vec<f64> = (0..batch * POSE_DIM)
        .map(|i| (i as f64 * 0.91).cos())
        .collect();
    for model in models() {
        let k = model.count();
        let traj =
            Trajectory::from_weights(model.clone(), &weights(k), &device, DType::F64).unwrap();
        let phi = traj.forward(times_tensor(&times, &device, DType::F64)); // [B, 6]
        let coeff = Tensor::<2>::from_data(
            TensorData::new(c.clone(), [batch, POSE_DIM]),
            (&device, DType::F64),
        );
        let loss = (phi.clone() * phi * coeff).sum();
        let grads = loss.backward();
        let got = host(traj.weights.grad(&grads).expect("weights are tracked"));

        let psi = model.matrix(&times); // [B, K]
        let poses: Vec<f64> = traj.poses_at(&times).concat(); // [B, 6]
        let mut want = vec![0.0; k * POSE_DIM];
        for b in 0..batch {
            for kk in 0..k {
                for j in 0..POSE_DIM {
                    let dl_dphi = 2.0 * c[b * POSE_DIM + j] * poses[b * POSE_DIM + j];
                    want[kk * POSE_DIM + j] += psi[b * k + kk] * dl_dphi;
                }
            }
        }
        assert!(
            max_abs_diff(&got, &want) < 1e-12,
            "{}: {}",
            model.name(),
            max_abs_diff(&got, &want)
        );
    }
}

#[test]
fn models_parse_from_toml_and_name_bad_keys() {
    let rbf: TrajectoryModel =
        toml::from_str("kind = \"rbf\"\ncentres_per_window = 3\nsigma = 0.05").unwrap();
    assert_eq!(rbf, TrajectoryModel::Rbf(Rbf::new(1, 3, Some(0.05))));
    assert_eq!(rbf.clone().with_windows(4).count(), 12);

    let waypoint: TrajectoryModel = toml::from_str("kind = \"waypoint\"").unwrap();
    assert_eq!(waypoint.count(), 100);
    let poly: TrajectoryModel = toml::from_str("kind = \"polynomial\"").unwrap();
    assert_eq!(poly.count(), 6);

    let unknown = toml::from_str::<TrajectoryModel>("kind = \"rbf\"\nsigmma = 0.1")
        .unwrap_err()
        .to_string();
    assert!(unknown.contains("sigmma"), "{unknown}");
    let kind = toml::from_str::<TrajectoryModel>("kind = \"spline\"")
        .unwrap_err()
        .to_string();
    assert!(kind.contains("spline"), "{kind}");
    assert!(kind.contains("custom.<name>"), "{kind}");
    // A bad value of a built-in model's key is that key's, not a registered model's name.
    let normalisation =
        toml::from_str::<TrajectoryModel>("kind = \"rbf\"\nnormalisation = \"bogus\"")
            .unwrap_err()
            .to_string();
    assert!(
        normalisation.contains("partition-of-unity"),
        "{normalisation}"
    );
    assert!(!normalisation.contains("custom."), "{normalisation}");

    let device = Device::flex();
    for (model, key) in [
        (TrajectoryModel::Rbf(Rbf::new(2, 1, Some(0.0))), "sigma"),
        (
            TrajectoryModel::Rbf(Rbf::new(2, 0, None)),
            "centres_per_window",
        ),
        (TrajectoryModel::Rbf(Rbf::new(0, 1, None)), "windows"),
        (
            TrajectoryModel::Waypoint(Waypoint { segments: 0 }),
            "segments",
        ),
        (
            TrajectoryModel::Polynomial(Polynomial { terms: 0 }),
            "terms",
        ),
    ] {
        let err = Trajectory::zeros(model, &device, DType::F32).unwrap_err();
        assert!(err.to_string().contains(key), "{err}");
    }
}

#[test]
fn record_round_trips_through_json() {
    let device = Device::flex();
    let model = TrajectoryModel::Rbf(Rbf::new(3, 2, Some(0.08)));
    let traj = Trajectory::from_weights(model, &weights(6), &device, DType::F64).unwrap();
    let json = serde_json::to_string(&traj.record()).unwrap();
    let back: TrajectoryRecord = serde_json::from_str(&json).unwrap();
    let again = Trajectory::from_record(&back, &device, DType::F64).unwrap();
    assert_eq!(back.model, *traj.model());
    // serde_json's default float parser may be off in the last bit (its `float_roundtrip`
    // feature is off in this workspace), hence a tolerance rather than equality.
    let times = odd_times(9);
    let err = max_abs_diff(
        &traj.poses_at(&times).concat(),
        &again.poses_at(&times).concat(),
    );
    assert!(err < 1e-14, "{err}");
}

/// Pairs of models whose first lies in the second's span: every segment of a 100-segment
/// waypoint model lies inside one of a 50-segment model's, and a cubic polynomial (N = 4) is
/// one of degree 5 (N = 6).
fn nested_models() -> [(TrajectoryModel, TrajectoryModel); 2] {
    [
        (
            TrajectoryModel::Waypoint(Waypoint { segments: 50 }),
            TrajectoryModel::Waypoint(Waypoint::default()),
        ),
        (
            TrajectoryModel::Polynomial(Polynomial { terms: 4 }),
            TrajectoryModel::Polynomial(Polynomial::default()),
        ),
    ]
}

#[test]
fn refit_moves_a_trajectory_into_a_model_that_contains_it() {
    // Every segment of a 100-segment waypoint model lies inside one segment of a 50-segment
    // model, so the coarse trajectory is in the fine one's span and the refit is exact; same for
    // a cubic polynomial (N = 4) refitted as N = 6.
    let device = Device::flex();
    let times = odd_times(200);
    for (coarse, fine) in nested_models() {
        let source = Trajectory::from_weights(
            coarse.clone(),
            &weights(coarse.count()),
            &device,
            DType::F64,
        )
        .unwrap();
        let moved = source.refit(fine.clone(), 1001).unwrap();
        assert_eq!(moved.model(), &fine);
        let err = max_abs_diff(
            &moved.poses_at(&times).concat(),
            &source.poses_at(&times).concat(),
        );
        assert!(err < 1e-9, "{} refit error {err}", fine.name());
    }
}

/// A zooming trajectory of `model` with the weights of [`weights`] and the zoom `lens`.
fn zooming(model: &TrajectoryModel, lens: &LensPath) -> Trajectory {
    Trajectory::from_weights(
        model.clone(),
        &weights(model.count()),
        &Device::flex(),
        DType::F64,
    )
    .unwrap()
    .with_lens(Some(lens))
    .unwrap()
}

#[test]
fn refit_carries_the_zoom_into_a_model_that_contains_it() {
    // As the poses above: the coarse model's u(t) = Ψ(t)·w_s lies in the fine model's span, so
    // the refitted zoom is the source's up to rounding, at times the fit never saw.
    let range = ZoomRange { min: 0.4, max: 3.0 };
    let times = odd_times(200);
    for (coarse, fine) in nested_models() {
        let lens = LensPath {
            range,
            weights: weights(coarse.count()).iter().map(|w| 0.7 * w[0]).collect(),
        };
        let source = zooming(&coarse, &lens);
        let zooms = source.zooms_at(&times);
        let (lo, hi) = zooms
            .iter()
            .fold((f64::MAX, 0.0f64), |(a, b), &s| (a.min(s), b.max(s)));
        assert!(
            hi / lo > 1.5,
            "{}: the source zooms: {lo}..{hi}",
            coarse.name()
        );
        let moved = source.refit(fine.clone(), 1001).unwrap();
        assert_eq!(moved.lens_path().map(|l| l.range), Some(range));
        let err = max_abs_diff(&moved.zooms_at(&times), &zooms);
        assert!(err < 1e-9, "{} zoom refit error {err}", fine.name());
    }
}

#[test]
fn refit_into_waypoints_keeps_the_zoom_within_each_segments_own_variation() {
    // A smooth zoom (a quintic's u(t)) refitted into 100 piecewise-constant segments from 1001
    // even samples: each segment's free value is the mean of the source's u at the samples in
    // it (the ridge aside, 1e-8 of the column norm), so it lies between their smallest and
    // largest, and s = zoom(u) being monotone, the refitted s at any time t of the segment lies
    // within the source's s over those samples and t itself.
    let range = ZoomRange::default();
    let source_model = TrajectoryModel::Polynomial(Polynomial::default());
    let fit_times = uniform_times(1001);
    let wanted: Vec<f64> = fit_times
        .iter()
        .map(|t| (0.5 * (2.0 * std::f64::consts::PI * t).sin() + 0.3 * t).exp())
        .collect();
    let lens = LensPath::fit(&source_model, range, &fit_times, &wanted).unwrap();
    let source = zooming(&source_model, &lens);
    let target = Waypoint::default();
    let moved = source
        .refit(TrajectoryModel::Waypoint(target.clone()), 1001)
        .unwrap();
    let source_at_samples = source.zooms_at(&fit_times);
    let segment = |t: f64| ((t * target.segments as f64).floor() as usize).min(target.segments - 1);
    let held_out = odd_times(300);
    let refitted = moved.zooms_at(&held_out);
    let own = source.zooms_at(&held_out);
    let mut widest = 0.0f64;
    for ((&t, &got), &at_t) in held_out.iter().zip(&refitted).zip(&own) {
        let (lo, hi) = fit_times
            .iter()
            .zip(&source_at_samples)
            .filter(|(u, _)| segment(**u) == segment(t))
            .map(|(_, &s)| s)
            .fold((at_t, at_t), |(a, b), s| (a.min(s), b.max(s)));
        assert!(
            got >= lo - 1e-9 && got <= hi + 1e-9,
            "t = {t}: refitted zoom {got} outside the segment's [{lo}, {hi}]"
        );
        widest = widest.max(hi - lo);
    }
    // The bound is tight, not vacuous: s' = s·(π·cos 2πt + 0.3) is at most 1.78 × 3.44 ≈ 6.1,
    // so s moves at most 0.061 across a segment of 0.01 (against a swing from 0.76 to 1.78).
    assert!(widest < 0.062, "{widest}");
}
