//! The dolly-zoom shot (`kind = "dolly-zoom"`, `splatraj_traj::shots`): its placed path and
//! zoom against the closed form (a dolly's line, z*(s) = r(s)/r_w), its defaults, bad values
//! named by key, and the size it holds: the object's projected size, rendered through the
//! zoom along the shot, stays put while the field of view halves (and drifts with a fixed lens);
//! the hold `metrics.json` reports (`shot.zoom`) and the verdict's `held_size` check, against
//! the closed form of a sphere seen along a dolly zoom.

mod common;

use burn::tensor::{DType, Device, Tensor, TensorData};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::host::{OnDevice, to_host};
use splatraj_render::render::{Channel, DeviceScene, RenderRequest, Zoom, render};
use splatraj_traj::costs::coverage;
use splatraj_traj::metrics::verdict::MAX_SIZE_CHANGE;
use splatraj_traj::metrics::{
    CheckKind, Deviation, ShotMetrics, ZoomFrame, ZoomHold, verdict, zoom_hold,
};
use splatraj_traj::shots::{DollySpec, ShotFrame, ShotSpec};

fn frame(object_centre: [f64; 3], working_radius: f64) -> ShotFrame {
    ShotFrame {
        object_centre,
        working_radius,
        world_up: [0.0, 0.0, 1.0],
        side: [1.0, 0.0, 0.0],
    }
}

#[test]
fn a_dolly_zoom_moves_on_the_dolly_line_and_zooms_with_the_distance() {
    let o = DVec3::new(0.5, -1.0, 2.0);
    let shot = ShotSpec::DollyZoom(DollySpec {
        elevation: 0.0,
        from: Some(1.0),
        to: Some(4.0),
        ..DollySpec::default()
    })
    .place(&frame(o.to_array(), 2.0))
    .unwrap();
    assert_eq!(shot.kind, "dolly-zoom");
    for s in [0.0, 0.25, 0.5, 1.0] {
        let r = 1.0 + 3.0 * s;
        assert!((shot.centre_at(s) - (o + DVec3::new(r, 0.0, 0.0))).length() < 1e-12);
        // z*(s) = r(s)/r_w with r_w = 2.
        assert!((shot.zoom_at(s).unwrap() - r / 2.0).abs() < 1e-12);
    }
    // Defaults: 0.6 r_w to 1.8 r_w, so the zoom goes from 0.6 to 1.8.
    let default = ShotSpec::DollyZoom(DollySpec::default())
        .place(&frame(o.to_array(), 2.0))
        .unwrap();
    assert_eq!(default.radius, (1.2, 3.6));
    assert!((default.zoom_at(0.0).unwrap() - 0.6).abs() < 1e-12);
    assert!((default.zoom_at(1.0).unwrap() - 1.8).abs() < 1e-12);
    // A plain dolly leaves the lens alone.
    let dolly = ShotSpec::Dolly(Default::default())
        .place(&frame(o.to_array(), 2.0))
        .unwrap();
    assert_eq!(dolly.zoom_at(0.5), None);
}

#[test]
fn bad_dolly_zoom_values_name_their_key() {
    let field = |spec: DollySpec| {
        ShotSpec::DollyZoom(spec)
            .place(&frame([0.0; 3], 1.0))
            .unwrap_err()
            .field
    };
    let base = DollySpec::default();
    assert_eq!(
        field(DollySpec {
            from: Some(0.0),
            ..base.clone()
        }),
        "from"
    );
    assert_eq!(
        field(DollySpec {
            to: Some(f64::NAN),
            ..base.clone()
        }),
        "to"
    );
    assert_eq!(
        field(DollySpec {
            elevation: 90.0,
            ..base.clone()
        }),
        "elevation"
    );
    let parsed: ShotSpec = toml::from_str("kind = \"dolly-zoom\"\nfrom = 0.5\nto = 2.0").unwrap();
    assert_eq!(parsed.kind(), "dolly-zoom");
    assert!(toml::from_str::<ShotSpec>("kind = \"dolly-zoom\"\nzoom = 2.0").is_err());
}

/// Rendered along the shot's ideal path through its zoom, the object's mask covers the same
/// share of the frame within 5 % while the vertical field of view changes by more than 2×;
/// the same path with a fixed lens shrinks the object by the distance ratio squared.
#[test]
fn the_ideal_dolly_zoom_holds_the_projected_size_while_the_fov_halves() {
    let scene = common::demo_room(20_000);
    let object = common::demo_object("blue box");
    let mask = common::demo_mask(&scene, &object);
    let device = Device::flex();
    let on_device = DeviceScene::new(&scene, &device, DType::F64);
    let camera = Intrinsics::from_fov_x(60.0, 96, 72).unwrap();
    let working = 0.6;
    let shot = ShotSpec::DollyZoom(DollySpec {
        from: Some(0.6 * working),
        to: Some(1.8 * working),
        ..DollySpec::default()
    })
    .place(&frame(object.center.map(f64::from), working))
    .unwrap();
    let samples: Vec<f64> = (0..7).map(|k| k as f64 / 6.0).collect();
    let poses: Vec<Pose> = samples.iter().map(|&s| shot.pose_at(s)).collect();
    let zooms: Vec<f64> = samples.iter().map(|&s| shot.zoom_at(s).unwrap()).collect();
    let coverages = |zoom: Option<Zoom>| -> Vec<f64> {
        let request = RenderRequest {
            zoom,
            ..RenderRequest::new(camera, vec![Channel::Mask(mask.clone())])
        };
        let images = render(&on_device, on_device.poses(&poses), &request)
            .unwrap()
            .images;
        let [b, h, w, _] = images.dims();
        to_host(coverage(images.reshape([b, h, w]))).unwrap()
    };
    let values = Tensor::<1>::from_data(
        TensorData::new(zooms.clone(), [zooms.len()]),
        (&device, DType::F64),
    );
    let zoomed = coverages(Some(Zoom::at(values, zooms.clone())));
    let mean = zoomed.iter().sum::<f64>() / zoomed.len() as f64;
    assert!(mean > 0.01, "the object is in view: {zoomed:?}");
    for c in &zoomed {
        assert!((c / mean - 1.0).abs() < 0.05, "held within 5 %: {zoomed:?}");
    }
    let fov = |s: f64| camera.zoomed(s).unwrap().vertical_fov_degrees();
    let ratio = fov(zooms[0]) / fov(zooms[6]);
    assert!(ratio >= 2.0, "the field of view changes {ratio}×");
    // With the fixed lens the object shrinks as the camera backs away: the check can fail.
    let fixed = coverages(None);
    assert!(
        fixed[0] > 4.0 * fixed[6],
        "a fixed lens loses the size: {fixed:?}"
    );
}

/// Frame width and height, and the focal length of a 60° horizontal field of view.
const W: f64 = 160.0;
const H: f64 = 90.0;
fn focal() -> f64 {
    0.5 * W / 30f64.to_radians().tan()
}

/// The horizontal field of view, degrees, of the frame camera zoomed by `s`.
fn fov_x(s: f64) -> f64 {
    2.0 * (0.5 * W / (focal() * s)).atan().to_degrees()
}

/// Sphere radius and working radius of the closed form below.
const SPHERE: f64 = 0.1;
const WORKING: f64 = 1.0;

/// The camera's distance at window time τ on the default dolly zoom: 0.6 → 1.8 r_w.
fn distance(tau: f64) -> f64 {
    WORKING * (0.6 + 1.2 * tau)
}

/// The zoom at which a sphere of radius R at distance d looks as large as at the working
/// radius: its image's radius is f·s·R/√(d² − R²) (below), so s = √(d² − R²)/√(r_w² − R²).
fn true_lock(d: f64) -> f64 {
    (d * d - SPHERE * SPHERE).sqrt() / (WORKING * WORKING - SPHERE * SPHERE).sqrt()
}

/// Window 1 of 2 rendered at t = 0.5 + j/50 (j = 0..=25, so τ = j/25): a sphere of radius R
/// centred on the view axis at `distance(τ)`, the camera zoomed by `zoom(j, d)`. Seen from
/// d, a sphere's outline is the circle where its tangent cone touches it, which a pinhole
/// images (on the axis) as a disc of radius ρ = f·s·R/√(d² − R²) pixels: coverage πρ²/(W·H).
fn sphere_frames(zoom: impl Fn(usize, f64) -> f64) -> Vec<ZoomFrame> {
    (0..=25)
        .map(|j| {
            let d = distance(j as f64 / 25.0);
            let s = zoom(j, d);
            let rho = focal() * s * SPHERE / (d * d - SPHERE * SPHERE).sqrt();
            ZoomFrame {
                t: 0.5 + j as f64 / 50.0,
                coverage: std::f64::consts::PI * rho * rho / (W * H),
                fov_x_degrees: fov_x(s),
            }
        })
        .collect()
}

/// The zoom of [`true_lock`] off by the factor 1 + a on even frames and 1 − a on odd ones.
fn off_by(a: f64) -> impl Fn(usize, f64) -> f64 {
    move |j, d| {
        true_lock(d)
            * if j.is_multiple_of(2) {
                1.0 + a
            } else {
                1.0 - a
            }
    }
}

#[test]
fn the_zoom_hold_reads_a_spheres_projected_size_and_the_field_of_view() {
    // Zoomed to the sphere's true depth, its image keeps its size exactly, while the field of
    // view narrows from fov(s(0)) to fov(s(1)); the middle 60 % is τ = 0.2 … 0.8, frames
    // j = 5 … 20.
    let hold = zoom_hold(&sphere_frames(|_, d| true_lock(d)), 1, 2).unwrap();
    assert_eq!(hold.frames, 16);
    let (lo, hi) = (hold.size_min.unwrap(), hold.size_max.unwrap());
    assert!(
        (lo - 1.0).abs() < 1e-12 && (hi - 1.0).abs() < 1e-12,
        "{hold:?}"
    );
    let whole = fov_x(true_lock(distance(0.0))) / fov_x(true_lock(distance(1.0)));
    let middle = fov_x(true_lock(distance(0.2))) / fov_x(true_lock(distance(0.8)));
    assert!(
        (hold.fov_ratio - whole).abs() < 1e-12,
        "{} vs {whole}",
        hold.fov_ratio
    );
    assert!((hold.fov_ratio_middle - middle).abs() < 1e-12);
    // The reading: the size within 5 % while the field of view changes at least 2×.
    assert!(hold.size_change().unwrap() <= 0.05 && hold.fov_ratio >= 2.0);

    // A zoom off by ±a on alternate frames: eight middle frames at 1 + a and eight at 1 − a,
    // whose linear sizes have the mean 1, so the hold reads 1 ∓ a exactly.
    let a = 0.03;
    let hold = zoom_hold(&sphere_frames(off_by(a)), 1, 2).unwrap();
    assert!(
        (hold.size_min.unwrap() - (1.0 - a)).abs() < 1e-12,
        "{hold:?}"
    );
    assert!(
        (hold.size_max.unwrap() - (1.0 + a)).abs() < 1e-12,
        "{hold:?}"
    );
    assert!((hold.size_change().unwrap() - a).abs() < 1e-12);

    // The zoom the run locks to, s = d/r_w, leaves the depth's share: the sphere grows by
    // d/√(d² − R²) as the camera comes closer, largest at τ = 0.2 and smallest at τ = 0.8.
    let hold = zoom_hold(&sphere_frames(|_, d| d / WORKING), 1, 2).unwrap();
    let grow = |tau: f64| {
        let d = distance(tau);
        d / (d * d - SPHERE * SPHERE).sqrt()
    };
    let ratio = hold.size_max.unwrap() / hold.size_min.unwrap();
    assert!((ratio - grow(0.2) / grow(0.8)).abs() < 1e-12, "{hold:?}");

    // No frame in the middle 60 %: nothing to judge; the object never there: no size.
    let ends: Vec<ZoomFrame> = sphere_frames(|_, d| true_lock(d))
        .into_iter()
        .filter(|f| f.t < 0.55 || f.t > 0.95)
        .collect();
    assert_eq!(zoom_hold(&ends, 1, 2), None);
    let unseen: Vec<ZoomFrame> = sphere_frames(|_, d| true_lock(d))
        .into_iter()
        .map(|f| ZoomFrame { coverage: 0.0, ..f })
        .collect();
    let hold = zoom_hold(&unseen, 1, 2).unwrap();
    assert_eq!((hold.size_min, hold.size_change()), (None, None));
}

/// A window that passes every other check, with a dolly zoom's `hold`.
fn dolly_zoom_window(hold: Option<ZoomHold>) -> splatraj_traj::metrics::WindowMetrics {
    let none = Deviation {
        mean: 0.0,
        max: 0.0,
    };
    splatraj_traj::metrics::WindowMetrics {
        shot: Some(ShotMetrics {
            kind: "dolly-zoom",
            samples: 30,
            elevation: none,
            radius: none,
            radius_relative: none,
            azimuth: none,
            aim: none,
            zoom: hold,
        }),
        ..common::passing_window(0.9, 10.0, 10.0)
    }
}

#[test]
fn the_verdict_holds_a_dolly_zooms_size_to_five_percent() {
    let hold = |a: f64| zoom_hold(&sphere_frames(off_by(a)), 1, 2);
    let check = |m| {
        let v = verdict(&m);
        let c = v
            .checks
            .iter()
            .find(|c| c.check == CheckKind::HeldSize)
            .cloned();
        (v, c)
    };
    let (good, held) = check(dolly_zoom_window(hold(0.03)));
    assert!(good.pass, "{good:#?}");
    let held = held.expect("a dolly zoom with frames is judged");
    assert_eq!(held.check.name(), "held_size");
    assert_eq!(held.limit, vec![MAX_SIZE_CHANGE]);
    assert!((held.value.unwrap() - 0.03).abs() < 1e-12);

    let (bad, held) = check(dolly_zoom_window(hold(0.08)));
    assert!(!bad.pass && !held.unwrap().pass);
    assert_eq!(bad.failed(), ["held_size"]);
    assert!(
        bad.problems[0].contains("changes its size by up to 8.0 %"),
        "{:?}",
        bad.problems
    );
    // Before the frames (no hold), or for another shot: no such check.
    assert!(check(dolly_zoom_window(None)).1.is_none());
    assert!(check(common::passing_window(0.9, 10.0, 10.0)).1.is_none());
}
