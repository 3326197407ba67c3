//! The dolly-zoom shot (`kind = "dolly-zoom"`, `splatraj_traj::shots`): its placed path and
//! zoom against the closed form (a dolly's line, z*(s) = r(s)/r_w), its defaults, bad values
//! named by key, and the size it holds: the object's projected size, rendered through the
//! zoom along the shot, stays put while the field of view halves (and drifts with a fixed lens).

mod common;

use burn::tensor::{DType, Device, Tensor, TensorData};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::host::{OnDevice, to_host};
use splatraj_render::render::{Channel, DeviceScene, RenderRequest, Zoom, render};
use splatraj_traj::costs::coverage;
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
