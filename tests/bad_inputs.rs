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
fn a_camera_of_ten_million_pixels_squared_is_refused_before_binning() {
    let case = Case::new();
    let camera = case.camera(|c| {
        c["width"] = 10_000_000.into();
        c["height"] = 10_000_000.into();
    });
    case.render_fails(
        &camera,
        &[],
        &[
            "`width` × `height`",
            "10000000 × 10000000",
            "PB",
            "--max-memory",
        ],
    );
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
