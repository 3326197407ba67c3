//! `splatraj run` writes `video.mp4`, `frame_metrics.csv` and `exports/<format>/`; the video
//! is the frames (read back by another MP4 implementation and decoded by OpenH264), and
//! `splatraj render-path` of the run's exported nerfstudio path gives the run's frames again.

mod common;

use std::path::{Path, PathBuf};

use common::{TINY_CONFIG, assert_clean_failure, s, splatraj, stderr, stdout};
use splatraj_camera_paths::Format;
use splatraj_report::video::decode_mp4;

/// The tiny config run with 6 frames at 12 fps; returns the config file and the run folder.
fn run_with_frames(dir: &Path) -> (PathBuf, PathBuf) {
    let config = dir.join("tiny.toml");
    std::fs::write(&config, TINY_CONFIG).unwrap();
    let runs = format!("output.runs_dir=\"{}\"", dir.join("runs").display());
    let out = splatraj(&[
        "run",
        s(&config),
        "--quiet",
        "--set",
        &runs,
        "--set",
        "output.fps=12",
        "--set",
        "output.seconds=0.5",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let run = PathBuf::from(stdout(&out).lines().last().unwrap().trim());
    (config, run)
}

fn png_rgb(path: &Path) -> Vec<u8> {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .into_rgb8()
        .into_raw()
}

/// Peak signal-to-noise ratio of `b` against `a` (dB).
fn psnr(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len());
    let mse = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    10.0 * (255.0f64.powi(2) / mse.max(1e-12)).log10()
}

fn csv_rows(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect()
}

#[test]
fn the_run_video_is_its_frames_and_its_exported_path_renders_them_again() {
    let dir = tempfile::tempdir().unwrap();
    let (config, run) = run_with_frames(dir.path());

    // 12 fps × 0.5 s = 6 frames, as PNGs and as the video.
    let frames: Vec<Vec<u8>> = (0..6)
        .map(|i| png_rgb(&run.join(format!("frames/frame_{i:04}.png"))))
        .collect();
    assert!(!run.join("frames/frame_0006.png").exists());
    let video = decode_mp4(&std::fs::read(run.join("video.mp4")).unwrap()).unwrap();
    assert_eq!((video.width, video.height), (40, 30));
    assert_eq!(video.samples, 6);
    assert_eq!(video.frames.len(), 6);
    assert!((video.fps - 12.0).abs() < 1e-2, "{}", video.fps);
    assert!(video.profile.contains("Baseline"), "{}", video.profile);
    for (i, (png, decoded)) in frames.iter().zip(&video.frames).enumerate() {
        // 4:2:0 chroma on 40×30 frames of saturated detail costs about 29–31 dB whatever
        // the trajectory shows; a frame that is not its PNG (a shifted or missing one) falls
        // far lower, and the ordering check below tells frames apart.
        let db = psnr(png, decoded);
        assert!(db > 27.0, "frame {i}: PSNR {db:.1} dB against its PNG");
    }
    // The video follows the frames: frame 0 is nearer its PNG than the last frame is.
    assert!(psnr(&frames[0], &video.frames[0]) > psnr(&frames[5], &video.frames[0]));

    // Per-frame metrics: one row per frame, windows in time order.
    let metrics = csv_rows(&run.join("frame_metrics.csv"));
    assert_eq!(metrics.len(), 6);
    let windows: Vec<f64> = metrics.iter().map(|r| r[2]).collect();
    assert_eq!(windows, [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]);

    // Every export format, holding the 6 frames, and the cut: the tiny config's 0.25 s windows
    // cut (`output.transitions` auto), so frames 0–2 are one shot and 3–5 the next.
    for format in Format::ALL {
        for name in format.file_names() {
            let file = run.join("exports").join(format.name()).join(name);
            assert!(file.is_file(), "{} missing", file.display());
        }
        let main = format.file_names()[usize::from(format == Format::Colmap)];
        let (_, path) = splatraj_camera_paths::read_camera_path(
            &run.join("exports").join(format.name()).join(main),
        )
        .unwrap();
        assert_eq!(path.cuts, vec![3], "{format}");
    }
    // Nothing half-written is left anywhere in the folder.
    for entry in walk(&run) {
        let name = entry.file_name().unwrap().to_string_lossy().into_owned();
        assert!(!name.ends_with(".partial"), "{}", entry.display());
    }

    // The exported nerfstudio path, rendered back with the run's config (plain frames, as the
    // run renders them by default): the run's frames and per-frame metrics.
    let back = dir.path().join("back");
    let camera_path = run.join("exports/nerfstudio/camera_path.json");
    let out = splatraj(&[
        "render-path",
        s(&config),
        s(&camera_path),
        "--out",
        s(&back),
        "--mask-overlay",
        "none",
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stdout(&out).trim(), s(&back));
    for (i, frame) in frames.iter().enumerate() {
        let again = png_rgb(&back.join(format!("frames/frame_{i:04}.png")));
        // The path went through a 4×4 matrix and a field of view in JSON: a pixel may land
        // one level apart where rounding tips over.
        let worst = frame
            .iter()
            .zip(&again)
            .map(|(&a, &b)| a.abs_diff(b))
            .max()
            .unwrap();
        assert!(worst <= 2, "frame {i}: a pixel differs by {worst}");
    }
    assert!(!back.join("frames/frame_0006.png").exists());
    for (a, b) in metrics
        .iter()
        .zip(&csv_rows(&back.join("frame_metrics.csv")))
    {
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() < 1e-4, "{a:?} vs {b:?}");
        }
    }
    let again = decode_mp4(&std::fs::read(back.join("video.mp4")).unwrap()).unwrap();
    assert_eq!(again.frames.len(), 6);
    assert!((again.fps - 12.0).abs() < 1e-2, "{}", again.fps);
}

/// Every file under `dir`.
fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files.extend(walk(&path));
        } else {
            files.push(path);
        }
    }
    files
}

#[test]
fn render_path_renders_a_trajectory_on_a_bare_scene_at_any_size() {
    let dir = tempfile::tempdir().unwrap();
    let (_, run) = run_with_frames(dir.path());
    // The run's demo room as a scene file.
    let scene = dir.path().join("demo.ply");
    let out = splatraj(&[
        "scene",
        "demo",
        "--out",
        s(&scene),
        "--gaussians",
        "3000",
        "--seed",
        "7",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));

    // The run folder's trajectory.json at 4 fps for 1 s, 80 pixels wide, no video.
    let plain = dir.path().join("plain");
    let out = splatraj(&[
        "render-path",
        s(&scene),
        s(&run),
        "--out",
        s(&plain),
        "--fps",
        "4",
        "--seconds",
        "1",
        "--width",
        "80",
        "--no-video",
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    for i in 0..4 {
        let png = image::open(plain.join(format!("frames/frame_{i:04}.png"))).unwrap();
        assert_eq!((png.width(), png.height()), (80, 60));
    }
    assert!(!plain.join("frames/frame_0004.png").exists());
    assert!(!plain.join("video.mp4").exists());
    // No objects without a config: no per-frame metrics.
    assert!(!plain.join("frame_metrics.csv").exists());

    // A COLMAP export renders too (its own 6 frames, at 30 fps: COLMAP has no frame rate).
    let colmap = dir.path().join("colmap");
    let out = splatraj(&[
        "render-path",
        s(&scene),
        s(&run.join("exports/colmap/images.txt")),
        "--out",
        s(&colmap),
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let video = decode_mp4(&std::fs::read(colmap.join("video.mp4")).unwrap()).unwrap();
    assert_eq!(video.frames.len(), 6);
    assert!((video.fps - 30.0).abs() < 1e-2, "{}", video.fps);

    // On one rayon thread (RAYON_NUM_THREADS=1, or one core) the render loop is the pool's
    // only thread: the frame writer once handed work to the pool and both waited for ever.
    let one_thread = dir.path().join("one_thread");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_splatraj"))
        .args([
            "render-path",
            s(&scene),
            s(&run.join("exports/colmap/images.txt")),
            "--out",
            s(&one_thread),
            "--quiet",
        ])
        .env("RAYON_NUM_THREADS", "1")
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if started.elapsed() > std::time::Duration::from_secs(120) {
            child.kill().unwrap();
            panic!("render-path on one rayon thread hung");
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    };
    assert!(status.success());
    let again = decode_mp4(&std::fs::read(one_thread.join("video.mp4")).unwrap()).unwrap();
    assert_eq!(again.frames, video.frames);
}

#[test]
fn render_path_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("demo.ply");
    let out = splatraj(&["scene", "demo", "--out", s(&scene), "--gaussians", "1000"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let path = dir.path().join("camera_path.json");
    std::fs::write(&path, "{\"frames\": []}").unwrap();
    assert_clean_failure(
        &splatraj(&["render-path", s(&scene), s(&path), "--out", s(dir.path())]),
        &["camera_path.json", "not a camera file"],
    );
    let (_, run) = run_with_frames(dir.path());
    let out_dir = dir.path().join("tinted");
    assert_clean_failure(
        &splatraj(&[
            "render-path",
            s(&scene),
            s(&run),
            "--out",
            s(&out_dir),
            "--mask-overlay",
            "tint",
        ]),
        &["--mask-overlay tint", "experiment config"],
    );
    // Nothing was written for the refused render.
    assert!(!out_dir.exists());
    // Overrides belong to a config, not a scene file.
    assert_clean_failure(
        &splatraj(&[
            "render-path",
            s(&scene),
            s(&run),
            "--out",
            s(&out_dir),
            "--set",
            "output.fps=10",
        ]),
        &["demo.ply", "--set", "experiment config"],
    );
    assert!(!out_dir.exists());
    assert_clean_failure(
        &splatraj(&[
            "render-path",
            s(&scene),
            s(&run),
            "--out",
            s(&out_dir),
            "--fps",
            "0",
        ]),
        &["--fps 0"],
    );
}

#[test]
fn a_trajectory_renders_on_another_scene_only_when_allowed_and_an_older_file_always() {
    let dir = tempfile::tempdir().unwrap();
    let (_, run) = run_with_frames(dir.path());
    // trajectory.json records the scene it was made on: the tiny config's demo room of 3000.
    let file = run.join("trajectory.json");
    let mut trajectory: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    assert_eq!(trajectory["scene"]["gaussians"], 3000);
    let other = dir.path().join("other.ply");
    let out = splatraj(&["scene", "demo", "--out", s(&other), "--gaussians", "2000"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let render = |path: &Path, out: &Path, extra: &[&str]| {
        let mut args = vec![
            "render-path",
            s(&other),
            s(path),
            "--out",
            s(out),
            "--fps",
            "4",
            "--seconds",
            "0.5",
            "--no-video",
            "--quiet",
        ];
        args.extend(extra);
        splatraj(&args)
    };
    let refused = dir.path().join("refused");
    assert_clean_failure(
        &render(&file, &refused, &[]),
        &["3000 Gaussians", "2000 Gaussians"],
    );
    assert!(!refused.exists());
    let allowed = dir.path().join("allowed");
    let out = render(&file, &allowed, &["--scene-mismatch", "allow"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("rendered anyway"), "{}", stderr(&out));
    assert!(allowed.join("frames/frame_0001.png").is_file());
    // A file written before the scene was recorded still renders on any scene.
    trajectory.as_object_mut().unwrap().remove("scene");
    let older = dir.path().join("older.json");
    std::fs::write(&older, trajectory.to_string()).unwrap();
    let out = render(&older, &dir.path().join("old"), &[]);
    assert!(out.status.success(), "{}", stderr(&out));
}
