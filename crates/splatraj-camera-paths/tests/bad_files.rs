//! Bad camera files end in an error that names the file, the element and the problem, and
//! never in a panic (every prefix of a good file is tried too).

use splatraj_camera_paths::camera::{CameraPath, Frame, Intrinsics};
use splatraj_camera_paths::supersplat::{Focus, SupersplatOptions};
use splatraj_camera_paths::{
    ExportOptions, Format, colmap, inria, nerfstudio, supersplat, transforms,
};

fn message(result: Result<CameraPath, splatraj_camera_paths::InterchangeError>) -> String {
    match result {
        Ok(path) => panic!("should fail, read {} frames", path.frames.len()),
        Err(e) => e.to_string(),
    }
}

fn mentions(message: &str, parts: &[&str]) {
    for p in parts {
        assert!(message.contains(p), "{message:?} does not mention {p:?}");
    }
}

const NERF_OK: &str = r#"{"camera_type": "perspective", "render_width": 64, "render_height": 48,
  "fps": 30, "seconds": 1, "camera_path": [
  {"camera_to_world": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], "fov": 50, "aspect": 1.333},
  {"camera_to_world": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1], "fov": 50, "aspect": 1.333}]}"#;

#[test]
fn nerfstudio_errors_name_file_element_and_problem() {
    assert!(nerfstudio::import(NERF_OK, "ok.json").is_ok());
    let short = NERF_OK.replacen(
        "0,0,1,0, 0,0,0,1], \"fov\": 50, \"aspect\": 1.333}]",
        "0,0,1, 0,0,0,1], \"fov\": 50, \"aspect\": 1.333}]",
        1,
    );
    mentions(
        &message(nerfstudio::import(&short, "p.json")),
        &[
            "p.json",
            "camera_path[1].camera_to_world",
            "15 numbers, expected 16",
        ],
    );
    let scaled = NERF_OK.replacen(
        "[1,0,0,0, 0,1,0,0, 0,0,1,0",
        "[2,0,0,0, 0,2,0,0, 0,0,2,0",
        1,
    );
    mentions(
        &message(nerfstudio::import(&scaled, "p.json")),
        &["camera_path[0].camera_to_world", "not a rotation"],
    );
    let fisheye = NERF_OK.replace("perspective", "fisheye");
    mentions(
        &message(nerfstudio::import(&fisheye, "p.json")),
        &["camera_type", "fisheye", "not supported"],
    );
    let bad_fov = NERF_OK.replacen("\"fov\": 50", "\"fov\": 190", 1);
    mentions(
        &message(nerfstudio::import(&bad_fov, "p.json")),
        &["camera_path[0].fov", "190"],
    );
    let no_fov = NERF_OK.replacen(", \"fov\": 50", "", 1);
    mentions(
        &message(nerfstudio::import(&no_fov, "p.json")),
        &["camera_path[0].fov", "missing"],
    );
    let no_height = NERF_OK.replace("\"render_height\": 48,", "");
    mentions(
        &message(nerfstudio::import(&no_height, "p.json")),
        &["p.json", "render_height"],
    );
    let empty = r#"{"render_width": 4, "render_height": 4, "camera_path": []}"#;
    mentions(
        &message(nerfstudio::import(empty, "p.json")),
        &["camera_path", "no cameras"],
    );
    let nan = NERF_OK.replacen("[1,0,0,0,", "[1,0,0,1e999,", 1);
    mentions(&message(nerfstudio::import(&nan, "p.json")), &["p.json"]);
}

#[test]
fn a_nerfstudio_length_that_is_not_a_positive_number_of_seconds_is_refused() {
    let path = nerfstudio::import(NERF_OK, "ok.json").unwrap();
    assert_eq!(path.seconds, Some(1.0));
    for bad in ["0", "-1"] {
        let text = NERF_OK.replacen("\"seconds\": 1", &format!("\"seconds\": {bad}"), 1);
        mentions(
            &message(nerfstudio::import(&text, "p.json")),
            &["p.json", "seconds", bad, "finite and > 0"],
        );
    }
}

#[test]
fn a_nerfstudio_camera_of_aspect_0_is_refused_naming_the_camera() {
    let text = NERF_OK.replacen("\"aspect\": 1.333}]", "\"aspect\": 0}]", 1);
    mentions(
        &message(nerfstudio::import(&text, "p.json")),
        &["p.json", "camera_path[1].aspect", "finite and > 0"],
    );
}

/// A SuperSplat track of two keyframes at `times` (frames), 1 s long at 30 fps.
fn supersplat_at(times: &str) -> String {
    format!(
        r#"{{"animTracks": [{{"frameRate": 30, "duration": 1, "keyframes": {{"times": {times},
        "values": {{"position": [0, 0, 0, 1, 0, 0], "target": [0, 0, 1, 1, 0, 1],
        "fov": [50, 50]}}}}}}]}}"#
    )
}

#[test]
fn supersplat_keyframe_times_must_be_frames_from_0_below_the_longest_track() {
    let ok = supersplat::import(&supersplat_at("[0, 30]"), "settings.json", 48, 1.0).unwrap();
    assert_eq!(ok.seconds, Some(1.0));
    for (times, element, value) in [
        ("[0, 1e12]", "keyframes.times[1]", "1000000000000"),
        ("[-1, 30]", "keyframes.times[0]", "-1"),
    ] {
        mentions(
            &message(supersplat::import(
                &supersplat_at(times),
                "settings.json",
                48,
                1.0,
            )),
            &["settings.json", element, value, "frames from 0"],
        );
    }
}

const CAMERAS_OK: &str = "1 PINHOLE 64 48 50 50 32 24\n";
const IMAGES_OK: &str = "1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 0 0 1 1 b.png\n\n";

#[test]
fn colmap_errors_name_file_line_and_problem() {
    let cameras = colmap::import_cameras(CAMERAS_OK, "cameras.txt").unwrap();
    assert_eq!(
        colmap::import(IMAGES_OK, "images.txt", Some(&cameras))
            .unwrap()
            .frames
            .len(),
        2
    );
    let bad_number = IMAGES_OK.replacen("2 1 0 0", "2 1 abc 0", 1);
    mentions(
        &message(colmap::import(&bad_number, "images.txt", Some(&cameras))),
        &[
            "images.txt",
            "line 3 (image 2)",
            "QX \"abc\" is not a number",
        ],
    );
    let short = IMAGES_OK.replacen("0 0 1 a.png", "a.png", 1);
    mentions(
        &message(colmap::import(&short, "images.txt", None)),
        &["line 1", "fields, expected IMAGE_ID"],
    );
    let zero = IMAGES_OK.replacen("1 1 0 0 0", "1 0 0 0 0", 1);
    mentions(
        &message(colmap::import(&zero, "images.txt", None)),
        &["line 1 (image 1)", "quaternion", "zero"],
    );
    let unknown_camera = IMAGES_OK.replacen("0 1 a.png", "0 7 a.png", 1);
    mentions(
        &message(colmap::import(
            &unknown_camera,
            "images.txt",
            Some(&cameras),
        )),
        &["line 1 (image 1)", "CAMERA_ID 7 is not in cameras.txt"],
    );
    let twice = IMAGES_OK.replacen("2 1 0 0", "1 1 0 0", 1);
    mentions(
        &message(colmap::import(&twice, "images.txt", None)),
        &["image id 1 appears twice"],
    );
    mentions(
        &message(colmap::import("# nothing\n", "images.txt", None)),
        &["images.txt", "no images"],
    );

    let camera_error = |text: &str| {
        colmap::import_cameras(text, "cameras.txt")
            .unwrap_err()
            .to_string()
    };
    mentions(
        &camera_error("1 OPENCV_FISHEYE 64 48 50 50 32 24 0 0 0 0\n"),
        &[
            "cameras.txt",
            "line 1 (camera 1)",
            "OPENCV_FISHEYE is not supported",
        ],
    );
    mentions(
        &camera_error("# c\n1 PINHOLE 64 48 50 50 32\n"),
        &[
            "line 2 (camera 1)",
            "PINHOLE takes 4 parameters, the line has 3",
        ],
    );
    mentions(
        &camera_error("1 PINHOLE 64 48 -50 50 32 24\n"),
        &["line 1 (camera 1)", "fx = -50"],
    );
    mentions(
        &camera_error("1 PINHOLE 64\n"),
        &["line 1", "CAMERA_ID MODEL"],
    );
}

const INRIA_OK: &str = r#"[{"id": 0, "img_name": "a", "width": 64, "height": 48,
  "position": [0, 0, 0], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 50, "fy": 50},
  {"id": 1, "img_name": "b", "width": 64, "height": 48,
  "position": [0, 0, 1], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 50, "fy": 50}]"#;

#[test]
fn inria_errors_name_file_camera_and_problem() {
    assert!(inria::import(INRIA_OK, "cameras.json").is_ok());
    let skewed = INRIA_OK.replacen(
        "\"position\": [0, 0, 1], \"rotation\": [[1, 0, 0]",
        "\"position\": [0, 0, 1], \"rotation\": [[1, 0.5, 0]",
        1,
    );
    mentions(
        &message(inria::import(&skewed, "cameras.json")),
        &["cameras.json", "[1] (id 1).rotation", "not a rotation"],
    );
    let mirrored = INRIA_OK.replacen("[0, 0, 1]], \"fx\": 50", "[0, 0, -1]], \"fx\": 50", 1);
    mentions(
        &message(inria::import(&mirrored, "cameras.json")),
        &["[0] (id 0)", "det R = -1"],
    );
    let bad_focal = INRIA_OK.replacen("\"fx\": 50", "\"fx\": 0", 1);
    mentions(
        &message(inria::import(&bad_focal, "cameras.json")),
        &["[0] (id 0)", "fx = 0"],
    );
    let no_rotation = INRIA_OK.replacen("\"rotation\": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], ", "", 1);
    mentions(
        &message(inria::import(&no_rotation, "cameras.json")),
        &["cameras.json", "rotation"],
    );
    mentions(
        &message(inria::import("[]", "cameras.json")),
        &["no cameras"],
    );
    mentions(
        &message(inria::import("{\"a\": 1}", "cameras.json")),
        &["cameras.json", "not a INRIA cameras.json file"],
    );
}

#[test]
fn supersplat_errors_name_the_element() {
    let text = r#"{"animTracks": [{"frameRate": 30, "keyframes": {"times": [0, 1],
        "values": {"position": [0, 0, 0, 1, 1], "target": [0, 0, 1, 1, 1, 2], "fov": [50, 50]}}}]}"#;
    mentions(
        &message(supersplat::import(text, "settings.json", 48, 1.0)),
        &[
            "settings.json",
            "animTracks[0].keyframes.values.position",
            "5 numbers for 2 keyframes",
        ],
    );
    let same_point = r#"{"animTracks": [{"frameRate": 30, "keyframes": {"times": [0],
        "values": {"position": [0, 0, 0], "target": [0, 0, 0], "fov": [50]}}}]}"#;
    mentions(
        &message(supersplat::import(same_point, "settings.json", 48, 1.0)),
        &["keyframe 0", "not away from the camera"],
    );
}

#[test]
fn detection_says_what_it_expected() {
    let dir =
        std::env::temp_dir().join(format!("splatraj-camera-paths-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let odd = dir.join("odd.json");
    std::fs::write(&odd, "{\"frames\": []}").unwrap();
    let err = splatraj_camera_paths::read_camera_path(&odd)
        .unwrap_err()
        .to_string();
    mentions(
        &err,
        &["odd.json", "camera_path.json", "cameras.json", "images.txt"],
    );
    let missing = dir.join("missing.json");
    let err = splatraj_camera_paths::read_camera_path(&missing)
        .unwrap_err()
        .to_string();
    mentions(&err, &["cannot read", "missing.json"]);
    let cameras = dir.join("cameras.txt");
    std::fs::write(&cameras, CAMERAS_OK).unwrap();
    let err = splatraj_camera_paths::read_camera_path(&cameras)
        .unwrap_err()
        .to_string();
    mentions(&err, &["images.txt"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn exports_refuse_what_they_cannot_write() {
    let camera = Intrinsics::centred(50.0, 64, 48);
    let mut path = CameraPath::from_phis(&[[0.0; 6], [0.0, 0.0, 0.0, 1.0, 0.0, 0.0]], camera, 30.0);
    path.frames[1] = Frame {
        camera: None,
        ..path.frames[1]
    };
    for format in Format::ALL {
        let err = splatraj_camera_paths::export(&path, format, &ExportOptions::default())
            .unwrap_err()
            .to_string();
        mentions(&err, &["frame 1 has no intrinsics"]);
        let empty = CameraPath {
            cuts: Vec::new(),
            frames: vec![],
            fps: None,
            seconds: None,
        };
        let err = splatraj_camera_paths::export(&empty, format, &ExportOptions::default())
            .unwrap_err()
            .to_string();
        mentions(&err, &["no frames"]);
    }
    let ok = CameraPath::from_phis(&[[0.0; 6]], camera, 30.0);
    let err = nerfstudio::export(
        &ok,
        &nerfstudio::NerfstudioOptions {
            fps: 0.0,
            keyframes_per_second: 2.0,
        },
    )
    .unwrap_err()
    .to_string();
    mentions(&err, &["fps 0"]);
    let err = supersplat::export(
        &ok,
        &SupersplatOptions {
            fps: 30.0,
            focus: Focus::PerFrame(vec![1.0, 2.0]),
            ..SupersplatOptions::default()
        },
    )
    .unwrap_err()
    .to_string();
    mentions(&err, &["2 focus distances for 1 frames"]);
}

#[test]
fn truncated_files_never_panic() {
    let camera = Intrinsics::centred(50.0, 64, 48);
    let path = CameraPath::from_phis(
        &[
            [0.1, 0.2, 0.3, 1.0, 2.0, 3.0],
            [0.0, -0.2, 0.1, 0.0, 2.0, 3.0],
        ],
        camera,
        30.0,
    );
    for format in Format::ALL {
        let files =
            splatraj_camera_paths::export(&path, format, &ExportOptions::default()).unwrap();
        for (name, text) in &files {
            for cut in 0..text.len() {
                if !text.is_char_boundary(cut) {
                    continue;
                }
                let prefix = &text[..cut];
                // Each reader either reads or says why; none panics.
                let _ = match (format, *name) {
                    (Format::Nerfstudio, _) => nerfstudio::import(prefix, name).map(|_| ()),
                    (Format::Inria, _) => inria::import(prefix, name).map(|_| ()),
                    (Format::Supersplat, _) => {
                        supersplat::import(prefix, name, 48, 1.0).map(|_| ())
                    }
                    (Format::Colmap, "cameras.txt") => {
                        colmap::import_cameras(prefix, name).map(|_| ())
                    }
                    (Format::Colmap, _) => colmap::import(prefix, name, None).map(|_| ()),
                    (Format::Transforms, _) => transforms::import(prefix, name).map(|_| ()),
                };
            }
        }
    }
}

/// A cause is said once: the errors carry serde's or the system's message in their text, not
/// as an error source, so a whole chain (`{:#}`, as the command line prints it) does not repeat
/// it (seen with a `targets.lifted.cameras` file that was not JSON).
#[test]
fn causes_are_said_once_in_a_printed_chain() {
    let dir = std::env::temp_dir().join(format!("splatraj-bad-files-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let broken = dir.join("cameras.json");
    std::fs::write(&broken, "{\"frames\": [1, 2,").unwrap();
    for (file, cause) in [
        (broken.clone(), "EOF while parsing"),
        (dir.join("missing.json"), "No such file"),
    ] {
        let Err(error) = splatraj_camera_paths::read_named_cameras(&file) else {
            panic!("{} is refused", file.display());
        };
        let chain = format!("{:#}", anyhow_like(&error));
        assert_eq!(chain.matches(cause).count(), 1, "{chain}");
        assert!(chain.contains(&file.display().to_string()), "{chain}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The error and each of its sources joined by ": ", as anyhow's `{:#}` prints a chain.
fn anyhow_like(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(s) = source {
        text.push_str(&format!(": {s}"));
        source = s.source();
    }
    text
}
