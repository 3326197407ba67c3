//! Our exports as the real tools read them, and paths the tools made as we read them.
//!
//! Two paths are exported ([`FIXTURES`]): [`tool_path`], one shot through one fixed camera, in
//! `tests/data/tools/ours/`, and [`cut_zoom_path`], three shots (two cuts) with a focal length
//! that changes frame by frame, in `tests/data/tools/ours_cut_zoom/` (rewritten by running this
//! test with `SPLATRAJ_WRITE_TOOL_INPUTS=1`; otherwise the test checks they are still what we
//! write). `scripts/make_tool_fixtures.py` loads them with nerfstudio's own
//! `get_path_from_json`, with pycolmap, and by the graphdeco 3DGS code's maths, and writes what
//! each computed to `tests/data/tools/<tool>_loaded.json` (`<tool>_loaded_cut_zoom.json` for
//! the second path); it also writes a spiral path made by nerfstudio's `get_spiral_path`
//! (`tools/nerfstudio_spiral/`) and a model written by pycolmap (`tools/pycolmap_model/`), with
//! the poses the tools hold (`*_truth.json`). Every comparison is within 1e-6.
//!
//! None of the tools reads a cut: nerfstudio's loader ignores `cuts` (and `keyframes`), COLMAP
//! skips the `# splatraj cuts:` comment (and pycolmap's `write_text` drops it), the graphdeco
//! code has no `shot`; the script shows each by loading the file again without them. So the
//! cut reaches a tool only as its two frames, one after the other: the tests check that each
//! tool holds exactly our frames, both frames of every cut among them and nothing between, each
//! with its own focal length, and that our own readers get the cuts back from every format.

use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3};
use serde_json::Value;
use splatraj_camera_paths::camera::{CameraPath, CameraPose, Frame, Intrinsics};
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

/// The first path the tools read: eight poses turning about all three axes (one past 180°),
/// with fx ≠ fy and an off-centre principal point (nerfstudio keeps only the vertical fov).
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

/// The second path: 12 frames in three shots, cut before frames 5 and 8, the lens zooming.
/// Shot 0 dollies back while zooming in (fy 420 → 924); shot 1, across the scene looking
/// back, holds fy = 600 (its three frames share one COLMAP camera); shot 2 turns while
/// zooming out (fy 1100 → 500), so fy spans 2.6× and changes across both cuts. fx = 1.02·fy
/// and the principal point is off centre, as in [`tool_path`].
fn cut_zoom_path() -> CameraPath {
    let frame = |phi: [f64; 6], fy: f64| Frame {
        pose: CameraPose::from_phi(phi),
        camera: Some(Intrinsics {
            fx: 1.02 * fy,
            fy,
            cx: 318.75,
            cy: 243.5,
            width: 640,
            height: 480,
        }),
    };
    let shot = |count: usize, at: &dyn Fn(f64) -> ([f64; 6], f64)| {
        (0..count)
            .map(|i| {
                let (phi, fy) = at(i as f64);
                frame(phi, fy)
            })
            .collect::<Vec<_>>()
    };
    let frames = [
        shot(5, &|t| {
            (
                [0.05 * t, 0.1, 0.0, 0.2, -0.3, -4.0 - 0.5 * t],
                420.0 * (1.0 + 0.3 * t),
            )
        }),
        shot(3, &|t| ([0.0, 3.0, 0.1, 3.0 + 0.1 * t, -0.5, 1.0], 600.0)),
        shot(4, &|t| {
            (
                [0.2, -1.2 + 0.3 * t, -0.05 * t, -2.5, 0.2 * t, 0.5],
                1100.0 - 200.0 * t,
            )
        }),
    ]
    .concat();
    CameraPath {
        frames,
        fps: Some(30.0),
        seconds: None,
        cuts: vec![5, 8],
    }
}

/// An exported path: where its files are, which formats are written there, and the suffix of
/// what the tools loaded of them (`nerfstudio_loaded{suffix}.json`, …).
struct Fixture {
    /// The folder under `tests/data/tools`.
    folder: &'static str,
    /// The formats written (the first path keeps the three its fixtures always had).
    formats: &'static [Format],
    /// The suffix of the `*_loaded` files.
    suffix: &'static str,
    /// The path exported.
    path: fn() -> CameraPath,
}

const FIXTURES: [Fixture; 2] = [
    Fixture {
        folder: "ours",
        formats: &[Format::Nerfstudio, Format::Colmap, Format::Inria],
        suffix: "",
        path: tool_path,
    },
    Fixture {
        folder: "ours_cut_zoom",
        formats: &Format::ALL,
        suffix: "_cut_zoom",
        path: cut_zoom_path,
    },
];

impl Fixture {
    /// What `tool` loaded of this path (`<tool>_loaded<suffix>.json`).
    fn loaded(&self, tool: &str) -> Value {
        json(&format!("{tool}_loaded{}.json", self.suffix))
    }

    /// What our reader makes of one of this path's exported files.
    fn ours(&self, file: &str) -> CameraPath {
        splatraj_camera_paths::read_camera_path(&data(self.folder).join(file))
            .unwrap()
            .1
    }

    /// Checks a tool holds as many frames as we wrote and, where the path cuts, that it ignored
    /// the cut (the script loaded the file the same without `key`), so the cut reaches it only
    /// as its two frames, which the caller's frame-by-frame comparison then checks.
    fn check_cut_only_as_frames(&self, loaded: &Value, frames: usize, key: &str) {
        let path = (self.path)();
        assert_eq!(
            frames,
            path.frames.len(),
            "{}: the tool holds a frame more or less than we wrote",
            self.folder
        );
        if !path.cuts.is_empty() {
            let ignored = loaded["same_without"].as_array().unwrap();
            assert!(
                ignored.iter().any(|k| k == key),
                "{}: the script did not show the tool ignores {key:?}: {ignored:?}",
                self.folder
            );
        }
    }
}

/// Frame `i` of `path`, naming its place at a cut (for messages).
fn frame_label(path: &CameraPath, i: usize) -> String {
    if path.cuts.contains(&(i + 1)) {
        format!("frame {i} (last before a cut)")
    } else if path.cuts.contains(&i) {
        format!("frame {i} (first after a cut)")
    } else {
        format!("frame {i}")
    }
}

#[test]
fn the_cut_zoom_path_cuts_and_zooms_by_more_than_two() {
    // What the second fixture is for: if this fails, the tools no longer see cuts or a zoom.
    let path = cut_zoom_path();
    assert_eq!(path.cuts, vec![5, 8]);
    let fy: Vec<f64> = path.frames.iter().map(|f| f.camera.unwrap().fy).collect();
    let (low, high) = (
        fy.iter().copied().fold(f64::INFINITY, f64::min),
        fy.iter().copied().fold(0.0, f64::max),
    );
    assert!(high / low >= 2.0, "{fy:?}");
    // Each cut switches place, and the focal length, between its two frames.
    for &k in &path.cuts {
        let (a, b) = (&path.frames[k - 1], &path.frames[k]);
        assert!(a.pose.centre.distance(b.pose.centre) > 1.0, "cut {k}");
        assert_ne!(a.camera.unwrap().fy, b.camera.unwrap().fy, "cut {k}");
    }
}

#[test]
fn our_exports_are_the_committed_tool_inputs() {
    let write = std::env::var_os("SPLATRAJ_WRITE_TOOL_INPUTS").is_some();
    for fixture in &FIXTURES {
        let path = (fixture.path)();
        for &format in fixture.formats {
            for (name, text) in
                splatraj_camera_paths::export(&path, format, &ExportOptions::default()).unwrap()
            {
                let file = data(fixture.folder).join(name);
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
}

#[test]
fn our_readers_read_back_the_cuts_from_every_format() {
    // Our readers (what render-path and [start] trajectory use) on the committed exports: the
    // cuts, the frame count, and both frames of each cut with their centre and focal length.
    for fixture in &FIXTURES {
        let path = (fixture.path)();
        for &format in fixture.formats {
            let file = match format {
                Format::Colmap => "images.txt",
                _ => format.file_names()[0],
            };
            let (read_format, back) =
                splatraj_camera_paths::read_camera_path(&data(fixture.folder).join(file)).unwrap();
            let what = format!("{}/{file}", fixture.folder);
            assert_eq!(read_format, format, "{what}");
            assert_eq!(back.cuts, path.cuts, "{what}: cuts");
            assert_eq!(back.frames.len(), path.frames.len(), "{what}: frames");
            for i in path.cuts.iter().flat_map(|&k| [k - 1, k]) {
                let (want, got) = (&path.frames[i], &back.frames[i]);
                close_all(
                    &[
                        got.pose.centre.to_array().as_slice(),
                        &[got.camera.unwrap().fy],
                    ]
                    .concat(),
                    &[
                        want.pose.centre.to_array().as_slice(),
                        &[want.camera.unwrap().fy],
                    ]
                    .concat(),
                    &format!("{what}: {}: centre, fy", frame_label(&path, i)),
                );
            }
        }
    }
}

#[test]
fn nerfstudio_loads_our_camera_path_as_we_wrote_it() {
    // tools/nerfstudio_loaded*.json: nerfstudio.cameras.camera_paths.get_path_from_json's
    // Cameras (camera_to_worlds 3×4, fx, fy, cx, cy, width, height) per frame. The loader
    // builds each frame's fx = fy from that entry's `fov`, so a zoom reaches it frame by
    // frame; it ignores `cuts` and `keyframes` (the viewer's), so a cut is two entries in a row.
    for fixture in &FIXTURES {
        let loaded = fixture.loaded("nerfstudio");
        let path = (fixture.path)();
        let read = fixture.ours("camera_path.json");
        let cameras = loaded["cameras"].as_array().unwrap();
        fixture.check_cut_only_as_frames(&loaded, cameras.len(), "cuts");
        for (i, ((tool, frame), back)) in cameras
            .iter()
            .zip(&path.frames)
            .zip(&read.frames)
            .enumerate()
        {
            let what = format!("{}: {}", fixture.folder, frame_label(&path, i));
            let c2w = numbers(&tool["camera_to_world"]);
            close_all(
                &c2w,
                &top(frame.pose.camera_to_world_opengl()),
                &format!("{what} c2w vs path"),
            );
            close_all(
                &c2w,
                &top(back.pose.camera_to_world_opengl()),
                &format!("{what} c2w vs our reader"),
            );
            let camera = frame.camera.unwrap();
            // camera_path.json keeps the vertical fov only: fx = fy, centred.
            let intrinsics = [camera.fy, camera.fy, 320.0, 240.0, 640.0, 480.0];
            let tool_k: Vec<f64> = ["fx", "fy", "cx", "cy", "width", "height"]
                .iter()
                .map(|k| tool[*k].as_f64().unwrap())
                .collect();
            close_all(&tool_k, &intrinsics, &format!("{what} intrinsics"));
            let b = back.camera.unwrap();
            close_all(
                &tool_k,
                &[b.fx, b.fy, b.cx, b.cy, b.width as f64, b.height as f64],
                &format!("{what} our reader's intrinsics"),
            );
        }
        check_viewer_keyframes(fixture, cameras);
    }
}

/// The viewer's keyframes of a fixture's `camera_path.json` against what `get_path_from_json`
/// loaded: each keyframe, placed at its frame by the transitions before it, holds that frame's
/// matrix and fov, and both frames of every cut are keyframes one frame apart. Read from the
/// file: the viewer's "Load Path" runs inside its GUI, which the script does not start.
fn check_viewer_keyframes(fixture: &Fixture, cameras: &[Value]) {
    let file = json(&format!("{}/camera_path.json", fixture.folder));
    let fps = file["fps"].as_f64().unwrap();
    let height = file["render_height"].as_u64().unwrap() as usize;
    let path = (fixture.path)();
    let mut seconds = 0.0;
    let mut keyed = Vec::new();
    for key in file["keyframes"].as_array().unwrap() {
        seconds += key["override_transition_sec"].as_f64().unwrap_or(0.0);
        let at = seconds * fps;
        let i = at.round() as usize;
        assert!((at - i as f64).abs() < 1e-9, "a keyframe between frames");
        let what = format!("{}: keyframe at {}", fixture.folder, frame_label(&path, i));
        close_all(
            &numbers(&key["matrix"])[..12],
            &numbers(&cameras[i]["camera_to_world"]),
            &what,
        );
        let fy = Intrinsics::focal_from_vertical_fov(key["fov"].as_f64().unwrap(), height);
        close_all(
            &[fy],
            &[cameras[i]["fy"].as_f64().unwrap()],
            &format!("{what} fov"),
        );
        keyed.push(i);
    }
    for &k in &path.cuts {
        assert!(
            keyed.windows(2).any(|w| w == [k - 1, k]),
            "{}: the cut before frame {k} is not a keyframe pair: {keyed:?}",
            fixture.folder
        );
    }
}

#[test]
fn pycolmap_loads_our_model_as_we_wrote_it() {
    // tools/pycolmap_loaded*.json: pycolmap.Reconstruction(dir): per image (by id) its name,
    // camera id, cam_from_world 3×4, and per camera its model and params. A zoom is one
    // camera per focal length, each image naming its own; COLMAP skips the cuts comment, so a
    // cut is two images with consecutive ids.
    for fixture in &FIXTURES {
        let loaded = fixture.loaded("pycolmap");
        let path = (fixture.path)();
        let read = fixture.ours("images.txt");
        let images = loaded["images"].as_array().unwrap();
        fixture.check_cut_only_as_frames(&loaded, images.len(), "# splatraj cuts:");
        for (i, ((tool, frame), back)) in images
            .iter()
            .zip(&path.frames)
            .zip(&read.frames)
            .enumerate()
        {
            let what = format!("{}: {}", fixture.folder, frame_label(&path, i));
            assert_eq!(tool["id"], i + 1, "{what}: image id");
            assert_eq!(tool["name"], splatraj_camera_paths::colmap::frame_name(i));
            let cam_from_world = numbers(&tool["cam_from_world"]);
            close_all(
                &cam_from_world,
                &top(frame.pose.world_to_camera()),
                &format!("{what} cam_from_world"),
            );
            close_all(
                &cam_from_world,
                &top(back.pose.world_to_camera()),
                &format!("{what} our reader"),
            );
            let id = tool["camera_id"].to_string();
            let camera = &loaded["cameras"][&id];
            assert_eq!(camera["model"], "PINHOLE");
            let c = frame.camera.unwrap();
            let b = back.camera.unwrap();
            for (k, whose) in [
                ([c.fx, c.fy, c.cx, c.cy], "ours"),
                ([b.fx, b.fy, b.cx, b.cy], "our reader's"),
            ] {
                close_all(
                    &numbers(&camera["params"]),
                    &k,
                    &format!("{what}: camera {id} params vs {whose}"),
                );
            }
            close_all(
                &[
                    camera["width"].as_f64().unwrap(),
                    camera["height"].as_f64().unwrap(),
                ],
                &[640.0, 480.0],
                "size",
            );
        }
        // One camera per distinct lens, as we write them: no more, no fewer.
        let mut lenses: Vec<[f64; 4]> = Vec::new();
        for f in &path.frames {
            let c = f.camera.unwrap();
            if !lenses.contains(&[c.fx, c.fy, c.cx, c.cy]) {
                lenses.push([c.fx, c.fy, c.cx, c.cy]);
            }
        }
        assert_eq!(
            loaded["cameras"].as_object().unwrap().len(),
            lenses.len(),
            "{}: cameras",
            fixture.folder
        );
    }
}

#[test]
fn graphdeco_reads_our_cameras_json_as_we_wrote_it() {
    // tools/inria_loaded*.json: per entry, the graphdeco code's R (camera-to-world rotation, as
    // their Camera holds it), T (world-to-camera translation), world-to-view 4×4 (row-major,
    // getWorld2View2 before their transpose) and FoVx, FoVy (radians), from that entry's own
    // fx, fy; the code reads no `shot`, so a cut is two entries in a row.
    for fixture in &FIXTURES {
        let loaded = fixture.loaded("inria");
        let path = (fixture.path)();
        let read = fixture.ours("cameras.json");
        let entries = loaded["cameras"].as_array().unwrap();
        fixture.check_cut_only_as_frames(&loaded, entries.len(), "shot");
        for (i, ((tool, frame), back)) in entries
            .iter()
            .zip(&path.frames)
            .zip(&read.frames)
            .enumerate()
        {
            let what = format!("{}: {}", fixture.folder, frame_label(&path, i));
            let r = frame.pose.rotation;
            let rows: Vec<f64> = (0..3)
                .flat_map(|k| [r.x_axis[k], r.y_axis[k], r.z_axis[k]])
                .collect();
            close_all(&numbers(&tool["R"]), &rows, &format!("{what} R"));
            close_all(
                &numbers(&tool["T"]),
                &frame.pose.world_to_camera_translation().to_array(),
                &format!("{what} T"),
            );
            let w2v = numbers(&tool["world_view"]);
            close_all(
                &w2v[..12],
                &top(frame.pose.world_to_camera()),
                &format!("{what} world-to-view"),
            );
            close_all(
                &w2v[..12],
                &top(back.pose.world_to_camera()),
                &format!("{what} our reader"),
            );
            // The focal lengths the tool's FoVx, FoVy stand for (graphdeco's fov2focal), in
            // pixels: 1e-6 rad of fov would hide a focal length off by 1e-3 pixel.
            let focal =
                |fov: &str, size: f64| size / (2.0 * (tool[fov].as_f64().unwrap() / 2.0).tan());
            for (c, whose) in [
                (frame.camera.unwrap(), "ours"),
                (back.camera.unwrap(), "our reader's"),
            ] {
                close_all(
                    &[
                        focal("FoVx", c.width as f64),
                        focal("FoVy", c.height as f64),
                    ],
                    &[c.fx, c.fy],
                    &format!("{what} fx, fy from FoVx, FoVy vs {whose}"),
                );
            }
        }
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
