//! `video.mp4`: synthetic frames encoded, read back by another MP4 implementation (the `mp4`
//! crate) and decoded by OpenH264: one H.264 Constrained Baseline track of the right size, frame
//! count and duration, and frames within codec error of what went in.

use splatraj_report::video::{VideoEncoder, VideoError, decode_mp4, encode_mp4};

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

/// The frames of `count` moving-square frames given to an encoder of `parallel` groups at
/// once, in the order of `runs` (or frame order), as an MP4.
fn encoded(count: usize, fps: f64, parallel: usize, run: Option<usize>) -> Vec<u8> {
    let (width, height) = (64, 48);
    let mut encoder = VideoEncoder::with_parallel(width, height, fps, parallel).unwrap();
    let order: Vec<usize> = match run {
        Some(run) => encoder
            .encoding_runs(count, run)
            .into_iter()
            .flatten()
            .collect(),
        None => (0..count).collect(),
    };
    let mut sorted = order.clone();
    sorted.sort();
    assert_eq!(sorted, (0..count).collect::<Vec<_>>(), "every frame once");
    for index in order {
        encoder.push(index, &frame(width, height, index)).unwrap();
    }
    encoder.finish().unwrap()
}

#[test]
fn groups_encoded_at_once_and_interleaved_make_the_same_mp4() {
    // 6 fps: a keyframe every 12 frames, so 30 frames are groups of 12, 12 and 6.
    let reference = encoded(30, 6.0, 1, None);
    for (parallel, run) in [(3, Some(1)), (2, Some(5)), (8, Some(2)), (3, None)] {
        assert!(
            encoded(30, 6.0, parallel, run) == reference,
            "{parallel} groups at once, runs of {run:?}"
        );
    }
    // And it is a video of those frames, in order: each decodes near itself (the square's sharp
    // edges cost a few dB late in a group) and farther from the frame 3 later.
    let video = decode_mp4(&reference).unwrap();
    assert_eq!(video.frames.len(), 30);
    for (k, back) in video.frames.iter().enumerate() {
        let db = psnr(&frame(64, 48, k), back);
        assert!(db > 25.0, "frame {k}: PSNR {db:.1} dB");
        assert!(db > psnr(&frame(64, 48, k + 3), back) + 3.0, "frame {k}");
    }
}

#[test]
fn encoding_runs_take_the_groups_in_turn() {
    // 1.5 fps: groups of 3 frames, 0–2, 3–5 and 6.
    let encoder = VideoEncoder::with_parallel(8, 8, 1.5, 3).unwrap();
    assert_eq!(
        encoder.encoding_runs(7, 1),
        [0..1, 3..4, 6..7, 1..2, 4..5, 2..3, 5..6]
    );
    let encoder = VideoEncoder::with_parallel(8, 8, 1.5, 2).unwrap();
    assert_eq!(encoder.encoding_runs(7, 2), [0..2, 3..5, 2..3, 5..6, 6..7]);
    let encoder = VideoEncoder::with_parallel(8, 8, 1.5, 1).unwrap();
    assert_eq!(encoder.encoding_runs(7, 5), [0..3, 3..6, 6..7]);
}

#[test]
fn frames_out_of_their_group_order_or_missing_are_errors() {
    let (width, height) = (24, 24);
    let picture = frame(width, height, 0);
    // Groups of 3 frames.
    let mut encoder = VideoEncoder::with_parallel(width, height, 1.5, 2).unwrap();
    let error = encoder.push(1, &picture).unwrap_err();
    assert!(
        matches!(
            error,
            VideoError::OutOfOrder {
                index: 1,
                expected: 0
            }
        ),
        "{error}"
    );
    encoder.push(0, &picture).unwrap();
    let error = encoder.push(2, &picture).unwrap_err();
    assert!(
        matches!(
            error,
            VideoError::OutOfOrder {
                index: 2,
                expected: 1
            }
        ),
        "{error}"
    );
    let error = encoder.push(0, &picture).unwrap_err();
    assert!(matches!(error, VideoError::Twice(0)), "{error}");
    // Two groups open (0 and 6), the most at once: a third may not begin.
    encoder.push(6, &picture).unwrap();
    let error = encoder.push(3, &picture).unwrap_err();
    assert!(
        matches!(error, VideoError::TooManyGroups { index: 3, open: 2 }),
        "{error}"
    );
    // Frames 0 and 6–7 given, 1–5 never: group 0 is short by frames 1 and 2 (and frames 3–5
    // never came).
    encoder.push(7, &picture).unwrap();
    let error = encoder.finish().unwrap_err();
    assert!(
        matches!(error, VideoError::Missing { from: 1, to: 3 }),
        "{error}"
    );
    // A whole group missing between two others.
    let mut encoder = VideoEncoder::with_parallel(width, height, 1.5, 2).unwrap();
    for index in [0, 1, 2, 6] {
        encoder.push(index, &picture).unwrap();
    }
    let error = encoder.finish().unwrap_err();
    assert!(
        matches!(error, VideoError::Missing { from: 3, to: 6 }),
        "{error}"
    );
}

#[test]
fn a_frame_rate_below_one_keyframe_a_frame_still_groups_two_frames() {
    // At 0.25 fps a keyframe every 2 s would be every frame: consecutive IDR pictures from
    // fresh encoders would share an id. Groups of two frames instead: 0–1, 2–3, 4.
    let encoder = VideoEncoder::with_parallel(8, 8, 0.25, 8).unwrap();
    assert_eq!(encoder.encoding_runs(5, 1), [0..1, 2..3, 4..5, 1..2, 3..4]);
}

#[test]
fn the_frames_the_groups_hold_scale_with_the_groups_and_stay_within_their_bound() {
    let held = VideoEncoder::held_bytes_for;
    // Each group holds the same frames, of the padded (even) size.
    assert_eq!(held(1280, 720, 3), 3 * held(1280, 720, 1));
    assert_eq!(held(1281, 721, 1), held(1282, 722, 1));
    let one_frame = 1282 * 722 * 3;
    assert_eq!(held(1282, 722, 1) % one_frame, 0);
    // The groups `new` encodes at once keep 4K frames within 256 MB, however many cores.
    let groups = VideoEncoder::parallel_for(3840, 2160);
    assert!(groups >= 1);
    let uhd = held(3840, 2160, groups);
    assert!(uhd <= 256 << 20, "{uhd}");
    assert!(uhd >= 3840 * 2160 * 3);
}
