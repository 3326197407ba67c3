//! Our exports as the real tools read them, and paths the tools made as we read them.
//!
//! `tests/data/tools/ours/` holds our exports of [`tool_path`] (rewritten by running this test
//! with `SPLATRAJ_WRITE_TOOL_INPUTS=1`; otherwise the test checks they are still what we
//! write). `scripts/make_tool_fixtures.py` loads them with nerfstudio's own
//! `get_path_from_json`, with pycolmap, and by the graphdeco 3DGS code's maths, and writes what
//! each computed to `tests/data/tools/*_loaded.json`; it also writes a spiral path made by
//! nerfstudio's `get_spiral_path` (`tools/nerfstudio_spiral/`) and a model written by pycolmap
//! (`tools/pycolmap_model/`), with the poses the tools hold (`*_truth.json`). Every
//! comparison is within 1e-6.

use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3};
use serde_json::Value;
use splatraj_camera_paths::camera::{CameraPath, CameraPose, Intrinsics};
use splatraj_camera_paths::{ExportOptions, Format};

const TOL: f64 = 1e-6;

fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/tools")
        .join(rel)
}

fn json(rel: &str) -> Value {
    serde_json::from_str(&std::fs::read_to_string(data(rel)).unwrap()).unwrap()
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .flat_map(|x| match x.as_array() {
            Some(_) => numbers(x),
            None => vec![x.as_f64().unwrap()],
        })
        .collect()
}

fn close_all(a: &[f64], b: &[f64], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: count");
    let worst = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(worst <= TOL, "{what}: differs by {worst:e}\n{a:?}\n{b:?}");
}

/// Rows of the top 3×4 of a 4×4.
fn top(m: [[f64; 4]; 4]) -> Vec<f64> {
    m[..3].iter().flatten().copied().collect()
}

/// The path the tools read: eight poses turning about all three axes (one past 180°), with
/// fx ≠ fy and an off-centre principal point (nerfstudio keeps only the vertical fov).
fn tool_path() -> CameraPath {
    let phis: Vec<[f64; 6]> = (0..8)
        .map(|i| {
            let t = i as f64;
            [
                0.3 * (0.7 * t).sin(),
                0.45 * t - 0.2,
                0.1 * (1.3 * t).cos(),
                1.5 * (0.4 * t).cos(),
                -0.3 + 0.05 * t,
                -4.0 + 0.6 * t,
            ]
        })
        .collect();
    let camera = Intrinsics {
        fx: 512.5,
        fy: 498.25,
        cx: 318.75,
        cy: 243.5,
        width: 640,
        height: 480,
    };
    CameraPath::from_phis(&phis, camera, 30.0)
}

#[test]
fn our_exports_are_the_committed_tool_inputs() {
    let path = tool_path();
    let write = std::env::var_os("SPLATRAJ_WRITE_TOOL_INPUTS").is_some();
    for format in [Format::Nerfstudio, Format::Colmap, Format::Inria] {
        for (name, text) in
            splatraj_camera_paths::export(&path, format, &ExportOptions::default()).unwrap()
        {
            let file = data("ours").join(name);
            if write {
                std::fs::create_dir_all(file.parent().unwrap()).unwrap();
                std::fs::write(&file, &text).unwrap();
            } else {
                let committed = std::fs::read_to_string(&file).unwrap();
                assert!(
                    committed == text,
                    "{} is not what we export now: rerun with SPLATRAJ_WRITE_TOOL_INPUTS=1 \
                     and scripts/make_tool_fixtures.py",
                    file.display()
                );
            }
        }
    }
}

/// What our reader makes of one of our exported files.
fn ours(file: &str) -> CameraPath {
    splatraj_camera_paths::read_camera_path(&data("ours").join(file))
        .unwrap()
        .1
}

#[test]
fn nerfstudio_loads_our_camera_path_as_we_wrote_it() {
    // tools/nerfstudio_loaded.json: nerfstudio.cameras.camera_paths.get_path_from_json's
    // Cameras (camera_to_worlds 3×4, fx, fy, cx, cy, width, height) per frame.
    let loaded = json("nerfstudio_loaded.json");
    let path = tool_path();
    let read = ours("camera_path.json");
    let cameras = loaded["cameras"].as_array().unwrap();
    assert_eq!(cameras.len(), path.frames.len());
    for (i, ((tool, frame), back)) in cameras
        .iter()
        .zip(&path.frames)
        .zip(&read.frames)
        .enumerate()
    {
        let c2w = numbers(&tool["camera_to_world"]);
        close_all(
            &c2w,
            &top(frame.pose.camera_to_world_opengl()),
            &format!("frame {i} c2w vs path"),
        );
        close_all(
            &c2w,
            &top(back.pose.camera_to_world_opengl()),
            &format!("frame {i} c2w vs our reader"),
        );
        let camera = frame.camera.unwrap();
        // camera_path.json keeps the vertical fov only: fx = fy, centred.
        let intrinsics = [camera.fy, camera.fy, 320.0, 240.0, 640.0, 480.0];
        let tool_k: Vec<f64> = ["fx", "fy", "cx", "cy", "width", "height"]
            .iter()
            .map(|k| tool[*k].as_f64().unwrap())
            .collect();
        close_all(&tool_k, &intrinsics, &format!("frame {i} intrinsics"));
        let b = back.camera.unwrap();
        close_all(
            &tool_k,
            &[b.fx, b.fy, b.cx, b.cy, b.width as f64, b.height as f64],
            &format!("frame {i} our reader's intrinsics"),
        );
    }
}

#[test]
fn pycolmap_loads_our_model_as_we_wrote_it() {
    // tools/pycolmap_loaded.json: pycolmap.Reconstruction(dir): per image (by id) its name,
    // camera id, cam_from_world 3×4, and per camera its model and params.
    let loaded = json("pycolmap_loaded.json");
    let path = tool_path();
    let images = loaded["images"].as_array().unwrap();
    assert_eq!(images.len(), path.frames.len());
    for (i, (tool, frame)) in images.iter().zip(&path.frames).enumerate() {
        assert_eq!(tool["name"], splatraj_camera_paths::colmap::frame_name(i));
        close_all(
            &numbers(&tool["cam_from_world"]),
            &top(frame.pose.world_to_camera()),
            &format!("image {i} cam_from_world"),
        );
        let id = tool["camera_id"].to_string();
        let camera = &loaded["cameras"][&id];
        assert_eq!(camera["model"], "PINHOLE");
        let c = frame.camera.unwrap();
        close_all(
            &numbers(&camera["params"]),
            &[c.fx, c.fy, c.cx, c.cy],
            &format!("camera {id} params"),
        );
        close_all(
            &[
                camera["width"].as_f64().unwrap(),
                camera["height"].as_f64().unwrap(),
            ],
            &[640.0, 480.0],
            "size",
        );
    }
}

#[test]
fn graphdeco_reads_our_cameras_json_as_we_wrote_it() {
    // tools/inria_loaded.json: per entry, the graphdeco code's R (camera-to-world rotation, as
    // their Camera holds it), T (world-to-camera translation), world-to-view 4×4 (row-major,
    // getWorld2View2 before their transpose) and FoVx, FoVy (radians).
    let loaded = json("inria_loaded.json");
    let path = tool_path();
    let read = ours("cameras.json");
    let entries = loaded["cameras"].as_array().unwrap();
    assert_eq!(entries.len(), path.frames.len());
    for (i, ((tool, frame), back)) in entries
        .iter()
        .zip(&path.frames)
        .zip(&read.frames)
        .enumerate()
    {
        let r = frame.pose.rotation;
        let rows: Vec<f64> = (0..3)
            .flat_map(|k| [r.x_axis[k], r.y_axis[k], r.z_axis[k]])
            .collect();
        close_all(&numbers(&tool["R"]), &rows, &format!("camera {i} R"));
        close_all(
            &numbers(&tool["T"]),
            &frame.pose.world_to_camera_translation().to_array(),
            &format!("camera {i} T"),
        );
        let w2v = numbers(&tool["world_view"]);
        close_all(
            &w2v[..12],
            &top(frame.pose.world_to_camera()),
            &format!("camera {i} world-to-view"),
        );
        close_all(
            &w2v[..12],
            &top(back.pose.world_to_camera()),
            &format!("camera {i} our reader"),
        );
        let c = frame.camera.unwrap();
        let fov = |f: f64, size: usize| 2.0 * (size as f64 / (2.0 * f)).atan();
        close_all(
            &[
                tool["FoVx"].as_f64().unwrap(),
                tool["FoVy"].as_f64().unwrap(),
            ],
            &[fov(c.fx, c.width), fov(c.fy, c.height)],
            &format!("camera {i} fov"),
        );
    }
}

/// Camera-to-world 3×4 rows (OpenGL camera axes, nerfstudio's) of `pose`.
fn opengl(pose: &CameraPose) -> Vec<f64> {
    top(pose.camera_to_world_opengl())
}

#[test]
fn a_spiral_made_by_nerfstudio_reads_as_nerfstudio_holds_it() {
    // tools/nerfstudio_spiral/camera_path.json: nerfstudio's get_spiral_path, written in the
    // schema of its viewer's render panel; truth: the Cameras it made (and get_path_from_json's
    // reading of the file, which the script checks equal).
    let truth = json("nerfstudio_spiral/truth.json");
    let (format, path) =
        splatraj_camera_paths::read_camera_path(&data("nerfstudio_spiral/camera_path.json"))
            .unwrap();
    assert_eq!(format, Format::Nerfstudio);
    let cameras = truth["cameras"].as_array().unwrap();
    assert_eq!(path.frames.len(), cameras.len());
    for (i, (tool, frame)) in cameras.iter().zip(&path.frames).enumerate() {
        close_all(
            &opengl(&frame.pose),
            &numbers(&tool["camera_to_world"]),
            &format!("spiral frame {i}"),
        );
        let c = frame.camera.unwrap();
        close_all(
            &[c.fx, c.fy, c.cx, c.cy],
            &["fx", "fy", "cx", "cy"].map(|k| tool[k].as_f64().unwrap()),
            &format!("spiral frame {i} intrinsics"),
        );
    }
}

#[test]
fn a_model_written_by_pycolmap_reads_as_pycolmap_holds_it() {
    // tools/pycolmap_model/: Reconstruction.write_text of a model built in pycolmap; truth:
    // each image's cam_from_world and camera params as pycolmap holds them.
    let truth = json("pycolmap_model/truth.json");
    let (format, path) =
        splatraj_camera_paths::read_camera_path(&data("pycolmap_model/images.txt")).unwrap();
    assert_eq!(format, Format::Colmap);
    let images = truth["images"].as_array().unwrap();
    assert_eq!(path.frames.len(), images.len());
    for (i, (tool, frame)) in images.iter().zip(&path.frames).enumerate() {
        close_all(
            &top(frame.pose.world_to_camera()),
            &numbers(&tool["cam_from_world"]),
            &format!("model image {i}"),
        );
        let c = frame.camera.unwrap();
        close_all(
            &[c.fx, c.fy, c.cx, c.cy],
            &numbers(&tool["params"]),
            &format!("model image {i} params"),
        );
        // The centre is −Rᵀt: the pose is a rigid motion, not just matching numbers.
        let rows = numbers(&tool["cam_from_world"]);
        let r = DMat3::from_cols_array(&[
            rows[0], rows[1], rows[2], rows[4], rows[5], rows[6], rows[8], rows[9], rows[10],
        ]);
        let centre = -(r * DVec3::new(rows[3], rows[7], rows[11]));
        assert!(
            centre.distance(frame.pose.centre) < TOL,
            "model image {i} centre"
        );
    }
}
