//! Up from a capture's cameras against closed forms: synthetic rigs around a known, tilted up
//! (cameras level, or rolled by known angles), and rigs that disagree.

use glam::{DMat3, DQuat, DVec3};
use splatraj_scene::cameras_up::{CamerasUpError, MAX_SPREAD_DEGREES, cameras_up};

/// The known up of the rigs: not a coordinate axis.
fn known_up() -> DVec3 {
    DVec3::new(0.3, -0.9, 0.2).normalize()
}

/// R_wc (OpenCV axes: columns right, down, forward) of a level camera at `centre` looking at
/// `target` under world `up`, then rolled by `roll_degrees` about its optical axis.
fn look_at(centre: DVec3, target: DVec3, up: DVec3, roll_degrees: f64) -> DMat3 {
    let forward = (target - centre).normalize();
    let down = -(up - forward * forward.dot(up)).normalize();
    // OpenCV is right-handed: x = y × z.
    let right = down.cross(forward);
    let level = DMat3::from_cols(right, down, forward);
    level * DMat3::from_quat(DQuat::from_rotation_z(roll_degrees.to_radians()))
}

/// Cameras on a circle around the origin, `elevation` degrees above its horizontal plane,
/// spanning `arc` degrees of azimuth, each looking at the origin.
fn orbit(count: usize, elevation: f64, arc: f64, roll: impl Fn(usize) -> f64) -> Vec<DMat3> {
    let up = known_up();
    let e1 = up.any_orthonormal_vector();
    let e2 = up.cross(e1);
    (0..count)
        .map(|i| {
            let azimuth = (arc * i as f64 / count as f64).to_radians();
            let el = elevation.to_radians();
            let centre =
                3.0 * ((e1 * azimuth.cos() + e2 * azimuth.sin()) * el.cos() + up * el.sin());
            look_at(centre, DVec3::ZERO, up, roll(i))
        })
        .collect()
}

fn angle_degrees(a: [f64; 3], b: DVec3) -> f64 {
    DVec3::from_array(a).angle_between(b).to_degrees()
}

#[test]
fn level_cameras_all_around_give_the_known_up_with_no_spread() {
    let up = cameras_up(&orbit(36, 30.0, 360.0, |_| 0.0), "rig").unwrap();
    assert!(angle_degrees(up.up, known_up()) < 1e-6, "{up:?}");
    assert!(up.spread_degrees < 1e-6);
    assert_eq!(up.cameras, 36);
    assert_eq!(up.describe(), "up from 36 cameras in rig (spread 0.0°)");
}

#[test]
fn cameras_looking_down_from_one_side_give_the_known_up_where_their_mean_up_tilts() {
    // A tabletop filmed from above on one side: 40° down, over 90° of azimuth.
    let rig = orbit(20, 40.0, 90.0, |_| 0.0);
    let up = cameras_up(&rig, "rig").unwrap();
    assert!(angle_degrees(up.up, known_up()) < 1e-6, "{up:?}");
    // The mean of the cameras' up vectors tilts toward the table by about the pitch.
    let mean: DVec3 = rig.iter().map(|r| -r.y_axis).sum::<DVec3>().normalize();
    assert!(mean.angle_between(known_up()).to_degrees() > 30.0);
}

#[test]
fn the_spread_is_the_90th_percentile_of_the_horizon_tilt() {
    // Rolls of 0°, 1°, …, 9° (alternating sign), four cameras each: 90 % within 8°.
    let up = cameras_up(
        &orbit(40, 20.0, 360.0, |i| {
            let r = (i % 10) as f64;
            if i % 2 == 0 { r } else { -r }
        }),
        "rig",
    )
    .unwrap();
    assert!(angle_degrees(up.up, known_up()) < 1.0, "{up:?}");
    assert!(
        (up.spread_degrees - 8.0).abs() < 1.0,
        "spread {}",
        up.spread_degrees
    );
}

#[test]
fn cameras_in_two_conventions_disagree() {
    // Every other camera upside down: a file whose writer flipped y for half of them.
    let rig = orbit(24, 20.0, 360.0, |i| if i % 2 == 0 { 0.0 } else { 180.0 });
    let error = cameras_up(&rig, "mixed.json").unwrap_err();
    assert!(
        matches!(error, CamerasUpError::Disagree { .. }),
        "{error:?}"
    );
    let message = error.to_string();
    assert!(
        message.contains("mixed.json") && message.contains("disagree"),
        "{message}"
    );
}

#[test]
fn a_quarter_of_the_photos_turned_to_portrait_disagree() {
    let rig = orbit(40, 20.0, 360.0, |i| if i % 4 == 0 { 90.0 } else { 0.0 });
    match cameras_up(&rig, "portrait.json") {
        Err(CamerasUpError::Disagree {
            spread_degrees,
            tilted,
            ..
        }) => {
            assert!(spread_degrees > MAX_SPREAD_DEGREES);
            assert_eq!(tilted, 10);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn too_few_or_non_finite_cameras_are_refused() {
    let rig = orbit(2, 20.0, 360.0, |_| 0.0);
    assert!(matches!(
        cameras_up(&rig, "two.json"),
        Err(CamerasUpError::TooFew { count: 2, .. })
    ));
    let mut rig = orbit(5, 20.0, 360.0, |_| 0.0);
    rig[3].x_axis.x = f64::NAN;
    assert!(matches!(
        cameras_up(&rig, "nan.json"),
        Err(CamerasUpError::NonFinite { index: 3, .. })
    ));
}
