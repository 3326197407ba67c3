//! Rendered images as pictures: PNG encoding and the object highlight.
//!
//! Values are floats in [0, 1] (clamped), row-major, as [`crate::host::to_host`] reads a
//! render's `[1, H, W, C]` images back.

use std::io::Cursor;

use crate::camera::Intrinsics;

/// Colour of the object highlight in pictures (magenta).
pub const HIGHLIGHT_RGB: [f64; 3] = [1.0, 0.2, 0.8];

/// Images could not be encoded.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// The values do not fill the picture.
    #[error("{what} has {got} values for a {width}×{height} picture")]
    Size {
        /// Which picture.
        what: &'static str,
        /// Values given.
        got: usize,
        /// Picture width.
        width: usize,
        /// Picture height.
        height: usize,
    },
    /// The encoder failed.
    #[error("PNG encoding: {0}")]
    Encode(#[from] image::ImageError),
}

fn to_u8(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// RGB values `[H·W·3]` from an RGB + mask render `[H·W·4]`, the masked pixels tinted with
/// [`HIGHLIGHT_RGB`] in proportion to the mask (`strength` at a full mask).
pub fn highlight(pixels: &[f64], strength: f64) -> Vec<f64> {
    pixels
        .chunks_exact(4)
        .flat_map(|px| {
            let m = strength * px[3].clamp(0.0, 1.0);
            (0..3).map(move |c| px[c].clamp(0.0, 1.0) * (1.0 - m) + m * HIGHLIGHT_RGB[c])
        })
        .collect()
}

/// PNG bytes of RGB values `[H·W·3]` in [0, 1] at the size of `k`.
pub fn png_rgb(rgb: &[f64], k: &Intrinsics) -> Result<Vec<u8>, ImageError> {
    let size = ImageError::Size {
        what: "RGB render",
        got: rgb.len(),
        width: k.width,
        height: k.height,
    };
    let pixels: Vec<u8> = rgb.iter().map(|&v| to_u8(v)).collect();
    let image = image::RgbImage::from_raw(k.width as u32, k.height as u32, pixels).ok_or(size)?;
    let mut bytes = Cursor::new(Vec::new());
    image.write_to(&mut bytes, image::ImageFormat::Png)?;
    Ok(bytes.into_inner())
}

/// PNG bytes of grey values `[H·W]` in [0, 1] at the size of `k`.
pub fn png_gray(values: &[f64], k: &Intrinsics) -> Result<Vec<u8>, ImageError> {
    let size = ImageError::Size {
        what: "mask render",
        got: values.len(),
        width: k.width,
        height: k.height,
    };
    let pixels: Vec<u8> = values.iter().map(|&v| to_u8(v)).collect();
    let image = image::GrayImage::from_raw(k.width as u32, k.height as u32, pixels).ok_or(size)?;
    let mut bytes = Cursor::new(Vec::new());
    image.write_to(&mut bytes, image::ImageFormat::Png)?;
    Ok(bytes.into_inner())
}
