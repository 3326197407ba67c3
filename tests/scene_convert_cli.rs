//! `splatraj scene convert` to the written formats: the format follows the output's name (or
//! `--format`), a name it cannot write is refused before anything is read, what it writes
//! `scene info` reads back, and `--sh-degree` writes another SH degree.

mod common;

use common::{assert_clean_failure, fixture, s, splatraj, stderr, stdout};

#[path = "../crates/splatraj-scene/tests/common/shared_data.rs"]
mod shared_data;
use shared_data::shared_data;

#[test]
fn biker_compressed_ply_to_spz_and_back_through_info() {
    let Some(input) = shared_data("biker.compressed.ply") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let spz = dir.path().join("out.spz");
    let out = splatraj(&["scene", "convert", s(&input), s(&spz)]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("(spz)"), "{}", stderr(&out));
    // A gzip stream (SPZ version 3), not a PLY as before.
    assert_eq!(std::fs::read(&spz).unwrap()[..2], [0x1f, 0x8b]);

    let info = splatraj(&["scene", "info", s(&spz), "--json"]);
    assert!(info.status.success(), "{}", stderr(&info));
    let json: serde_json::Value = serde_json::from_str(&stdout(&info)).unwrap();
    assert_eq!(json["format"], "spz");
    assert_eq!(json["gaussians"], 152_746);
    assert_eq!(json["sh_degree"], 0);

    let compressed = dir.path().join("again.compressed.ply");
    let out = splatraj(&["scene", "convert", s(&spz), s(&compressed)]);
    assert!(out.status.success(), "{}", stderr(&out));
    let info = splatraj(&["scene", "info", s(&compressed), "--json"]);
    let json: serde_json::Value = serde_json::from_str(&stdout(&info)).unwrap();
    assert_eq!(json["format"], "compressed-ply");
    assert_eq!(json["gaussians"], 152_746);
}

#[test]
fn names_it_cannot_write_are_refused() {
    let input = fixture("fruit_drops_minimal.ply");
    let dir = tempfile::tempdir().unwrap();
    for (name, mentions) in [
        (
            "out.xyz",
            &["out.xyz", "'.xyz'", ".spz", ".compressed.ply"][..],
        ),
        ("out.sog", &["out.sog", "does not write"][..]),
        ("out", &["without an extension"][..]),
    ] {
        let target = dir.path().join(name);
        let out = splatraj(&["scene", "convert", s(&input), s(&target)]);
        assert_clean_failure(&out, mentions);
        assert!(!target.exists());
    }
    // --format names the format of any file, but not one whose name says another.
    let target = dir.path().join("out.ply");
    let out = splatraj(&["scene", "convert", s(&input), s(&target), "--format", "spz"]);
    assert_clean_failure(&out, &["out.ply", "inria-ply", "spz"]);
    let out = splatraj(&["scene", "convert", s(&input), s(&target), "--format", "sog"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("does not write"), "{}", stderr(&out));
    let target = dir.path().join("out.bin");
    let out = splatraj(&["scene", "convert", s(&input), s(&target), "--format", "spz"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let info = splatraj(&["scene", "info", s(&target), "--json"]);
    assert!(stdout(&info).contains("\"spz\""), "{}", stdout(&info));
}

#[test]
fn a_folder_in_the_way_is_not_replaced() {
    let input = fixture("fruit_drops_minimal.ply");
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("out.compressed.ply");
    std::fs::create_dir(&target).unwrap();
    let out = splatraj(&["scene", "convert", s(&input), s(&target)]);
    assert_clean_failure(&out, &["out.compressed.ply", "a folder"]);
    assert!(target.is_dir());
}

#[test]
fn sh_degree_lowers_and_raises_what_is_written() {
    // Degree 3 in, as real captures hold.
    let input = fixture("fruit_drops_minimal.ply");
    let dir = tempfile::tempdir().unwrap();
    let degree_of = |path: &std::path::Path| -> serde_json::Value {
        let info = splatraj(&["scene", "info", s(path), "--json"]);
        assert!(info.status.success(), "{}", stderr(&info));
        let json: serde_json::Value = serde_json::from_str(&stdout(&info)).unwrap();
        assert_eq!(json["gaussians"], 4721);
        json["sh_degree"].clone()
    };
    let convert = |from: &std::path::Path, name: &str, degree: &str| {
        let target = dir.path().join(name);
        let args = [
            "scene",
            "convert",
            s(from),
            s(&target),
            "--sh-degree",
            degree,
        ];
        (splatraj(&args), target)
    };
    assert_eq!(degree_of(&input), 3);
    for (degree, name) in [
        ("0", "zero.ply"),
        ("1", "one.spz"),
        ("3", "three.compressed.ply"),
    ] {
        let (out, target) = convert(&input, name, degree);
        assert!(out.status.success(), "{}", stderr(&out));
        let said = stderr(&out);
        assert!(said.contains(&format!("SH degree {degree}")), "{said}");
        assert_eq!(degree_of(&target).to_string(), degree);
    }
    // From degree 0 back up to 2: zeros above the colour, written and read back.
    let (out, raised) = convert(&dir.path().join("zero.ply"), "raised.ply", "2");
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(degree_of(&raised), 2);
    // clap refuses 4 before anything is read.
    let (out, target) = convert(&input, "four.ply", "4");
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("--sh-degree") && stderr(&out).contains("0..=3"));
    assert!(!target.exists());
}
