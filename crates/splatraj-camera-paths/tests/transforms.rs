//! nerfstudio `transforms.json` against a hand-written fixture (`tests/data/transforms.json`)
//! whose cameras were worked out by hand, without the reader's conventions: frame 1 stands at
//! (1, 2, 3) looking along world +x with +z up (so world −y is to its right), frame 2 is the
//! OpenGL identity camera moved to (0, 0, 5), which looks along world −z with +y up.

use std::path::{Path, PathBuf};

use glam::DVec3;
use splatraj_camera_paths::{
    CameraPose, Format, Intrinsics, detect, read_named_cameras, transforms,
};

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/transforms.json")
}

/// Pixel position of world point `p` (pixel centres at +0.5, as the crate's convention).
fn project(pose: &CameraPose, camera: &Intrinsics, p: DVec3) -> (f64, f64, f64) {
    let q = pose.world_to_camera_rotation() * (p - pose.centre);
    (
        camera.cx + camera.fx * q.x / q.z,
        camera.cy + camera.fy * q.y / q.z,
        q.z,
    )
}

#[test]
fn transforms_json_reads_poses_intrinsics_and_names() {
    let path = fixture();
    assert_eq!(detect(&path).unwrap(), Format::Transforms);
    let cameras = read_named_cameras(&path).unwrap();
    assert_eq!(cameras.format, Format::Transforms);
    assert_eq!(
        cameras.names,
        vec![
            Some("images/frame_00001.png".to_string()),
            Some("images/frame_00002.png".to_string())
        ]
    );
    let frames = &cameras.path.frames;
    assert_eq!(frames.len(), 2);

    // Frame 1: the file-level intrinsics (distortion ignored).
    let c0 = frames[0].camera.unwrap();
    assert_eq!(
        c0,
        Intrinsics {
            fx: 500.0,
            fy: 510.0,
            cx: 320.0,
            cy: 240.0,
            width: 640,
            height: 480
        }
    );
    assert!(frames[0].pose.centre.distance(DVec3::new(1.0, 2.0, 3.0)) < 1e-12);
    assert!(frames[0].pose.forward().distance(DVec3::X) < 1e-12);
    // 4 ahead, 1 to the right (world −y), 1 up (world +z): u = 320 + 500/4, v = 240 − 510/4.
    let (u, v, depth) = project(&frames[0].pose, &c0, DVec3::new(5.0, 1.0, 4.0));
    assert!((u - 445.0).abs() < 1e-9 && (v - 112.5).abs() < 1e-9 && (depth - 4.0).abs() < 1e-12);

    // Frame 2: its own intrinsics win over the file's.
    let c1 = frames[1].camera.unwrap();
    assert_eq!((c1.fx, c1.fy, c1.cx, c1.cy), (250.0, 255.0, 160.0, 120.0));
    assert_eq!((c1.width, c1.height), (320, 240));
    assert!(frames[1].pose.forward().distance(-DVec3::Z) < 1e-12);
    // 5 ahead, 1 right (+x), 2 up (+y): u = 160 + 250/5, v = 120 − 255·2/5.
    let (u, v, depth) = project(&frames[1].pose, &c1, DVec3::new(1.0, 2.0, 0.0));
    assert!((u - 210.0).abs() < 1e-9 && (v - 18.0).abs() < 1e-9 && (depth - 5.0).abs() < 1e-12);
}

#[test]
fn transforms_json_errors_name_the_file_and_the_element() {
    let text = std::fs::read_to_string(fixture()).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();

    let mut sheared = json.clone();
    sheared["frames"][1]["transform_matrix"][0][1] = 0.5.into();
    let e = transforms::import(&sheared.to_string(), "t.json")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("t.json: frames[1] (images/frame_00002.png).transform_matrix"),
        "{e}"
    );

    let mut no_size = json.clone();
    no_size.as_object_mut().unwrap().remove("w");
    let e = transforms::import(&no_size.to_string(), "t.json")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("t.json: frames[0].w: missing"), "{e}");

    // A field of view of 4 rad would make a negative focal length: named as written.
    let mut wide = json.clone();
    let keys = wide.as_object_mut().unwrap();
    for key in ["fl_x", "fl_y"] {
        keys.remove(key);
    }
    keys.insert("camera_angle_x".into(), 4.0.into());
    let e = transforms::import(&wide.to_string(), "t.json")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("t.json: frames[0].camera_angle_x: 4.0 is not a field of view in radians"),
        "{e}"
    );

    json["camera_model"] = "OPENCV_FISHEYE".into();
    let e = transforms::import(&json.to_string(), "t.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("frames[0].camera_model: OPENCV_FISHEYE"), "{e}");

    let e = transforms::import(r#"{"frames": []}"#, "t.json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("t.json: frames"), "{e}");
}
