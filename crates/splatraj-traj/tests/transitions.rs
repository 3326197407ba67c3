//! Transitions: a trajectory cut into shots is continuous within each shot and jumps only at
//! its cuts (fitted, sampled, read back from JSON), the path metrics and the optimiser's path
//! grid never take a rate across a cut, and `"auto"` cuts between two sides of a small part
//! in a short window but pans between neighbours.

use burn::tensor::{DType, Device};
use glam::DVec3;
use splatraj_render::camera::Pose;
use splatraj_traj::metrics::shot_path_metrics;
use splatraj_traj::optimise::WindowStart;
use splatraj_traj::optimise::start::routed_start_trajectory;
use splatraj_traj::optimise::trajectory::shot_path_times;
use splatraj_traj::trajectory::{
    Rbf, RbfNormalisation, ShotSpans, Trajectory, TrajectoryModel, TrajectoryRecord, uniform_times,
};
use splatraj_traj::transitions::{
    CutReason, Join, JoinKind, JoinLimits, JoinPart, TransitionMode, judge_join, plan_joins,
    shot_spans,
};

const UP: DVec3 = DVec3::Z;

fn rbf(windows: usize) -> TrajectoryModel {
    TrajectoryModel::Rbf(Rbf {
        normalisation: RbfNormalisation::PartitionOfUnity,
        ..Rbf::new(windows, 3, None)
    })
}

/// Three held views, the first far from the others, each looking at its own point.
fn views() -> Vec<Pose> {
    [
        (DVec3::new(0.0, -2.0, 1.0), DVec3::ZERO),
        (DVec3::new(5.0, 2.0, 1.0), DVec3::new(5.0, 0.0, 0.0)),
        (DVec3::new(5.5, 2.2, 1.1), DVec3::new(5.6, 0.0, 0.0)),
    ]
    .map(|(eye, at)| Pose::look_at(eye, at, UP).unwrap())
    .to_vec()
}

/// The start of three held windows cut before window 1 (so shots {0}, {1, 2}).
fn cut_start() -> Trajectory {
    let spans = ShotSpans::new(3, vec![1]).unwrap();
    let model = rbf(3).cut(spans).unwrap();
    let starts: Vec<WindowStart> = views().into_iter().map(WindowStart::Hold).collect();
    // No pan at the cut (share 0), the usual quarter at the pan between windows 1 and 2.
    routed_start_trajectory(
        model,
        &starts,
        &[],
        &[0.0, 0.25],
        &Device::default(),
        DType::F64,
    )
    .unwrap()
}

fn centre(p: &[f64; 6]) -> DVec3 {
    DVec3::new(p[3], p[4], p[5])
}

#[test]
fn cut_trajectory_is_continuous_within_shots_and_jumps_at_the_cut() {
    let trajectory = cut_start();
    let spans = trajectory.model().shots(3);
    assert_eq!(spans.len(), 2);
    assert_eq!(spans.cut_times(), vec![1.0 / 3.0]);
    let times = uniform_times(3001);
    let poses = trajectory.poses_at(&times);
    let mut largest_within = 0.0f64;
    let mut across = Vec::new();
    for k in 0..times.len() - 1 {
        let step = centre(&poses[k]).distance(centre(&poses[k + 1]));
        if spans.same_shot(times[k], times[k + 1]) {
            largest_within = largest_within.max(step);
        } else {
            across.push(step);
        }
    }
    // One cut, a jump of about the views' distance (≈ 6.4); within a shot the steps of 1/3000
    // of the path stay small (the pan between windows 1 and 2 is short).
    assert_eq!(across.len(), 1, "one step crosses a cut");
    assert!(across[0] > 5.0, "the cut jumps: {}", across[0]);
    assert!(
        largest_within < 0.05,
        "continuous within shots: {largest_within}"
    );
    // Each side of the cut is its own window's held view.
    let before = trajectory.poses_at(&[1.0 / 3.0 - 1e-6])[0];
    let after = trajectory.poses_at(&[1.0 / 3.0])[0];
    let v = views();
    let (b, a) = (
        centre(&before).distance(v[0].centre()),
        centre(&after).distance(v[1].centre()),
    );
    assert!(b < 0.05 && a < 0.05, "{b} {a}");
}

#[test]
fn cut_model_reads_back_from_json() {
    let record = cut_start().record();
    let text = serde_json::to_string(&record).unwrap();
    assert!(text.contains("\"kind\":\"cuts\""), "{text}");
    let back: TrajectoryRecord = serde_json::from_str(&text).unwrap();
    assert_eq!(back.model, record.model);
    for (x, y) in back
        .weights
        .iter()
        .flatten()
        .zip(record.weights.iter().flatten())
    {
        assert!((x - y).abs() <= 1e-12 * y.abs().max(1.0));
    }
    back.validate().unwrap();
    // A cut outside the windows is refused, naming the key.
    let bad = text.replace("\"cuts\":[1]", "\"cuts\":[3]");
    let error = serde_json::from_str::<TrajectoryRecord>(&bad).unwrap_err();
    assert!(error.to_string().contains("cuts"), "{error}");
}

#[test]
fn path_rates_and_path_grid_leave_out_the_cut() {
    let trajectory = cut_start();
    let spans = trajectory.model().shots(3);
    let pose_at = |t: &[f64]| trajectory.poses_at(t);
    let metrics = shot_path_metrics(&pose_at, &spans, 3001, None, Some(9.0), &[]);
    // Window 0 holds its view to the cut: no speed; window 1 pans on to window 2 only.
    assert!(
        metrics[0].motion.peak_speed < 0.1,
        "{:?}",
        metrics[0].motion
    );
    assert!(metrics[0].motion.peak_angular_speed < 1.0);
    // The same grid as one shot sees the jump as a flight of thousands of units a second.
    let single = shot_path_metrics(&pose_at, &ShotSpans::single(3), 3001, None, Some(9.0), &[]);
    assert!(single[0].motion.peak_speed > 1000.0);
    // The optimiser's path grid of window 0 stops before the cut, window 1's starts on it.
    let (times, _) = shot_path_times(0, &spans, 16, 0.0);
    assert!(times.iter().all(|&t| t < 1.0 / 3.0), "{times:?}");
    let (times, _) = shot_path_times(1, &spans, 16, 0.0);
    assert!(times.iter().all(|&t| t >= 1.0 / 3.0 - 1e-12), "{times:?}");
}

/// Window k's and k + 1's parts: small boxes around `a` and `b`.
fn parts(a: DVec3, b: DVec3, half: f64) -> [JoinPart; 2] {
    [a, b].map(|c| JoinPart {
        centre: c.to_array(),
        bounds: (c.to_array(), [half; 3]),
    })
}

fn limits(window_seconds: f64) -> JoinLimits {
    JoinLimits {
        turn: 45.0,
        orbit: 45.0,
        speed: None,
        window_seconds,
    }
}

#[test]
fn auto_cuts_between_two_sides_of_a_small_part_and_pans_between_neighbours() {
    // A skull's top and its jaw from below: the parts 0.1 apart on a 0.1 object, seen from
    // opposite sides at 0.5.
    let (top, jaw) = (DVec3::new(0.0, 0.0, 0.05), DVec3::new(0.0, 0.0, -0.05));
    let above = Pose::look_at(top + DVec3::new(0.3, 0.0, 0.4), top, UP).unwrap();
    let below = Pose::look_at(jaw + DVec3::new(-0.3, 0.0, -0.4), jaw, UP).unwrap();
    let opposite = Join {
        from: above,
        to: below,
        parts: parts(top, jaw, 0.05),
        route: None,
    };
    match judge_join(&opposite, &limits(1.0)) {
        JoinKind::Cut(CutReason::TooFast {
            needed_seconds,
            available_seconds,
            ..
        }) => assert!(needed_seconds > available_seconds),
        other => panic!("expected a cut for pacing, got {other:?}"),
    }
    // Neighbours on a table, 0.3 apart, seen from the same side: a pan of a few degrees.
    let (mug, ball) = (DVec3::new(0.0, 0.0, 0.0), DVec3::new(0.3, 0.0, 0.0));
    let side = DVec3::new(0.0, -1.0, 0.5);
    let neighbours = Join {
        from: Pose::look_at(mug + side, mug, UP).unwrap(),
        to: Pose::look_at(ball + side, ball, UP).unwrap(),
        parts: parts(mug, ball, 0.05),
        route: None,
    };
    assert_eq!(judge_join(&neighbours, &limits(1.0)), JoinKind::Pan);
    // Two parts of a room 0.7 apart, each seen from 0.3 in front: the camera's move sweeps
    // 130° about the first part, but it trucks from one to the next (neither view looks at
    // their common centre): a pan, as the demo's pans pass the verdict at 3 s windows.
    let far = DVec3::new(0.7, 0.0, 0.0);
    let front = DVec3::new(0.0, -0.3, 0.0);
    let trucking = Join {
        from: Pose::look_at(mug + front, mug, UP).unwrap(),
        to: Pose::look_at(far + front, far, UP).unwrap(),
        parts: parts(mug, far, 0.05),
        route: None,
    };
    assert_eq!(judge_join(&trucking, &limits(3.0)), JoinKind::Pan);
    // A 10 s window gives even the opposite sides time enough to pan, but the straight way
    // between them runs through the part: still a cut, for another reason.
    assert!(matches!(
        judge_join(&opposite, &limits(10.0)),
        JoinKind::Cut(CutReason::ThroughPart { .. })
    ));
    // The modes: pan and cut whatever the joins, auto as judged.
    let joins = [opposite, neighbours];
    let auto = plan_joins(TransitionMode::Auto, &joins, &limits(1.0));
    assert!(auto[0].is_cut() && !auto[1].is_cut());
    assert!(
        plan_joins(TransitionMode::Pan, &joins, &limits(1.0))
            .iter()
            .all(|k| !k.is_cut())
    );
    let cut = plan_joins(TransitionMode::Cut, &joins, &limits(1.0));
    assert_eq!(cut, vec![JoinKind::Cut(CutReason::Asked); 2]);
    assert_eq!(shot_spans(3, &auto).unwrap().cuts, vec![1]);
}
