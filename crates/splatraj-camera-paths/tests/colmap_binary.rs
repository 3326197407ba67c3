//! COLMAP's binary model read as the text model is: a record that does not fit the file, or a
//! camera model COLMAP does not have, is an error naming the file and the record; a count that
//! claims more records than the bytes hold is refused before anything is reserved. (Poses read
//! from `images.bin` against a closed form: `splatraj-experiment`'s `tests/scene_up.rs`.)

use splatraj_camera_paths::colmap::read_named;
use splatraj_camera_paths::colmap_binary::{cameras_text, images_text};

/// One image record: id 7, the identity pose, camera 1, `a b.png`, no points.
fn one_image() -> Vec<u8> {
    let mut bytes = 1u64.to_le_bytes().to_vec();
    bytes.extend(7u32.to_le_bytes());
    for v in [1.0f64, 0.0, 0.0, 0.0, 0.5, -1.0, 2.0] {
        bytes.extend(v.to_le_bytes());
    }
    bytes.extend(1u32.to_le_bytes());
    bytes.extend(b"a b.png\0");
    bytes.extend(0u64.to_le_bytes());
    bytes
}

#[test]
fn records_become_the_text_models_lines() {
    let text = images_text(&one_image(), "images.bin").unwrap();
    assert_eq!(text, "7 1 0 0 0 0.5 -1 2 1 a b.png\n\n");
    let mut camera = 1u64.to_le_bytes().to_vec();
    camera.extend(3u32.to_le_bytes());
    camera.extend(1i32.to_le_bytes()); // PINHOLE
    camera.extend(640u64.to_le_bytes());
    camera.extend(480u64.to_le_bytes());
    for v in [500.0f64, 510.0, 320.0, 240.0] {
        camera.extend(v.to_le_bytes());
    }
    assert_eq!(
        cameras_text(&camera, "cameras.bin").unwrap(),
        "3 PINHOLE 640 480 500 510 320 240\n"
    );
}

#[test]
fn images_bin_is_read_with_cameras_bin_beside_it() {
    // A folder of this process's own (the crate has no temporary-folder dependency).
    let dir = std::env::temp_dir().join(format!("splatraj-colmap-bin-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("images.bin"), one_image()).unwrap();
    let mut camera = 1u64.to_le_bytes().to_vec();
    camera.extend(1u32.to_le_bytes());
    camera.extend(0i32.to_le_bytes()); // SIMPLE_PINHOLE
    camera.extend(64u64.to_le_bytes());
    camera.extend(48u64.to_le_bytes());
    for v in [50.0f64, 32.0, 24.0] {
        camera.extend(v.to_le_bytes());
    }
    std::fs::write(dir.join("cameras.bin"), camera).unwrap();
    let read = read_named(&dir.join("images.bin"));
    std::fs::remove_dir_all(&dir).unwrap();
    let (path, names) = read.unwrap();
    assert_eq!(names, ["a b.png"]);
    let frame = &path.frames[0];
    // t = −R_cw·c with R_cw = I: the centre is −t.
    assert_eq!(frame.pose.centre.to_array(), [-0.5, 1.0, -2.0]);
    assert_eq!(frame.camera.unwrap().fx, 50.0);
}

#[test]
fn bad_binary_models_are_refused_naming_the_record() {
    // A count of 10¹⁸ images in a file of 90 bytes: refused, nothing reserved.
    let mut huge = one_image();
    huge[..8].copy_from_slice(&1_000_000_000_000_000_000u64.to_le_bytes());
    let error = images_text(&huge, "images.bin").unwrap_err().to_string();
    assert!(
        error.contains("images.bin") && error.contains("do not fit"),
        "{error}"
    );
    // Cut inside the record.
    let cut = &one_image()[..85];
    let error = images_text(cut, "images.bin").unwrap_err().to_string();
    assert!(error.contains("image record 0"), "{error}");
    // Trailing bytes.
    let mut long = one_image();
    long.push(0);
    let error = images_text(&long, "images.bin").unwrap_err().to_string();
    assert!(error.contains("1 bytes after the last record"), "{error}");
    // A camera model COLMAP does not have.
    let mut camera = 1u64.to_le_bytes().to_vec();
    camera.extend(1u32.to_le_bytes());
    camera.extend(42i32.to_le_bytes());
    camera.extend([0u8; 16]);
    let error = cameras_text(&camera, "cameras.bin")
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("camera record 0") && error.contains("42"),
        "{error}"
    );
}
