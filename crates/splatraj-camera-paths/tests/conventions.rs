//! Each format's axes and units against values worked out by hand (not by this crate): one
//! known camera exported and compared with the hand-written numbers, and hand-written files
//! imported and compared with the known pose.
//!
//! The known camera A: centre c = (2, 0, 0), looking at the origin (along −x) with world up +z.
//! In OpenCV axes its camera x (right) is +y, camera y (down) is −z and camera z (forward) is
//! −x, so R_wc has columns (0, 1, 0), (0, 0, −1), (−1, 0, 0). trace R = 0, so the angle is
//! 120°; the axis is (R32 − R23, R13 − R31, R21 − R12) ∝ (−1, −1, 1), so
//! ω = (2π/3)·(−1, −1, 1)/√3. Intrinsics: fx = fy = 200, 300×200 pixels, centred, so the
//! vertical field of view is 2·atan(100/200) = 53.13010235415598°.

use std::f64::consts::PI;

use serde_json::Value;
use splatraj_camera_paths::camera::{CameraPath, CameraPose, Intrinsics};
use splatraj_camera_paths::supersplat::{Focus, SupersplatOptions};
use splatraj_camera_paths::{colmap, inria, nerfstudio, supersplat};

const FOV_A: f64 = 53.13010235415598;

fn phi_a() -> [f64; 6] {
    let s = 2.0 * PI / 3.0 / 3f64.sqrt();
    [-s, -s, s, 2.0, 0.0, 0.0]
}

fn camera_a() -> Intrinsics {
    Intrinsics {
        fx: 200.0,
        fy: 200.0,
        cx: 150.0,
        cy: 100.0,
        width: 300,
        height: 200,
    }
}

fn path_a() -> CameraPath {
    CameraPath::from_phis(&[phi_a()], camera_a(), 30.0)
}

fn close(a: f64, b: f64, what: &str) {
    assert!((a - b).abs() < 1e-9, "{what}: {a} != {b}");
}

fn close_all(a: &[f64], b: &[f64], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    for (k, (x, y)) in a.iter().zip(b).enumerate() {
        close(*x, *y, &format!("{what}[{k}]"));
    }
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .flat_map(|x| match x {
            Value::Array(inner) => inner.iter().map(|y| y.as_f64().unwrap()).collect(),
            other => vec![other.as_f64().unwrap()],
        })
        .collect()
}

/// The same pose: rotations and centres within 1e-9.
fn same_pose(a: &CameraPose, phi: [f64; 6]) {
    let b = CameraPose::from_phi(phi);
    let (r, c) = a.max_difference(&b);
    assert!(r < 1e-9 && c < 1e-9, "{a:?} vs {b:?}: {r:e} {c:e}");
}

#[test]
fn rotation_of_the_known_pose_is_the_hand_computed_matrix() {
    let pose = CameraPose::from_phi(phi_a());
    let cols = pose.rotation.to_cols_array();
    close_all(
        &cols,
        &[0.0, 1.0, 0.0, 0.0, 0.0, -1.0, -1.0, 0.0, 0.0],
        "R_wc columns",
    );
    let w2c = pose.world_to_camera();
    // R_cw rows are R_wc's columns; t = −R_cw·c = (0, 0, 2).
    close_all(
        w2c.as_flattened(),
        &[
            0.0, 1.0, 0.0, 0.0, //
            0.0, 0.0, -1.0, 0.0, //
            -1.0, 0.0, 0.0, 2.0, //
            0.0, 0.0, 0.0, 1.0,
        ],
        "world_to_camera",
    );
}

#[test]
fn nerfstudio_export_is_opengl_camera_to_world_and_vertical_fov() {
    let text = nerfstudio::export(&path_a(), &Default::default()).unwrap();
    let json: Value = serde_json::from_str(&text).unwrap();
    // OpenGL axes: x right = (0, 1, 0), y up = (0, 0, 1), z backward = (1, 0, 0), centre
    // (2, 0, 0); row-major.
    let expected = [
        0.0, 0.0, 1.0, 2.0, //
        1.0, 0.0, 0.0, 0.0, //
        0.0, 1.0, 0.0, 0.0, //
        0.0, 0.0, 0.0, 1.0,
    ];
    let entry = &json["camera_path"][0];
    close_all(
        &numbers(&entry["camera_to_world"]),
        &expected,
        "camera_to_world",
    );
    close(entry["fov"].as_f64().unwrap(), FOV_A, "fov");
    close(entry["aspect"].as_f64().unwrap(), 1.5, "aspect");
    assert_eq!(json["camera_type"], "perspective");
    assert_eq!(json["render_width"], 300);
    assert_eq!(json["render_height"], 200);
    close(json["fps"].as_f64().unwrap(), 30.0, "fps");
    close(json["seconds"].as_f64().unwrap(), 1.0 / 30.0, "seconds");
    let key = &json["keyframes"][0];
    close_all(&numbers(&key["matrix"]), &expected, "keyframe matrix");
    close(key["fov"].as_f64().unwrap(), FOV_A, "keyframe fov");
}

#[test]
fn nerfstudio_hand_written_file_imports_as_the_known_pose() {
    let text = r#"{
        "camera_type": "perspective", "render_width": 300, "render_height": 200,
        "fps": 24, "seconds": 1,
        "camera_path": [{"camera_to_world": [0,0,1,2, 1,0,0,0, 0,1,0,0, 0,0,0,1],
                         "fov": 53.13010235415598, "aspect": 1.5}]
    }"#;
    let path = nerfstudio::import(text, "hand.json").unwrap();
    same_pose(&path.frames[0].pose, phi_a());
    let camera = path.frames[0].camera.unwrap();
    close(camera.fx, 200.0, "fx");
    close(camera.fy, 200.0, "fy");
    close(camera.cx, 150.0, "cx");
    close(camera.cy, 100.0, "cy");
    assert_eq!((camera.width, camera.height), (300, 200));
    assert_eq!(path.fps, Some(24.0));
}

#[test]
fn colmap_export_is_world_to_camera_quaternion_and_translation() {
    let files = colmap::export(&path_a()).unwrap();
    // R_cw rotates by 120° about (1, 1, −1)/√3: q = (cos 60°, sin 60°·(1, 1, −1)/√3)
    // = (0.5, 0.5, 0.5, −0.5); t = (0, 0, 2).
    let line = files
        .images
        .lines()
        .find(|l| !l.starts_with('#') && !l.trim().is_empty())
        .unwrap();
    let tokens: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(tokens.len(), 10, "{line}");
    assert_eq!(tokens[0], "1");
    let values: Vec<f64> = tokens[1..8].iter().map(|t| t.parse().unwrap()).collect();
    close_all(
        &values,
        &[0.5, 0.5, 0.5, -0.5, 0.0, 0.0, 2.0],
        "qw qx qy qz tx ty tz",
    );
    assert_eq!(tokens[8], "1");
    assert_eq!(tokens[9], "frame_0000.png");
    // The image line is followed by its (empty) points line.
    let mut lines = files.images.lines().skip_while(|l| *l != line);
    lines.next();
    assert_eq!(lines.next(), Some(""));

    let camera = files.cameras.lines().find(|l| !l.starts_with('#')).unwrap();
    let tokens: Vec<&str> = camera.split_whitespace().collect();
    assert_eq!(&tokens[..4], &["1", "PINHOLE", "300", "200"]);
    let params: Vec<f64> = tokens[4..].iter().map(|t| t.parse().unwrap()).collect();
    close_all(&params, &[200.0, 200.0, 150.0, 100.0], "fx fy cx cy");
}

#[test]
fn colmap_hand_written_model_imports_as_the_known_pose() {
    let cameras = "# comment\n3 SIMPLE_PINHOLE 300 200 200 150 100\n";
    let images = "# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n\
                  # POINTS2D[]\n\
                  7 0.5 0.5 0.5 -0.5 0 0 2 3 a b.png\n\
                  10.0 20.0 -1\n";
    let cameras = colmap::import_cameras(cameras, "cameras.txt").unwrap();
    let path = colmap::import(images, "images.txt", Some(&cameras)).unwrap();
    assert_eq!(path.frames.len(), 1);
    same_pose(&path.frames[0].pose, phi_a());
    assert_eq!(path.frames[0].camera, Some(camera_a()));
}

#[test]
fn inria_export_is_centre_and_camera_to_world_rows() {
    let text = inria::export(&path_a()).unwrap();
    let json: Value = serde_json::from_str(&text).unwrap();
    let camera = &json[0];
    assert_eq!(camera["id"], 0);
    assert_eq!(camera["width"], 300);
    assert_eq!(camera["height"], 200);
    close_all(&numbers(&camera["position"]), &[2.0, 0.0, 0.0], "position");
    // Rows of R_wc (columns right, down, forward as above).
    close_all(
        &numbers(&camera["rotation"]),
        &[0.0, 0.0, -1.0, 1.0, 0.0, 0.0, 0.0, -1.0, 0.0],
        "rotation rows",
    );
    close(camera["fx"].as_f64().unwrap(), 200.0, "fx");
    close(camera["fy"].as_f64().unwrap(), 200.0, "fy");
}

#[test]
fn inria_hand_written_file_imports_as_the_known_pose() {
    let text = r#"[{"id": 4, "img_name": "x", "width": 300, "height": 200,
        "position": [2, 0, 0], "rotation": [[0, 0, -1], [1, 0, 0], [0, -1, 0]],
        "fx": 200, "fy": 200}]"#;
    let path = inria::import(text, "cameras.json").unwrap();
    same_pose(&path.frames[0].pose, phi_a());
    assert_eq!(path.frames[0].camera, Some(camera_a()));
}

#[test]
fn supersplat_export_flips_x_and_y_and_targets_along_the_view() {
    // Camera B: identity rotation (looks along +z, y down: upright in a y-down scene) at
    // (1, 0, −4); focus 4 puts the target at (1, 0, 0). The viewer's world is the scene
    // turned 180° about z: (x, y, z) → (−x, −y, z).
    let path = CameraPath::from_phis(&[[0.0, 0.0, 0.0, 1.0, 0.0, -4.0]], camera_a(), 30.0);
    let options = SupersplatOptions {
        fps: 30.0,
        focus: Focus::Distance(4.0),
        ..SupersplatOptions::default()
    };
    let text = supersplat::export(&path, &options).unwrap();
    let json: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(json["version"], 2);
    assert_eq!(json["startMode"], "animTrack");
    let track = &json["animTracks"][0];
    close(track["frameRate"].as_f64().unwrap(), 30.0, "frameRate");
    let keys = &track["keyframes"];
    close_all(&numbers(&keys["times"]), &[0.0], "times (frames)");
    close_all(
        &numbers(&keys["values"]["position"]),
        &[-1.0, 0.0, -4.0],
        "position",
    );
    close_all(
        &numbers(&keys["values"]["target"]),
        &[-1.0, 0.0, 0.0],
        "target",
    );
    close_all(&numbers(&keys["values"]["fov"]), &[FOV_A], "fov (degrees)");
    let initial = &json["cameras"][0]["initial"];
    close_all(
        &numbers(&initial["position"]),
        &[-1.0, 0.0, -4.0],
        "initial",
    );
}

#[test]
fn supersplat_hand_written_track_imports_by_look_at() {
    // Viewer position (0, 1, −1) is scene (0, −1, −1): one unit above (y down) and one behind
    // the origin it looks at. Forward (0, 1, 1)/√2; right = forward × up(0, −1, 0) = (1, 0, 0);
    // down = forward × right = (0, 1, −1)/√2: a rotation of −45° about x.
    let text = r#"{"animTracks": [{"name": "cameraAnim", "duration": 0, "frameRate": 30,
        "keyframes": {"times": [0], "values": {"position": [0, 1, -1], "target": [0, 0, 0],
        "fov": [53.13010235415598]}}}]}"#;
    let path = supersplat::import(text, "settings.json", 200, 1.5).unwrap();
    same_pose(&path.frames[0].pose, [-PI / 4.0, 0.0, 0.0, 0.0, -1.0, -1.0]);
    let camera = path.frames[0].camera.unwrap();
    close(camera.fy, 200.0, "fy");
    assert_eq!((camera.width, camera.height), (300, 200));
}
