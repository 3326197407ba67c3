//! Export → import gives the same poses (rotation entries and centres within 1e-6, and Φ
//! itself where the angle is away from π) and the intrinsics each format can hold, for every
//! format; also through files on disk and format detection.

use std::f64::consts::PI;

use splatraj_camera_paths::camera::{CameraPath, CameraPose, Frame, Intrinsics};
use splatraj_camera_paths::supersplat::{Focus, Keyframes, SupersplatOptions};
use splatraj_camera_paths::{ExportOptions, Format, colmap, inria, nerfstudio, supersplat};

const TOL: f64 = 1e-6;

/// Poses of every kind: identity, tiny and large angles (one just short of π), a half turn
/// about each axis, far centres.
fn phis() -> Vec<[f64; 6]> {
    let s = 2.0 * PI / 3.0 / 3f64.sqrt();
    let near_pi = PI - 1e-4;
    vec![
        [0.0; 6],
        [-s, -s, s, 2.0, 0.0, 0.0],
        [1e-9, -2e-9, 0.0, 1.0, 2.0, 3.0],
        [0.3, -1.2, 2.0, -5.5, 0.25, 10.0],
        [0.6 * near_pi, 0.8 * near_pi, 0.0, 0.1, -0.2, 0.3],
        [PI, 0.0, 0.0, 1e3, -2e3, 5e2],
        [0.0, PI, 0.0, -0.001, 0.002, 0.0],
        [0.0, 0.0, -PI, 7.0, 7.0, 7.0],
        [-2.5, 0.4, 0.9, -1e-3, 4.0, -8.0],
    ]
}

fn camera() -> Intrinsics {
    Intrinsics {
        fx: 412.5,
        fy: 398.25,
        cx: 161.0,
        cy: 119.5,
        width: 320,
        height: 240,
    }
}

fn same_poses(exported: &CameraPath, imported: &CameraPath, what: &str) {
    assert_eq!(
        exported.frames.len(),
        imported.frames.len(),
        "{what}: count"
    );
    for (i, (a, b)) in exported.frames.iter().zip(&imported.frames).enumerate() {
        let (r, c) = a.pose.max_difference(&b.pose);
        assert!(
            r < TOL && c < TOL,
            "{what}: frame {i}: rotation differs by {r:e}, centre by {c:e}"
        );
        let (pa, pb) = (a.pose.phi(), b.pose.phi());
        let angle = pa[..3].iter().map(|v| v * v).sum::<f64>().sqrt();
        if angle < PI - 1e-3 {
            for k in 0..6 {
                assert!(
                    (pa[k] - pb[k]).abs() < TOL,
                    "{what}: frame {i}: Φ[{k}] {} vs {}",
                    pa[k],
                    pb[k]
                );
            }
        }
    }
}

fn same_camera(a: &Intrinsics, b: &Intrinsics, what: &str) {
    for (name, x, y) in [
        ("fx", a.fx, b.fx),
        ("fy", a.fy, b.fy),
        ("cx", a.cx, b.cx),
        ("cy", a.cy, b.cy),
    ] {
        assert!((x - y).abs() < TOL, "{what}: {name} {x} vs {y}");
    }
    assert_eq!((a.width, a.height), (b.width, b.height), "{what}: size");
}

#[test]
fn phi_round_trips_through_the_rotation_matrix() {
    for phi in phis() {
        let pose = CameraPose::from_phi(phi);
        let back = CameraPose::from_phi(pose.phi());
        let (r, c) = pose.max_difference(&back);
        assert!(r < 1e-12 && c == 0.0, "{phi:?}");
        let w2c = CameraPose::from_world_to_camera(&pose.world_to_camera()).unwrap();
        let (r, c) = pose.max_difference(&w2c);
        assert!(r < 1e-12 && c < 1e-9, "{phi:?}: {r:e} {c:e}");
    }
}

#[test]
fn nerfstudio_round_trip() {
    // The file holds a vertical fov only: fx = fy, centred.
    let camera = Intrinsics::centred(287.0, 320, 240);
    let path = CameraPath::from_phis(&phis(), camera, 24.0);
    let options = nerfstudio::NerfstudioOptions {
        fps: 24.0,
        keyframes_per_second: 2.0,
    };
    let text = nerfstudio::export(&path, &options).unwrap();
    let back = nerfstudio::import(&text, "camera_path.json").unwrap();
    same_poses(&path, &back, "nerfstudio");
    for f in &back.frames {
        same_camera(&camera, &f.camera.unwrap(), "nerfstudio");
    }
    assert_eq!(back.fps, Some(24.0));
}

#[test]
fn nerfstudio_keyframes_are_frames_at_their_times() {
    let phis: Vec<[f64; 6]> = (0..61)
        .map(|i| [0.0, i as f64 * 0.01, 0.0, i as f64 * 0.1, 0.0, 0.0])
        .collect();
    let path = CameraPath::from_phis(&phis, camera(), 30.0);
    let options = nerfstudio::NerfstudioOptions {
        fps: 30.0,
        keyframes_per_second: 2.0,
    };
    let json: serde_json::Value =
        serde_json::from_str(&nerfstudio::export(&path, &options).unwrap()).unwrap();
    let keys = json["keyframes"].as_array().unwrap();
    let entries = json["camera_path"].as_array().unwrap();
    assert_eq!(entries.len(), 61);
    // 60 frames of 1/30 s between the first and the last: 2 s, 2 keyframes a second.
    assert_eq!(keys.len(), 5);
    assert_eq!(keys[0]["matrix"], entries[0]["camera_to_world"]);
    assert_eq!(keys[4]["matrix"], entries[60]["camera_to_world"]);
    assert_eq!(keys[2]["matrix"], entries[30]["camera_to_world"]);
    assert_eq!(keys[0]["override_transition_enabled"], false);
    let total: f64 = keys[1..]
        .iter()
        .map(|k| k["override_transition_sec"].as_f64().unwrap())
        .sum();
    assert!((total - 2.0).abs() < 1e-12, "{total}");
}

#[test]
fn colmap_round_trip_with_several_cameras() {
    let mut path = CameraPath::from_phis(&phis(), camera(), 30.0);
    // A second camera for some frames: cameras.txt gets two lines.
    let other = Intrinsics {
        fx: 100.0,
        ..camera()
    };
    path.frames[3].camera = Some(other);
    path.frames[5].camera = Some(other);
    let files = colmap::export(&path).unwrap();
    let camera_lines = files
        .cameras
        .lines()
        .filter(|l| !l.starts_with('#'))
        .count();
    assert_eq!(camera_lines, 2);
    let cameras = colmap::import_cameras(&files.cameras, "cameras.txt").unwrap();
    let back = colmap::import(&files.images, "images.txt", Some(&cameras)).unwrap();
    same_poses(&path, &back, "colmap");
    for (a, b) in path.frames.iter().zip(&back.frames) {
        same_camera(&a.camera.unwrap(), &b.camera.unwrap(), "colmap");
    }
    // Without cameras.txt: the same poses, no intrinsics.
    let bare = colmap::import(&files.images, "images.txt", None).unwrap();
    same_poses(&path, &bare, "colmap without cameras");
    assert!(bare.frames.iter().all(|f| f.camera.is_none()));
}

#[test]
fn inria_round_trip() {
    // The file has no principal point: centred cameras round-trip exactly.
    let camera = Intrinsics {
        cx: 160.0,
        cy: 120.0,
        ..camera()
    };
    let path = CameraPath::from_phis(&phis(), camera, 30.0);
    let text = inria::export(&path).unwrap();
    let back = inria::import(&text, "cameras.json").unwrap();
    same_poses(&path, &back, "inria");
    for f in &back.frames {
        same_camera(&camera, &f.camera.unwrap(), "inria");
    }
}

#[test]
fn supersplat_round_trip_of_upright_cameras() {
    // SuperSplat keeps position, target and vertical fov: cameras without roll about the
    // viewing axis (image up as close to the scene's −y as the view allows) round-trip.
    let up = glam::DVec3::new(0.0, -1.0, 0.0);
    let eyes_targets = [
        ([0.0, -1.0, -3.0], [0.1, 0.2, 0.3]),
        ([2.5, 0.5, 1.0], [-1.0, 0.0, 0.0]),
        ([-4.0, -2.0, 8.0], [0.0, 0.5, 0.0]),
        ([0.3, 0.0, 0.0], [0.3, 0.1, 5.0]),
    ];
    let camera = Intrinsics::centred(250.0, 320, 240);
    let frames: Vec<Frame> = eyes_targets
        .iter()
        .map(|(e, t)| Frame {
            pose: CameraPose::look_at((*e).into(), (*t).into(), up).unwrap(),
            camera: Some(camera),
        })
        .collect();
    let path = CameraPath {
        cuts: Vec::new(),
        frames,
        fps: Some(30.0),
        seconds: None,
    };
    let options = SupersplatOptions {
        fps: 30.0,
        focus: Focus::PerFrame(vec![1.0, 2.0, 0.5, 10.0]),
        // Every frame keyed: exact at each frame (sparse keys: tests/supersplat_keys.rs).
        keyframes: Keyframes::EveryFrame,
    };
    let text = supersplat::export(&path, &options).unwrap();
    let back = supersplat::import(&text, "settings.json", 240, 320.0 / 240.0).unwrap();
    same_poses(&path, &back, "supersplat");
    for f in &back.frames {
        same_camera(&camera, &f.camera.unwrap(), "supersplat");
    }
}

#[test]
fn every_format_round_trips_through_files_and_detection() {
    let dir = std::env::temp_dir().join(format!("splatraj-camera-paths-{}", std::process::id()));
    let camera = Intrinsics::centred(300.0, 320, 240);
    let up = glam::DVec3::new(0.0, -1.0, 0.0);
    let frames = (0..5)
        .map(|i| Frame {
            pose: CameraPose::look_at(
                [i as f64, -1.0, -4.0].into(),
                [0.0, 0.0, i as f64 * 0.2].into(),
                up,
            )
            .unwrap(),
            camera: Some(camera),
        })
        .collect();
    let path = CameraPath {
        cuts: Vec::new(),
        frames,
        fps: Some(30.0),
        seconds: None,
    };
    for format in Format::ALL {
        let folder = dir.join(format.name());
        std::fs::create_dir_all(&folder).unwrap();
        // Every SuperSplat frame keyed, so each format reads back exactly.
        let options = ExportOptions {
            supersplat_keyframes: Keyframes::EveryFrame,
            ..ExportOptions::default()
        };
        let files = splatraj_camera_paths::export(&path, format, &options).unwrap();
        let names: Vec<&str> = files.iter().map(|f| f.0).collect();
        assert_eq!(names, format.file_names());
        for (name, text) in &files {
            std::fs::write(folder.join(name), text).unwrap();
        }
        let main = match format {
            Format::Colmap => "images.txt",
            _ => format.file_names()[0],
        };
        let (detected, back) = splatraj_camera_paths::read_camera_path(&folder.join(main)).unwrap();
        assert_eq!(detected, format);
        same_poses(&path, &back, format.name());
        if format == Format::Colmap {
            same_camera(&camera, &back.frames[0].camera.unwrap(), "colmap file");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn continuous_phis_follow_a_turn_through_pi() {
    // A camera turning about z through a full turn: Φ from a file wraps at π; the continuous
    // rotation vectors keep growing (0.3 rad steps) and give the same rotations.
    let phis: Vec<[f64; 6]> = (0..25)
        .map(|i| [0.0, 0.0, i as f64 * 0.3, i as f64, 0.0, 0.0])
        .collect();
    let camera = Intrinsics::centred(100.0, 64, 48);
    let path = CameraPath::from_phis(&phis, camera, 30.0);
    let wrapped = path.phis();
    assert!(wrapped.iter().all(|p| p[2].abs() <= PI + 1e-12));
    let continuous = path.continuous_phis();
    for (i, (c, p)) in continuous.iter().zip(&phis).enumerate() {
        assert!(
            (c[2] - p[2]).abs() < 1e-9,
            "frame {i}: {} vs {}",
            c[2],
            p[2]
        );
        assert!(c[0].abs() < 1e-12 && c[1].abs() < 1e-12, "frame {i}");
    }
    // Resampled at twice the density: the frames themselves, and midpoints between them.
    let dense = path.resampled_phis(49);
    assert_eq!(dense.len(), 49);
    for (i, d) in dense.iter().enumerate() {
        let expected = i as f64 * 0.15;
        assert!((d[2] - expected).abs() < 1e-9, "sample {i}: {}", d[2]);
        assert!((d[3] - i as f64 * 0.5).abs() < 1e-9, "sample {i}: {}", d[3]);
    }
    assert_eq!(path.resampled_phis(3).len(), 3);
    let single = CameraPath::from_phis(&phis[..1], camera, 30.0);
    assert_eq!(single.resampled_phis(4), vec![phis[0]; 4]);
}
