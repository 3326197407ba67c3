//! What a first run on an unknown capture relies on: the view search finds the open side of
//! an enclosed object (against a brute-force scan of directions), its choice over windows is
//! the cheapest sequence (against enumerating every sequence), the working distance is
//! measured right (against the closed form of a sphere's silhouette), and the verdict fails a
//! camera inside its object and an object behind an occluder, naming the query.

mod common;

use burn::tensor::{DType, Device};
use common::scene_of;
use glam::DVec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::render::{DeviceScene, Rasterizer};
use splatraj_scene::Scene;
use splatraj_traj::clearance::{Occupancy, OccupancySpec};
use splatraj_traj::metrics::{CheckKind, WindowObject, verdict, window_metrics};
use splatraj_traj::optimise::views::{measure_views, search_views};
use splatraj_traj::optimise::{
    Candidate, ViewSearch, ViewWeights, ViewedObject, WindowViews, calibrated_radius, choose_views,
};

/// Points on a sphere of radius `r` about `centre` (a Fibonacci lattice of `n` points).
fn sphere_points(centre: [f32; 3], r: f32, n: usize) -> Vec<[f32; 3]> {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    (0..n)
        .map(|k| {
            let z = 1.0 - 2.0 * (k as f32 + 0.5) / n as f32;
            let ring = (1.0 - z * z).sqrt();
            let a = golden * k as f32;
            [
                centre[0] + r * ring * a.cos(),
                centre[1] + r * ring * a.sin(),
                centre[2] + r * z,
            ]
        })
        .collect()
}

/// A ball of radius 0.1 at the origin (the object, first 400 Gaussians) inside a cube of
/// opaque walls at ±0.6 with the +y face open.
fn enclosed_object() -> (Scene, usize) {
    let mut means = sphere_points([0.0; 3], 0.1, 400);
    let mut scales = vec![[0.02f32; 3]; means.len()];
    let object = means.len();
    let steps = 40;
    for axis in 0..3 {
        for side in [-1.0f32, 1.0] {
            if axis == 1 && side > 0.0 {
                continue; // the open side
            }
            for i in 0..=steps {
                for j in 0..=steps {
                    // The wall's normal along `axis`, its grid along the other two.
                    let mut point = [0.0; 3];
                    point[axis] = 0.6 * side;
                    point[(axis + 1) % 3] = -0.6 + 1.2 * i as f32 / steps as f32;
                    point[(axis + 2) % 3] = -0.6 + 1.2 * j as f32 / steps as f32;
                    means.push(point);
                    let mut s = [0.02f32; 3];
                    s[axis] = 0.004;
                    scales.push(s);
                }
            }
        }
    }
    (scene_of(means, scales), object)
}

fn camera() -> Intrinsics {
    Intrinsics::from_fov_x(60.0, 64, 48).unwrap()
}

#[test]
fn the_view_search_finds_the_open_side_as_a_brute_force_scan_does() {
    let (host, object) = enclosed_object();
    let device = Device::flex();
    let scene = DeviceScene::new(&host, &device, DType::F32);
    let keep: Vec<bool> = (0..host.len()).map(|i| i < object).collect();
    let alone = DeviceScene::new(&host.subset(&keep), &device, DType::F32);
    let mask: Vec<f32> = keep.iter().map(|&k| if k { 1.0 } else { 0.0 }).collect();
    let viewed = ViewedObject {
        scene: &scene,
        alone: &alone,
        mask: &mask,
        centre: [0.0; 3],
        half_extent: [0.1; 3],
        radius: 1.5,
        target_ratio: 0.05,
    };
    let up = [0.0, 0.0, 1.0];
    // Azimuth 0 along −x: the search's first guess looks through a wall.
    let reference = [-1.0, 0.0, 0.0];
    let search = ViewSearch {
        azimuths: 8,
        elevations_degrees: vec![-30.0, 0.0, 30.0],
        distances: vec![1.0],
        width: 48,
    };
    let occupancy = Occupancy::new(
        &host,
        OccupancySpec {
            sigma: 2.0,
            min_opacity: 0.2,
        },
    );
    let small = Intrinsics::from_fov_x(60.0, 48, 36).unwrap();
    let candidates = search_views(
        &viewed,
        &search,
        reference,
        up,
        &camera(),
        Rasterizer::default(),
        Some((&occupancy, 0.1)),
    )
    .unwrap();
    assert_eq!(candidates.len(), 24);
    let first = &candidates[search.azimuths]; // azimuth 0, elevation 0
    assert!(first.visible_share < 0.05, "through the wall: {first:?}");

    let windows = [WindowViews {
        candidates: candidates.clone(),
        radius: 1.5,
        target_ratio: 0.05,
        used: Vec::new(),
    }];
    let chosen = candidates[choose_views(&windows, &ViewWeights::default(), Some(0.1)).unwrap()[0]];

    // Brute force: every 5° of azimuth and 10° of elevation at the same distance.
    let mut poses = Vec::new();
    for a in 0..72 {
        for e in -6..=6 {
            let (az, el) = ((a * 5) as f64, (e * 10) as f64);
            let (az, el) = (az.to_radians(), el.to_radians());
            let direction = DVec3::new(az.cos() * el.cos(), az.sin() * el.cos(), el.sin());
            poses.push(Pose::look_at(direction * 1.5, DVec3::ZERO, DVec3::Z).unwrap());
        }
    }
    let scanned = measure_views(&viewed, &poses, &small, Rasterizer::default()).unwrap();
    let best = scanned.iter().map(|m| m.0).fold(0.0, f64::max);
    println!("chosen {chosen:?}, best scanned visible share {best:.3}");
    assert!(best > 0.9, "the open side shows the whole ball: {best}");
    assert!(
        chosen.visible_share >= best - 0.1,
        "the search's choice shows {:.3}, the scan's best {best:.3}",
        chosen.visible_share
    );
    // It looks in through the open face (+y).
    assert!(Pose(chosen.pose).centre().y > 0.5, "{chosen:?}");
    // Every view the scan finds clear comes from the open side too.
    for (pose, (visible, _)) in poses.iter().zip(&scanned) {
        if *visible > 0.5 {
            assert!(pose.centre().y > 0.0, "{pose:?} sees {visible}");
        }
    }
}

/// Candidates with random visible shares at random places, for the sequence test.
fn random_window(rng: &mut ChaCha8Rng, count: usize) -> WindowViews {
    let candidates = (0..count)
        .map(|_| {
            let eye = DVec3::new(
                rng.random_range(-2.0..2.0),
                rng.random_range(-2.0..2.0),
                rng.random_range(0.1..2.0),
            );
            Candidate {
                pose: Pose::look_at(eye, DVec3::ZERO, DVec3::Z).unwrap().0,
                azimuth_degrees: 0.0,
                elevation_degrees: rng.random_range(-20.0..60.0),
                distance: eye.length(),
                visible_share: rng.random_range(0.0..1.0),
                coverage: rng.random_range(0.01..0.5),
                clearance: Some(rng.random_range(0.0..0.3)),
                inside_object: rng.random_bool(0.1),
            }
        })
        .collect();
    WindowViews {
        candidates,
        radius: rng.random_range(0.5..1.5),
        target_ratio: 0.15,
        used: vec![rng.random_range(0..count)],
    }
}

#[test]
fn the_chosen_views_are_the_cheapest_sequence_of_all() {
    // A window without a candidate has no choice.
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut empty = random_window(&mut rng, 2);
    empty.candidates.clear();
    empty.used.clear();
    let full = random_window(&mut rng, 2);
    assert!(choose_views(&[full, empty], &ViewWeights::default(), None).is_none());
    let weights = ViewWeights::default();
    let margin = Some(0.1);
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for _ in 0..20 {
        let windows: Vec<WindowViews> = (0..3).map(|_| random_window(&mut rng, 5)).collect();
        let cost = |seq: &[usize]| -> f64 {
            let mut total = 0.0;
            for (w, &k) in windows.iter().zip(seq) {
                total += w.cost(k, &weights, margin);
            }
            for i in 1..seq.len() {
                let (a, b) = (&windows[i - 1], &windows[i]);
                total += weights.pairwise(
                    &a.candidates[seq[i - 1]],
                    a.radius,
                    &b.candidates[seq[i]],
                    b.radius,
                );
            }
            total
        };
        let mut best = f64::INFINITY;
        for a in 0..5 {
            for b in 0..5 {
                for c in 0..5 {
                    best = best.min(cost(&[a, b, c]));
                }
            }
        }
        let chosen = choose_views(&windows, &weights, margin).unwrap();
        assert!(
            (cost(&chosen) - best).abs() < 1e-12,
            "{chosen:?}: {} against the best {best}",
            cost(&chosen)
        );
    }
}

#[test]
fn the_measured_working_distance_frames_a_ball_as_its_silhouette_says() {
    // A dense shell of thin Gaussians on a ball of radius ρ: seen from d its silhouette is a
    // disc of angular radius asin(ρ'/d), with ρ' = ρ + 3σ where the Gaussians end, and the
    // tangent of that angle is fx pixels per unit on the image plane.
    let (rho, sigma) = (0.2f32, 0.003f32);
    let centre = [0.3f32, -0.2, 0.1];
    let host = scene_of(sphere_points(centre, rho, 12000), vec![[sigma; 3]; 12000]);
    let device = Device::flex();
    let alone = DeviceScene::new(&host, &device, DType::F32);
    let k = Intrinsics::from_fov_x(60.0, 192, 144).unwrap();
    let target = 0.15;
    let measured = calibrated_radius(
        &alone,
        centre.map(f64::from),
        0.5, // the box's estimate may be off by a factor 2
        target,
        [0.0, 0.0, 1.0],
        &k,
        Rasterizer::default(),
    )
    .unwrap();
    // Closed form: π (fx·tan(asin(ρ'/d)))² = target·W·H.
    let pixels = (target * (k.width * k.height) as f64 / std::f64::consts::PI).sqrt();
    let tan = pixels / k.fx;
    let edge = f64::from(rho + 3.0 * sigma);
    let expected = edge / (tan / (1.0 + tan * tan).sqrt());
    println!("measured {measured:.4}, closed form {expected:.4}");
    // The rasterizer's 0.3 px² dilation widens the 29-pixel silhouette a little.
    assert!(
        (measured / expected - 1.0).abs() < 0.08,
        "measured {measured}, closed form {expected}"
    );
}

/// The metrics and verdict of one window whose camera stays at `eye` looking at the origin.
fn judged(
    host: &Scene,
    object: usize,
    eye: DVec3,
    target_ratio: f64,
) -> splatraj_traj::metrics::Verdict {
    let device = Device::flex();
    let on_device = DeviceScene::new(host, &device, DType::F32);
    let keep: Vec<bool> = (0..host.len()).map(|i| i < object).collect();
    let alone = DeviceScene::new(&host.subset(&keep), &device, DType::F32);
    let mask: Vec<f32> = keep.iter().map(|&k| if k { 1.0 } else { 0.0 }).collect();
    let window = WindowObject {
        name: "ball",
        mask: &mask,
        alone: &alone,
        target_ratio,
        rasterizer: Rasterizer::default(),
        bounds: Some(([0.0; 3], [0.1; 3])),
    };
    // A slight drift so the samples differ; the camera keeps looking at the ball.
    let pose_at = |times: &[f64]| -> Vec<[f64; 6]> {
        times
            .iter()
            .map(|&t| {
                let e = eye + DVec3::new(0.0, 0.0, 0.01 * t);
                // At the ball's centre the camera looks out along +x.
                let look = if eye.length() < 1e-6 {
                    e + DVec3::X
                } else {
                    DVec3::ZERO
                };
                Pose::look_at(e, look, DVec3::Z).unwrap().0
            })
            .collect()
    };
    let metrics = window_metrics(&on_device, &window, 0, 1, 8, &camera(), &pose_at).unwrap();
    let v = verdict(&metrics);
    println!("{:?}\n{v:#?}", metrics.framing);
    v
}

fn failed(v: &splatraj_traj::metrics::Verdict) -> Vec<CheckKind> {
    v.checks
        .iter()
        .filter(|c| !c.pass)
        .map(|c| c.check)
        .collect()
}

#[test]
fn the_verdict_fails_a_camera_inside_the_object_and_one_behind_a_wall() {
    let (host, object) = enclosed_object();
    // Through the open side, at a distance where the ball covers about 6 % of the frame.
    let clear = judged(&host, object, DVec3::new(0.0, 0.9, 0.0), 0.06);
    assert!(clear.pass, "{clear:#?}");
    assert!(clear.problems.is_empty());

    // Behind the −x wall: the ball is in frame but hidden.
    let hidden = judged(&host, object, DVec3::new(-0.9, 0.0, 0.0), 0.06);
    assert!(!hidden.pass);
    let kinds = failed(&hidden);
    assert!(
        kinds.contains(&CheckKind::Visible) && kinds.contains(&CheckKind::Hidden),
        "{kinds:?}"
    );
    assert!(
        hidden
            .problems
            .iter()
            .any(|p| p.starts_with("window 0 \"ball\"")
                && p.contains("hidden behind other geometry")),
        "{:?}",
        hidden.problems
    );

    // At the ball's centre: inside the object, which it cannot show.
    let inside = judged(&host, object, DVec3::new(0.0, 0.0, 0.0), 0.06);
    assert!(
        failed(&inside).contains(&CheckKind::InsideObject),
        "{inside:#?}"
    );
    assert!(
        inside
            .problems
            .iter()
            .any(|p| p.contains("inside the object's box")),
        "{:?}",
        inside.problems
    );
}

#[test]
fn the_framed_share_counts_the_middle_samples_that_show_the_object_centred() {
    let (host, object) = enclosed_object();
    let device = Device::flex();
    let on_device = DeviceScene::new(&host, &device, DType::F32);
    let keep: Vec<bool> = (0..host.len()).map(|i| i < object).collect();
    let alone = DeviceScene::new(&host.subset(&keep), &device, DType::F32);
    let mask: Vec<f32> = keep.iter().map(|&k| if k { 1.0 } else { 0.0 }).collect();
    let window = WindowObject {
        name: "ball",
        mask: &mask,
        alone: &alone,
        target_ratio: 0.06,
        rasterizer: Rasterizer::default(),
        bounds: Some(([0.0; 3], [0.1; 3])),
    };
    // Through the open side; looking at the ball until `away_from`, then along +x (the ball
    // out of frame: 90° off a 60° lens's axis).
    let eye = DVec3::new(0.0, 0.9, 0.0);
    let share = |away_from: f64| {
        let pose_at = |times: &[f64]| -> Vec<[f64; 6]> {
            times
                .iter()
                .map(|&t| {
                    let look = if t < away_from {
                        DVec3::ZERO
                    } else {
                        eye + DVec3::X
                    };
                    Pose::look_at(eye, look, DVec3::Z).unwrap().0
                })
                .collect()
        };
        let m = window_metrics(&on_device, &window, 0, 1, 10, &camera(), &pose_at).unwrap();
        m.framing.framed_share.unwrap()
    };
    // Of 10 samples at (k + ½)/10, the middle 60 % holds k = 2…7 (0.25 … 0.75).
    assert_eq!(share(2.0), 1.0);
    assert_eq!(share(0.5), 0.5); // 0.25, 0.35, 0.45 framed
    assert_eq!(share(0.3), 1.0 / 6.0); // 0.25 only
    // Looking away at the window's ends only: the middle is whole.
    assert_eq!(share(0.8), 1.0);
}
