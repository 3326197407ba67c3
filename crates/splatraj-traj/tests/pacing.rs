//! Pacing: the path metrics' turning and orbit rates against closed forms (a camera circling
//! its subject, one panning on the spot, one walking straight at it), and the verdict's
//! `framed_share`, `turning` and `orbiting` checks on both sides of their limits.

mod common;

use glam::DVec3;
use splatraj_render::camera::Pose;
use splatraj_traj::metrics::verdict::{MAX_ORBIT_RATE, MAX_TURN_RATE, MIN_FRAMED_SHARE};
use splatraj_traj::metrics::{CheckKind, MotionMetrics, path_metrics, verdict};

const UP: DVec3 = DVec3::Z;

/// Per-window path metrics of `pose_at` over one window of `seconds` on 2001 samples, with
/// the orbit measured about `o`.
fn rates(pose_at: &dyn Fn(f64) -> Pose, seconds: f64, o: DVec3) -> MotionMetrics {
    let poses = |t: &[f64]| t.iter().map(|&t| pose_at(t).0).collect();
    let mut all = path_metrics(&poses, 1, 2001, None, Some(seconds), &[o.to_array()]);
    all.remove(0).motion
}

fn close(got: f64, want: f64) {
    assert!(
        (got - want).abs() <= 1e-6 * want.abs().max(1.0),
        "{got} vs {want}"
    );
}

#[test]
fn turning_and_orbit_rates_match_closed_forms() {
    let seconds = 4.0;
    let o = DVec3::new(0.5, -1.0, 0.2);
    // Circling o at radius 2 and 30°/s over the window, looking at it, level with it: the
    // direction to the camera and the view both turn about up at 30°/s.
    let omega = 30f64.to_radians() * seconds; // per unit of normalised time
    let circling = |t: f64| {
        let phase = omega * t;
        let eye = o + 2.0 * DVec3::new(phase.cos(), phase.sin(), 0.0);
        Pose::look_at(eye, o, UP).unwrap()
    };
    let m = rates(&circling, seconds, o);
    close(m.peak_orbit_speed.unwrap(), 30.0);
    close(m.peak_angular_speed, 30.0);

    // Standing 3 units from o and panning at 20°/s: the view turns, the camera does not move
    // about o.
    let eye = o + DVec3::new(3.0, 0.0, 0.0);
    let panning = |t: f64| {
        let heading = (20f64 * seconds * t).to_radians();
        Pose::look_at(eye, eye + DVec3::new(heading.cos(), heading.sin(), 0.0), UP).unwrap()
    };
    let m = rates(&panning, seconds, o);
    close(m.peak_orbit_speed.unwrap(), 0.0);
    close(m.peak_angular_speed, 20.0);

    // Passing o at distance d and speed v along a straight line: the orbit rate peaks at v/d
    // radians per second as the camera passes closest (the view held fixed: no turning).
    let (d, v) = (1.5, 0.8);
    let passing = |t: f64| {
        let eye = o + DVec3::new(d, v * seconds * (t - 0.5), 0.0);
        Pose::look_at(eye, eye - DVec3::X, UP).unwrap()
    };
    let m = rates(&passing, seconds, o);
    let peak = (v / d).to_degrees();
    assert!(
        (m.peak_orbit_speed.unwrap() - peak).abs() < 1e-3 * peak,
        "{:?} vs {peak}",
        m.peak_orbit_speed
    );
    close(m.peak_angular_speed, 0.0);

    // No centre given: no orbit rate.
    let poses = |t: &[f64]| t.iter().map(|&t| passing(t).0).collect();
    assert!(
        path_metrics(&poses, 1, 101, None, Some(seconds), &[])[0]
            .motion
            .peak_orbit_speed
            .is_none()
    );
}

#[test]
fn the_verdict_holds_framed_share_and_pacing_to_their_limits() {
    let good = verdict(&common::passing_window(0.85, 44.0, 44.0));
    assert!(good.pass, "{good:#?}");
    let names: Vec<&str> = good.checks.iter().map(|c| c.check.name()).collect();
    for name in ["framed_share", "turning", "orbiting"] {
        assert!(names.contains(&name), "{names:?}");
    }
    let limit = |kind: CheckKind| {
        good.checks
            .iter()
            .find(|c| c.check == kind)
            .map(|c| c.limit.clone())
    };
    assert_eq!(limit(CheckKind::FramedShare), Some(vec![0.8]));
    assert_eq!(limit(CheckKind::Turning), Some(vec![45.0]));
    assert_eq!(limit(CheckKind::Orbiting), Some(vec![45.0]));
    assert_eq!(
        (MIN_FRAMED_SHARE, MAX_TURN_RATE, MAX_ORBIT_RATE),
        (0.8, 45.0, 45.0)
    );

    // Each on the wrong side of its limit fails alone, with a sentence naming the window, the
    // figure and a fix.
    for (metrics, kind, says) in [
        (
            common::passing_window(0.75, 44.0, 44.0),
            CheckKind::FramedShare,
            "75 % of the window's middle 60 %",
        ),
        (
            common::passing_window(0.85, 61.0, 44.0),
            CheckKind::Turning,
            "turns at up to 61°/s",
        ),
        (
            common::passing_window(0.85, 44.0, 83.0),
            CheckKind::Orbiting,
            "circles the object at up to 83°/s",
        ),
    ] {
        let v = verdict(&metrics);
        assert_eq!(v.failed(), vec![kind.name()], "{v:#?}");
        assert_eq!(v.problems.len(), 1);
        let problem = &v.problems[0];
        assert!(
            problem.starts_with("window 1 \"jaw\"") && problem.contains(says),
            "{problem}"
        );
        assert!(problem.contains("likely fix"), "{problem}");
    }

    // Rates per unit of normalised time mean nothing to a viewer: not judged.
    let mut unknown = common::passing_window(0.85, 500.0, 500.0);
    if let Some(p) = unknown.path.as_mut() {
        p.motion.seconds = None;
    }
    let v = verdict(&unknown);
    assert!(v.pass, "{v:#?}");
    assert!(v.checks.iter().all(|c| c.check != CheckKind::Turning));
}

#[test]
fn pans_get_the_time_their_turn_and_orbit_need_within_bounds() {
    use splatraj_traj::optimise::pans::MAX_PAN_SHARE;
    use splatraj_traj::optimise::route::ROUTE_TRANSITION;
    use splatraj_traj::optimise::{PanLimits, WindowStart, pan_shares};
    let limits = PanLimits {
        turn: Some(40.0),
        orbit: Some(40.0),
        window_seconds: 3.0,
    };
    // Standing still and turning by θ about up: the smoothstep over 2·s·3 s peaks at
    // 1.5·θ/(6 s), which is 40°/s at s = 1.5·θ/40/6.
    let eye = DVec3::new(1.0, 2.0, 0.5);
    let heading = |degrees: f64| {
        let a = degrees.to_radians();
        WindowStart::Hold(Pose::look_at(eye, eye + DVec3::new(a.cos(), a.sin(), 0.0), UP).unwrap())
    };
    let share = |starts: &[WindowStart], centres: &[[f64; 3]]| pan_shares(starts, centres, limits);
    let far = [[50.0, 0.0, 0.0], [50.0, 0.0, 0.0]]; // no orbit to speak of
    let turned = share(&[heading(10.0), heading(58.0)], &far);
    close(turned[0], 1.5 * 48.0 / 40.0 / 6.0); // 0.3
    assert_eq!(
        share(&[heading(0.0), heading(20.0)], &far),
        vec![ROUTE_TRANSITION]
    );
    assert_eq!(
        share(&[heading(0.0), heading(120.0)], &far),
        vec![MAX_PAN_SHARE]
    );
    // Orbiting o by 44° at a fixed distance, the view's turn kept small: the orbit sets it.
    let o = DVec3::new(0.0, 0.0, 0.0);
    let around = |degrees: f64| {
        let a = degrees.to_radians();
        let c = o + 2.0 * DVec3::new(a.cos(), a.sin(), 0.0);
        WindowStart::Hold(Pose::look_at(c, c - DVec3::X, UP).unwrap())
    };
    let orbited = share(
        &[around(0.0), around(44.0)],
        &[o.to_array(), [50.0, 0.0, 0.0]],
    );
    close(orbited[0], 1.5 * 44.0 / 40.0 / 6.0); // 0.275
    // Without limits every pan keeps a quarter window.
    let free = PanLimits {
        turn: None,
        orbit: None,
        window_seconds: 3.0,
    };
    assert_eq!(
        pan_shares(&[heading(0.0), heading(120.0)], &far, free),
        vec![ROUTE_TRANSITION]
    );
}
