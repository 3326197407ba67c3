//! Frames to an H.264 MP4 (`video.mp4`) that browsers and common players play, without a
//! system ffmpeg.
//!
//! Encoding is Cisco's OpenH264 (the `openh264` crate builds its bundled C++ source): Constrained
//! Baseline profile, 4:2:0 chroma (yuv420p), BT.601 limited range, which every browser decodes.
//! Muxing is `muxide` (pure Rust; the `moov` box goes before the media data, so a browser starts
//! playing before the whole file has arrived). Frames are RGB8, row-major; H.264 4:2:0 needs an
//! even width and height, so an odd frame is padded by repeating its last column or row (the
//! video is then one pixel larger than the frames).
//!
//! **Groups of pictures in parallel.** Each group of pictures (a keyframe and the frames up to
//! the next, [`KEYFRAME_SECONDS`]) is encoded by an encoder of its own, on a thread of its own:
//! a group starts from a keyframe and refers to nothing before it, so the groups are
//! independent. One OpenH264 encoder encodes a frame as one slice, mostly on one thread, and
//! took 4–7 ms a 720p frame, more than a GPU takes to render it; several groups encoded at once
//! keep up, when their frames come interleaved ([`VideoEncoder::encoding_runs`]). The bytes do
//! not depend on how many run at once: every group has a fresh encoder whatever the machine.

mod decode;
mod gop;

use std::collections::BTreeMap;
use std::ops::Range;
use std::time::Duration;

use muxide::api::{Muxer, MuxerBuilder, VideoCodec};
use openh264::encoder::{EncoderConfig, FrameRate, IntraFramePeriod, RateControlMode, VuiConfig};

pub use decode::{DecodedVideo, decode_mp4};
use gop::{EncodedFrame, GopWorker, Spare};

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
    /// A frame was given twice.
    #[error("video: frame {0} was given twice")]
    Twice(usize),
    /// A frame came before the one its group needs next.
    #[error("video: frame {index} came when frame {expected} was next in its group")]
    OutOfOrder {
        /// The frame given.
        index: usize,
        /// The frame its group needs next.
        expected: usize,
    },
    /// A frame began a group while as many groups as may run at once were still open.
    #[error(
        "video: frame {index} begins a group while {open} groups are still open (at most \
         {open} at once: give the frames in `VideoEncoder::encoding_runs` order)"
    )]
    TooManyGroups {
        /// The frame given.
        index: usize,
        /// Groups open, the most at once.
        open: usize,
    },
    /// Frames never given.
    #[error("video: frames {from}..{to} are missing")]
    Missing {
        /// The first frame missing.
        from: usize,
        /// The frame after the last missing one.
        to: usize,
    },
}

/// A keyframe every this many seconds, so players can seek; also the length of the groups
/// encoded in parallel.
pub const KEYFRAME_SECONDS: f64 = 2.0;

/// Groups encoded at once, at most (a 9-second video at 30 frames a second has five).
const MAX_PARALLEL_GROUPS: usize = 8;

/// Host memory the groups' queued and in-progress frames may take, bytes: it bounds the groups
/// at once for large frames (a 4K frame is 25 MB).
const PARALLEL_BYTES: usize = 256 << 20;

/// Encodes RGB frames into an MP4 held in memory, each group of pictures on its own encoder
/// and thread (module docs).
pub struct VideoEncoder {
    config: EncoderConfig,
    muxer: Muxer<Vec<u8>>,
    /// Frame size as given.
    size: (usize, usize),
    /// Encoded size (even).
    padded: (usize, usize),
    fps: f64,
    /// Frames in a group (the last group may have fewer).
    group_frames: usize,
    /// Groups encoded at once, at most.
    parallel: usize,
    /// Groups being encoded, by group index.
    running: BTreeMap<usize, GopWorker>,
    /// Groups encoded and not muxed yet (a later group may finish first).
    encoded: BTreeMap<usize, Vec<EncodedFrame>>,
    /// The next group to mux; every group before it is in the MP4.
    next_to_mux: usize,
    /// Frames given so far.
    frames: usize,
    /// The groups' conversion and encoding time, summed over the groups finished.
    encoding: Duration,
    /// Frame buffers the groups have finished with, to be filled again (a 720p frame's fresh
    /// allocation and copy cost about a millisecond).
    spare: Spare,
}

impl VideoEncoder {
    /// An encoder for `width` × `height` frames shown at `fps` frames per second, encoding as
    /// many groups at once as [`VideoEncoder::parallel_for`] says.
    pub fn new(width: usize, height: usize, fps: f64) -> Result<Self, VideoError> {
        Self::with_parallel(width, height, fps, Self::parallel_for(width, height))
    }

    /// Groups [`VideoEncoder::new`] encodes at once for `width` × `height` frames: half the
    /// cores, at most 8, and within 256 MB of frames.
    pub fn parallel_for(width: usize, height: usize) -> usize {
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        let by_memory = PARALLEL_BYTES / Self::held_bytes_for(width, height, 1).max(1);
        (cores / 2).min(MAX_PARALLEL_GROUPS).min(by_memory).max(1)
    }

    /// Host memory `parallel` groups of `width` × `height` frames may hold at once, bytes: their
    /// queued and in-progress frames (what an up-front memory check adds beside the renders,
    /// before any encoder is made).
    pub fn held_bytes_for(width: usize, height: usize, parallel: usize) -> usize {
        // Saturating: sizes come from files, and a refusal must not overflow first.
        [
            gop::FRAMES_HELD,
            width.next_multiple_of(2),
            height.next_multiple_of(2),
            3,
        ]
        .into_iter()
        .fold(parallel, usize::saturating_mul)
    }

    /// [`VideoEncoder::new`] encoding at most `parallel` groups at once (the bytes are the
    /// same for any `parallel`).
    pub fn with_parallel(
        width: usize,
        height: usize,
        fps: f64,
        parallel: usize,
    ) -> Result<Self, VideoError> {
        check_fps(fps)?;
        if width == 0 || height == 0 || width.max(height) > 3840 || width.min(height) > 2160 {
            return Err(VideoError::Size { width, height });
        }
        let padded = (width.next_multiple_of(2), height.next_multiple_of(2));
        // At least two frames a group: consecutive keyframes from fresh encoders would share
        // an IDR picture id, which H.264 forbids for IDR pictures next to each other.
        let group_frames = (KEYFRAME_SECONDS * fps).round().max(2.0) as usize;
        let config = EncoderConfig::new()
            .max_frame_rate(FrameRate::from_hz(fps as f32))
            // Constant quality, no rate control: rendered frames come back within a few levels
            // (35 dB or better on the demo's frames, about 40 kB a second at 320×240) and the
            // encoder has no bitrate to chase.
            .rate_control_mode(RateControlMode::Off)
            // Every frame is kept: a skipped frame would leave the video shorter than the PNGs.
            .skip_frames(false)
            .intra_frame_period(IntraFramePeriod::from_num_frames(group_frames as u32))
            // OpenH264 chooses its own threads: with one slice a frame it still gains from them
            // (guitar 720p, one group at a time: 4.6 ms a frame against 5.7 ms with one thread;
            // the same bytes). The groups are the rest of the parallelism.
            .num_threads(0)
            // openh264's RGB → YUV conversion is BT.601 limited range: say so in the stream.
            .vui(VuiConfig::bt601());
        let muxer = MuxerBuilder::new(Vec::new())
            .video(VideoCodec::H264, padded.0 as u32, padded.1 as u32, fps)
            .build()
            .map_err(|e| VideoError::Mux(e.to_string()))?;
        Ok(Self {
            config,
            muxer,
            size: (width, height),
            padded,
            fps,
            group_frames,
            parallel: parallel.max(1),
            running: BTreeMap::new(),
            encoded: BTreeMap::new(),
            next_to_mux: 0,
            frames: 0,
            encoding: Duration::ZERO,
            spare: Spare::new(),
        })
    }

    /// The frames `0..count` as runs of at most `run` consecutive frames, in an order that
    /// keeps the groups this encoder runs at once busy: the groups taken as many at a time,
    /// their runs in turn. Giving the frames in this order needs no frame held back; in frame
    /// order one group is encoded at a time.
    pub fn encoding_runs(&self, count: usize, run: usize) -> Vec<Range<usize>> {
        let run = run.max(1);
        let groups: Vec<Range<usize>> = (0..count)
            .step_by(self.group_frames)
            .map(|start| start..(start + self.group_frames).min(count))
            .collect();
        let mut runs = Vec::new();
        for together in groups.chunks(self.parallel) {
            let mut offset = 0;
            while together.iter().any(|g| g.start + offset < g.end) {
                for g in together {
                    let start = g.start + offset;
                    if start < g.end {
                        runs.push(start..(start + run).min(g.end));
                    }
                }
                offset += run;
            }
        }
        runs
    }

    /// Gives frame `index` (RGB8, row-major, width × height × 3 bytes). Each group's frames
    /// must come in order. Up to as many groups as run at once may be open, their frames
    /// interleaved ([`VideoEncoder::encoding_runs`]); a group begins only once the oldest open
    /// one has all its frames, if that many are open.
    pub fn push(&mut self, index: usize, rgb: &[u8]) -> Result<(), VideoError> {
        let (width, height) = self.size;
        if rgb.len() != width * height * 3 {
            return Err(VideoError::FrameBytes {
                index,
                got: rgb.len(),
                expected: width * height * 3,
                width,
                height,
            });
        }
        let (group, position) = (index / self.group_frames, index % self.group_frames);
        if group < self.next_to_mux || self.encoded.contains_key(&group) {
            return Err(VideoError::Twice(index));
        }
        if position == 0 {
            if self.running.contains_key(&group) {
                return Err(VideoError::Twice(index));
            }
            // The oldest group makes room, once it has all its frames.
            if self.running.len() >= self.parallel {
                let complete = self
                    .running
                    .first_key_value()
                    .is_some_and(|(_, oldest)| oldest.given() == self.group_frames);
                if !complete {
                    return Err(VideoError::TooManyGroups {
                        index,
                        open: self.running.len(),
                    });
                }
                self.finish_oldest()?;
            }
            let worker = GopWorker::spawn(self.config, self.padded, index, self.spare.giver())?;
            self.running.insert(group, worker);
        }
        let Some(worker) = self.running.get_mut(&group) else {
            return Err(VideoError::OutOfOrder {
                index,
                expected: group * self.group_frames,
            });
        };
        let expected = group * self.group_frames + worker.given();
        if index != expected {
            return Err(VideoError::OutOfOrder { index, expected });
        }
        let mut padded = self.spare.take();
        pad_to(rgb, self.size, self.padded, &mut padded);
        if let Err(stopped) = worker.send(index, padded) {
            // The group's thread ended early: its own error says why.
            let failed = self.running.remove(&group).map(GopWorker::join);
            return Err(match failed {
                Some(Err(cause)) => cause,
                _ => stopped,
            });
        }
        if worker.given() == self.group_frames {
            worker.close();
        }
        self.frames += 1;
        self.collect_finished()?;
        Ok(())
    }

    /// Frames given so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Time the groups' threads spent converting and encoding, summed over the groups
    /// finished so far (they run at the same time: this is work, not wall-clock time).
    pub fn encoding_time(&self) -> Duration {
        self.encoding
    }

    /// The finished MP4 file's bytes, once every frame from 0 on is given.
    pub fn finish(mut self) -> Result<Vec<u8>, VideoError> {
        if self.frames == 0 {
            return Err(VideoError::Empty);
        }
        self.wait_for_groups()?;
        self.mux_in_order(Stage::End)?;
        // Every group muxed: no frame is missing.
        if let Some((&group, frames)) = self.encoded.iter().next() {
            let gap = if group == self.next_to_mux {
                // The group itself is short, and later ones were given.
                let start = group * self.group_frames + frames.len();
                start..(group + 1) * self.group_frames
            } else {
                self.next_to_mux * self.group_frames..group * self.group_frames
            };
            return Err(VideoError::Missing {
                from: gap.start,
                to: gap.end,
            });
        }
        self.muxer
            .finish_in_place()
            .map_err(|e| VideoError::Mux(e.to_string()))?;
        Ok(self.muxer.into_writer())
    }

    /// Waits for every group given frames to be encoded (then [`VideoEncoder::encoding_time`]
    /// counts them all).
    pub fn wait_for_groups(&mut self) -> Result<(), VideoError> {
        while !self.running.is_empty() {
            self.finish_oldest()?;
        }
        Ok(())
    }

    /// Waits for the oldest running group and keeps its frames.
    fn finish_oldest(&mut self) -> Result<(), VideoError> {
        if let Some((group, worker)) = self.running.pop_first() {
            self.keep(group, worker)?;
        }
        Ok(())
    }

    /// Keeps the frames of every group that has finished, without waiting.
    fn collect_finished(&mut self) -> Result<(), VideoError> {
        let done: Vec<usize> = self
            .running
            .iter()
            .filter(|(_, worker)| worker.is_finished())
            .map(|(&group, _)| group)
            .collect();
        for group in done {
            if let Some(worker) = self.running.remove(&group) {
                self.keep(group, worker)?;
            }
        }
        Ok(())
    }

    /// Waits for `group`'s `worker`, keeps its frames and muxes what now follows in order.
    fn keep(&mut self, group: usize, worker: GopWorker) -> Result<(), VideoError> {
        let done = worker.join()?;
        self.encoding += done.time;
        self.encoded.insert(group, done.frames);
        self.mux_in_order(Stage::Giving)
    }

    /// Muxes the encoded groups that follow the muxed ones, whole groups in order; at the
    /// `End`, the last group may be shorter.
    fn mux_in_order(&mut self, stage: Stage) -> Result<(), VideoError> {
        while let Some(frames) = self.encoded.get(&self.next_to_mux) {
            let complete = frames.len() == self.group_frames;
            let last = stage == Stage::End && self.encoded.len() == 1;
            if !complete && !last {
                break;
            }
            let frames = self.encoded.remove(&self.next_to_mux).unwrap_or_default();
            let first = self.next_to_mux * self.group_frames;
            for (k, frame) in frames.iter().enumerate() {
                let pts = (first + k) as f64 / self.fps;
                self.muxer
                    .write_video(pts, &frame.bytes, frame.keyframe)
                    .map_err(|e| VideoError::Mux(format!("frame {}: {e}", first + k)))?;
            }
            self.next_to_mux += 1;
        }
        Ok(())
    }
}

/// Whether frames may still come ([`VideoEncoder::mux_in_order`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    /// Frames are still being given: only whole groups are muxed.
    Giving,
    /// Every frame is given: the last group may be short.
    End,
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
    for (index, frame) in frames.into_iter().enumerate() {
        encoder.push(index, frame)?;
    }
    encoder.finish()
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
            encoder.push(0, &[0; 5]),
            Err(VideoError::FrameBytes { got: 5, .. })
        ));
        assert!(matches!(encoder.finish(), Err(VideoError::Empty)));
    }
}
