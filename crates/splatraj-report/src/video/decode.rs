//! Reading a `video.mp4` back: the container parsed by another implementation than the muxer,
//! the frames decoded by OpenH264, to check what [`super::VideoEncoder`] wrote.

use super::VideoError;

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
