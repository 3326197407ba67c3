//! A path with a cut, exported in every format and read back by our readers: the cut comes
//! back at the same frame, the two frames of the cut are each their own shot's camera (never a
//! frame between the shots), the sparse SuperSplat track and the nerfstudio keyframes key both
//! frames of the cut, resampling never blends across it, and a cut outside the frames is
//! refused naming the key.

use glam::DVec3;
use splatraj_camera_paths::camera::{CameraPath, CameraPose, Frame, Intrinsics};
use splatraj_camera_paths::{ExportOptions, Format, colmap, export, inria, nerfstudio, supersplat};

fn camera() -> Intrinsics {
    Intrinsics::centred(300.0, 320, 240)
}

/// 20 frames: a slow dolly along x in shot 0 (frames 0–9), then a cut to the other side of
/// the scene, looking back, in shot 1 (frames 10–19).
fn cut_path() -> CameraPath {
    let frame = |eye: DVec3, at: DVec3| Frame {
        pose: CameraPose::look_at(eye, at, DVec3::Z).unwrap(),
        camera: Some(camera()),
    };
    let mut frames: Vec<Frame> = (0..10)
        .map(|i| {
            let x = 0.01 * i as f64;
            frame(DVec3::new(x, -2.0, 1.0), DVec3::new(x, 0.0, 0.0))
        })
        .collect();
    frames.extend((0..10).map(|i| {
        let x = 0.01 * i as f64;
        frame(DVec3::new(x, 3.0, 0.5), DVec3::new(x, 0.0, 0.0))
    }));
    CameraPath {
        frames,
        fps: Some(30.0),
        seconds: None,
        cuts: vec![10],
    }
}

fn read_back(format: Format, files: &[(&str, String)]) -> CameraPath {
    let text = |name: &str| &files.iter().find(|f| f.0 == name).unwrap().1;
    match format {
        Format::Nerfstudio => nerfstudio::import(text("camera_path.json"), "camera_path.json"),
        Format::Supersplat => {
            supersplat::import(text("settings.json"), "settings.json", 240, 4.0 / 3.0)
        }
        Format::Inria => inria::import(text("cameras.json"), "cameras.json"),
        Format::Colmap => colmap::import(text("images.txt"), "images.txt", None),
        Format::Transforms => unreachable!("not written"),
    }
    .unwrap()
}

#[test]
fn every_format_reads_the_cut_back_as_a_cut() {
    let path = cut_path();
    for format in Format::ALL {
        let files = export(&path, format, &ExportOptions::default()).unwrap();
        let back = read_back(format, &files);
        assert_eq!(back.cuts, vec![10], "{format}");
        assert_eq!(back.frames.len(), 20, "{format}");
        // The frames either side of the cut are the shots' own cameras, to the tolerance of
        // the format (SuperSplat keeps no roll; its positions are exact at keys).
        for i in [9, 10] {
            let (want, got) = (path.frames[i].pose.centre, back.frames[i].pose.centre);
            assert!(
                want.distance(got) < 1e-6,
                "{format}: frame {i}: {want} vs {got}"
            );
        }
        assert_eq!(back.shot_of_frame(9), 0);
        assert_eq!(back.shot_of_frame(10), 1);
    }
}

#[test]
fn keyframes_hold_both_frames_of_the_cut() {
    let path = cut_path();
    let text = nerfstudio::export(&path, &nerfstudio::NerfstudioOptions::default()).unwrap();
    let value: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(value["cuts"], serde_json::json!([10]));
    // Two keyframes (first, last) by rate, plus frames 9 and 10: the transition into frame
    // 10 lasts one frame.
    let keyframes = value["keyframes"].as_array().unwrap();
    assert_eq!(keyframes.len(), 4);
    let into_cut = keyframes[2]["override_transition_sec"].as_f64().unwrap();
    assert!((into_cut - 1.0 / 30.0).abs() < 1e-12, "{into_cut}");
    // The sparse SuperSplat track keys frames 9 and 10 too.
    let settings = supersplat::export(&path, &supersplat::SupersplatOptions::default()).unwrap();
    let value: serde_json::Value = serde_json::from_str(&settings).unwrap();
    let times: Vec<f64> = value["animTracks"][0]["keyframes"]["times"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_f64().unwrap())
        .collect();
    assert!(times.contains(&9.0) && times.contains(&10.0), "{times:?}");
    assert_eq!(value["animTracks"][0]["cuts"], serde_json::json!([10]));
}

#[test]
fn resampling_never_blends_across_a_cut() {
    let path = cut_path();
    // 39 samples over 20 frames: sample 19 falls half way between frames 9 and 10.
    let phis = path.resampled_phis(39);
    let y = |p: &[f64; 6]| p[4];
    assert!(
        phis.iter()
            .all(|p| (y(p) + 2.0).abs() < 1e-9 || (y(p) - 3.0).abs() < 1e-9)
    );
}

#[test]
fn a_cut_outside_the_frames_is_refused_naming_the_key() {
    let text = nerfstudio::export(&cut_path(), &nerfstudio::NerfstudioOptions::default()).unwrap();
    let bad = text.replace("\"cuts\": [\n    10\n  ]", "\"cuts\": [\n    20\n  ]");
    assert_ne!(bad, text);
    let error = nerfstudio::import(&bad, "camera_path.json").unwrap_err();
    assert!(error.to_string().contains("cuts"), "{error}");
    let mut path = cut_path();
    path.cuts = vec![0];
    assert!(export(&path, Format::Inria, &ExportOptions::default()).is_err());
}
