//! A GPU's output frames come back as 8-bit levels packed on the device (4 bytes a pixel), and
//! as floats only in the passes whose frames need the mask on the host (the report's tinted
//! keyframes): the bytes read back are exactly that, and the frames are flex's, a level apart
//! at most where the two backends' f32 values straddle half a level (docs/gpu.md, "Frames read
//! back as 8-bit levels").
//!
//! Runs on the wgpu backend (lavapipe in CI); its own test binary, as the render counters are
//! process-wide.
#![cfg(feature = "wgpu")]

mod common;

use burn::tensor::DType;
use splatraj_experiment::config::MaskOverlay;
use splatraj_experiment::outputs::path_render::{
    PathObject, PathRender, Video, keyframe_indices, render_path,
};
use splatraj_render::backend::BackendKind;
use splatraj_render::camera::Intrinsics;
use splatraj_render::counters;
use splatraj_render::render::{DeviceScene, Rasterizer};
use splatraj_scene::demo::{DemoConfig, demo_scene};
use splatraj_semantic::sources::label_mask;

#[test]
fn gpu_frames_read_back_packed_levels_except_keyframes() {
    let scene = demo_scene(&DemoConfig {
        gaussians: 20_000,
        ..DemoConfig::default()
    })
    .unwrap();
    let mask = label_mask(&scene, "red mug").unwrap();

    // 12 frames of one window, of which the report takes 5 as tinted keyframes.
    let (width, height) = (64, 48);
    let k = Intrinsics::from_fov_x(70.0, width, height).unwrap();
    let count = 12;
    let frames = common::dolly_frames(k, count, (0.03, 0.05), 4.0);
    let job = PathRender {
        frames: &frames,
        objects: vec![PathObject {
            mask: &mask,
            target_ratio: 0.1,
        }],
        overlay: MaskOverlay::None,
        rasterizer: Rasterizer::Fused,
        video: Video::None,
    };
    let render = |backend: BackendKind| {
        let uploaded = DeviceScene::new(&scene, &backend.device().unwrap(), DType::F32);
        let dir = tempfile::tempdir().unwrap();
        let before = counters::snapshot();
        let rendered = render_path(&uploaded, &job, dir.path(), &mut |_| {}).unwrap();
        let read = counters::snapshot().since(&before);
        let pictures: Vec<Vec<u8>> = (0..count)
            .map(|i| {
                let path = dir.path().join(format!("frames/frame_{i:04}.png"));
                image::open(&path).unwrap().to_rgb8().into_raw()
            })
            .collect();
        (read, pictures, rendered.metrics)
    };
    let (gpu, gpu_pictures, gpu_metrics) = render(BackendKind::Wgpu);
    let (_, flex_pictures, flex_metrics) = render(BackendKind::Flex);

    // Each pass is one frame (the default schedule) and reads its mask's moment sums (4
    // floats: the framing figures are made of them on the host), then its picture: RGB and
    // the mask as floats for a keyframe, else one packed 32-bit value a pixel.
    let keyframes = keyframe_indices(&frames.times, 1).concat();
    assert_eq!(keyframes.len(), 5, "the report's keyframes of the window");
    let pixels = (width * height) as u64;
    let floats = keyframes.len() as u64 * pixels * 4 * 4;
    let packed = (count - keyframes.len()) as u64 * pixels * 4;
    let framing = count as u64 * 4 * 4;
    assert_eq!(gpu.reads, 2 * count as u64);
    assert_eq!(gpu.bytes_down, floats + packed + framing);

    // The same framing figures as flex's, within f32 sums' rounding, and the object in view.
    assert_eq!(gpu_metrics.len(), count);
    assert_eq!(flex_metrics.len(), count);
    for (g, f) in gpu_metrics.iter().zip(&flex_metrics) {
        let frame = g.frame;
        assert_eq!(
            (g.frame, g.window, g.tce.is_some()),
            (f.frame, f.window, f.tce.is_some())
        );
        assert!(
            (g.coverage - f.coverage).abs() <= 1e-5,
            "frame {frame}: {g:?} vs {f:?}"
        );
        assert!(
            (g.tre - f.tre).abs() <= 1e-5,
            "frame {frame}: {g:?} vs {f:?}"
        );
        let (gt, ft) = (g.tce.unwrap_or(0.0), f.tce.unwrap_or(0.0));
        assert!((gt - ft).abs() <= 1e-4, "frame {frame}: {g:?} vs {f:?}");
    }
    assert!(
        flex_metrics.iter().all(|m| m.coverage > 1e-3),
        "the object is in view"
    );

    // The same pictures as flex's, but where the two backends' f32 values lie on either side
    // of half a level.
    let mut apart = 0;
    for (i, (got, want)) in gpu_pictures.iter().zip(&flex_pictures).enumerate() {
        assert_eq!(got.len(), want.len());
        for (&g, &w) in got.iter().zip(want) {
            assert!(
                g.abs_diff(w) <= 1,
                "frame {i}: level {g} on wgpu, {w} on flex"
            );
            apart += usize::from(g != w);
        }
    }
    let values = count * width * height * 3;
    assert!(apart * 200 < values, "{apart} of {values} levels apart");
    assert!(
        gpu_pictures.iter().flatten().any(|&v| v > 60),
        "the frames show something"
    );
}
