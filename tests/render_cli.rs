//! `splatraj render` and `splatraj bench render` end to end: outputs and their sizes, the
//! `--grad` JSON, the camera and mask forms, and clean failures that write nothing.

mod common;

use common::{assert_clean_failure, s, splatraj, stderr};

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use glam::DVec3;
use serde_json::{Value, json};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_scene::demo::{DEMO_UP, DEMO_VIEWPOINT, demo_layout};

/// A 20 000-Gaussian demo scene in a fresh temporary folder.
fn demo(dir: &Path) -> PathBuf {
    let ply = dir.join("demo.ply");
    let out = splatraj(&["scene", "demo", "--gaussians", "20000", "--out", s(&ply)]);
    assert!(out.status.success(), "{}", stderr(&out));
    ply
}

/// A camera 0.3 m from the red mug, looking at it from the demo's standing viewpoint.
fn mug_pose() -> Pose {
    let mug = demo_layout()
        .into_iter()
        .find(|o| o.name == "red mug")
        .unwrap();
    let target = DVec3::from_array(mug.center.map(f64::from));
    let viewpoint = DVec3::from_array(DEMO_VIEWPOINT.map(f64::from));
    let eye = target + (viewpoint - target).normalize() * 0.3;
    Pose::look_at(eye, target, DVec3::from_array(DEMO_UP.map(f64::from))).unwrap()
}

fn intrinsics() -> Intrinsics {
    Intrinsics::from_fov_x(60.0, 96, 72).unwrap()
}

fn camera_json(k: &Intrinsics, pose: &Pose) -> Value {
    json!({
        "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy,
        "width": k.width, "height": k.height,
        "pose": pose.0,
    })
}

fn write_json(path: &Path, value: &Value) -> PathBuf {
    std::fs::write(path, serde_json::to_string_pretty(value).unwrap()).unwrap();
    path.to_path_buf()
}

/// mask.npy as (shape, values).
fn read_npy(path: &Path) -> (Vec<u64>, Vec<f32>) {
    let npy = npyz::NpyFile::new(BufReader::new(File::open(path).unwrap())).unwrap();
    let shape = npy.shape().to_vec();
    (shape, npy.into_vec::<f32>().unwrap())
}

fn files_in(dir: &Path) -> Vec<String> {
    match std::fs::read_dir(dir) {
        Ok(entries) => entries
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect(),
        Err(_) => Vec::new(),
    }
}

#[test]
fn renders_rgb_and_mask_of_a_label() {
    let dir = tempfile::tempdir().unwrap();
    let ply = demo(dir.path());
    let camera = write_json(
        &dir.path().join("cam.json"),
        &camera_json(&intrinsics(), &mug_pose()),
    );
    let out_dir = dir.path().join("out");
    let out = splatraj(&[
        "render",
        "--scene",
        s(&ply),
        "--camera",
        s(&camera),
        "--label",
        "Red Mug",
        "--out",
        s(&out_dir),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(out.stdout.is_empty(), "no JSON without --grad");

    let rgb = image::open(out_dir.join("rgb.png")).unwrap();
    assert_eq!((rgb.width(), rgb.height()), (96, 72));
    assert_eq!(rgb.color(), image::ColorType::Rgb8);
    let mask_png = image::open(out_dir.join("mask.png")).unwrap();
    assert_eq!((mask_png.width(), mask_png.height()), (96, 72));
    let (shape, mask) = read_npy(&out_dir.join("mask.npy"));
    assert_eq!(shape, vec![72, 96]);
    assert!(mask.iter().all(|v| (0.0..=1.0).contains(v)));
    let coverage = mask.iter().map(|&v| f64::from(v)).sum::<f64>() / mask.len() as f64;
    assert!(
        (0.03..0.6).contains(&coverage),
        "the mug is in view: {coverage}"
    );
    // No temporary files are left beside the outputs.
    let mut files = files_in(&out_dir);
    files.sort();
    assert_eq!(files, ["mask.npy", "mask.png", "rgb.png"]);

    // --width/--height rescale the intrinsics: the same view, smaller.
    let small = dir.path().join("small");
    let out = splatraj(&[
        "render",
        "--scene",
        s(&ply),
        "--camera",
        s(&camera),
        "--label",
        "3",
        "--width",
        "48",
        "--height",
        "36",
        "--out",
        s(&small),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let (shape, small_mask) = read_npy(&small.join("mask.npy"));
    assert_eq!(shape, vec![36, 48]);
    let small_coverage =
        small_mask.iter().map(|&v| f64::from(v)).sum::<f64>() / small_mask.len() as f64;
    assert!(
        (small_coverage - coverage).abs() < 0.05,
        "{small_coverage} vs {coverage}"
    );
}

#[test]
fn world_to_camera_and_npy_mask_match_pose_and_label() {
    let dir = tempfile::tempdir().unwrap();
    let ply = demo(dir.path());
    let k = intrinsics();
    let pose = mug_pose();
    let by_pose = write_json(&dir.path().join("pose.json"), &camera_json(&k, &pose));
    let m = pose.world_to_camera();
    let rows: Vec<Vec<f64>> = (0..4).map(|r| m.row(r).to_array().to_vec()).collect();
    let by_matrix = write_json(
        &dir.path().join("matrix.json"),
        &json!({
            "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy,
            "width": k.width, "height": k.height,
            "world_to_camera": rows,
        }),
    );
    // The red mug's mask as uint8 .npy, from the scene's labels.
    let scene = splatraj_scene::read_scene(&ply, &Default::default())
        .unwrap()
        .scene;
    let ids = &scene.extras.labels.as_ref().unwrap().ids;
    let mask: Vec<u8> = ids.iter().map(|&id| u8::from(id == 3)).collect();
    let mask_path = dir.path().join("mug.npy");
    npyz::to_file_1d(&mask_path, mask).unwrap();

    let a = dir.path().join("a");
    let b = dir.path().join("b");
    let out = splatraj(&[
        "render",
        "--scene",
        s(&ply),
        "--camera",
        s(&by_pose),
        "--label",
        "red mug",
        "--out",
        s(&a),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = splatraj(&[
        "render",
        "--scene",
        s(&ply),
        "--camera",
        s(&by_matrix),
        "--mask",
        s(&mask_path),
        "--out",
        s(&b),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let (_, ma) = read_npy(&a.join("mask.npy"));
    let (_, mb) = read_npy(&b.join("mask.npy"));
    let diff = ma
        .iter()
        .zip(&mb)
        .fold(0.0f32, |d, (x, y)| d.max((x - y).abs()));
    assert!(diff < 1e-3, "max difference {diff}");
}

#[test]
fn a_render_into_an_earlier_render_replaces_it_whole_and_other_folders_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let ply = demo(dir.path());
    let camera = write_json(
        &dir.path().join("cam.json"),
        &camera_json(&intrinsics(), &mug_pose()),
    );
    let out_dir = dir.path().join("out");
    let render = |out: &Path, object: &[&str]| {
        let mut args = vec!["render", "--scene", s(&ply), "--camera", s(&camera)];
        args.extend_from_slice(object);
        args.extend(["--out", s(out)]);
        splatraj(&args)
    };
    let first = render(&out_dir, &["--label", "red mug"]);
    assert!(first.status.success(), "{}", stderr(&first));
    // Without an object the new render has no mask: the old mask must not stay beside it.
    let second = render(&out_dir, &[]);
    assert!(second.status.success(), "{}", stderr(&second));
    assert_eq!(files_in(&out_dir), ["rgb.png"]);
    let mut beside = files_in(dir.path());
    beside.sort();
    assert_eq!(
        beside,
        ["cam.json", "demo.ply", "out"],
        "no staging or lock left"
    );

    // A folder holding the user's other files is refused and left as it was; so is `.`,
    // which cannot be replaced whole.
    let (mine, notes) = (dir.path().join("mine"), dir.path().join("mine/notes.txt"));
    std::fs::create_dir(&mine).unwrap();
    std::fs::write(&notes, "mine").unwrap();
    assert_clean_failure(&render(&mine, &[]), &["notes.txt", "does not write"]);
    assert_eq!(files_in(&mine), ["notes.txt"]);
    assert_clean_failure(&render(Path::new("."), &[]), &["no name of its own"]);
}

#[test]
fn grad_prints_costs_gradient_and_timings() {
    let dir = tempfile::tempdir().unwrap();
    let ply = demo(dir.path());
    let camera = write_json(
        &dir.path().join("cam.json"),
        &camera_json(&intrinsics(), &mug_pose()),
    );
    let out = splatraj(&[
        "render",
        "--scene",
        s(&ply),
        "--camera",
        s(&camera),
        "--label",
        "red mug",
        "--grad",
        "--repeats",
        "2",
        "--target-ratio",
        "0.2",
        "--dtype",
        "f64",
        "--out",
        s(&dir.path().join("out")),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let number = |key: &str| {
        let v = report[key]
            .as_f64()
            .unwrap_or_else(|| panic!("{key} in {report}"));
        assert!(v.is_finite(), "{key} = {v}");
        v
    };
    let (tce, tre, loss) = (number("tce"), number("tre"), number("loss"));
    assert!((loss - (tce + tre)).abs() < 1e-12);
    assert!(
        (0.0..0.5).contains(&tce),
        "the mug is near the centre: {tce}"
    );
    assert!(
        (tre - (number("coverage") - 0.2).abs()).abs() < 1e-9,
        "{report}"
    );
    assert!(number("forward_ms") > 0.0 && number("forward_backward_ms") > 0.0);
    let grad: Vec<f64> = report["grad_pose"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(grad.len(), 6);
    assert!(grad.iter().all(|g| g.is_finite()));
    assert!(grad.iter().any(|g| g.abs() > 1e-4), "{grad:?}");
}

#[test]
fn grad_of_an_object_out_of_view_has_no_tce_and_a_zero_gradient() {
    let dir = tempfile::tempdir().unwrap();
    let ply = demo(dir.path());
    // At the mug, looking away from it (toward the standing viewpoint's opposite side).
    let pose = mug_pose();
    let away = Pose::look_at(
        pose.centre(),
        pose.centre() * 2.0 - DVec3::new(0.32, -0.22, 0.80),
        DVec3::Z,
    )
    .unwrap();
    let camera = write_json(
        &dir.path().join("cam.json"),
        &camera_json(&intrinsics(), &away),
    );
    let out = splatraj(&[
        "render",
        "--scene",
        s(&ply),
        "--camera",
        s(&camera),
        "--label",
        "red mug",
        "--grad",
        "--out",
        s(&dir.path().join("out")),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["coverage"].as_f64(), Some(0.0), "{report}");
    // An object covering none of the frame has no centre, so no framing error: TCE is
    // undefined (null), as in frame_metrics.csv, not the 0 of a perfectly centred object.
    assert!(report["tce"].is_null(), "{report}");
    assert!(
        (report["loss"].as_f64().unwrap() - report["tre"].as_f64().unwrap()).abs() < 1e-12,
        "the loss is TRE alone: {report}"
    );
    assert!((report["tre"].as_f64().unwrap() - 0.15).abs() < 1e-6);
    for g in report["grad_pose"].as_array().unwrap() {
        assert_eq!(g.as_f64(), Some(0.0), "{report}");
    }
}

#[test]
fn bad_inputs_fail_cleanly_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let ply = demo(dir.path());
    let good = camera_json(&intrinsics(), &mug_pose());
    let camera = write_json(&dir.path().join("cam.json"), &good);
    let mut extra = good.clone();
    extra["fov"] = json!(60);
    let unknown_key = write_json(&dir.path().join("unknown.json"), &extra);
    let mut both = good.clone();
    both["world_to_camera"] = json!([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]);
    let both = write_json(&dir.path().join("both.json"), &both);
    let mut neither = good.clone();
    neither.as_object_mut().unwrap().remove("pose");
    let neither = write_json(&dir.path().join("neither.json"), &neither);
    let short_mask = dir.path().join("short.npy");
    npyz::to_file_1d(&short_mask, vec![1u8, 0, 1]).unwrap();

    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (
            vec!["--camera", s(&unknown_key), "--label", "red mug"],
            vec!["unknown.json", "`fov`"],
        ),
        (vec!["--camera", s(&both)], vec!["both.json", "not both"]),
        (
            vec!["--camera", s(&neither)],
            vec!["neither.json", "`pose`", "`world_to_camera`"],
        ),
        (
            vec!["--camera", s(&camera), "--mask", s(&short_mask)],
            vec!["short.npy", "3 values", "20000 Gaussians"],
        ),
        (
            vec!["--camera", s(&camera), "--label", "teapot"],
            vec!["teapot", "red mug", "glass of water"],
        ),
        (
            vec!["--camera", s(&camera), "--grad"],
            vec!["--grad", "--label"],
        ),
    ];
    for (i, (args, mentions)) in cases.iter().enumerate() {
        let out_dir = dir.path().join(format!("out{i}"));
        let mut all = vec!["render", "--scene", s(&ply), "--out", s(&out_dir)];
        all.extend(args.iter().copied());
        let out = splatraj(&all);
        assert_clean_failure(&out, mentions);
        assert!(files_in(&out_dir).is_empty(), "case {i} wrote files");
    }
}

#[test]
fn uncompiled_backend_names_its_feature() {
    if cfg!(feature = "wgpu") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let camera = write_json(
        &dir.path().join("cam.json"),
        &camera_json(&intrinsics(), &mug_pose()),
    );
    let out = splatraj(&[
        "render",
        "--scene",
        "missing.ply",
        "--camera",
        s(&camera),
        "--backend",
        "wgpu",
    ]);
    assert_clean_failure(&out, &["wgpu", "--features wgpu"]);
}

#[test]
fn example_camera_frames_the_mug() {
    let dir = tempfile::tempdir().unwrap();
    let ply = demo(dir.path());
    let camera = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/cameras/demo_mug.json");
    let out = splatraj(&[
        "render",
        "--scene",
        s(&ply),
        "--camera",
        s(&camera),
        "--label",
        "red mug",
        "--width",
        "80",
        "--grad",
        "--out",
        s(&dir.path().join("out")),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    let coverage = report["coverage"].as_f64().unwrap();
    assert!((0.08..0.25).contains(&coverage), "{report}");
    assert!(report["tce"].as_f64().unwrap() < 0.15, "{report}");
    assert_eq!(report["height"].as_u64(), Some(60), "aspect ratio kept");
}

#[test]
fn bench_render_tiny_configuration() {
    let out = splatraj(&[
        "bench",
        "render",
        "--sizes",
        "10000",
        "--resolutions",
        "64",
        "--repeats",
        "1",
        "--threads",
        "1",
        "--rasterizer",
        "tensor",
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    let rows = report["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "pruned and unpruned");
    for row in rows {
        assert_eq!(row["gaussians"], 10000);
        assert_eq!(row["rayon_threads"], 1);
        for key in [
            "coverage",
            "forward_ms",
            "forward_backward_ms",
            "tce",
            "tre",
        ] {
            let v = row[key].as_f64().unwrap_or_else(|| panic!("{key}: {row}"));
            assert!(v.is_finite() && v >= 0.0, "{key}: {row}");
        }
        assert!(row["coverage"].as_f64().unwrap() > 0.05, "{row}");
        if cfg!(target_os = "linux") {
            assert!(row["peak_mb"].as_f64().unwrap() > 1.0, "{row}");
        }
    }
    assert_eq!(rows[0]["pruning"], "object");
    assert_eq!(rows[1]["pruning"], "none");
    // Pruning is exact: same costs either way.
    assert!((rows[0]["tce"].as_f64().unwrap() - rows[1]["tce"].as_f64().unwrap()).abs() < 1e-5);
}

#[test]
fn label_sidecar_of_a_real_scene() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/splatraj-scene/tests/data");
    let ply = data.join("fruit_drops_minimal.ply");
    let sidecar = data.join("fruit_drops_minimal.json");
    let dir = tempfile::tempdir().unwrap();
    // Above the fruit (the scene's up is −z), looking at the centre of its robust bounds.
    let centre = DVec3::new(0.75, 0.11, -2.12);
    let pose = Pose::look_at(centre + DVec3::new(0.0, -0.25, -0.35), centre, DVec3::NEG_Z).unwrap();
    let camera = write_json(
        &dir.path().join("cam.json"),
        &camera_json(&Intrinsics::from_fov_x(60.0, 64, 48).unwrap(), &pose),
    );
    let out_dir = dir.path().join("out");
    let out = splatraj(&[
        "render",
        "--scene",
        s(&ply),
        "--labels",
        s(&sidecar),
        "--camera",
        s(&camera),
        "--label",
        "category 4",
        "--grad",
        "--out",
        s(&out_dir),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(report["coverage"].as_f64().unwrap() > 0.0, "{report}");
    let (shape, _) = read_npy(&out_dir.join("mask.npy"));
    assert_eq!(shape, vec![48, 64]);

    // Without the sidecar the scene has no labels: the error says so and suggests --mask.
    let out = splatraj(&[
        "render",
        "--scene",
        s(&ply),
        "--camera",
        s(&camera),
        "--label",
        "category 4",
        "--out",
        s(&dir.path().join("none")),
    ]);
    assert_clean_failure(&out, &["fruit_drops_minimal.ply", "no labels", "--mask"]);
    assert!(files_in(&dir.path().join("none")).is_empty());
}

#[test]
fn bench_step_counts_one_render_call_shared_and_one_per_window() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("tiny.toml");
    std::fs::write(&config, common::TINY_CONFIG).unwrap();
    let out = splatraj(&[
        "bench",
        "step",
        "--config",
        s(&config),
        "--steps",
        "2",
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let rows: Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    let rows = rows.as_array().unwrap();
    let renders = |passes: &str| {
        let row = rows.iter().find(|r| r["passes"] == passes).expect(passes);
        assert_eq!(row["steps"], 2);
        assert_eq!(row["counts"]["reads"], 1, "one read a step: {row}");
        assert!(row["ms_per_step"].as_f64().unwrap() > 0.0);
        assert!(row["best_total"].as_f64().unwrap().is_finite());
        row["counts"]["renders"].as_u64().unwrap()
    };
    // The tiny config has two windows.
    assert_eq!(renders("per-window"), 2);
    assert_eq!(renders("shared"), 1);
}
