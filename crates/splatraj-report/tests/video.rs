//! `video.mp4`: synthetic frames encoded, read back by another MP4 implementation (the `mp4`
//! crate) and decoded by OpenH264: one H.264 Constrained Baseline track of the right size, frame
//! count and duration, and frames within codec error of what went in.

use splatraj_report::video::{decode_mp4, encode_mp4};

/// A smooth picture (rendered frames are smooth too).
fn gradient(width: usize, height: usize) -> Vec<u8> {
    (0..height)
        .flat_map(|y| {
            (0..width).flat_map(move |x| {
                [
                    (40 + 150 * x / width) as u8,
                    (60 + 120 * y / height) as u8,
                    90,
                ]
            })
        })
        .collect()
}

/// [`gradient`] with a 12×10 magenta square that moves 2 pixels per frame `k` (even
/// positions, so 4:2:0 chroma does not smear its edges).
fn frame(width: usize, height: usize, k: usize) -> Vec<u8> {
    let mut rgb = gradient(width, height);
    for y in 8..18 {
        for x in (2 * k..2 * k + 12).map(|x| x % width) {
            rgb[(y * width + x) * 3..][..3].copy_from_slice(&[230, 40, 200]);
        }
    }
    rgb
}

/// Peak signal-to-noise ratio of `b` against `a` (dB).
fn psnr(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len());
    let mse = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    10.0 * (255.0f64.powi(2) / mse.max(1e-12)).log10()
}

#[test]
fn frames_come_back_from_the_mp4_within_codec_error() {
    let (width, height, count, fps) = (64, 48, 12, 12.0);
    let frames: Vec<Vec<u8>> = (0..count).map(|k| frame(width, height, k)).collect();
    let bytes = encode_mp4(frames.iter().map(Vec::as_slice), width, height, fps).unwrap();
    // ISO base media: `ftyp` first, and `moov` before `mdat` so browsers start at once.
    assert_eq!(&bytes[4..8], b"ftyp");
    let at = |name: &[u8]| bytes.windows(4).position(|w| w == name).unwrap();
    assert!(at(b"moov") < at(b"mdat"));

    let video = decode_mp4(&bytes).unwrap();
    assert_eq!((video.width, video.height), (width, height));
    assert_eq!(video.samples, count);
    assert_eq!(video.frames.len(), count);
    assert!(
        (video.seconds - count as f64 / fps).abs() < 1e-3,
        "{}",
        video.seconds
    );
    assert!((video.fps - fps).abs() < 1e-2, "{}", video.fps);
    // Baseline without B-frames: what browsers and phones decode.
    assert!(video.profile.contains("Baseline"), "{}", video.profile);
    for (k, (sent, back)) in frames.iter().zip(&video.frames).enumerate() {
        let db = psnr(sent, back);
        assert!(db > 30.0, "frame {k}: PSNR {db:.1} dB");
    }
    // The frames are told apart: frame 0 decodes nearer to itself than to frame 6.
    assert!(psnr(&frames[0], &video.frames[0]) > psnr(&frames[6], &video.frames[0]) + 5.0);
}

#[test]
fn odd_sizes_are_padded_to_even() {
    let (width, height) = (41, 31);
    let frames = vec![gradient(width, height); 3];
    let bytes = encode_mp4(frames.iter().map(Vec::as_slice), width, height, 30.0).unwrap();
    let video = decode_mp4(&bytes).unwrap();
    assert_eq!((video.width, video.height), (42, 32));
    assert_eq!(video.frames.len(), 3);
    // The frame's own pixels survive; the padding repeats the edge.
    let crop: Vec<u8> = video.frames[0]
        .chunks_exact(42 * 3)
        .take(height)
        .flat_map(|row| row[..width * 3].to_vec())
        .collect();
    assert!(psnr(&frames[0], &crop) > 30.0);
}
