//! Rendered images as pictures: PNG encoding, the object highlight, and 8-bit levels made on
//! the device ([`packed_rgb8`]) for a GPU's frames.
//!
//! Values are floats in [0, 1] (clamped), row-major, as [`crate::host::to_host`] reads a
//! render's `[1, H, W, C]` images back.

use std::io::Cursor;

use burn::backend::Dispatch;
use burn::tensor::{Int, Tensor};

use crate::camera::Intrinsics;
use crate::fused::levels::PackedLevels;

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

/// A value in [0, 1] (clamped) as an 8-bit level, the one rounding rule of every picture:
/// to the nearest level, halves up (`f64::round`'s rule on these non-negative values; NaN is 0).
#[inline]
pub fn to_u8(v: f64) -> u8 {
    // Not `f64::round`: the baseline x86-64 target has no rounding instruction, and its libm
    // call per channel was a tenth of an output frame's time on the host. The difference from
    // the whole part is exact in f64, so the result is `round`'s bit for bit.
    let level = v.clamp(0.0, 1.0) * 255.0;
    let whole = level as u8;
    whole + u8::from(level - f64::from(whole) >= 0.5)
}

/// One pixel of [`highlight`]: RGB + mask `px` tinted.
#[inline]
fn tint(px: [f64; 4], strength: f64) -> [f64; 3] {
    let m = strength * px[3].clamp(0.0, 1.0);
    std::array::from_fn(|c| px[c].clamp(0.0, 1.0) * (1.0 - m) + m * HIGHLIGHT_RGB[c])
}

/// RGB values `[H·W·3]` from an RGB + mask render `[H·W·4]`, the masked pixels tinted with
/// [`HIGHLIGHT_RGB`] in proportion to the mask (`strength` at a full mask).
pub fn highlight(pixels: &[f64], strength: f64) -> Vec<f64> {
    pixels
        .chunks_exact(4)
        .flat_map(|px| tint([px[0], px[1], px[2], px[3]], strength))
        .collect()
}

/// 8-bit RGB `[P·3]` of `pixels` `[P, C]` (C = 3, or 4 with the mask last): the first three
/// channels as they are, or tinted as [`highlight`] does with `tint_strength`. The same bytes
/// as [`to_u8`] of [`highlight`] (or of the channels) read back as f64, without the f64 copies.
pub fn rgb8<E: Copy + Into<f64>>(
    pixels: &[E],
    channels: usize,
    tint_strength: Option<f64>,
) -> Vec<u8> {
    assert!(channels >= 3 && (tint_strength.is_none() || channels == 4));
    let mut out = vec![0; pixels.len() / channels * 3];
    // The channel counts of renders spelled out, so that each loop knows its stride. Written
    // into place with a known stride rather than pushed, a tinted 720p frame's conversion took
    // 6.0 ms of one thread instead of 7.9 (untinted 5.7 against 5.9); written into place by one
    // loop for any count, 8.2 ms (untinted 6.5): the known stride is the gain. The levels'
    // rounding (`to_u8`) is the rest and is not in lanes: about 1 % of a first-try run.
    match channels {
        3 => rgb8_into(pixels, 3, tint_strength, &mut out),
        4 => rgb8_into(pixels, 4, tint_strength, &mut out),
        _ => rgb8_into(pixels, channels, tint_strength, &mut out),
    }
    out
}

/// [`rgb8`] into `out` `[P·3]`; inlined where `channels` is a constant.
#[inline(always)]
fn rgb8_into<E: Copy + Into<f64>>(
    pixels: &[E],
    channels: usize,
    tint_strength: Option<f64>,
    out: &mut [u8],
) {
    for (px, rgb8) in pixels.chunks_exact(channels).zip(out.chunks_exact_mut(3)) {
        let rgb = match tint_strength {
            Some(strength) => tint(
                [px[0].into(), px[1].into(), px[2].into(), px[3].into()],
                strength,
            ),
            None => [px[0].into(), px[1].into(), px[2].into()],
        };
        rgb8.copy_from_slice(&rgb.map(to_u8));
    }
}

/// The 8-bit levels of the first three channels of `images` `[B, H, W, C ≥ 3]`, made where the
/// images are and packed into one integer a pixel: r + 256·g + 65536·b `[B, H, W]`.
/// [`unpack_rgb8`] reads them back.
///
/// Why: a GPU's frames came back as floats, 4 bytes a channel (RGB and the object's mask at
/// 720p: 14.7 MB a frame, 4 GB over a first-try run); packed they are 4 bytes a pixel. One
/// operation ([`crate::fused::levels`]): one kernel on a GPU, a loop on the host. The levels
/// follow [`to_u8`]'s rule (the nearest, halves up) computed in f32: a value within about 1e-5
/// of half a level may land one level from `to_u8` of the same value, which computes in f64
/// (`tests/backend.rs`, `packed_levels_are_rgb8_s_on_every_backend`). Panics when C < 3 (a
/// caller's bug).
pub fn packed_rgb8(images: Tensor<4>) -> Tensor<3, Int> {
    let channels = images.dims()[3];
    assert!(channels >= 3, "packing RGB levels of {channels} channels");
    Tensor::from_dispatch(<Dispatch as PackedLevels>::packed_rgb8(
        images.into_dispatch(),
    ))
}

/// 8-bit RGB `[P·3]` of [`packed_rgb8`]'s values `[P]` as read back.
pub fn unpack_rgb8(packed: &[i32]) -> Vec<u8> {
    packed
        .iter()
        .flat_map(|&levels| [levels as u8, (levels >> 8) as u8, (levels >> 16) as u8])
        .collect()
}

/// PNG bytes of RGB values `[H·W·3]` in [0, 1] at the size of `k`.
pub fn png_rgb(rgb: &[f64], k: &Intrinsics) -> Result<Vec<u8>, ImageError> {
    let pixels: Vec<u8> = rgb.iter().map(|&v| to_u8(v)).collect();
    png_rgb8(&pixels, k.width, k.height)
}

/// PNG bytes of 8-bit RGB `[H·W·3]` of a `width` × `height` picture (the encoder and settings
/// `RgbImage::write_to` uses, so the same bytes).
pub fn png_rgb8(pixels: &[u8], width: usize, height: usize) -> Result<Vec<u8>, ImageError> {
    use image::ImageEncoder;
    if pixels.len() != width * height * 3 {
        return Err(ImageError::Size {
            what: "RGB render",
            got: pixels.len(),
            width,
            height,
        });
    }
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes).write_image(
        pixels,
        width as u32,
        height as u32,
        image::ExtendedColorType::Rgb8,
    )?;
    Ok(bytes)
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

#[cfg(test)]
mod tests {
    use super::{highlight, rgb8, to_u8};

    /// `f64::round`'s level, the rule `to_u8` must keep.
    fn by_round(v: f64) -> u8 {
        (v.clamp(0.0, 1.0) * 255.0).round() as u8
    }

    #[test]
    fn levels_are_round_s_bit_for_bit() {
        let mut values = vec![
            0.0,
            1.0,
            -0.0,
            -1.0,
            2.0,
            f64::NAN,
            f64::INFINITY,
            -f64::INFINITY,
        ];
        for k in 0..=256 {
            // Each level's exact half and its neighbours, where the two rules could part.
            let half = (k as f64 - 0.5) / 255.0;
            values.extend([half, half.next_up(), half.next_down(), k as f64 / 255.0]);
        }
        let mut state = 0x9e37_79b9_u64;
        for _ in 0..100_000 {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1);
            values.push((state >> 11) as f64 / (1u64 << 53) as f64 * 1.2 - 0.1);
        }
        for v in values {
            assert_eq!(to_u8(v), by_round(v), "{v:e}");
        }
    }

    /// `rgb8` of f32 values gives the bytes of `to_u8` on the values read as f64: the channels
    /// as they are (3 or 4 of them, and more), or tinted as `highlight` tints them.
    #[test]
    fn rgb8_gives_the_levels_of_the_values_read_back_as_f64() {
        let mut next = crate::test_random::uniform(0x2545_f491_u64);
        let mut pixels: Vec<f32> = (0..4 * 5000).map(|_| (next() * 1.4 - 0.2) as f32).collect();
        pixels[..6].copy_from_slice(&[f32::NAN, -0.0, 1.0, f32::INFINITY, 0.5, 0.001_960_784]);
        let wide: Vec<f64> = pixels.iter().map(|&v| f64::from(v)).collect();
        for channels in [3, 4, 5] {
            let expected: Vec<u8> = wide
                .chunks_exact(channels)
                .flat_map(|px| px[..3].iter().map(|&v| to_u8(v)))
                .collect();
            assert_eq!(
                rgb8(&pixels, channels, None),
                expected,
                "{channels} channels"
            );
        }
        let tinted: Vec<u8> = highlight(&wide, 0.4).iter().map(|&v| to_u8(v)).collect();
        assert_eq!(rgb8(&pixels, 4, Some(0.4)), tinted, "tinted");
    }
}
