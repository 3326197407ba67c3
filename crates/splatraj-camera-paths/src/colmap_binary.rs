//! COLMAP's binary model, `images.bin` and `cameras.bin` (what `colmap mapper` writes by
//! default), read by turning each record into the line the text model has for it: the text
//! reader ([`crate::colmap`]) then reads both, with one set of checks.
//!
//! Layout (COLMAP `src/colmap/scene/reconstruction_io.cc`, little-endian):
//! - `cameras.bin`: u64 count; per camera u32 `CAMERA_ID`, i32 model id, u64 `WIDTH`, u64
//!   `HEIGHT`, then the model's parameters as f64 (their count fixed by the model);
//! - `images.bin`: u64 count; per image u32 `IMAGE_ID`, f64 `QW QX QY QZ`, f64 `TX TY TZ`, u32
//!   `CAMERA_ID`, the `NAME` up to a zero byte, u64 count of 2D points, then per point f64 X,
//!   f64 Y, i64 `POINT3D_ID` (skipped, as the text reader skips its points line).
//!
//! Counts are checked against the bytes left before anything is reserved, so a corrupt count
//! is an error naming the record, not an allocation.

use std::fmt::Write as _;
use std::path::Path;

use crate::error::{InterchangeError, Result, invalid};

/// COLMAP's camera models by id: name and parameter count (`src/colmap/sensor/models.h`).
const MODELS: [(&str, usize); 11] = [
    ("SIMPLE_PINHOLE", 3),
    ("PINHOLE", 4),
    ("SIMPLE_RADIAL", 4),
    ("RADIAL", 5),
    ("OPENCV", 8),
    ("OPENCV_FISHEYE", 8),
    ("FULL_OPENCV", 12),
    ("FOV", 5),
    ("SIMPLE_RADIAL_FISHEYE", 4),
    ("RADIAL_FISHEYE", 5),
    ("THIN_PRISM_FISHEYE", 12),
];

/// Bytes of an image record without its name and points: id, pose, camera id, the name's zero
/// byte, the point count.
const IMAGE_FIXED_BYTES: usize = 4 + 7 * 8 + 4 + 1 + 8;
/// Bytes of one 2D point of an image record.
const POINT_BYTES: usize = 8 + 8 + 8;
/// Bytes of a camera record without its parameters.
const CAMERA_FIXED_BYTES: usize = 4 + 4 + 8 + 8;

/// The whole binary file at `path`, naming it in errors.
pub fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    splatraj_scene::input::read_bytes(path).map_err(|error| InterchangeError::Read {
        path: path.to_path_buf(),
        error,
    })
}

/// `images.bin` bytes as `images.txt` text (each image line, then an empty points line).
pub fn images_text(bytes: &[u8], file: &str) -> Result<String> {
    let mut reader = Reader { bytes, at: 0, file };
    let count = reader.count("the image count", IMAGE_FIXED_BYTES)?;
    let mut text = String::new();
    for i in 0..count {
        let element = format!("image record {i}");
        let id = reader.u32(&element)?;
        let pose: Vec<f64> = (0..7)
            .map(|_| reader.f64(&element))
            .collect::<Result<_>>()?;
        let camera = reader.u32(&element)?;
        let name = reader.name(&element)?;
        let points = reader.count(&format!("{element}: its point count"), POINT_BYTES)?;
        reader.skip(points * POINT_BYTES, &element)?;
        let pose: Vec<String> = pose.iter().map(f64::to_string).collect();
        let _ = writeln!(text, "{id} {} {camera} {name}\n", pose.join(" "));
    }
    reader.end()?;
    Ok(text)
}

/// `cameras.bin` bytes as `cameras.txt` text.
pub fn cameras_text(bytes: &[u8], file: &str) -> Result<String> {
    let mut reader = Reader { bytes, at: 0, file };
    let count = reader.count("the camera count", CAMERA_FIXED_BYTES)?;
    let mut text = String::new();
    for i in 0..count {
        let element = format!("camera record {i}");
        let id = reader.u32(&element)?;
        let model = reader.i32(&element)?;
        let &(name, parameters) = usize::try_from(model)
            .ok()
            .and_then(|m| MODELS.get(m))
            .ok_or_else(|| invalid(file, &element, format!("unknown camera model id {model}")))?;
        let width = reader.u64(&element)?;
        let height = reader.u64(&element)?;
        let params: Vec<String> = (0..parameters)
            .map(|_| reader.f64(&element).map(|v| v.to_string()))
            .collect::<Result<_>>()?;
        let _ = writeln!(text, "{id} {name} {width} {height} {}", params.join(" "));
    }
    reader.end()?;
    Ok(text)
}

/// A cursor over a binary model file.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
    file: &'a str,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self, element: &str) -> Result<[u8; N]> {
        let end = self.at + N;
        let slice = self.bytes.get(self.at..end).ok_or_else(|| {
            invalid(
                self.file,
                element,
                format!("the file ends at byte {} inside it", self.bytes.len()),
            )
        })?;
        self.at = end;
        Ok(slice.try_into().expect("N bytes"))
    }

    fn u32(&mut self, element: &str) -> Result<u32> {
        self.take(element).map(u32::from_le_bytes)
    }

    fn i32(&mut self, element: &str) -> Result<i32> {
        self.take(element).map(i32::from_le_bytes)
    }

    fn u64(&mut self, element: &str) -> Result<u64> {
        self.take(element).map(u64::from_le_bytes)
    }

    fn f64(&mut self, element: &str) -> Result<f64> {
        self.take(element).map(f64::from_le_bytes)
    }

    /// A count of records of at least `record_bytes` each, refused when the bytes left cannot
    /// hold them.
    fn count(&mut self, what: &str, record_bytes: usize) -> Result<usize> {
        let count = self.u64(what)?;
        let left = (self.bytes.len() - self.at) as u64;
        if count > left / record_bytes as u64 {
            return Err(invalid(
                self.file,
                what,
                format!(
                    "{count} records of at least {record_bytes} bytes do not fit in the {left} \
                     bytes left"
                ),
            ));
        }
        Ok(count as usize)
    }

    fn skip(&mut self, bytes: usize, element: &str) -> Result<()> {
        if self.bytes.len() - self.at < bytes {
            return Err(invalid(self.file, element, "the file ends inside it"));
        }
        self.at += bytes;
        Ok(())
    }

    /// A name up to its zero byte, as one line of text.
    fn name(&mut self, element: &str) -> Result<String> {
        let rest = &self.bytes[self.at..];
        let end = rest
            .iter()
            .position(|&b| b == 0)
            .ok_or_else(|| invalid(self.file, element, "the image name has no end (zero byte)"))?;
        let name = String::from_utf8_lossy(&rest[..end]).into_owned();
        if name.trim().is_empty() || name.contains(['\n', '\r']) {
            return Err(invalid(
                self.file,
                element,
                format!("the image name {name:?} is empty or spans lines"),
            ));
        }
        self.at += end + 1;
        Ok(name)
    }

    fn end(&self) -> Result<()> {
        if self.at != self.bytes.len() {
            return Err(invalid(
                self.file,
                "the end",
                format!("{} bytes after the last record", self.bytes.len() - self.at),
            ));
        }
        Ok(())
    }
}
