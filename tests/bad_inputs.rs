//! Bad inputs through every command, one test per case: each fails with one `error:`
//! paragraph and a non-zero exit, names the file, key or option at fault, and leaves no output
//! behind (no run folder, no image, no converted file).

mod common;

use std::path::{Path, PathBuf};

use common::{TINY_CONFIG, assert_clean_failure, s, splatraj, stderr};

/// A temporary folder with the tiny config (runs go to `runs/` inside it) and a camera file.
struct Case {
    dir: tempfile::TempDir,
}

impl Case {
    fn new() -> Self {
        let case = Case {
            dir: tempfile::tempdir().unwrap(),
        };
        let text = TINY_CONFIG.replace(
            "[output]\n",
            &format!("[output]\nruns_dir = \"{}\"\n", case.runs().display()),
        );
        std::fs::write(case.config(), text).unwrap();
        case
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    fn config(&self) -> PathBuf {
        self.path("tiny.toml")
    }

    fn runs(&self) -> PathBuf {
        self.path("runs")
    }

    /// The tiny config with `extra` TOML appended (tables it opens come last).
    fn config_with(&self, extra: &str) -> PathBuf {
        let path = self.path("variant.toml");
        let text = std::fs::read_to_string(self.config()).unwrap();
        std::fs::write(&path, format!("{text}\n{extra}\n")).unwrap();
        path
    }

    /// `splatraj run CONFIG --set ARGS…` must fail naming `mentions`, with no run folder.
    fn run_fails(&self, config: &Path, extra: &[&str], mentions: &[&str]) -> String {
        let mut args = vec!["run", s(config), "--quiet"];
        args.extend(extra);
        let out = splatraj(&args);
        assert_clean_failure(&out, mentions);
        assert!(!self.runs().exists(), "a run folder was left");
        stderr(&out)
    }

    /// A demo scene file (3 000 Gaussians with labels).
    fn scene(&self) -> PathBuf {
        let path = self.path("demo.ply");
        let out = splatraj(&["scene", "demo", "--out", s(&path), "--gaussians", "3000"]);
        assert!(out.status.success(), "{}", stderr(&out));
        path
    }

    /// A camera file: the demo's mug camera with `edit` applied.
    fn camera(&self, edit: impl FnOnce(&mut serde_json::Value)) -> PathBuf {
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/cameras/demo_mug.json");
        let mut camera: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(file).unwrap()).unwrap();
        edit(&mut camera);
        let path = self.path("camera.json");
        std::fs::write(&path, camera.to_string()).unwrap();
        path
    }

    /// `splatraj render` of `camera` must fail naming `mentions`, writing nothing.
    fn render_fails(&self, camera: &Path, extra: &[&str], mentions: &[&str]) {
        let scene = self.scene();
        let out_dir = self.path("out");
        let mut args = vec![
            "render",
            "--scene",
            s(&scene),
            "--camera",
            s(camera),
            "--label",
            "red mug",
            "--out",
            s(&out_dir),
        ];
        args.extend(extra);
        assert_clean_failure(&splatraj(&args), mentions);
        assert!(!out_dir.exists(), "render left {}", out_dir.display());
    }
}

// --- Sizes that cannot fit are refused before any work, naming the key and the limit. ---

#[test]
fn a_camera_of_the_largest_side_squared_is_refused_for_its_memory_before_binning() {
    let case = Case::new();
    let camera = case.camera(|c| {
        c["width"] = 65_536.into();
        c["height"] = 65_536.into();
    });
    case.render_fails(
        &camera,
        &[],
        &["`width` × `height`", "65536 × 65536", "GB", "--max-memory"],
    );
}

#[test]
fn a_camera_file_wider_than_any_image_is_refused_naming_the_file() {
    let case = Case::new();
    let camera = case.camera(|c| c["width"] = 1_000_000_000.into());
    case.render_fails(&camera, &[], &["camera.json", "1000000000×240", "65536"]);
}

#[test]
fn a_camera_file_with_data_after_its_object_is_refused_naming_the_file() {
    let case = Case::new();
    let camera = case.camera(|_| {});
    let text = std::fs::read_to_string(&camera).unwrap();
    std::fs::write(&camera, format!("{text}\n{{\"width\": 8}}")).unwrap();
    case.render_fails(&camera, &[], &["camera.json", "trailing characters"]);
}

#[test]
fn a_hundred_million_basis_functions_are_refused() {
    let case = Case::new();
    let config = case.config_with("[trajectory]\nkind = \"rbf\"\ncentres_per_window = 100000000");
    for extra in [&[][..], &["--check"][..]] {
        case.run_fails(
            &config,
            extra,
            &["`trajectory`", "200000000 basis functions", "memory"],
        );
    }
}

#[test]
fn a_hundred_thousand_pose_restarts_are_refused() {
    let case = Case::new();
    let out = splatraj(&[
        "pose",
        s(&case.config()),
        "--quiet",
        "--restarts",
        "100000",
        "--max-memory",
        "8",
    ]);
    assert_clean_failure(&out, &["`start.restarts`", "100000", "8.0 GB"]);
    assert!(!case.runs().exists());
}

#[test]
fn an_output_width_of_a_hundred_thousand_is_refused_by_check_and_run_and_the_limit_raises() {
    let case = Case::new();
    let set = ["--set", "output.width=100000", "--set", "output.height=240"];
    let set16 = [&set[..], &["--set", "output.metric_samples=16"]].concat();
    // 16 poses × 2 renders × 2.4e7 pixels × 48 bytes ≈ 37 GB, above an 8 GB limit.
    for extra in [&[][..], &["--check"][..]] {
        let args = [&set16[..], &["--max-memory", "8"], extra].concat();
        case.run_fails(
            &case.config(),
            &args,
            &["`output.width`", "100000 × 240", "8.0 GB"],
        );
    }
    let raised = [&set16[..], &["--max-memory", "1000", "--check"]].concat();
    let config = case.config();
    let mut args = vec!["run", s(&config), "--quiet"];
    args.extend(raised);
    let out = splatraj(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!case.runs().exists(), "--check makes no folder");
}

// --- Inputs that would make the maths non-finite. ---

#[test]
fn a_camera_pose_of_1e308_is_refused_and_no_image_is_written() {
    let case = Case::new();
    let camera = case.camera(|c| c["pose"] = serde_json::json!([1e308, 0, 0, 0, 0, 0]));
    case.render_fails(
        &camera,
        &[],
        &["camera.json", "key `pose`", "rotation vector"],
    );
}

#[test]
fn a_camera_centre_beyond_f32_range_is_refused() {
    let case = Case::new();
    let camera = case.camera(|c| c["pose"] = serde_json::json!([0, 0, 0, 1e30, 0, 0]));
    case.render_fails(&camera, &[], &["camera.json", "key `pose`", "c_x"]);
}

#[test]
fn a_world_to_camera_of_three_rows_is_refused_naming_the_key() {
    let case = Case::new();
    let camera = case.camera(|c| {
        c.as_object_mut().unwrap().remove("pose");
        c["world_to_camera"] = serde_json::json!([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]);
    });
    case.render_fails(&camera, &[], &["camera.json", "`world_to_camera`", "4×4"]);
}

#[test]
fn a_start_pose_of_1e308_is_refused_naming_the_key() {
    let case = Case::new();
    let set = "start.pose=[1e308, 0, 0, 0, 0, 0]";
    case.run_fails(
        &case.config(),
        &["--set", set],
        &["`start.pose`", "rotation vector"],
    );
}

// --- Files read strictly. ---

#[test]
fn a_ply_of_a_version_other_than_1_0_is_refused_by_scene_info() {
    let case = Case::new();
    let ply = case.path("v9.ply");
    std::fs::write(
        &ply,
        "ply\nformat ascii 9.9\nelement vertex 1\nproperty float x\nend_header\n1\n",
    )
    .unwrap();
    let out = splatraj(&["scene", "info", s(&ply)]);
    assert_clean_failure(&out, &["v9.ply", "version 9.9", "only 1.0"]);
}

#[test]
fn a_ply_with_a_property_declared_twice_is_refused_and_not_converted() {
    let case = Case::new();
    let ply = case.path("twice.ply");
    std::fs::write(
        &ply,
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
         property float x\nend_header\n1 2 3\n",
    )
    .unwrap();
    let converted = case.path("converted.ply");
    let out = splatraj(&["scene", "convert", s(&ply), s(&converted)]);
    assert_clean_failure(
        &out,
        &["twice.ply", "property 'x'", "declared twice", "line 6"],
    );
    assert!(!converted.exists());
}

#[test]
fn a_scene_with_a_nan_names_the_drop_invalid_option() {
    let case = Case::new();
    let ply = case.path("nan.ply");
    let names = [
        "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
        "rot_0", "rot_1", "rot_2", "rot_3",
    ];
    let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\n".to_vec();
    for n in names {
        bytes.extend(format!("property float {n}\n").as_bytes());
    }
    bytes.extend(b"end_header\n");
    let values = [
        f32::NAN,
        0.,
        0.,
        0.1,
        0.2,
        0.3,
        0.5,
        -3.,
        -3.,
        -3.,
        1.,
        0.,
        0.,
        0.,
    ];
    for v in values {
        bytes.extend(v.to_le_bytes());
    }
    std::fs::write(&ply, bytes).unwrap();
    let out = splatraj(&["scene", "info", s(&ply)]);
    assert_clean_failure(&out, &["nan.ply", "Gaussian 0", "--drop-invalid"]);
}

#[test]
fn a_missing_file_names_the_os_error_once() {
    let case = Case::new();
    let camera = case.camera(|_| {});
    let missing = case.path("missing.ply");
    let out = splatraj(&["render", "--scene", s(&missing), "--camera", s(&camera)]);
    assert_clean_failure(&out, &["missing.ply"]);
    let err = stderr(&out);
    assert_eq!(err.matches("os error 2").count(), 1, "{err}");
}

// --- Config errors name their key; enums list the accepted values. ---

fn config_error(extra: &str, mentions: &[&str]) {
    let case = Case::new();
    let config = case.config_with(extra);
    let err = case.run_fails(&config, &[], mentions);
    assert!(err.contains("variant.toml"), "names the file: {err}");
}

#[test]
fn a_string_for_an_integer_names_the_key() {
    config_error(
        "[start]\nrestarts = \"ten\"",
        &["`start.restarts`", "\"ten\"", "expected usize"],
    );
}

#[test]
fn an_unknown_trajectory_kind_lists_the_kinds() {
    config_error(
        "[trajectory]\nkind = \"spline\"",
        &["`trajectory`", "spline", "rbf", "waypoint", "polynomial"],
    );
}

#[test]
fn an_unknown_backend_lists_the_backends() {
    let case = Case::new();
    let text = std::fs::read_to_string(case.config()).unwrap();
    let config = case.path("variant.toml");
    std::fs::write(&config, format!("backend = \"cuda\"\n{text}")).unwrap();
    case.run_fails(
        &config,
        &[],
        &["variant.toml", "`backend`", "cuda", "flex", "wgpu"],
    );
}

#[test]
fn an_unknown_upright_mode_lists_the_modes() {
    config_error(
        "[costs.upright]\nweight = 1.0\nmode = \"sideways\"",
        &["`costs.upright.mode`", "sideways", "up-vector", "roll"],
    );
}

#[test]
fn a_start_pose_of_five_values_names_the_key_and_the_length() {
    config_error(
        "[start]\npose = [0, 0, 0, 1, 2]",
        &["`start.pose`", "length 5", "6"],
    );
}

// --- `--set` errors name the option, not the file. ---

fn set_error(assignment: &str, mentions: &[&str]) {
    let case = Case::new();
    let err = case.run_fails(&case.config(), &["--set", assignment], mentions);
    assert!(err.contains(&format!("--set {assignment}")), "{err}");
    assert!(!err.contains("tiny.toml"), "blames the file: {err}");
}

#[test]
fn set_with_an_empty_value_names_the_option() {
    set_error("optimiser.iterations=", &["no value"]);
}

#[test]
fn set_with_an_unclosed_list_names_the_option() {
    set_error("start.pose=[1,2", &["not a valid TOML value"]);
}

#[test]
fn set_with_a_float_for_an_integer_names_the_option_and_key() {
    set_error(
        "optimiser.iterations=1e3",
        &["`optimiser.iterations`", "expected usize"],
    );
}

#[test]
fn set_with_an_unknown_enum_value_names_the_option_and_lists_the_values() {
    set_error("trajectory.kind=\"spline\"", &["rbf", "waypoint"]);
}

// --- The table: one bad input per row, over every command. ---

/// What every row of [`TABLE`] shares: a demo scene and a finished tiny run (made once).
struct Fixture {
    dir: tempfile::TempDir,
}

impl Fixture {
    fn new() -> Self {
        let fixture = Fixture {
            dir: tempfile::tempdir().unwrap(),
        };
        let scene = fixture.scene();
        let out = splatraj(&["scene", "demo", "--out", s(&scene), "--gaussians", "3000"]);
        assert!(out.status.success(), "{}", stderr(&out));
        let config = fixture.dir.path().join("tiny.toml");
        std::fs::write(
            &config,
            fixture.config_text(&fixture.dir.path().join("runs")),
        )
        .unwrap();
        let out = splatraj(&["run", s(&config), "--quiet"]);
        assert!(out.status.success(), "{}", stderr(&out));
        fixture
    }

    /// The demo scene (3 000 Gaussians with labels).
    fn scene(&self) -> PathBuf {
        self.dir.path().join("demo.ply")
    }

    /// The tiny config with its runs going to `runs`.
    fn config_text(&self, runs: &Path) -> String {
        TINY_CONFIG.replace(
            "[output]\n",
            &format!("[output]\nruns_dir = \"{}\"\n", runs.display()),
        )
    }

    /// The finished run's folder.
    fn run(&self) -> PathBuf {
        let tiny = self.dir.path().join("runs/tiny");
        std::fs::read_dir(tiny)
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path()
    }

    /// The run's `trajectory.json` as JSON.
    fn trajectory(&self) -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(self.run().join("trajectory.json")).unwrap())
            .unwrap()
    }
}

/// Writes `value` as JSON to `dir/name` and returns the path as an argument.
fn json_file(dir: &Path, name: &str, value: &serde_json::Value) -> String {
    let path = dir.join(name);
    std::fs::write(&path, value.to_string()).unwrap();
    path.display().to_string()
}

/// A run's `trajectory.json` with `edit` applied, in `dir`.
fn trajectory_with(f: &Fixture, dir: &Path, edit: impl FnOnce(&mut serde_json::Value)) -> String {
    let mut t = f.trajectory();
    edit(&mut t);
    json_file(dir, "traj.json", &t)
}

/// The tiny config (runs into `dir/runs`) with `--set`-style `extra` TOML appended.
fn config_in(f: &Fixture, dir: &Path, extra: &str) -> String {
    let path = dir.join("run.toml");
    std::fs::write(
        &path,
        format!("{}\n{extra}\n", f.config_text(&dir.join("runs"))),
    )
    .unwrap();
    path.display().to_string()
}

/// `COMMAND CONFIG EXTRA…` with the tiny config in `dir` (runs into `dir/runs`).
fn config_command(f: &Fixture, dir: &Path, command: &str, extra: &[&str]) -> Vec<String> {
    let config = config_in(f, dir, "");
    let mut args = strings(&[command, &config]);
    args.extend(strings(extra));
    args
}

/// `run CONFIG --check --set SETTING` with the tiny config in `dir`.
fn run_check_setting(f: &Fixture, dir: &Path, setting: &str) -> Vec<String> {
    config_command(f, dir, "run", &["--check", "--set", setting])
}

/// A `.npy` of `values` f32 whose header claims `shape`.
fn npy_claiming(dir: &Path, shape: &str, values: usize) -> String {
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend((header.len() as u16).to_le_bytes());
    bytes.extend(header.as_bytes());
    bytes.extend(std::iter::repeat_n(0u8, 4 * values));
    let path = dir.join("mask.npy");
    std::fs::write(&path, bytes).unwrap();
    path.display().to_string()
}

/// An INRIA PLY header with no vertices.
fn empty_scene(dir: &Path) -> String {
    let mut text = "ply\nformat binary_little_endian 1.0\nelement vertex 0\n".to_string();
    for n in [
        "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
        "rot_0", "rot_1", "rot_2", "rot_3",
    ] {
        text += &format!("property float {n}\n");
    }
    text += "end_header\n";
    let path = dir.join("empty.ply");
    std::fs::write(&path, text).unwrap();
    path.display().to_string()
}

/// The run's export in `format` (`exports/<format>/<name>`) with `edit` applied, in `dir`.
fn export_with(
    f: &Fixture,
    dir: &Path,
    format: &str,
    name: &str,
    edit: impl FnOnce(&mut serde_json::Value),
) -> String {
    let file = f.run().join("exports").join(format).join(name);
    let mut value: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(file).unwrap()).unwrap();
    edit(&mut value);
    json_file(dir, name, &value)
}

/// `render-path` of the fixture's scene along `path`, into `dir/out`.
fn render_path_of(f: &Fixture, dir: &Path, path: &str) -> Vec<String> {
    let out = dir.join("out").display().to_string();
    strings(&["render-path", s(&f.scene()), path, "--out", &out, "--quiet"])
}

/// A copy of the run folder in `dir/run` with only `files` of it, and `report` of it.
fn report_of_copy(f: &Fixture, dir: &Path, files: &[&str]) -> (PathBuf, Vec<String>) {
    let run = dir.join("run");
    std::fs::create_dir(&run).unwrap();
    for name in files {
        std::fs::copy(f.run().join(name), run.join(name)).unwrap();
    }
    let args = strings(&["report", s(&run), "--scene", s(&f.scene())]);
    (run, args)
}

/// One row: what it proves (its name), the command line it builds in its own folder (inputs
/// made there first), and what the one-paragraph error must name. Every row must exit
/// non-zero without a panic and leave its folder exactly as it was (no output, no run folder,
/// no temporary).
struct Row {
    proves: &'static str,
    args: fn(&Fixture, &Path) -> Vec<String>,
    mentions: &'static [&'static str],
}

/// `render` of the fixture's scene from the demo mug camera with `mask` (a `.npy` path).
fn render_with_mask(f: &Fixture, d: &Path, mask: &str) -> Vec<String> {
    let camera = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/cameras/demo_mug.json");
    let out = d.join("out").display().to_string();
    strings(&[
        "render",
        "--scene",
        s(&f.scene()),
        "--camera",
        s(&camera),
        "--mask",
        mask,
        "--out",
        &out,
    ])
}

fn strings(args: &[&str]) -> Vec<String> {
    args.iter().map(|a| a.to_string()).collect()
}

const TABLE: &[Row] = &[
    Row {
        proves: "run_check_refuses_a_learning_rate_above_one_radian_per_step",
        args: |f, d| run_check_setting(f, d, "optimiser.learning_rate=1e30"),
        mentions: &["`optimiser.learning_rate`", "(0, 1]"],
    },
    Row {
        proves: "run_check_refuses_a_learning_rate_of_zero_that_never_moves",
        args: |f, d| run_check_setting(f, d, "optimiser.learning_rate=0"),
        mentions: &["`optimiser.learning_rate`", "(0, 1]"],
    },
    Row {
        proves: "run_whose_weighted_costs_overflow_names_the_weight_not_the_learning_rate",
        args: |f, d| config_command(f, d, "run", &["--quiet", "--set", "costs.tce.weight=1e308"]),
        mentions: &["`costs.tce.weight`", "step 0"],
    },
    Row {
        proves: "a_config_nested_too_deep_is_refused_by_place_without_quoting_its_line",
        args: |_, d| {
            let path = d.join("deep.toml");
            let depth = 100_000;
            let text = format!("a = {}{}\n", "[".repeat(depth), "]".repeat(depth));
            std::fs::write(&path, text).unwrap();
            strings(&["run", &path.display().to_string(), "--check"])
        },
        mentions: &["deep.toml", "not valid TOML at line 1, column"],
    },
    Row {
        proves: "run_check_refuses_a_field_of_view_near_180_degrees_by_its_working_distance",
        args: |f, d| run_check_setting(f, d, "camera.fov_x=179.9999"),
        mentions: &[
            "`queries.0`",
            "working distance",
            "`camera.fov_x` (now 179.9999°)",
        ],
    },
    Row {
        proves: "run_check_refuses_a_target_ratio_near_zero_by_its_working_distance",
        args: |f, d| run_check_setting(f, d, "camera.target_ratio=1e-300"),
        mentions: &[
            "`queries.0`",
            "working distance",
            "target ratio (now 1e-300)",
        ],
    },
    Row {
        proves: "run_check_refuses_a_frame_rate_the_video_cannot_hold_in_few_digits",
        args: |f, d| run_check_setting(f, d, "output.fps=1e-300"),
        mentions: &["`output.fps` = 1e-300", "between 0.01 and 1000"],
    },
    Row {
        proves: "run_check_refuses_a_clearance_margin_wider_than_the_scene",
        args: |f, d| run_check_setting(f, d, "costs.clearance.margin=1e300"),
        mentions: &["`costs.clearance.margin` = 1e300", "diagonal"],
    },
    Row {
        proves: "pose_refuses_zero_iterations_naming_the_key",
        args: |f, d| {
            config_command(
                f,
                d,
                "pose",
                &["--quiet", "--set", "pose.optimiser.iterations=0"],
            )
        },
        mentions: &["`pose.optimiser.iterations`", "at least 1"],
    },
    Row {
        proves: "pose_names_a_nan_max_memory_by_its_flag",
        args: |f, d| config_command(f, d, "pose", &["--quiet", "--max-memory", "NaN"]),
        mentions: &["--max-memory", "NaN"],
    },
    Row {
        proves: "render_names_a_zero_target_ratio_by_its_flag",
        args: |f, d| {
            let camera =
                Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/cameras/demo_mug.json");
            let out = d.join("out").display().to_string();
            strings(&[
                "render",
                "--scene",
                s(&f.scene()),
                "--camera",
                s(&camera),
                "--label",
                "1",
                "--grad",
                "--target-ratio",
                "0",
                "--out",
                &out,
            ])
        },
        mentions: &["--target-ratio", "(0, 1]"],
    },
    Row {
        proves: "run_check_refuses_a_runs_dir_that_is_a_file",
        args: |f, d| {
            std::fs::write(d.join("taken"), "a file").unwrap();
            let c = config_in(f, d, "");
            let set = format!("output.runs_dir=\"{}\"", d.join("taken").display());
            strings(&["run", &c, "--check", "--set", &set])
        },
        mentions: &["`output.runs_dir`", "not a folder"],
    },
    Row {
        proves: "run_refuses_an_fps_the_video_cannot_hold_before_making_a_folder",
        args: |f, d| config_command(f, d, "run", &["--quiet", "--set", "output.fps=1e9"]),
        mentions: &["`output.fps`", "1000"],
    },
    Row {
        proves: "run_check_refuses_a_start_trajectory_with_a_weight_of_1e300",
        args: |f, d| {
            let t = trajectory_with(f, d, |t| t["weights"][0][3] = 1e300.into());
            let c = config_in(f, d, &format!("[start]\ntrajectory = \"{t}\""));
            strings(&["run", &c, "--check"])
        },
        mentions: &["`start.trajectory`", "row 0", "1e300"],
    },
    Row {
        proves: "render_path_refuses_a_trajectory_missing_a_weight_row",
        args: |f, d| {
            let t = trajectory_with(f, d, |t| {
                t["weights"].as_array_mut().unwrap().pop();
            });
            let out = d.join("out").display().to_string();
            strings(&["render-path", s(&f.scene()), &t, "--out", &out, "--quiet"])
        },
        mentions: &["traj.json", "expected 8 rows", "got 7"],
    },
    Row {
        proves: "export_refuses_a_trajectory_missing_a_weight_row_as_render_path_does",
        args: |f, d| {
            let t = trajectory_with(f, d, |t| {
                t["weights"].as_array_mut().unwrap().pop();
            });
            let out = d.join("out").display().to_string();
            strings(&["export", &t, "--format", "nerfstudio", "--out", &out])
        },
        mentions: &["traj.json", "expected 8 rows", "got 7"],
    },
    Row {
        proves: "render_path_refuses_a_trajectory_whose_fx_is_0",
        args: |f, d| {
            let t = trajectory_with(f, d, |t| t["output_intrinsics"]["fx"] = 0.into());
            let out = d.join("out").display().to_string();
            strings(&["render-path", s(&f.scene()), &t, "--out", &out, "--quiet"])
        },
        mentions: &["traj.json", "`output_intrinsics`", "fx = 0"],
    },
    Row {
        proves: "render_path_refuses_weights_of_1e300_as_export_does",
        args: |f, d| {
            let t = trajectory_with(f, d, |t| t["weights"][2][1] = (-1e300).into());
            let out = d.join("out").display().to_string();
            strings(&["render-path", s(&f.scene()), &t, "--out", &out, "--quiet"])
        },
        mentions: &["traj.json", "row 2, component 1", "-1e300"],
    },
    Row {
        proves: "render_path_refuses_a_nerfstudio_camera_beyond_1e15",
        args: |f, d| {
            let file = f.run().join("exports/nerfstudio/camera_path.json");
            let mut path: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(file).unwrap()).unwrap();
            path["camera_path"][1]["camera_to_world"][7] = 1e20.into();
            let p = json_file(d, "camera_path.json", &path);
            let out = d.join("out").display().to_string();
            strings(&["render-path", s(&f.scene()), &p, "--out", &out, "--quiet"])
        },
        mentions: &["camera_path.json", "frame 1", "1e20"],
    },
    Row {
        proves: "render_path_refuses_an_fps_the_video_cannot_hold_naming_the_flag",
        args: |f, d| {
            let out = d.join("out").display().to_string();
            let run = f.run().display().to_string();
            strings(&[
                "render-path",
                s(&f.scene()),
                &run,
                "--out",
                &out,
                "--fps",
                "1e9",
            ])
        },
        mentions: &["--fps", "1000"],
    },
    Row {
        proves: "render_path_refuses_a_config_whose_queries_are_not_the_trajectorys_windows",
        args: |f, d| {
            let c = config_in(f, d, "[[queries]]\ntext = \"plant\"");
            let out = d.join("out").display().to_string();
            let run = f.run().display().to_string();
            strings(&["render-path", &c, &run, "--out", &out, "--quiet"])
        },
        mentions: &["2 query windows", "3 queries"],
    },
    Row {
        proves: "render_path_refuses_to_replace_a_folder_holding_other_files",
        args: |f, d| {
            std::fs::create_dir(d.join("out")).unwrap();
            std::fs::write(d.join("out/notes.txt"), "mine").unwrap();
            let out = d.join("out").display().to_string();
            let run = f.run().display().to_string();
            strings(&["render-path", s(&f.scene()), &run, "--out", &out, "--quiet"])
        },
        mentions: &["notes.txt", "does not write"],
    },
    Row {
        proves: "render_refuses_a_scene_without_gaussians_naming_the_file",
        args: |_, d| {
            let scene = empty_scene(d);
            let camera =
                Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/cameras/demo_mug.json");
            let out = d.join("out").display().to_string();
            strings(&[
                "render",
                "--scene",
                &scene,
                "--camera",
                s(&camera),
                "--out",
                &out,
            ])
        },
        mentions: &["empty.ply", "no Gaussians"],
    },
    Row {
        proves: "render_path_refuses_a_scene_without_gaussians_naming_the_file",
        args: |f, d| {
            let scene = empty_scene(d);
            let out = d.join("out").display().to_string();
            let run = f.run().display().to_string();
            strings(&["render-path", &scene, &run, "--out", &out, "--quiet"])
        },
        mentions: &["empty.ply", "no Gaussians"],
    },
    Row {
        proves: "render_refuses_a_mask_npy_whose_shape_claims_more_than_it_holds",
        args: |f, d| render_with_mask(f, d, &npy_claiming(d, "(3000,)", 100)),
        mentions: &["mask.npy", "shape [3000]", "needs 12000 bytes", "holds 400"],
    },
    Row {
        // query's picture is one file written atomically: never through a FIFO (or device).
        proves: "query_refuses_to_write_its_picture_through_a_fifo_naming_it",
        args: |f, d| {
            let out = d.join("out");
            std::fs::create_dir(&out).unwrap();
            let fifo = out.join("query.png");
            let made = std::process::Command::new("mkfifo").arg(&fifo).status();
            assert!(made.is_ok_and(|s| s.success()), "mkfifo");
            let out = out.display().to_string();
            strings(&[
                "query",
                "--scene",
                s(&f.scene()),
                "--query",
                "red mug",
                "--out",
                &out,
            ])
        },
        mentions: &["query.png", "special file"],
    },
    Row {
        // npyz multiplies the shape unchecked: 2^65 elements panicked in a debug build.
        proves: "render_refuses_a_mask_npy_whose_shape_product_overflows_without_panicking",
        args: |f, d| render_with_mask(f, d, &npy_claiming(d, "(4294967296, 4294967296, 2)", 1)),
        mentions: &[
            "mask.npy",
            "[4294967296, 4294967296, 2]",
            "more elements than 2^64",
        ],
    },
    Row {
        proves: "report_refuses_a_metrics_json_of_the_wrong_shape",
        args: |f, d| {
            let run = d.join("run");
            std::fs::create_dir(&run).unwrap();
            for name in ["config.toml", "trajectory.json"] {
                std::fs::copy(f.run().join(name), run.join(name)).unwrap();
            }
            std::fs::write(run.join("metrics.json"), r#"{"windows": 5}"#).unwrap();
            strings(&["report", s(&run), "--scene", s(&f.scene())])
        },
        mentions: &["metrics.json", "`windows`"],
    },
    Row {
        proves: "report_refuses_a_scene_other_than_the_runs",
        args: |f, d| {
            let run = d.join("run");
            std::fs::create_dir(&run).unwrap();
            for name in ["config.toml", "trajectory.json", "metrics.json"] {
                std::fs::copy(f.run().join(name), run.join(name)).unwrap();
            }
            let other = d.join("other.ply");
            let out = splatraj(&["scene", "demo", "--out", s(&other), "--gaussians", "2000"]);
            assert!(out.status.success(), "{}", stderr(&out));
            strings(&["report", s(&run), "--scene", s(&other)])
        },
        mentions: &["2000 Gaussians", "3000", "`run.gaussians`", "--scene"],
    },
    Row {
        proves: "query_names_a_bad_top_fraction_by_its_flag_spelt_with_dashes",
        args: |f, d| {
            let out = d.join("out").display().to_string();
            strings(&[
                "query",
                "--scene",
                s(&f.scene()),
                "--query",
                "red mug",
                "--top-fraction",
                "2",
                "--out",
                &out,
            ])
        },
        mentions: &["--top-fraction", "(0, 1]"],
    },
    Row {
        proves: "bench_frames_names_a_nan_target_ratio_by_its_flag",
        args: |_, _| {
            strings(&[
                "bench",
                "frames",
                "--target-ratio",
                "NaN",
                "--gaussians",
                "3000",
                "--frames",
                "2",
            ])
        },
        mentions: &["--target-ratio", "NaN"],
    },
    Row {
        proves: "render_path_refuses_a_nerfstudio_path_of_1e15_seconds_like_seconds_flag",
        args: |f, d| {
            let p = export_with(f, d, "nerfstudio", "camera_path.json", |p| {
                p["seconds"] = 1e15.into();
            });
            render_path_of(f, d, &p)
        },
        mentions: &[
            "camera_path.json",
            "`seconds`",
            "1000000000000000 s",
            "memory",
        ],
    },
    Row {
        proves: "render_path_refuses_an_fps_flag_the_video_cannot_hold_before_rendering",
        args: |f, d| {
            let t = trajectory_with(f, d, |_| {});
            let out = d.join("out").display().to_string();
            strings(&[
                "render-path",
                s(&f.scene()),
                &t,
                "--fps",
                "1e-7",
                "--out",
                &out,
                "--quiet",
            ])
        },
        mentions: &["--fps 1e-7", "between 0.01 and 1000"],
    },
    Row {
        proves: "render_path_refuses_a_nerfstudio_fps_the_video_cannot_hold",
        args: |f, d| {
            let p = export_with(f, d, "nerfstudio", "camera_path.json", |p| {
                p["fps"] = 1e-7.into();
            });
            render_path_of(f, d, &p)
        },
        mentions: &["camera_path.json", "`fps`", "1e-7", "between 0.01 and 1000"],
    },
    Row {
        proves: "render_path_refuses_a_nerfstudio_length_of_0_seconds",
        args: |f, d| {
            let p = export_with(f, d, "nerfstudio", "camera_path.json", |p| {
                p["seconds"] = 0.into();
            });
            render_path_of(f, d, &p)
        },
        mentions: &["camera_path.json", "seconds", "finite and > 0"],
    },
    Row {
        proves: "render_path_refuses_a_nerfstudio_camera_of_aspect_0_naming_it",
        args: |f, d| {
            let p = export_with(f, d, "nerfstudio", "camera_path.json", |p| {
                p["camera_path"][2]["aspect"] = 0.into();
            });
            render_path_of(f, d, &p)
        },
        mentions: &[
            "camera_path.json",
            "camera_path[2].aspect",
            "finite and > 0",
        ],
    },
    Row {
        proves: "render_path_refuses_a_supersplat_keyframe_at_1e12_frames",
        args: |f, d| {
            let p = export_with(f, d, "supersplat", "settings.json", |p| {
                let times = p["animTracks"][0]["keyframes"]["times"]
                    .as_array_mut()
                    .unwrap();
                *times.last_mut().unwrap() = 1e12.into();
            });
            render_path_of(f, d, &p)
        },
        mentions: &[
            "settings.json",
            "keyframes.times[",
            "1000000000000",
            "below",
        ],
    },
    Row {
        proves: "render_path_refuses_a_supersplat_keyframe_before_0",
        args: |f, d| {
            let p = export_with(f, d, "supersplat", "settings.json", |p| {
                p["animTracks"][0]["keyframes"]["times"][0] = (-1).into();
            });
            render_path_of(f, d, &p)
        },
        mentions: &["settings.json", "keyframes.times[0]", "-1", "from 0"],
    },
    Row {
        proves: "render_path_refuses_a_config_of_another_scene_than_the_trajectorys_naming_both",
        args: |f, d| {
            let c = config_in(f, d, "");
            let out = d.join("out").display().to_string();
            let traj = f.run().join("trajectory.json").display().to_string();
            strings(&[
                "render-path",
                &c,
                &traj,
                "--out",
                &out,
                "--quiet",
                "--set",
                "scene.demo.gaussians=2000",
            ])
        },
        mentions: &[
            "trajectory.json",
            "of 3000 Gaussians",
            "of 2000 Gaussians",
            "--scene-mismatch allow",
        ],
    },
    Row {
        proves: "render_path_refuses_a_scene_file_other_than_the_trajectorys_naming_both",
        args: |f, d| {
            let other = d.join("other.ply");
            let out = splatraj(&["scene", "demo", "--out", s(&other), "--gaussians", "2000"]);
            assert!(out.status.success(), "{}", stderr(&out));
            let out = d.join("out").display().to_string();
            let run = f.run().display().to_string();
            strings(&["render-path", s(&other), &run, "--out", &out, "--quiet"])
        },
        mentions: &[
            "trajectory.json",
            "3000 Gaussians",
            "other.ply",
            "2000 Gaussians",
        ],
    },
    Row {
        proves: "report_refuses_a_run_folder_without_metrics_json",
        args: |f, d| report_of_copy(f, d, &["config.toml", "trajectory.json"]).1,
        mentions: &["metrics.json", "missing"],
    },
    Row {
        proves: "report_refuses_a_run_folder_without_trajectory_json",
        args: |f, d| report_of_copy(f, d, &["config.toml", "metrics.json"]).1,
        mentions: &["trajectory.json", "missing"],
    },
    Row {
        proves: "report_refuses_a_garbage_history_csv_naming_the_line",
        args: |f, d| {
            let (run, args) =
                report_of_copy(f, d, &["config.toml", "trajectory.json", "metrics.json"]);
            std::fs::write(run.join("history.csv"), "\0\u{1}\u{2}not,a,csv\n1,2\n").unwrap();
            args
        },
        mentions: &["history.csv", "line 2", "2 fields", "header has 3"],
    },
    Row {
        proves: "report_refuses_a_history_csv_without_its_total_column",
        args: |f, d| {
            let (run, args) =
                report_of_copy(f, d, &["config.toml", "trajectory.json", "metrics.json"]);
            std::fs::write(run.join("history.csv"), "step,q0_tce\n0,1.5\n").unwrap();
            args
        },
        mentions: &["history.csv", "line 1", "no `total` column"],
    },
    Row {
        proves: "lift_masks_refuses_a_mask_of_another_size_than_its_camera_naming_both_sizes",
        args: |f, d| {
            let masks = d.join("m");
            std::fs::create_dir(&masks).unwrap();
            // The run's frames are 40×30; 7×5 is no rescale of them (aspect 1.4, not 1.333).
            image::GrayImage::from_pixel(7, 5, image::Luma([1]))
                .save(masks.join("frame_0000.png"))
                .unwrap();
            let cameras = f.run().join("exports/inria/cameras.json");
            let out = d.join("lifted.json").display().to_string();
            let masks = masks.display().to_string();
            strings(&[
                "scene",
                "lift-masks",
                "--scene",
                s(&f.scene()),
                "--cameras",
                s(&cameras),
                "--masks",
                &masks,
                "--out",
                &out,
            ])
        },
        mentions: &["frame_0000.png", "size 7×5", "40×30"],
    },
];

/// Every file and folder under `dir` (relative paths, sorted).
fn tree(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path.clone());
            }
            out.push(path.strip_prefix(dir).unwrap().to_path_buf());
        }
    }
    out.sort();
    out
}

#[test]
fn every_row_of_the_bad_input_table_fails_cleanly_naming_its_fault_and_writes_nothing() {
    let fixture = Fixture::new();
    let mut failures = Vec::new();
    for row in TABLE {
        let dir = fixture.dir.path().join(row.proves);
        std::fs::create_dir(&dir).unwrap();
        let args = (row.args)(&fixture, &dir);
        let before = tree(&dir);
        let out = splatraj(&args.iter().map(String::as_str).collect::<Vec<_>>());
        let checked = std::panic::catch_unwind(|| {
            // Progress lines may come first (a run prints its plan); the error is the last
            // line, the only one starting `error:`.
            let err = stderr(&out);
            assert!(!out.status.success(), "should fail: {err}");
            assert!(!err.contains("panicked"), "{err}");
            let last = err.trim_end().lines().last().unwrap_or_default();
            assert!(last.starts_with("error: "), "{err}");
            assert_eq!(err.matches("error:").count(), 1, "one error: {err}");
            for m in row.mentions {
                assert!(last.contains(m), "{last:?} does not mention {m:?}");
            }
            assert!(
                !err.contains("--top_fraction"),
                "flags are spelt with dashes: {err}"
            );
            assert_eq!(tree(&dir), before, "the folder changed: {err}");
        });
        if let Err(e) = checked {
            let message = e
                .downcast_ref::<String>()
                .cloned()
                .unwrap_or_else(|| "(no message)".into());
            failures.push(format!("{}: {message}", row.proves));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

// --- What a re-run and an object never in view give. ---

#[test]
fn render_path_into_its_own_earlier_folder_replaces_it_whole() {
    let fixture = Fixture::new();
    let out = fixture.dir.path().join("frames_out");
    let run = fixture.run();
    let render = |seconds: &str| {
        let o = splatraj(&[
            "render-path",
            s(&fixture.scene()),
            s(&run),
            "--out",
            s(&out),
            "--quiet",
            "--fps",
            "10",
            "--seconds",
            seconds,
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        std::fs::read_dir(out.join("frames")).unwrap().count()
    };
    assert_eq!(render("0.5"), 5);
    assert_eq!(
        render("0.2"),
        2,
        "the first render's frames went with its folder"
    );
    let names: Vec<String> = std::fs::read_dir(fixture.dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(
        names.is_empty(),
        "no staging folder or lock left: {names:?}"
    );
}

#[test]
fn an_object_never_in_view_has_an_undefined_tce_not_zero() {
    let case = Case::new();
    let out = splatraj(&[
        "pose",
        s(&case.config()),
        "--quiet",
        // Far above the scene, looking up (+z): the mug is never in the frame.
        "--set",
        "start.pose=[0, 0, 0, 0, 0, 50]",
        "--set",
        "pose.optimiser.iterations=1",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("TCE undefined"), "{}", stderr(&out));
    let folder = common::stdout(&out);
    let metrics: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(Path::new(folder.trim()).join("metrics.json")).unwrap(),
    )
    .unwrap();
    let m = &metrics["metrics"];
    assert_eq!(m["visible_fraction"], 0.0, "{m}");
    assert!(m["tce"].is_null() && m["tce_max"].is_null(), "{m}");
}
