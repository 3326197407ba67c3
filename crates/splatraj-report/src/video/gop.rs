//! One group of pictures encoded on a thread of its own: a fresh OpenH264 encoder fed the
//! group's frames through a short queue, returning each frame's bytes.

use std::sync::mpsc::{Receiver, Sender, SyncSender, channel, sync_channel};
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
    /// The frame's NAL units, as the encoder wrote them (what the muxer takes).
    pub bytes: Vec<u8>,
    /// Whether the frame is a keyframe (IDR or I).
    pub keyframe: bool,
}

/// A group's frames and the time its thread spent converting and encoding them.
#[derive(Debug, Default)]
pub(super) struct EncodedGroup {
    /// The frames, in order.
    pub frames: Vec<EncodedFrame>,
    /// Conversion to YUV and encoding, summed over the frames.
    pub time: Duration,
}

/// Frame buffers the groups' threads have finished with, handed back to be filled again.
pub(super) struct Spare {
    giver: Sender<Vec<u8>>,
    taker: Receiver<Vec<u8>>,
}

impl Spare {
    /// No buffer yet.
    pub fn new() -> Self {
        let (giver, taker) = channel();
        Self { giver, taker }
    }

    /// Where a group's thread hands its buffers back.
    pub fn giver(&self) -> Sender<Vec<u8>> {
        self.giver.clone()
    }

    /// A buffer handed back, or a new one. There are never more than the frames in flight.
    pub fn take(&self) -> Vec<u8> {
        self.taker.try_recv().unwrap_or_default()
    }
}

/// A group being encoded: the queue to its thread and the thread. Dropped, it closes the
/// queue and waits for the thread (a few frames at most), so no encoder outlives the video.
pub(super) struct GopWorker {
    /// `None` once the group's last frame is given.
    frames: Option<SyncSender<Vec<u8>>>,
    /// Frames given so far.
    given: usize,
    /// `None` once joined.
    thread: Option<JoinHandle<Result<EncodedGroup, VideoError>>>,
}

impl GopWorker {
    /// Starts the group whose first frame is `first`, for frames of `padded` size (even),
    /// with an encoder of `config`; the buffers it has encoded go back through `spare`.
    pub fn spawn(
        config: EncoderConfig,
        padded: (usize, usize),
        first: usize,
        spare: Sender<Vec<u8>>,
    ) -> Result<Self, VideoError> {
        let encoder =
            Encoder::with_api_config(OpenH264API::from_source(), config).map_err(|e| {
                VideoError::Encoder(format!(
                    "starting an encoder for {}×{} frames from frame {first}: {e}",
                    padded.0, padded.1
                ))
            })?;
        let (frames, queue) = sync_channel(QUEUED);
        let group = Group {
            padded,
            first,
            queue,
            spare,
        };
        let thread = std::thread::Builder::new()
            .name(format!("h264 from frame {first}"))
            .spawn(move || encode_group(encoder, group))
            .map_err(|e| {
                VideoError::Encoder(format!(
                    "starting the thread that encodes the frames from {first} ({e}): the \
                     process is short of memory or threads; under an address-space limit \
                     (`ulimit -v`) every thread's stack counts"
                ))
            })?;
        Ok(Self {
            frames: Some(frames),
            given: 0,
            thread: Some(thread),
        })
    }

    /// Queues frame `index` (padded RGB8), waiting while the queue is full.
    pub fn send(&mut self, index: usize, padded_rgb: Vec<u8>) -> Result<(), VideoError> {
        let Some(frames) = &self.frames else {
            return Err(VideoError::Encoder(format!(
                "frame {index}'s group was closed before it"
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
        self.thread.as_ref().is_none_or(JoinHandle::is_finished)
    }

    /// Waits for the group's frames.
    pub fn join(mut self) -> Result<EncodedGroup, VideoError> {
        self.wait()
    }

    /// Closes the queue and waits for the thread.
    fn wait(&mut self) -> Result<EncodedGroup, VideoError> {
        self.close();
        match self.thread.take() {
            Some(thread) => thread
                .join()
                .map_err(|_| VideoError::Encoder("a group's encoder panicked".into()))?,
            None => Ok(EncodedGroup::default()),
        }
    }
}

impl Drop for GopWorker {
    fn drop(&mut self) {
        // A video given up (an error, a stop): its frames are not needed, its thread is ended.
        let _ = self.wait();
    }
}

/// What a group's thread works on.
struct Group {
    /// Encoded frame size (even).
    padded: (usize, usize),
    /// The group's first frame.
    first: usize,
    /// Its frames, padded RGB8.
    queue: Receiver<Vec<u8>>,
    /// Where the frames' buffers go back once converted.
    spare: Sender<Vec<u8>>,
}

/// Encodes the frames the group's queue gives until it is closed.
fn encode_group(mut encoder: Encoder, group: Group) -> Result<EncodedGroup, VideoError> {
    let mut encoded_group = EncodedGroup::default();
    for (k, rgb) in group.queue.into_iter().enumerate() {
        let clock = Instant::now();
        let yuv = YUVBuffer::from_rgb8_source(RgbSliceU8::new(&rgb, group.padded));
        // Handed back for a later frame; nobody taking it back is no error.
        let _ = group.spare.send(rgb);
        let encoded = encoder.encode(&yuv).map_err(|e| {
            // OpenH264 sets itself up on a group's first frame: what fails there is most often
            // the memory for its buffers, which its own message does not say.
            let cause = if k == 0 {
                " (the encoder sets itself up on this frame: most often the process is short \
                 of memory; under an address-space limit (`ulimit -v`) raise it or render \
                 smaller frames)"
            } else {
                ""
            };
            VideoError::Encoder(format!("frame {}: {e}{cause}", group.first + k))
        })?;
        encoded_group.frames.push(EncodedFrame {
            keyframe: matches!(encoded.frame_type(), FrameType::IDR | FrameType::I),
            bytes: encoded.to_vec(),
        });
        encoded_group.time += clock.elapsed();
    }
    Ok(encoded_group)
}
