//! One test per kind of bad input: each must be an error (never a panic) whose message names
//! the file, the element or property, and what is wrong.

mod common;

use std::path::{Path, PathBuf};

use common::{fixture, payload_offset};
use splatraj_scene::formats::{ReadOptions, read_label_sidecar};
use splatraj_scene::{InvalidPolicy, SceneError, read_scene};

const FRUIT_STRIDE: usize = 63 * 4;

/// fruit_drops with `edit` applied to its bytes, written to a temporary file.
fn edited_fruit(dir: &Path, edit: impl FnOnce(&mut Vec<u8>, usize)) -> PathBuf {
    let mut bytes = std::fs::read(fixture("fruit_drops_minimal.ply")).unwrap();
    let start = payload_offset(&bytes);
    edit(&mut bytes, start);
    let path = dir.join("edited.ply");
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Sets float `property` (index in the 63-float layout) of Gaussian `i`.
fn set_float(bytes: &mut [u8], start: usize, i: usize, property: usize, value: f32) {
    let at = start + i * FRUIT_STRIDE + 4 * property;
    bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
}

fn error_of(path: &Path, options: &ReadOptions) -> String {
    match read_scene(path, options) {
        Ok(_) => panic!("{} was accepted", path.display()),
        Err(e) => e.to_string(),
    }
}

fn assert_mentions(message: &str, parts: &[&str]) {
    for part in parts {
        assert!(
            message.contains(part),
            "message {message:?} does not mention {part:?}"
        );
    }
}

#[test]
fn truncated_payload() {
    let dir = tempfile::tempdir().unwrap();
    let path = edited_fruit(dir.path(), |b, start| {
        b.truncate(start + 100 * FRUIT_STRIDE + 17)
    });
    let message = error_of(&path, &ReadOptions::default());
    assert_mentions(
        &message,
        &["edited.ply", "truncated", "'vertex'", "4721", "row 100"],
    );
}

#[test]
fn truncated_header() {
    let dir = tempfile::tempdir().unwrap();
    let path = edited_fruit(dir.path(), |b, _| b.truncate(200));
    assert_mentions(
        &error_of(&path, &ReadOptions::default()),
        &["edited.ply", "header"],
    );
}

#[test]
fn malformed_header_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = edited_fruit(dir.path(), |b, _| {
        let text = b"property float x\n";
        let at = b.windows(text.len()).position(|w| w == text).unwrap();
        b[at..at + 8].copy_from_slice(b"propurty");
    });
    assert_mentions(
        &error_of(&path, &ReadOptions::default()),
        &["edited.ply", "header"],
    );
}

#[test]
fn missing_required_property() {
    let dir = tempfile::tempdir().unwrap();
    let path = edited_fruit(dir.path(), |b, _| {
        let text = b"property float opacity\n";
        let at = b.windows(text.len()).position(|w| w == text).unwrap();
        b[at..at + text.len()].copy_from_slice(b"property float opacitx\n");
    });
    assert_mentions(
        &error_of(&path, &ReadOptions::default()),
        &["edited.ply", "'vertex'", "'opacity'"],
    );
}

#[test]
fn unknown_format() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.splat");
    std::fs::write(&path, b"\x00\x01\x02 definitely not a splat").unwrap();
    assert_mentions(
        &error_of(&path, &ReadOptions::default()),
        &["scene.splat", "unknown scene format"],
    );
}

#[test]
fn empty_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.ply");
    std::fs::write(&path, b"").unwrap();
    assert_mentions(
        &error_of(&path, &ReadOptions::default()),
        &["empty.ply", "unknown scene format"],
    );
}

#[test]
fn missing_file() {
    let message = error_of(Path::new("/nonexistent/scene.ply"), &ReadOptions::default());
    assert_mentions(&message, &["/nonexistent/scene.ply"]);
}

#[test]
fn nan_position() {
    let dir = tempfile::tempdir().unwrap();
    let path = edited_fruit(dir.path(), |b, start| set_float(b, start, 42, 1, f32::NAN));
    assert_mentions(
        &error_of(&path, &ReadOptions::default()),
        &["edited.ply", "Gaussian 42", "x/y/z", "not finite"],
    );
}

#[test]
fn infinite_sh_coefficient() {
    let dir = tempfile::tempdir().unwrap();
    // f_rest_16 (green, coefficient 2) of Gaussian 7.
    let path = edited_fruit(dir.path(), |b, start| {
        set_float(b, start, 7, 9 + 16, f32::INFINITY)
    });
    assert_mentions(
        &error_of(&path, &ReadOptions::default()),
        &["Gaussian 7", "f_rest_16", "not finite"],
    );
}

#[test]
fn zero_quaternion() {
    let dir = tempfile::tempdir().unwrap();
    let path = edited_fruit(dir.path(), |b, start| {
        (58..62).for_each(|k| set_float(b, start, 3, k, 0.0))
    });
    assert_mentions(
        &error_of(&path, &ReadOptions::default()),
        &["Gaussian 3", "rot_0..3", "zero norm"],
    );
}

#[test]
fn scale_that_activates_to_zero() {
    let dir = tempfile::tempdir().unwrap();
    // exp(-200) underflows to 0 in f32: a Gaussian with no extent.
    let path = edited_fruit(dir.path(), |b, start| set_float(b, start, 9, 56, -200.0));
    assert_mentions(
        &error_of(&path, &ReadOptions::default()),
        &["Gaussian 9", "scale_1", "after activation"],
    );
}

#[test]
fn lenient_option_drops_and_counts() {
    let dir = tempfile::tempdir().unwrap();
    let path = edited_fruit(dir.path(), |b, start| {
        set_float(b, start, 5, 0, f32::NAN);
        set_float(b, start, 6, 56, -200.0);
        (58..62).for_each(|k| set_float(b, start, 7, k, 0.0));
    });
    let options = ReadOptions {
        invalid: InvalidPolicy::Drop,
        ..Default::default()
    };
    let loaded = read_scene(&path, &options).unwrap();
    assert_eq!(loaded.dropped, 3);
    assert_eq!(loaded.scene.len(), 4721 - 3);
    let original = read_scene(&fixture("fruit_drops_minimal.ply"), &ReadOptions::default())
        .unwrap()
        .scene;
    // Gaussian 8 of the file is now at index 5.
    assert_eq!(loaded.scene.means[5], original.means[8]);
    assert_eq!(loaded.scene.extras.properties[0].values.len(), 4721 - 3);
}

#[test]
fn label_sidecar_of_wrong_length() {
    let message = match read_label_sidecar(&fixture("fruit_drops_minimal.json"), 4000) {
        Ok(_) => panic!("accepted"),
        Err(e) => e.to_string(),
    };
    assert_mentions(
        &message,
        &["fruit_drops_minimal.json", "4721 labels", "4000 Gaussians"],
    );
}

#[test]
fn label_sidecar_not_json_or_wrong_shape() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("labels.json");
    std::fs::write(&path, "{\"dataset\": {}}").unwrap();
    let message = read_label_sidecar(&path, 10).unwrap_err().to_string();
    assert_mentions(&message, &["labels.json", "point_annotations"]);
    std::fs::write(&path, "[1, 2, 3.5]").unwrap();
    let message = read_label_sidecar(&path, 3).unwrap_err().to_string();
    assert_mentions(&message, &["labels.json", "[2]", "3.5", "whole number"]);
    std::fs::write(&path, "[1, 2").unwrap();
    assert_mentions(
        &read_label_sidecar(&path, 2).unwrap_err().to_string(),
        &["not valid JSON"],
    );
}

#[test]
fn compressed_with_too_few_chunks() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = std::fs::read(fixture("test.compressed.ply")).unwrap();
    let text = b"element chunk 1\n";
    let at = bytes.windows(text.len()).position(|w| w == text).unwrap();
    bytes[at + text.len() - 2] = b'0';
    let path = dir.path().join("bad.compressed.ply");
    std::fs::write(&path, bytes).unwrap();
    let message = error_of(&path, &ReadOptions::default());
    assert!(matches!(
        read_scene(&path, &ReadOptions::default()),
        Err(SceneError::Malformed { .. })
    ));
    assert_mentions(
        &message,
        &[
            "bad.compressed.ply",
            "64 Gaussians need 1 chunks of 256, the file has 0",
        ],
    );
}

#[test]
fn point_cloud_ply_is_not_a_splat() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cloud.ply");
    std::fs::write(
        &path,
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n0 0 0 255 0 0\n",
    )
    .unwrap();
    assert_mentions(
        &error_of(&path, &ReadOptions::default()),
        &["cloud.ply", "point cloud"],
    );
}

/// fruit_drops with its header text edited by `edit` (the payload kept as is).
fn edited_header(dir: &Path, edit: impl FnOnce(&str) -> String) -> PathBuf {
    edited_fruit(dir, |b, start| {
        let header = String::from_utf8(b[..start].to_vec()).unwrap();
        let mut out = edit(&header).into_bytes();
        out.extend_from_slice(&b[start..]);
        *b = out;
    })
}

/// A minimal ASCII Gaussian PLY with `rows` as its data lines and `count` declared.
fn ascii_scene(dir: &Path, count: usize, rows: &[&str]) -> PathBuf {
    let path = dir.join("ascii.ply");
    let mut text = format!("ply\nformat ascii 1.0\nelement vertex {count}\n");
    for p in [
        "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
        "rot_0", "rot_1", "rot_2", "rot_3",
    ] {
        text.push_str(&format!("property float {p}\n"));
    }
    text.push_str("end_header\n");
    for row in rows {
        text.push_str(row);
        text.push('\n');
    }
    std::fs::write(&path, text).unwrap();
    path
}

const ROW: &str = "0 0 0 0.1 0.2 0.3 0.5 -3 -3 -3 1 0 0 0";

#[test]
fn a_property_declared_twice_is_refused_naming_it_and_its_lines() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["x", "opacity"] {
        // The second declaration replaces an unused property, so the row size is unchanged and
        // a lenient reader would read shifted columns.
        let path = edited_header(dir.path(), |h| {
            h.replacen(
                "property float f_rest_44\n",
                &format!("property float {name}\n"),
                1,
            )
        });
        let options = ReadOptions {
            invalid: InvalidPolicy::Drop,
            ..ReadOptions::default()
        };
        assert_mentions(
            &error_of(&path, &options),
            &[
                "edited.ply",
                &format!("property '{name}'"),
                "'vertex'",
                "declared twice",
                "line",
            ],
        );
    }
}

#[test]
fn binary_data_longer_than_the_header_count_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = edited_header(dir.path(), |h| {
        h.replacen("element vertex 4721\n", "element vertex 4719\n", 1)
    });
    assert_mentions(
        &error_of(&path, &ReadOptions::default()),
        &["edited.ply", "2 more rows", "'vertex'", "4719"],
    );
}

#[test]
fn binary_trailing_bytes_that_are_not_rows_are_only_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let path = edited_fruit(dir.path(), |b, _| b.extend_from_slice(b"junk"));
    assert_eq!(
        read_scene(&path, &ReadOptions::default())
            .unwrap()
            .scene
            .len(),
        4721
    );
}

#[test]
fn ascii_rows_beyond_the_header_count_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = ascii_scene(dir.path(), 1, &[ROW, ROW]);
    assert_mentions(
        &error_of(&path, &ReadOptions::default()),
        &["ascii.ply", "1 more rows", "'vertex'"],
    );
    // The same rows with the right count read.
    let path = ascii_scene(dir.path(), 2, &[ROW, ROW]);
    assert_eq!(
        read_scene(&path, &ReadOptions::default())
            .unwrap()
            .scene
            .len(),
        2
    );
}

#[test]
fn an_ascii_row_with_an_extra_value_is_refused_naming_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let extra = format!("{ROW} 7");
    let path = ascii_scene(dir.path(), 2, &[ROW, &extra]);
    // 3 header lines, 14 properties, end_header: the second row is line 20.
    assert_mentions(
        &error_of(&path, &ReadOptions::default()),
        &[
            "ascii.ply",
            "line 20",
            "'vertex'",
            "row 1",
            "15 values",
            "14",
        ],
    );
}
