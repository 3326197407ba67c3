//! The fast output path writes the same files as the plain one: a path rendered one frame at a
//! time ([`FrameSchedule::Sequential`]) and pipelined (encoding on its own threads, frames in
//! passes of 1, 2 and 3 poses, the video's groups of pictures encoded one, two or three at a
//! time with their frames rendered interleaved) gives byte-identical frames, keyframes,
//! `frame_metrics.csv` and `video.mp4`, with both rasterizers and both overlays.

mod common;

use std::path::Path;

use burn::tensor::{DType, Device};
use glam::DVec3;
use splatraj_experiment::config::MaskOverlay;
use splatraj_experiment::outputs::camera_paths::PathFrames;
use splatraj_experiment::outputs::path_render::{
    FrameSchedule, PathObject, PathRender, Video, render_path_with,
};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::render::{DeviceScene, Rasterizer};
use splatraj_scene::demo::{DEMO_VIEWPOINT, DemoConfig, demo_scene};
use splatraj_semantic::sources::label_mask;

/// Every file under `dir`, relative path and bytes, sorted by path.
fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(folder) = stack.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let name = path.strip_prefix(dir).unwrap().display().to_string();
                out.push((name, std::fs::read(&path).unwrap()));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn pipelined_and_batched_frames_are_the_sequential_frames_byte_for_byte() {
    let scene = demo_scene(&DemoConfig {
        gaussians: 20_000,
        ..DemoConfig::default()
    })
    .unwrap();
    let masks: Vec<Vec<f32>> = ["red mug", "blue box"]
        .iter()
        .map(|name| label_mask(&scene, name).unwrap())
        .collect();
    let uploaded = DeviceScene::new(&scene, &Device::flex(), DType::F32);

    // 7 frames over two windows (4 + 3: a pass of 3 poses ends at the window's edge), 520 px
    // wide so the keyframes are shrunk, odd height so the video pads.
    let k = Intrinsics::from_fov_x(70.0, 520, 67).unwrap();
    let count = 7;
    // Groups of pictures of 3 frames (a keyframe every 2 s): 0–2, 3–5 and 6.
    let frames = common::dolly_frames(k, count, (0.05, 0.1), 1.5);
    let objects: Vec<PathObject> = masks
        .iter()
        .map(|mask| PathObject {
            mask,
            target_ratio: 0.1,
        })
        .collect();

    for rasterizer in [Rasterizer::Fused, Rasterizer::Tensor] {
        for overlay in [MaskOverlay::None, MaskOverlay::Tint] {
            let job = PathRender {
                frames: &frames,
                objects: objects.clone(),
                overlay,
                rasterizer,
                video: Video::Mp4,
            };
            let render = |schedule: FrameSchedule| {
                let dir = tempfile::tempdir().unwrap();
                let mut told = Vec::new();
                let rendered = render_path_with(
                    &uploaded,
                    &job,
                    dir.path(),
                    &mut |done| told.push(done),
                    schedule,
                )
                .unwrap();
                assert_eq!(told, (1..=count).collect::<Vec<_>>());
                assert_eq!(rendered.metrics.len(), count);
                (files(dir.path()), rendered.metrics)
            };
            let (reference, metrics) = render(FrameSchedule::Sequential);
            let names: Vec<&str> = reference.iter().map(|(n, _)| n.as_str()).collect();
            assert!(names.contains(&"video.mp4") && names.contains(&"frame_metrics.csv"));
            assert!(names.contains(&"frames/frame_0006.png"));
            assert_eq!(
                names.iter().any(|n| n.starts_with("keyframes/")),
                overlay == MaskOverlay::None
            );
            for (batch, groups) in [
                (1, None),
                (3, None),
                (1, Some(3)),
                (3, Some(2)),
                (2, Some(1)),
            ] {
                let schedule = FrameSchedule::Pipelined { batch, groups };
                let (fast, fast_metrics) = render(schedule);
                let case = format!("{rasterizer:?} {overlay:?} {}", schedule.name());
                assert_eq!(fast_metrics, metrics, "{case}");
                assert_eq!(fast.len(), reference.len(), "{case}");
                for ((name, bytes), (fast_name, fast_bytes)) in reference.iter().zip(&fast) {
                    assert_eq!(name, fast_name, "{case}");
                    assert!(bytes == fast_bytes, "{case}: {name} differs");
                }
            }
        }
    }
}

#[test]
fn schedules_parse_and_name_themselves() {
    for text in ["sequential", "pipelined:1", "pipelined:4", "pipelined:2:3"] {
        let schedule: FrameSchedule = text.parse().unwrap();
        assert_eq!(schedule.name(), text);
    }
    assert_eq!(
        "pipelined".parse::<FrameSchedule>().unwrap(),
        FrameSchedule::default()
    );
    for bad in [
        "pipelined:0",
        "pipelined:x",
        "pipelined:2:0",
        "pipelined:2:3:4",
        "sequential:2",
        "fast",
        "",
    ] {
        assert!(bad.parse::<FrameSchedule>().is_err(), "{bad}");
    }
}

#[test]
fn a_failing_writer_stops_the_render_with_its_error() {
    // The frames folder is a file: the first frame's write fails on the writer thread, and
    // render_path_with returns that error rather than hanging or reporting a closed queue.
    let scene = demo_scene(&DemoConfig {
        gaussians: 2_000,
        ..DemoConfig::default()
    })
    .unwrap();
    let uploaded = DeviceScene::new(&scene, &Device::flex(), DType::F32);
    let k = Intrinsics::from_fov_x(60.0, 32, 24).unwrap();
    let eye = DVec3::from_array(DEMO_VIEWPOINT.map(f64::from));
    let pose = Pose::look_at(eye, DVec3::new(0.0, 0.3, 0.8), DVec3::Z).unwrap();
    let frames = PathFrames {
        cuts: Vec::new(),
        times: vec![0.0; 20],
        poses: vec![pose.0; 20],
        cameras: vec![k; 20],
        fps: 10.0,
    };
    let job = PathRender {
        frames: &frames,
        objects: Vec::new(),
        overlay: MaskOverlay::None,
        rasterizer: Rasterizer::Fused,
        video: Video::None,
    };
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("frames/frame_0000.png")).unwrap();
    let error = render_path_with(
        &uploaded,
        &job,
        dir.path(),
        &mut |_| {},
        FrameSchedule::Pipelined {
            batch: 2,
            groups: None,
        },
    )
    .unwrap_err();
    assert!(format!("{error:#}").contains("frame_0000.png"), "{error:#}");
}
