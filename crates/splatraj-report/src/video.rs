//! Frames to an H.264 MP4 (`video.mp4`) that browsers and common players play, without a
//! system ffmpeg.
//!
//! Encoding is Cisco's OpenH264 (the `openh264` crate builds its bundled C++ source): Constrained
//! Baseline profile, 4:2:0 chroma (yuv420p), BT.601 limited range, which every browser decodes.
//! Muxing is `muxide` (pure Rust; the `moov` box goes before the media data, so a browser starts
//! playing before the whole file has arrived). Frames are RGB8, row-major; H.264 4:2:0 needs an
//! even width and height, so an odd frame is padded by repeating its last column or row (the
//! video is then one pixel larger than the frames).

use muxide::api::{Muxer, MuxerBuilder, VideoCodec};
use openh264::OpenH264API;
use openh264::encoder::{
    Encoder, EncoderConfig, FrameRate, FrameType, IntraFramePeriod, RateControlMode, VuiConfig,
};
use openh264::formats::{RgbSliceU8, YUVBuffer};

/// Highest frame rate accepted, frames per second: the MP4's 90 kHz clock needs distinct
/// ticks per frame, and no player shows more.
pub const MAX_FPS: f64 = 1000.0;

/// Lowest frame rate accepted, frames per second (a frame every 100 s): the MP4 counts a
/// frame's duration in 32 bits of its 90 kHz clock (13 hours at most), and anything slower
/// than this is a slide show, not a video.
pub const MIN_FPS: f64 = 0.01;

/// Refuses a frame rate outside [[`MIN_FPS`], [`MAX_FPS`]].
pub fn check_fps(fps: f64) -> Result<(), VideoError> {
    if fps.is_finite() && (MIN_FPS..=MAX_FPS).contains(&fps) {
        Ok(())
    } else {
        Err(VideoError::Fps(fps))
    }
}

/// Why a video could not be made.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    /// The frame rate is outside [[`MIN_FPS`], [`MAX_FPS`]].
    #[error("video: frame rate {0:?} is not between {MIN_FPS} and {MAX_FPS} frames per second")]
    Fps(f64),
    /// The frame size is zero or larger than H.264 level 5.2 allows (3840×2160).
    #[error("video: frame size {width}×{height} is not between 1×1 and 3840×2160")]
    Size {
        /// Frame width.
        width: usize,
        /// Frame height.
        height: usize,
    },
    /// A frame does not have width × height × 3 bytes.
    #[error("video: frame {index} has {got} bytes, a {width}×{height} RGB frame has {expected}")]
    FrameBytes {
        /// Frame index.
        index: usize,
        /// Bytes given.
        got: usize,
        /// Bytes expected.
        expected: usize,
        /// Frame width.
        width: usize,
        /// Frame height.
        height: usize,
    },
    /// No frame was given.
    #[error("video: no frames")]
    Empty,
    /// OpenH264 refused.
    #[error("video: H.264 encoder: {0}")]
    Encoder(String),
    /// The MP4 muxer refused.
    #[error("video: MP4 muxer: {0}")]
    Mux(String),
}

/// A keyframe every this many seconds, so players can seek.
const KEYFRAME_SECONDS: f64 = 2.0;

/// Encodes RGB frames one by one into an MP4 held in memory.
pub struct VideoEncoder {
    encoder: Encoder,
    muxer: Muxer<Vec<u8>>,
    /// Frame size as given.
    size: (usize, usize),
    /// Encoded size (even).
    padded: (usize, usize),
    fps: f64,
    frames: usize,
    rgb: Vec<u8>,
}

impl VideoEncoder {
    /// An encoder for `width` × `height` frames shown at `fps` frames per second.
    pub fn new(width: usize, height: usize, fps: f64) -> Result<Self, VideoError> {
        check_fps(fps)?;
        if width == 0 || height == 0 || width.max(height) > 3840 || width.min(height) > 2160 {
            return Err(VideoError::Size { width, height });
        }
        let padded = (width.next_multiple_of(2), height.next_multiple_of(2));
        let config = EncoderConfig::new()
            .max_frame_rate(FrameRate::from_hz(fps as f32))
            // Constant quality, no rate control: rendered frames come back within a few levels
            // (35 dB or better on the demo's frames, about 40 kB a second at 320×240) and the
            // encoder has no bitrate to chase.
            .rate_control_mode(RateControlMode::Off)
            // Every frame is kept: a skipped frame would leave the video shorter than the PNGs.
            .skip_frames(false)
            .intra_frame_period(IntraFramePeriod::from_num_frames(
                (KEYFRAME_SECONDS * fps).round().max(1.0) as u32,
            ))
            // openh264's RGB → YUV conversion is BT.601 limited range: say so in the stream.
            .vui(VuiConfig::bt601());
        let encoder = Encoder::with_api_config(OpenH264API::from_source(), config)
            .map_err(|e| VideoError::Encoder(e.to_string()))?;
        let muxer = MuxerBuilder::new(Vec::new())
            .video(VideoCodec::H264, padded.0 as u32, padded.1 as u32, fps)
            .build()
            .map_err(|e| VideoError::Mux(e.to_string()))?;
        Ok(Self {
            encoder,
            muxer,
            size: (width, height),
            padded,
            fps,
            frames: 0,
            rgb: Vec::new(),
        })
    }

    /// Appends one frame: RGB8, row-major, width × height × 3 bytes.
    pub fn push(&mut self, rgb: &[u8]) -> Result<(), VideoError> {
        let (width, height) = self.size;
        if rgb.len() != width * height * 3 {
            return Err(VideoError::FrameBytes {
                index: self.frames,
                got: rgb.len(),
                expected: width * height * 3,
                width,
                height,
            });
        }
        pad_to(rgb, self.size, self.padded, &mut self.rgb);
        let yuv = YUVBuffer::from_rgb8_source(RgbSliceU8::new(&self.rgb, self.padded));
        let encoded = self
            .encoder
            .encode(&yuv)
            .map_err(|e| VideoError::Encoder(format!("frame {}: {e}", self.frames)))?;
        let keyframe = matches!(encoded.frame_type(), FrameType::IDR | FrameType::I);
        let bytes = encoded.to_vec();
        let pts = self.frames as f64 / self.fps;
        self.muxer
            .write_video(pts, &bytes, keyframe)
            .map_err(|e| VideoError::Mux(format!("frame {}: {e}", self.frames)))?;
        self.frames += 1;
        Ok(())
    }

    /// Frames pushed so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// The finished MP4 file's bytes.
    pub fn finish(mut self) -> Result<Vec<u8>, VideoError> {
        if self.frames == 0 {
            return Err(VideoError::Empty);
        }
        self.muxer
            .finish_in_place()
            .map_err(|e| VideoError::Mux(e.to_string()))?;
        Ok(self.muxer.into_writer())
    }
}

/// `rgb` (`size`) into `out` (`padded`), repeating the last column and row into the padding.
fn pad_to(rgb: &[u8], size: (usize, usize), padded: (usize, usize), out: &mut Vec<u8>) {
    let ((w, h), (pw, ph)) = (size, padded);
    out.clear();
    out.reserve(pw * ph * 3);
    for y in 0..ph {
        let row = &rgb[y.min(h - 1) * w * 3..][..w * 3];
        out.extend_from_slice(row);
        for _ in w..pw {
            out.extend_from_slice(&row[(w - 1) * 3..]);
        }
    }
}

/// An MP4 of `frames` (RGB8, each `width` × `height`) at `fps`.
pub fn encode_mp4<'a>(
    frames: impl IntoIterator<Item = &'a [u8]>,
    width: usize,
    height: usize,
    fps: f64,
) -> Result<Vec<u8>, VideoError> {
    let mut encoder = VideoEncoder::new(width, height, fps)?;
    for frame in frames {
        encoder.push(frame)?;
    }
    encoder.finish()
}

/// A video read back: what its container says and its frames decoded.
#[derive(Debug, Clone)]
pub struct DecodedVideo {
    /// Track width in pixels.
    pub width: usize,
    /// Track height in pixels.
    pub height: usize,
    /// Frames per second the track's timing gives.
    pub fps: f64,
    /// Track duration in seconds.
    pub seconds: f64,
    /// H.264 profile (`AvcConstrainedBaseline`, …).
    pub profile: String,
    /// Samples in the track.
    pub samples: usize,
    /// Every decoded frame, RGB8 row-major.
    pub frames: Vec<Vec<u8>>,
}

/// Reads an MP4 holding one H.264 track and decodes every frame, to check a video: the
/// container is parsed by `mp4` (another implementation than the muxer) and the samples
/// are decoded by OpenH264 from the parameter sets the container declares.
pub fn decode_mp4(bytes: &[u8]) -> Result<DecodedVideo, VideoError> {
    let demux = |e: mp4::Error| VideoError::Mux(format!("reading back: {e}"));
    let mut reader = mp4::Mp4Reader::read_header(std::io::Cursor::new(bytes), bytes.len() as u64)
        .map_err(demux)?;
    let tracks: Vec<&mp4::Mp4Track> = reader.tracks().values().collect();
    let [track] = tracks.as_slice() else {
        return Err(VideoError::Mux(format!(
            "reading back: {} tracks, expected one",
            tracks.len()
        )));
    };
    if track.media_type().map_err(demux)? != mp4::MediaType::H264 {
        return Err(VideoError::Mux(
            "reading back: the track is not H.264".into(),
        ));
    }
    let (id, samples) = (track.track_id(), track.sample_count());
    let (width, height) = (usize::from(track.width()), usize::from(track.height()));
    let seconds = track.duration().as_secs_f64();
    let profile = format!("{:?}", track.video_profile().map_err(demux)?);
    // Annex B for the decoder: start codes instead of the container's 4-byte lengths.
    let mut stream = Vec::new();
    for set in [
        track.sequence_parameter_set().map_err(demux)?,
        track.picture_parameter_set().map_err(demux)?,
    ] {
        stream.extend_from_slice(&[0, 0, 0, 1]);
        stream.extend_from_slice(set);
    }
    let mut decoder = openh264::decoder::Decoder::new()
        .map_err(|e| VideoError::Encoder(format!("decoder: {e}")))?;
    let mut frames = Vec::new();
    for sample_id in 1..=samples {
        let sample = reader
            .read_sample(id, sample_id)
            .map_err(demux)?
            .ok_or_else(|| VideoError::Mux(format!("reading back: sample {sample_id} missing")))?;
        let mut rest: &[u8] = &sample.bytes;
        while rest.len() >= 4 {
            let len = u32::from_be_bytes([rest[0], rest[1], rest[2], rest[3]]) as usize;
            let nal = rest.get(4..4 + len).ok_or_else(|| {
                VideoError::Mux(format!("reading back: sample {sample_id} is truncated"))
            })?;
            stream.extend_from_slice(&[0, 0, 0, 1]);
            stream.extend_from_slice(nal);
            rest = &rest[4 + len..];
        }
        let decoded = decoder
            .decode(&stream)
            .map_err(|e| VideoError::Encoder(format!("decoding sample {sample_id}: {e}")))?;
        stream.clear();
        if let Some(yuv) = decoded {
            let mut rgb = vec![0; width * height * 3];
            yuv.write_rgb8(&mut rgb);
            frames.push(rgb);
        }
    }
    Ok(DecodedVideo {
        width,
        height,
        fps: samples as f64 / seconds.max(f64::MIN_POSITIVE),
        seconds,
        profile,
        samples: samples as usize,
        frames,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn odd_frames_are_padded_with_their_edge() {
        // 3×1 → 4×2: the last column repeats, then the only row repeats.
        let rgb = [1, 1, 1, 2, 2, 2, 3, 3, 3];
        let mut out = Vec::new();
        pad_to(&rgb, (3, 1), (4, 2), &mut out);
        let row = [1, 1, 1, 2, 2, 2, 3, 3, 3, 3, 3, 3];
        assert_eq!(out, [row, row].concat());
    }

    #[test]
    fn bad_sizes_and_rates_are_errors() {
        assert!(matches!(
            VideoEncoder::new(0, 4, 30.0),
            Err(VideoError::Size { .. })
        ));
        assert!(matches!(
            VideoEncoder::new(4, 4, f64::NAN),
            Err(VideoError::Fps(_))
        ));
        let mut encoder = VideoEncoder::new(4, 4, 30.0).unwrap();
        assert!(matches!(
            encoder.push(&[0; 5]),
            Err(VideoError::FrameBytes { got: 5, .. })
        ));
        assert!(matches!(encoder.finish(), Err(VideoError::Empty)));
    }
}
