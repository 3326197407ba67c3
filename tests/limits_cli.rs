//! Limits of every command: sizes from options, configs and files are refused before any
//! work when their memory or time cannot fit (naming what sizes them), inputs that are not
//! regular files are refused without reading, and a signal stops the frames at a whole frame.
//!
//! Every refusal must come within seconds (the test would otherwise hang or be killed for
//! memory), as one `error:` paragraph.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{TINY_CONFIG, assert_clean_failure, s, splatraj, stderr};
use splatraj_camera_paths::camera::{CameraPath, CameraPose, Frame, Intrinsics};
use splatraj_camera_paths::{ExportOptions, Format};

/// The tiny config in `dir`, its runs going to `dir/runs`.
fn tiny_config(dir: &Path) -> PathBuf {
    let config = dir.join("tiny.toml");
    let text = TINY_CONFIG.replace(
        "[output]\n",
        &format!("[output]\nruns_dir = \"{}\"\n", dir.join("runs").display()),
    );
    std::fs::write(&config, text).unwrap();
    config
}

/// A demo scene of 2 000 Gaussians in `dir`.
fn tiny_scene(dir: &Path) -> PathBuf {
    let scene = dir.join("tiny.ply");
    let out = splatraj(&["scene", "demo", "--out", s(&scene), "--gaussians", "2000"]);
    assert!(out.status.success(), "{}", stderr(&out));
    scene
}

/// A nerfstudio camera path of `frames` frames at `width` × `height`, looking into the demo
/// room from its middle.
fn nerfstudio_path(dir: &Path, frames: usize, (width, height): (usize, usize)) -> PathBuf {
    let path = CameraPath {
        cuts: Vec::new(),
        frames: (0..frames)
            .map(|i| Frame {
                pose: CameraPose::from_phi([0.0, 0.01 * i as f64, 0.0, 0.0, 0.0, -1.0]),
                camera: Some(Intrinsics {
                    fx: width as f64,
                    fy: width as f64,
                    cx: width as f64 / 2.0,
                    cy: height as f64 / 2.0,
                    width,
                    height,
                }),
            })
            .collect(),
        fps: Some(30.0),
        seconds: None,
    };
    let files = splatraj_camera_paths::export(&path, Format::Nerfstudio, &ExportOptions::default())
        .unwrap();
    let file = dir.join("camera_path.json");
    std::fs::write(&file, &files[0].1).unwrap();
    file
}

/// Runs splatraj with `args`, asserting it ended within `seconds`.
fn quickly(seconds: u64, args: &[&str]) -> std::process::Output {
    let started = Instant::now();
    let out = splatraj(args);
    assert!(
        started.elapsed() < Duration::from_secs(seconds),
        "{args:?} took {:?}",
        started.elapsed()
    );
    out
}

/// Refused: a non-zero exit, no panic, and the last line the error naming `mentions` (a
/// command may print what it read first).
fn assert_refused(output: &std::process::Output, mentions: &[&str]) {
    let err = stderr(output);
    assert!(!output.status.success(), "should fail: {err}");
    assert!(
        !err.contains("panicked") && !err.contains("internal error"),
        "{err}"
    );
    let last = err.trim_end().lines().last().unwrap_or_default();
    assert!(last.starts_with("error: "), "{err}");
    for m in mentions {
        assert!(last.contains(m), "{last:?} does not mention {m:?}");
    }
}

#[test]
fn a_huge_query_picture_is_refused_before_rendering_naming_width_and_memory() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let out = quickly(
        20,
        &[
            "query",
            "--scene",
            s(&scene),
            "--query",
            "red mug",
            "--width",
            "1000000",
            "--height",
            "1000000",
            "--out",
            s(&dir.path().join("q.png")),
        ],
    );
    assert_clean_failure(&out, &["--width", "memory", "TB"]);
}

#[test]
fn run_check_refuses_what_cannot_fit_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let config = tiny_config(dir.path());
    for (set, key) in [
        (
            "optimiser.iterations=1000000000000",
            "`optimiser.iterations`",
        ),
        (
            "optimiser.path_samples=1000000000",
            "`optimiser.path_samples`",
        ),
        ("output.seconds=1e12", "`output.seconds`"),
        // The view search is quadratic in the restarts: refused for its time.
        ("start.restarts=10000000", "`start.restarts`"),
    ] {
        let out = quickly(20, &["run", s(&config), "--check", "--set", set]);
        assert_clean_failure(&out, &[key]);
    }
    // A time limit bounds the optimisation: its history is sized by what can run in it.
    let out = quickly(
        60,
        &[
            "run",
            s(&config),
            "--check",
            "--set",
            "optimiser.iterations=1000000000000",
            "--set",
            "optimiser.time_limit_s=2",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
}

/// A camera whose view search fits this machine's memory (3.6 GB against 75 % of 7 GB, the
/// smallest CI machine) but not the 3 GB address space the process is given: without the
/// address-space limit in the plan the run starts and aborts on a failed allocation.
#[cfg(target_os = "linux")]
#[test]
fn run_check_refuses_work_beyond_the_address_space_limit_naming_ulimit() {
    use std::os::unix::process::CommandExt;
    let dir = tempfile::tempdir().unwrap();
    let config = tiny_config(dir.path());
    let mut command = Command::new(env!("CARGO_BIN_EXE_splatraj"));
    command.args([
        "run",
        s(&config),
        "--check",
        "--set",
        "camera.width=2000",
        "--set",
        "camera.height=1000",
    ]);
    // SAFETY: setrlimit is async-signal-safe and only changes the child's own limit.
    unsafe {
        command.pre_exec(|| {
            let limit = libc::rlimit {
                rlim_cur: 3_000_000_000,
                rlim_max: 3_000_000_000,
            };
            if libc::setrlimit(libc::RLIMIT_AS, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let out = command.output().unwrap();
    assert_clean_failure(
        &out,
        &["`camera.width`", "address-space limit", "ulimit -v"],
    );
}

#[test]
fn run_check_of_ten_million_object_or_random_restarts_answers_in_seconds_without_building_them() {
    // Building 10⁷ starts took minutes before the check answered; the check builds one and
    // weighs the rest by the time model (the memory limit is raised so that the time is
    // what is judged, whatever this machine's memory).
    let dir = tempfile::tempdir().unwrap();
    let config = tiny_config(dir.path());
    for kind in ["objects", "random"] {
        let kind = format!("start.kind=\"{kind}\"");
        let restarts = [
            "run",
            s(&config),
            "--check",
            "--set",
            "start.restarts=10000000",
            "--set",
            &kind,
            "--set",
            "max_memory_gb=1000",
        ];
        let out = quickly(20, &restarts);
        let err = stderr(&out);
        assert!(out.status.success(), "{err}");
        // 10⁷ restarts × 3 steps at ≥ 1 ms a step: a warning naming the key and the hours.
        assert!(
            err.contains("`start.restarts`")
                && err.contains("will take at least")
                && err.contains(" h"),
            "{err}"
        );
        // Under a time limit of 2 s at most 2000 steps run: most restarts would never begin,
        // yet each start is built first.
        let mut limited = restarts.to_vec();
        limited.extend(["--set", "optimiser.time_limit_s=2"]);
        let out = quickly(20, &limited);
        assert_clean_failure(
            &out,
            &["`start.restarts`", "`optimiser.time_limit_s`", "2000"],
        );
    }
    assert!(!dir.path().join("runs").exists());
}

#[test]
fn a_run_with_a_huge_iteration_count_and_a_time_limit_stops_at_the_limit_without_abort() {
    let dir = tempfile::tempdir().unwrap();
    let config = tiny_config(dir.path());
    let out = quickly(
        120,
        &[
            "run",
            s(&config),
            "--quiet",
            "--set",
            "optimiser.iterations=1000000000000",
            "--set",
            "optimiser.time_limit_s=1",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn render_repeats_bench_threads_and_study_seeds_are_refused_for_their_size() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let camera = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/cameras/demo_mug.json");
    let out = quickly(
        20,
        &[
            "render",
            "--scene",
            s(&scene),
            "--camera",
            s(&camera),
            // --repeats times the pose-gradient probe, so it counts only with --grad.
            "--grad",
            "--label",
            "red mug",
            "--repeats",
            "1000000000",
            "--out",
            s(&dir.path().join("r")),
        ],
    );
    assert_clean_failure(&out, &["--repeats", "at least"]);
    let out = quickly(
        20,
        &["bench", "render", "--threads", "100000", "--sizes", "1000"],
    );
    assert_clean_failure(&out, &["--threads", "memory"]);
    let config = tiny_config(dir.path());
    let out = quickly(
        20,
        &["study", s(&config), "--seeds", "1000000000", "--dry-run"],
    );
    assert_clean_failure(&out, &["--seeds"]);
}

#[test]
fn render_path_refuses_frames_too_large_or_too_many_from_options_or_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let path = nerfstudio_path(dir.path(), 3, (32, 24));
    let out_dir = dir.path().join("frames");
    let out = quickly(
        20,
        &[
            "render-path",
            s(&scene),
            s(&path),
            "--out",
            s(&out_dir),
            "--width",
            "60000",
        ],
    );
    assert_refused(&out, &["--width", "memory"]);
    // The size written in the file is checked like the option.
    let huge = nerfstudio_path(dir.path(), 2, (60_000, 50_000));
    let out = quickly(
        20,
        &["render-path", s(&scene), s(&huge), "--out", s(&out_dir)],
    );
    assert_refused(&out, &["the path file's", "memory"]);
    // Beyond 65 536 pixels a side no camera is made at all, whatever the memory.
    let out = quickly(
        20,
        &[
            "render-path",
            s(&scene),
            s(&path),
            "--out",
            s(&out_dir),
            "--width",
            "1000000000",
        ],
    );
    assert_refused(&out, &["--width", "65536"]);
    assert!(!out_dir.join("frames").exists(), "nothing rendered");
}

#[test]
fn inputs_that_are_not_regular_files_are_refused_without_reading() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let config = tiny_config(dir.path());
    let zero = "/dev/zero";
    for args in [
        vec!["scene", "info", zero],
        vec!["run", zero, "--check"],
        vec![
            "query",
            "--scene",
            s(&scene),
            "--labels",
            zero,
            "--query",
            "mug",
        ],
        vec![
            "render",
            "--scene",
            s(&scene),
            "--camera",
            zero,
            "--out",
            "unused",
        ],
        vec!["render-path", s(&scene), zero, "--out", "unused"],
    ] {
        let out = quickly(20, &args);
        assert_clean_failure(&out, &[zero, "not a regular file"]);
    }
    // A pipe: opening it would wait for a writer.
    let fifo = dir.path().join("fifo.ply");
    let made = Command::new("mkfifo").arg(&fifo).status();
    if made.is_ok_and(|s| s.success()) {
        let out = quickly(20, &["scene", "info", s(&fifo)]);
        assert_clean_failure(&out, &["fifo.ply", "not a regular file"]);
    }
    let _ = config;
}

/// A PLY header declaring `properties` float properties of `vertex` and no rows.
fn ply_with_properties(path: &Path, properties: usize) {
    let mut header = String::from("ply\nformat binary_little_endian 1.0\nelement vertex 1000000\n");
    for i in 0..properties {
        header += &format!("property float f_rest_{i}\n");
    }
    header += "end_header\n";
    std::fs::write(path, header).unwrap();
}

#[test]
fn a_ply_header_of_a_hundred_thousand_properties_is_refused_as_too_long_not_as_a_duplicate() {
    let dir = tempfile::tempdir().unwrap();
    let long = dir.path().join("long.ply");
    ply_with_properties(&long, 100_000);
    let out = quickly(20, &["scene", "info", s(&long)]);
    assert_clean_failure(&out, &["end_header", "longer"]);
    assert!(!stderr(&out).contains("twice"), "{}", stderr(&out));
    // Within the limit, the columns are sized by the data the file holds (none), not by the
    // header's row count: the truncation is reported, without gigabytes allocated first.
    let wide = dir.path().join("wide.ply");
    ply_with_properties(&wide, 20_000);
    let out = quickly(20, &["scene", "info", s(&wide)]);
    assert_clean_failure(&out, &["wide.ply"]);
}

#[test]
fn sigint_during_render_path_says_stopped_and_leaves_its_output_folder_as_it_was() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    let path = nerfstudio_path(dir.path(), 3000, (64, 48));
    let out_dir = dir.path().join("out");
    let child = Command::new(env!("CARGO_BIN_EXE_splatraj"))
        .args([
            "render-path",
            s(&scene),
            s(&path),
            "--out",
            s(&out_dir),
            "--quiet",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // render-path fills a staging folder beside `out` (`.out.PID.partial`, docs/outputs.md)
    // and renames it into place at the end: wait for its first frames, then interrupt.
    let frames = dir
        .path()
        .join(format!(".out.{}.partial", child.id()))
        .join("frames");
    let started = Instant::now();
    while std::fs::read_dir(&frames).map_or(0, |d| d.count()) < 3 {
        assert!(started.elapsed() < Duration::from_secs(120), "no frames");
        std::thread::sleep(Duration::from_millis(20));
    }
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let output = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "{err}");
    assert!(err.contains("stopped"), "{err}");
    // A stopped render-path leaves its output folder as it was (here: not there), and no
    // staging folder or lock behind.
    assert!(!out_dir.exists(), "no half-made output folder");
    let left: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(left.is_empty(), "nothing staged left: {left:?}");
}

#[test]
fn bench_frames_refuses_a_frame_size_that_cannot_fit_before_building_a_scene() {
    let out = quickly(
        20,
        &[
            "bench",
            "frames",
            "--no-scene",
            "--gaussians",
            "2000",
            "--sizes",
            "200000x200000",
            "--frames",
            "1",
        ],
    );
    assert_clean_failure(&out, &["--frames", "--sizes", "memory"]);
}

#[test]
fn bench_render_refuses_a_resolution_or_repeat_count_that_cannot_fit_before_any_child() {
    // 10⁶ × 10⁶ pixels: terabytes of render buffers.
    let out = quickly(
        20,
        &[
            "bench",
            "render",
            "--sizes",
            "1000",
            "--resolutions",
            "1000000",
        ],
    );
    assert_clean_failure(&out, &["--resolutions", "memory"]);
    // 10⁹ repeats of even a 16² render: at least 10⁻⁴ s each, over a day.
    let out = quickly(
        20,
        &[
            "bench",
            "render",
            "--sizes",
            "1000",
            "--resolutions",
            "16",
            "--repeats",
            "1000000000",
        ],
    );
    assert_clean_failure(&out, &["--repeats", "would take"]);
}

#[test]
fn pose_refuses_sgld_iterations_that_would_take_over_a_day() {
    let dir = tempfile::tempdir().unwrap();
    let config = tiny_config(dir.path());
    let out = quickly(
        60,
        &[
            "pose",
            s(&config),
            "--quiet",
            "--sgld",
            "2",
            "--set",
            "sgld.iterations=1000000000000",
        ],
    );
    assert_refused(&out, &["`sgld.iterations`", "would take"]);
    assert!(
        !dir.path().join("runs").exists()
            || std::fs::read_dir(dir.path().join("runs"))
                .unwrap()
                .next()
                .is_none(),
        "no run folder is made for a refused pose run"
    );
}

#[test]
fn bench_flags_that_are_not_numbers_are_refused_naming_the_flag() {
    let out = quickly(20, &["bench", "render", "--sizes", "1000", "--fov", "nan"]);
    assert_clean_failure(&out, &["--fov", "field of view"]);
    for (flag, value) in [("--fov", "nan"), ("--fps", "nan"), ("--seconds", "nan")] {
        let out = quickly(
            20,
            &[
                "bench",
                "frames",
                "--no-scene",
                "--gaussians",
                "2000",
                flag,
                value,
            ],
        );
        assert_clean_failure(&out, &[flag]);
    }
}

#[test]
fn bench_frames_refuses_a_video_that_would_take_over_a_day() {
    // 10¹² s at 30 fps: 3·10¹³ frames, at least 10⁻⁴ s each.
    let out = quickly(
        20,
        &[
            "bench",
            "frames",
            "--no-scene",
            "--gaussians",
            "2000",
            "--seconds",
            "1e12",
        ],
    );
    assert_clean_failure(&out, &["--seconds", "would take"]);
}

#[test]
fn a_worker_thread_count_that_cannot_fit_or_is_not_a_number_is_refused_naming_the_variable() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_scene(dir.path());
    for (value, mentions) in [
        (
            "100000",
            &["RAYON_NUM_THREADS", "100000 worker threads", "memory"][..],
        ),
        (
            "four",
            &["RAYON_NUM_THREADS", "\"four\"", "not a thread count"][..],
        ),
    ] {
        let started = Instant::now();
        let out = Command::new(env!("CARGO_BIN_EXE_splatraj"))
            .args(["scene", "info", s(&scene)])
            .env("RAYON_NUM_THREADS", value)
            .output()
            .unwrap();
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "{value}: took {:?}",
            started.elapsed()
        );
        assert_clean_failure(&out, mentions);
    }
}

/// The start's route checks each segment's clearance every quarter margin: a margin of 1e-12
/// asked for 10¹² checks per segment and `run --check` never ended.
#[test]
fn run_check_with_a_tiny_clearance_margin_answers() {
    let dir = tempfile::tempdir().unwrap();
    let config = tiny_config(dir.path());
    let out = quickly(
        120,
        &[
            "run",
            s(&config),
            "--check",
            "--set",
            "costs.clearance.margin=1e-12",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
}
