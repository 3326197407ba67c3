//! One group of pictures encoded on a thread of its own: a fresh OpenH264 encoder fed the
//! group's frames through a short queue, returning each frame's bytes.

use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use openh264::OpenH264API;
use openh264::encoder::{Encoder, EncoderConfig, FrameType};
use openh264::formats::{RgbSliceU8, YUVBuffer};

use super::VideoError;

/// Frames a group's queue holds before the one giving them waits.
const QUEUED: usize = 2;

/// Frames a running group may hold at once: its queue, the one being converted and encoded,
/// and the encoder's own copies (for the memory bound of the groups at once).
pub(super) const FRAMES_HELD: usize = QUEUED + 2;

/// One frame's H.264 bytes.
#[derive(Debug, Default)]
pub(super) struct EncodedFrame {
    /// NAL units, Annex B (what the muxer takes).
    pub bytes: Vec<u8>,
    /// Whether the frame is a keyframe (IDR or I).
    pub keyframe: bool,
}

/// An encoder with `config` (what every group uses).
pub(super) fn encoder(config: EncoderConfig) -> Result<Encoder, VideoError> {
    Encoder::with_api_config(OpenH264API::from_source(), config)
        .map_err(|e| VideoError::Encoder(e.to_string()))
}

/// A group being encoded: the queue to its thread and the thread.
pub(super) struct GopWorker {
    /// `None` once the group's last frame is given.
    frames: Option<SyncSender<Vec<u8>>>,
    /// Frames given so far.
    given: usize,
    thread: JoinHandle<Result<EncodedGroup, VideoError>>,
}

/// A group's frames and the time its thread spent converting and encoding them.
#[derive(Debug, Default)]
pub(super) struct EncodedGroup {
    /// The frames, in order.
    pub frames: Vec<EncodedFrame>,
    /// Conversion to YUV and encoding, summed over the frames.
    pub time: Duration,
}

impl GopWorker {
    /// Starts the group whose first frame is `first`, for frames of `padded` size (even).
    pub fn spawn(
        config: EncoderConfig,
        padded: (usize, usize),
        first: usize,
    ) -> Result<Self, VideoError> {
        let encoder = encoder(config)?;
        let (frames, queue) = sync_channel(QUEUED);
        let thread = std::thread::Builder::new()
            .name(format!("h264 from frame {first}"))
            .spawn(move || encode_group(encoder, padded, first, queue))
            .map_err(|e| {
                VideoError::Encoder(format!("starting a thread for frame {first}: {e}"))
            })?;
        Ok(Self {
            frames: Some(frames),
            given: 0,
            thread,
        })
    }

    /// Queues frame `index` (padded RGB8), waiting while the queue is full.
    pub fn send(&mut self, index: usize, padded_rgb: Vec<u8>) -> Result<(), VideoError> {
        let Some(frames) = &self.frames else {
            return Err(VideoError::Order(format!(
                "frame {index} came after its group ended"
            )));
        };
        if frames.send(padded_rgb).is_err() {
            // The thread ended early: its own error says why.
            self.frames = None;
            return Err(VideoError::Encoder(format!(
                "the encoder of frame {index}'s group stopped"
            )));
        }
        self.given += 1;
        Ok(())
    }

    /// Frames given so far.
    pub fn given(&self) -> usize {
        self.given
    }

    /// Tells the thread no more frames come.
    pub fn close(&mut self) {
        self.frames = None;
    }

    /// Whether the thread has ended (all its frames encoded, or failed).
    pub fn is_finished(&self) -> bool {
        self.thread.is_finished()
    }

    /// Waits for the group's frames.
    pub fn join(mut self) -> Result<EncodedGroup, VideoError> {
        self.close();
        self.thread
            .join()
            .map_err(|_| VideoError::Encoder("a group's encoder panicked".into()))?
    }
}

/// Encodes the frames `queue` gives (the first is frame `first`) until it is closed.
fn encode_group(
    mut encoder: Encoder,
    padded: (usize, usize),
    first: usize,
    queue: Receiver<Vec<u8>>,
) -> Result<EncodedGroup, VideoError> {
    let mut group = EncodedGroup::default();
    for (k, rgb) in queue.into_iter().enumerate() {
        let clock = Instant::now();
        let yuv = YUVBuffer::from_rgb8_source(RgbSliceU8::new(&rgb, padded));
        let encoded = encoder
            .encode(&yuv)
            .map_err(|e| VideoError::Encoder(format!("frame {}: {e}", first + k)))?;
        group.frames.push(EncodedFrame {
            keyframe: matches!(encoded.frame_type(), FrameType::IDR | FrameType::I),
            bytes: encoded.to_vec(),
        });
        group.time += clock.elapsed();
    }
    Ok(group)
}
