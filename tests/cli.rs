//! The `splatraj` binary end to end: exit codes, JSON output, files written whole.

mod common;

use common::{assert_clean_failure, fixture, splatraj, stderr};

#[test]
fn info_json_describes_a_real_scene() {
    let ply = fixture("fruit_drops_minimal.ply");
    let json = fixture("fruit_drops_minimal.json");
    let out = splatraj(&[
        "scene",
        "info",
        ply.to_str().unwrap(),
        "--labels",
        json.to_str().unwrap(),
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let info: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    assert_eq!(info["gaussians"], 4721);
    assert_eq!(info["sh_degree"], 3);
    assert_eq!(info["format"], "inria-ply");
    assert_eq!(info["labels"]["counts"]["4"]["gaussians"], 1038);
    assert_eq!(info["labels"]["counts"]["4"]["name"], "Category 4");
    assert_eq!(info["other_properties"][0], "transform");
    let up = &info["up_guess"]["up"];
    assert!(up.is_array() && up.as_array().unwrap().len() == 3);
}

#[test]
fn info_text_is_readable() {
    let out = splatraj(&[
        "scene",
        "info",
        fixture("test.compressed.ply").to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("Gaussians:       64") && text.contains("SH degree:       3"),
        "{text}"
    );
}

#[test]
fn convert_then_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let out_path = dir.path().join("converted.ply");
    let out = splatraj(&[
        "scene",
        "convert",
        fixture("test.compressed.ply").to_str().unwrap(),
        out_path.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let info = splatraj(&["scene", "info", out_path.to_str().unwrap(), "--json"]);
    let info: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    assert_eq!(info["format"], "inria-ply");
    assert_eq!(info["gaussians"], 64);
    assert_eq!(info["sh_degree"], 3);
}

#[test]
fn demo_writes_the_requested_count() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("demo.ply");
    let out = splatraj(&[
        "scene",
        "demo",
        "--out",
        path.to_str().unwrap(),
        "--gaussians",
        "50000",
        "--seed",
        "3",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let info = splatraj(&["scene", "info", path.to_str().unwrap(), "--json"]);
    let info: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    assert_eq!(info["gaussians"], 50000);
    assert_eq!(
        info["up_guess"]["up"],
        serde_json::json!([0.0, 0.0, 1.0]),
        "the demo is z-up"
    );
    let labels = info["labels"]["counts"].as_object().unwrap();
    assert!(
        labels.values().filter(|c| c["name"].is_string()).count() >= 8,
        "floor, walls, table, ≥5 objects"
    );
}

#[test]
fn garbage_input_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("garbage.ply");
    std::fs::write(&path, "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nend_header\n\x01").unwrap();
    assert_clean_failure(
        &splatraj(&["scene", "info", path.to_str().unwrap()]),
        &["garbage.ply"],
    );
}

#[test]
fn convert_failure_leaves_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.spz");
    std::fs::write(&bad, b"NGSP\x04\x00\x00\x00").unwrap();
    let out_path = dir.path().join("out.ply");
    assert_clean_failure(
        &splatraj(&[
            "scene",
            "convert",
            bad.to_str().unwrap(),
            out_path.to_str().unwrap(),
        ]),
        &["bad.spz"],
    );
    assert!(!out_path.exists());
    let missing_dir = dir.path().join("no/such/dir/out.ply");
    let good = fixture("test.compressed.ply");
    assert_clean_failure(
        &splatraj(&[
            "scene",
            "convert",
            good.to_str().unwrap(),
            missing_dir.to_str().unwrap(),
        ]),
        &["out.ply"],
    );
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        1,
        "only bad.spz remains"
    );
}

#[test]
fn demo_rejects_an_absurd_size() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("demo.ply");
    assert_clean_failure(
        &splatraj(&[
            "scene",
            "demo",
            "--out",
            path.to_str().unwrap(),
            "--gaussians",
            "10",
        ]),
        &["10"],
    );
    assert!(!path.exists());
}

/// `splatraj devices` without wgpu in the build: the CPU's threads as rayon counts them
/// (RAYON_NUM_THREADS), and why there is no GPU listing; status 0.
#[test]
fn devices_lists_the_cpu_threads_and_says_why_no_gpu() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_splatraj"))
        .args(["devices", "--json"])
        .env("RAYON_NUM_THREADS", "3")
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let listing: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    assert_eq!(listing["cpu_threads"], 3);
    if cfg!(feature = "wgpu") {
        return;
    }
    assert!(listing["wgpu"].is_null());
    let why = listing["wgpu_unavailable"].as_str().unwrap();
    assert!(why.contains("--features wgpu"), "{why}");
    let text = splatraj(&["devices"]);
    assert!(text.status.success());
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(
        text.contains("threads") && text.contains("--features wgpu"),
        "{text}"
    );
}
