//! Niantic SPZ reader: versions 1-3 (one gzip stream) and 4 (zstd streams behind a plain header).
//!
//! Written from the format's definition in the nianticlabs/spz repository (README "File Format"
//! and the reference loader `src/cc/load-spz.cc`), checked against a real version 4 file
//! (`shared/data/biker.spz`) and the same scene as a PlayCanvas compressed PLY.
//!
//! # Layout
//!
//! Every version stores six attribute arrays, each for all Gaussians in turn, in this order:
//! positions, alphas, colours, scales, rotations, spherical harmonics (SH).
//!
//! - Versions 1-3: the file is a gzip stream. Its content is a 16-byte little-endian header
//!   (`"NGSP"`, u32 version, u32 count, u8 SH degree, u8 fractional bits, u8 flags, u8 reserved)
//!   followed by the six arrays back to back.
//! - Version 4: the file starts, uncompressed, with a 32-byte header: the 16 bytes above with the
//!   last byte being the number of streams, then u32 `tocByteOffset` and 12 reserved bytes.
//!   Bytes `[32, tocByteOffset)` hold extension records, a table of contents follows at
//!   `tocByteOffset` (per stream: u64 compressed size, u64 uncompressed size), then each non-empty
//!   array as its own zstd stream, in the order above.
//! - Extension records (flag `0x2`) are `u32 type, u32 byte length, payload`. In version 4 they
//!   sit between the header and the table of contents; in gzip files current writers put them
//!   after the arrays (an earlier writer put them before).
//!
//! # Encodings (per Gaussian)
//!
//! - Position: 3 × 24-bit signed fixed point with `fractional bits` bits after the point
//!   (version 1: 3 × float16).
//! - Alpha: u8, the *activated* opacity × 255.
//! - Colour: 3 × u8, the SH DC term as `f_dc · 0.15 · 255 + 127.5` (0.15 rather than C0 so that
//!   colours a little outside [0, 1] survive).
//! - Scale: 3 × u8, the log-scale as `(log s + 10) · 16`.
//! - Rotation, versions 1-2: 3 × u8 for x, y, z in [-1, 1] (w ≥ 0 is recomputed). Versions 3-4:
//!   "smallest three" in a u32: the top 2 bits index (in x, y, z, w order) the largest
//!   component, which is recomputed; the other three, from the last index to the first, take 10
//!   bits each from the low end: 9 bits of magnitude in units of (1/√2)/511, then a sign bit.
//! - SH (degree ≥ 1): u8 per coefficient, `(b − 128) / 128`, coefficient-major with the colour
//!   channel varying fastest (the same layout as [`Scene::sh`] after its DC term).
//!
//! # Coordinate system
//!
//! SPZ stores data in RUB axes (x right, y up, z back: the OpenGL/three.js convention) unless an
//! `SPZ_ADOBE_coordinate_system` extension names another system. INRIA PLY files, and so
//! [`Scene`], use RDF (x right, y down, z forward: COLMAP/OpenCV). The reader converts: it
//! negates y and z of positions, conjugates rotations by the same 180° turn about x (which
//! negates the quaternion's y and z) and negates the SH coefficients that are odd in y or in z.
//! Checked on the biker scene: its SPZ and compressed-PLY copies agree, Gaussian by Gaussian,
//! only with this flip (positions within quantisation, rotations to 1 − |q·q'| < 1e-6).

use std::f32::consts::FRAC_1_SQRT_2;
use std::io::Read;
use std::path::Path;

use super::bytes::{f16_to_f32, read_u32, read_u64, show_bytes};
use crate::error::{Result, SceneError};
use crate::scene::{Scene, sh_coeffs_for_degree};

/// The first four bytes of an SPZ header ("Niantic Gaussian splat"), the first bytes of a v4 file.
pub const MAGIC_BYTES: &[u8] = b"NGSP";

const GZIP_MAGIC: &[u8] = &[0x1f, 0x8b];
const LEGACY_HEADER_LEN: usize = 16;
const V4_HEADER_LEN: usize = 32;
const TOC_ENTRY_LEN: usize = 16;

/// Far above any trained scene (the largest are around 10 million); it turns a corrupt count
/// into an error before anything of that size is allocated.
const MAX_POINTS: u32 = 100_000_000;
/// With 24 fractional bits a 24-bit position covers [-0.5, 0.5): more cannot be meant.
const MAX_FRACTIONAL_BITS: u8 = 24;
/// SPZ allows SH up to degree 4; [`Scene`] keeps up to 3.
const MAX_FILE_SH_DEGREE: u8 = 4;
const MAX_SCENE_SH_DEGREE: u8 = 3;
/// DC colour scale of the format (see the module docs).
const COLOR_SCALE: f32 = 0.15;
/// Log-scales are stored as `(log s + LOG_SCALE_OFFSET) · LOG_SCALE_STEPS`.
const LOG_SCALE_OFFSET: f32 = 10.0;
const LOG_SCALE_STEPS: f32 = 16.0;
/// SH coefficients are stored as `128 + 128 · value`.
const SH_STEPS: f32 = 128.0;
/// Deflate cannot expand data more than about 1032-fold, so a header claiming more than that
/// from the file's size is corrupt, whatever the content.
const MAX_DEFLATE_RATIO: usize = 1032;
/// A zstd block yields at most 128 KiB and costs at least 4 bytes (an RLE block), so no zstd
/// stream expands more than 32768-fold.
const MAX_ZSTD_RATIO: u64 = 32_768;
/// Largest ratio of a version 4 file's decoded arrays to its size that a capture can have.
/// zstd alone would allow [`MAX_ZSTD_RATIO`], but a capture's positions and rotations are
/// nearly random bits that compress a few-fold at most (the fruit and biker captures: 1.3–2×
/// over all arrays), so an array set more than deflate's bound larger than the whole file
/// repeats one value millions of times: a crafted or corrupt count, refused before decoding
/// (a 37 KB file claiming 60 M Gaussians took 4.5 GB under the zstd bound alone).
const MAX_PLAUSIBLE_V4_RATIO: usize = MAX_DEFLATE_RATIO;
/// Room for extension records after the arrays of a gzip file; anything beyond is ignored.
const MAX_LEGACY_EXTENSION_BYTES: usize = 1 << 20;
const FLAG_ANTIALIASED: u8 = 0x1;
const FLAG_HAS_EXTENSIONS: u8 = 0x2;
/// `SPZ_ADOBE_coordinate_system`: a u32 naming the axes the data is stored in.
const EXT_COORDINATE_SYSTEM: u32 = 0xADBE_0003;

const ATTRIBUTE_NAMES: [&str; 6] = [
    "positions",
    "alphas",
    "colours",
    "scales",
    "rotations",
    "spherical harmonics",
];

/// Decodes an SPZ file (any version 1-4) into an unvalidated scene of activated values in the
/// PLY (RDF) convention.
pub fn decode_spz(bytes: &[u8], path: &Path) -> Result<Scene> {
    if bytes.starts_with(GZIP_MAGIC) {
        return decode_gzip(bytes, path);
    }
    if bytes.starts_with(MAGIC_BYTES) {
        let Some(version) = read_u32(bytes, 4) else {
            return Err(malformed(
                path,
                format!(
                    "truncated: the file has {} bytes, an SPZ header needs at least 16",
                    bytes.len()
                ),
            ));
        };
        return match version {
            4 => decode_v4(bytes, path),
            // An ungzipped legacy file: the same content without the gzip wrapper.
            1..=3 => {
                let header = parse_legacy_header(bytes, path)?;
                decode_legacy_body(header, &bytes[LEGACY_HEADER_LEN..], path)
            }
            v => Err(unsupported_version(path, v)),
        };
    }
    Err(malformed(
        path,
        format!(
            "not an SPZ file: it starts with {}, expected \"NGSP\" (version 4) or a gzip stream \
             (versions 1-3)",
            show_bytes(bytes)
        ),
    ))
}

/// Header fields shared by all versions.
#[derive(Debug, Clone, Copy)]
struct Header {
    version: u32,
    count: u32,
    sh_degree: u8,
    fractional_bits: u8,
    flags: u8,
}

impl Header {
    /// Parses the 16 bytes common to all versions; `bytes` must hold at least 16.
    fn from_prefix(bytes: &[u8]) -> Option<Self> {
        Some(Header {
            version: read_u32(bytes, 4)?,
            count: read_u32(bytes, 8)?,
            sh_degree: *bytes.get(12)?,
            fractional_bits: *bytes.get(13)?,
            flags: *bytes.get(14)?,
        })
    }

    /// Rejects values no valid file holds, before any size is computed from them.
    fn check(&self, path: &Path) -> Result<()> {
        if self.count > MAX_POINTS {
            return Err(malformed(
                path,
                format!(
                    "the SPZ header claims {} Gaussians; splatraj reads at most {MAX_POINTS} \
                     (the count is most likely corrupt)",
                    self.count
                ),
            ));
        }
        if self.sh_degree > MAX_FILE_SH_DEGREE {
            return Err(malformed(
                path,
                format!(
                    "SH degree {} is impossible (SPZ allows 0-{MAX_FILE_SH_DEGREE})",
                    self.sh_degree
                ),
            ));
        }
        if self.fractional_bits > MAX_FRACTIONAL_BITS {
            return Err(malformed(
                path,
                format!(
                    "{} fractional bits for positions is impossible (at most \
                     {MAX_FRACTIONAL_BITS} fit a 24-bit fixed-point value)",
                    self.fractional_bits
                ),
            ));
        }
        Ok(())
    }

    /// Bytes of each attribute array, in file order.
    fn attribute_sizes(&self, path: &Path) -> Result<[usize; 6]> {
        let position = if self.version == 1 { 6 } else { 9 };
        let rotation = if self.version >= 3 { 4 } else { 3 };
        let per_gaussian = [position, 1, 3, 3, rotation, 3 * sh_dim(self.sh_degree)];
        let n = self.count as usize;
        let mut sizes = [0usize; 6];
        for (size, per) in sizes.iter_mut().zip(per_gaussian) {
            *size = n
                .checked_mul(per)
                .ok_or_else(|| too_large(path, self.count))?;
        }
        Ok(sizes)
    }
}

/// SH coefficients per colour channel beyond the DC term, as SPZ stores them.
fn sh_dim(degree: u8) -> usize {
    sh_coeffs_for_degree(degree) - 1
}

fn parse_legacy_header(bytes: &[u8], path: &Path) -> Result<Header> {
    let header = bytes
        .get(..LEGACY_HEADER_LEN)
        .and_then(Header::from_prefix)
        .ok_or_else(|| {
            malformed(
                path,
                format!(
                    "truncated: the SPZ content has {} bytes, its header needs {LEGACY_HEADER_LEN}",
                    bytes.len()
                ),
            )
        })?;
    match header.version {
        1..=3 => {}
        4 => {
            return Err(malformed(
                path,
                "SPZ version 4 inside a gzip stream: version 4 files are not gzipped (their \
                 streams are zstd-compressed), so this file is corrupt",
            ));
        }
        v => return Err(unsupported_version(path, v)),
    }
    header.check(path)?;
    Ok(header)
}

/// Versions 1-3: gunzips (bounded by what the header says) and decodes the content.
fn decode_gzip(bytes: &[u8], path: &Path) -> Result<Scene> {
    let gzip_error = |e: std::io::Error| {
        malformed(
            path,
            format!("the SPZ gzip stream is truncated or corrupt: {e}"),
        )
    };
    let mut gz = flate2::read::GzDecoder::new(bytes);
    let mut head = Vec::with_capacity(LEGACY_HEADER_LEN);
    (&mut gz)
        .take(LEGACY_HEADER_LEN as u64)
        .read_to_end(&mut head)
        .map_err(gzip_error)?;
    if !head.starts_with(MAGIC_BYTES) {
        return Err(malformed(
            path,
            format!(
                "the gzip stream does not hold an SPZ file: its content starts with {}, expected \
                 \"NGSP\"",
                show_bytes(&head)
            ),
        ));
    }
    let header = parse_legacy_header(&head, path)?;
    let sizes = header.attribute_sizes(path)?;
    let payload = checked_sum(&sizes).ok_or_else(|| too_large(path, header.count))?;
    let most = bytes.len().saturating_mul(MAX_DEFLATE_RATIO);
    if payload > most {
        return Err(malformed(
            path,
            format!(
                "the SPZ header claims {} Gaussians ({payload} bytes of data), but a gzip stream \
                 of {} bytes holds at most about {most}: the count is corrupt",
                header.count,
                bytes.len()
            ),
        ));
    }
    let limit = payload.saturating_add(MAX_LEGACY_EXTENSION_BYTES);
    let mut body = Vec::new();
    body.try_reserve_exact(payload)
        .map_err(|_| too_large(path, header.count))?;
    (&mut gz)
        .take(limit as u64 + 1)
        .read_to_end(&mut body)
        .map_err(gzip_error)?;
    if body.len() > limit {
        tracing::warn!(
            "{}: more than {MAX_LEGACY_EXTENSION_BYTES} bytes follow the SPZ data; ignoring them",
            path.display()
        );
        body.truncate(limit);
    }
    decode_legacy_body(header, &body, path)
}

/// Decodes the arrays (and extension records) that follow a 16-byte legacy header.
fn decode_legacy_body(header: Header, body: &[u8], path: &Path) -> Result<Scene> {
    let sizes = header.attribute_sizes(path)?;
    let payload = checked_sum(&sizes).ok_or_else(|| too_large(path, header.count))?;
    let (data, extensions) = split_legacy_extensions(body, payload, header.flags, path);
    let arrays = split_arrays(data, &sizes, path)?;
    let records = parse_extension_records(extensions).map_err(|e| malformed(path, e))?;
    let flips = axis_flips(&records, path)?;
    unpack(&header, &arrays, flips, path)
}

/// Finds the data and the extension records in a legacy body. Current writers append the
/// records after the arrays, an earlier one put them before; the records' own framing tells.
fn split_legacy_extensions<'a>(
    body: &'a [u8],
    payload: usize,
    flags: u8,
    path: &Path,
) -> (&'a [u8], &'a [u8]) {
    let extra = body.len().saturating_sub(payload);
    if extra == 0 {
        return (body, &[]);
    }
    let (head, tail) = body.split_at(payload);
    if flags & FLAG_HAS_EXTENSIONS != 0 {
        if parse_extension_records(tail).is_ok() {
            return (head, tail);
        }
        let (lead, rest) = body.split_at(extra);
        if parse_extension_records(lead).is_ok() {
            return (rest, lead);
        }
    }
    tracing::warn!(
        "{}: ignoring {extra} bytes after the SPZ data that are not extension records",
        path.display()
    );
    (head, &[])
}

/// Version 4: plain header, extension records, table of contents, one zstd stream per array.
fn decode_v4(bytes: &[u8], path: &Path) -> Result<Scene> {
    if bytes.len() < V4_HEADER_LEN {
        return Err(malformed(
            path,
            format!(
                "truncated: the file has {} bytes, an SPZ version 4 header needs {V4_HEADER_LEN}",
                bytes.len()
            ),
        ));
    }
    let header = Header::from_prefix(bytes).ok_or_else(|| malformed(path, "truncated header"))?;
    header.check(path)?;
    let declared_streams = bytes[15] as usize;
    let toc_offset = read_u32(bytes, 16).unwrap_or(0) as usize;
    let sizes = header.attribute_sizes(path)?;
    // Writers omit empty arrays (SH at degree 0, everything when there are no Gaussians).
    let streams: Vec<usize> = (0..6).filter(|&a| sizes[a] > 0).collect();
    if declared_streams != streams.len() {
        let names: Vec<&str> = streams.iter().map(|&a| ATTRIBUTE_NAMES[a]).collect();
        return Err(malformed(
            path,
            format!(
                "the SPZ header declares {declared_streams} streams, but {} Gaussians of SH \
                 degree {} need {} ({})",
                header.count,
                header.sh_degree,
                streams.len(),
                names.join(", ")
            ),
        ));
    }
    if toc_offset < V4_HEADER_LEN {
        return Err(malformed(
            path,
            format!(
                "the SPZ table of contents offset {toc_offset} points into the {V4_HEADER_LEN}-byte \
                 header"
            ),
        ));
    }
    let toc_end = toc_offset.saturating_add(declared_streams * TOC_ENTRY_LEN);
    if toc_end > bytes.len() {
        return Err(malformed(
            path,
            format!(
                "truncated: the SPZ table of contents needs bytes {toc_offset}..{toc_end}, the \
                 file has {}",
                bytes.len()
            ),
        ));
    }
    // A file too short for its streams is reported as truncated by the loop below; one that
    // holds them all is judged on what they claim to decode to.
    let declared = (0..declared_streams)
        .map(|i| read_u64(bytes, toc_offset + i * TOC_ENTRY_LEN).unwrap_or(0))
        .fold(0u64, u64::saturating_add);
    let decoded_bytes = sizes.iter().fold(0usize, |a, &b| a.saturating_add(b));
    if (toc_end as u64).saturating_add(declared) <= bytes.len() as u64
        && decoded_bytes > bytes.len().saturating_mul(MAX_PLAUSIBLE_V4_RATIO)
    {
        return Err(malformed(
            path,
            format!(
                "the SPZ header claims {} Gaussians ({decoded_bytes} bytes of arrays) in a \
                 {}-byte file, more than {MAX_PLAUSIBLE_V4_RATIO}-fold: a capture's positions \
                 and rotations compress a few-fold at most, so the count is corrupt",
                header.count,
                bytes.len()
            ),
        ));
    }
    let extension_zone = &bytes[V4_HEADER_LEN..toc_offset];
    let records = if header.flags & FLAG_HAS_EXTENSIONS != 0 {
        parse_extension_records(extension_zone).map_err(|e| malformed(path, e))?
    } else {
        if !extension_zone.is_empty() {
            tracing::warn!(
                "{}: ignoring {} bytes between the SPZ header and its table of contents",
                path.display(),
                extension_zone.len()
            );
        }
        Vec::new()
    };
    let flips = axis_flips(&records, path)?;

    let mut decoded: [Vec<u8>; 6] = Default::default();
    let mut offset = toc_end;
    for (i, &attribute) in streams.iter().enumerate() {
        let entry = toc_offset + i * TOC_ENTRY_LEN;
        let compressed = read_u64(bytes, entry).unwrap_or(0);
        let uncompressed = read_u64(bytes, entry + 8).unwrap_or(0);
        let name = ATTRIBUTE_NAMES[attribute];
        let expected = sizes[attribute];
        if uncompressed != expected as u64 {
            return Err(malformed(
                path,
                format!(
                    "SPZ stream {i} ({name}): the table of contents says {uncompressed} bytes \
                     uncompressed, {} Gaussians need {expected}",
                    header.count
                ),
            ));
        }
        let remaining = bytes.len() - offset;
        if compressed > remaining as u64 {
            return Err(malformed(
                path,
                format!(
                    "truncated: SPZ stream {i} ({name}) needs {compressed} compressed bytes, \
                     {remaining} remain"
                ),
            ));
        }
        if expected as u64 > compressed.saturating_mul(MAX_ZSTD_RATIO) {
            return Err(malformed(
                path,
                format!(
                    "SPZ stream {i} ({name}) cannot hold {expected} bytes in {compressed} \
                     compressed bytes (zstd expands at most {MAX_ZSTD_RATIO}-fold): the count or \
                     the table of contents is corrupt"
                ),
            ));
        }
        let end = offset + compressed as usize;
        decoded[attribute] = decompress_zstd(&bytes[offset..end], expected, i, name, path)?;
        offset = end;
    }
    if offset < bytes.len() {
        tracing::warn!(
            "{}: ignoring {} bytes after the last SPZ stream",
            path.display(),
            bytes.len() - offset
        );
    }
    let arrays: [&[u8]; 6] = std::array::from_fn(|a| decoded[a].as_slice());
    unpack(&header, &arrays, flips, path)
}

/// Decompresses one zstd stream (one or more frames) that must yield exactly `expected` bytes.
fn decompress_zstd(
    src: &[u8],
    expected: usize,
    index: usize,
    name: &str,
    path: &Path,
) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    out.try_reserve_exact(expected).map_err(|_| {
        malformed(
            path,
            format!("SPZ stream {index} ({name}): cannot allocate {expected} bytes"),
        )
    })?;
    out.resize(expected, 0);
    let mut decoder = ruzstd::decoding::FrameDecoder::new();
    match decoder.decode_all(src, &mut out) {
        Ok(written) if written == expected => Ok(out),
        Ok(written) => Err(malformed(
            path,
            format!(
                "truncated: SPZ stream {index} ({name}) decompresses to {written} bytes, \
                 {expected} expected"
            ),
        )),
        Err(ruzstd::decoding::errors::FrameDecoderError::TargetTooSmall) => Err(malformed(
            path,
            format!(
                "SPZ stream {index} ({name}) decompresses to more than the {expected} bytes its \
                 table of contents gives"
            ),
        )),
        Err(e) => Err(malformed(
            path,
            format!("SPZ stream {index} ({name}) is not valid zstd data: {e}"),
        )),
    }
}

/// Cuts the six arrays out of `data`, naming the first one that is short.
fn split_arrays<'a>(data: &'a [u8], sizes: &[usize; 6], path: &Path) -> Result<[&'a [u8]; 6]> {
    let mut arrays: [&[u8]; 6] = [&[]; 6];
    let mut rest = data;
    for (a, &size) in sizes.iter().enumerate() {
        if rest.len() < size {
            return Err(malformed(
                path,
                format!(
                    "truncated: SPZ {} need {size} bytes, {} remain",
                    ATTRIBUTE_NAMES[a],
                    rest.len()
                ),
            ));
        }
        let (array, tail) = rest.split_at(size);
        arrays[a] = array;
        rest = tail;
    }
    Ok(arrays)
}

/// One `type, length, payload` extension record.
#[derive(Debug, Clone, Copy)]
struct ExtensionRecord<'a> {
    kind: u32,
    payload: &'a [u8],
}

/// Splits a block of extension records; `Err` says what is wrong with the framing.
fn parse_extension_records(block: &[u8]) -> std::result::Result<Vec<ExtensionRecord<'_>>, String> {
    let mut records = Vec::new();
    let mut at = 0usize;
    while at < block.len() {
        let (Some(kind), Some(len)) = (read_u32(block, at), read_u32(block, at + 4)) else {
            return Err(format!(
                "SPZ extension record at byte {at} of its block is cut short: {} bytes remain, a \
                 record header needs 8",
                block.len() - at
            ));
        };
        let start = at + 8;
        let len = len as usize;
        let Some(payload) = block.get(start..start.saturating_add(len)) else {
            return Err(format!(
                "SPZ extension record 0x{kind:08x} claims {len} bytes, {} remain",
                block.len() - start
            ));
        };
        records.push(ExtensionRecord { kind, payload });
        at = start + len;
    }
    Ok(records)
}

/// Sign flips that take the file's axes to the scene's RDF axes. Each flip is its own inverse,
/// so the same signs take the scene's axes back to the file's (the writer uses them so).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct AxisFlips(pub(crate) [f32; 3]);

impl AxisFlips {
    /// SPZ's default storage axes, RUB, to RDF (and back): y and z change sign.
    pub(crate) const RUB_TO_RDF: AxisFlips = AxisFlips([1.0, -1.0, -1.0]);

    /// Signs of the quaternion's x, y, z under the flip.
    ///
    /// Flipping axes with F = diag(f) maps a rotation R to F R F. Whether F is a rotation or a
    /// reflection, F R F = G R G⁻¹ for the rotation G = det(F)·F, a half turn (or identity) about
    /// a coordinate axis, and conjugating by it scales the quaternion's vector part by det(F)·f.
    pub(crate) fn quaternion_signs(self) -> [f32; 3] {
        let [x, y, z] = self.0;
        let det = x * y * z;
        [det * x, det * y, det * z]
    }

    /// Sign of each SH coefficient beyond DC (degrees 1-3, 15 of them) under the flip: the
    /// product of the flips of the axes that the basis polynomial is odd in.
    pub(crate) fn sh_signs(self) -> [f32; 15] {
        // Odd-in (x, y, z) of the real SH basis in the usual 3DGS order: y, z, x; xy, yz,
        // 3z²−1, xz, x²−y²; y(3x²−y²), xyz, y(4z²−x²−y²), z(2z²−3x²−3y²), x(4z²−x²−y²),
        // z(x²−y²), x(x²−3y²).
        const ODD: [[bool; 3]; 15] = [
            [false, true, false],
            [false, false, true],
            [true, false, false],
            [true, true, false],
            [false, true, true],
            [false, false, false],
            [true, false, true],
            [false, false, false],
            [false, true, false],
            [true, true, true],
            [false, true, false],
            [false, false, true],
            [true, false, false],
            [false, false, true],
            [true, false, false],
        ];
        ODD.map(|odd| {
            (0..3)
                .filter(|&k| odd[k])
                .map(|k| self.0[k])
                .product::<f32>()
        })
    }
}

/// Axis flips for the file's coordinate system: RUB unless `SPZ_ADOBE_coordinate_system` says
/// otherwise. Other extensions carry nothing the scene needs and are skipped.
fn axis_flips(records: &[ExtensionRecord<'_>], path: &Path) -> Result<AxisFlips> {
    let mut flips = AxisFlips::RUB_TO_RDF;
    for record in records {
        if record.kind != EXT_COORDINATE_SYSTEM {
            tracing::debug!(
                "{}: skipping SPZ extension 0x{:08x} ({} bytes)",
                path.display(),
                record.kind,
                record.payload.len()
            );
            continue;
        }
        let code = read_u32(record.payload, 0).ok_or_else(|| {
            malformed(
                path,
                format!(
                    "the SPZ coordinate-system extension has {} payload bytes, it needs 4",
                    record.payload.len()
                ),
            )
        })?;
        flips = flips_for_coordinate_system(code, path)?;
    }
    Ok(flips)
}

/// Flips from the named axes of `SPZ_ADOBE_coordinate_system` to RDF.
fn flips_for_coordinate_system(code: u32, path: &Path) -> Result<AxisFlips> {
    // Codes 1-8 are plain axis directions; 9-16 swap y and z by a quarter turn.
    const NAMES: [&str; 17] = [
        "UNSPECIFIED",
        "LDB",
        "RDB",
        "LUB",
        "RUB",
        "LDF",
        "RDF",
        "LUF",
        "RUF",
        "LFD",
        "RFD",
        "LFU",
        "RFU",
        "LBD",
        "RBD",
        "LBU",
        "RBU",
    ];
    match code {
        // The reference loader reads UNSPECIFIED as the default, RUB.
        0 => Ok(AxisFlips::RUB_TO_RDF),
        1..=8 => {
            let axes = NAMES[code as usize].as_bytes();
            let sign = |letter: u8, towards_rdf: u8| if letter == towards_rdf { 1.0 } else { -1.0 };
            Ok(AxisFlips([
                sign(axes[0], b'R'),
                sign(axes[1], b'D'),
                sign(axes[2], b'F'),
            ]))
        }
        9..=16 => Err(malformed(
            path,
            format!(
                "the SPZ data is stored in {} axes (SPZ_ADOBE_coordinate_system = {code}), a \
                 rotated system splatraj does not read; convert the file to RUB or RDF first",
                NAMES[code as usize]
            ),
        )),
        _ => Err(malformed(
            path,
            format!(
                "unknown SPZ coordinate system {code} (SPZ_ADOBE_coordinate_system allows 0-16)"
            ),
        )),
    }
}

/// Turns the packed arrays (already checked to have the sizes the header implies) into a scene.
fn unpack(header: &Header, arrays: &[&[u8]; 6], flips: AxisFlips, path: &Path) -> Result<Scene> {
    let n = header.count as usize;
    let [positions, alphas, colours, scales, rotations, sh_bytes] = *arrays;
    let sh_degree = header.sh_degree.min(MAX_SCENE_SH_DEGREE);
    if header.sh_degree > MAX_SCENE_SH_DEGREE {
        tracing::warn!(
            "{}: SPZ SH degree {} is more than splatraj renders; keeping degrees 0-{}",
            path.display(),
            header.sh_degree,
            MAX_SCENE_SH_DEGREE
        );
    }
    if header.flags & FLAG_ANTIALIASED != 0 {
        // Such scenes were trained with Mip-Splatting's filter in the renderer; ours has none,
        // so they may show some aliasing. Worth a note, not a refusal.
        tracing::info!(
            "{}: the SPZ scene was trained with antialiasing; it is rendered without the filter",
            path.display()
        );
    }
    let file_dim = sh_dim(header.sh_degree);
    let kept_dim = sh_dim(sh_degree);
    let unit = 2f32.powi(-i32::from(header.fractional_bits));
    let f = flips.0;
    let q_signs = flips.quaternion_signs();
    let sh_signs = flips.sh_signs();

    let means: Vec<[f32; 3]> = if header.version == 1 {
        positions
            .chunks_exact(6)
            .map(|p| {
                std::array::from_fn(|k| {
                    f[k] * f16_to_f32(u16::from_le_bytes([p[2 * k], p[2 * k + 1]]))
                })
            })
            .collect()
    } else {
        positions
            .chunks_exact(9)
            .map(|p| {
                std::array::from_fn(|k| {
                    // Shift up then back down (arithmetic) to sign-extend the 24-bit value.
                    let raw = i32::from_le_bytes([0, p[3 * k], p[3 * k + 1], p[3 * k + 2]]) >> 8;
                    f[k] * raw as f32 * unit
                })
            })
            .collect()
    };
    let opacities: Vec<f32> = alphas.iter().map(|&a| f32::from(a) / 255.0).collect();
    let scales: Vec<[f32; 3]> = scales
        .chunks_exact(3)
        .map(|s| std::array::from_fn(|k| log_scale_from_byte(s[k]).exp()))
        .collect();
    let to_scene_quaternion =
        |[x, y, z, w]: [f32; 4]| [w, q_signs[0] * x, q_signs[1] * y, q_signs[2] * z];
    let rotations: Vec<[f32; 4]> = if header.version >= 3 {
        rotations
            .chunks_exact(4)
            .map(|r| to_scene_quaternion(quaternion_smallest_three(r)))
            .collect()
    } else {
        rotations
            .chunks_exact(3)
            .map(|r| to_scene_quaternion(quaternion_first_three(r)))
            .collect()
    };

    let stride = 3 * (kept_dim + 1);
    let mut sh = Vec::with_capacity(n * stride);
    let dc_of = |dc: &[u8]| -> [f32; 3] { std::array::from_fn(|c| dc_from_byte(dc[c])) };
    if kept_dim == 0 {
        for dc in colours.chunks_exact(3) {
            sh.extend(dc_of(dc));
        }
    } else {
        // Degree-4 coefficients (if any) come last in each Gaussian's run and are skipped.
        for (dc, rest) in colours
            .chunks_exact(3)
            .zip(sh_bytes.chunks_exact(3 * file_dim))
        {
            sh.extend(dc_of(dc));
            for (coeff, sign) in rest.chunks_exact(3).take(kept_dim).zip(sh_signs) {
                sh.extend(coeff.iter().map(|&b| sign * sh_from_byte(b)));
            }
        }
    }

    let lengths = [
        means.len(),
        opacities.len(),
        scales.len(),
        rotations.len(),
        sh.len() / stride,
    ];
    if lengths.iter().any(|&l| l != n) {
        // The callers size every array from the header, so this is a bug, not bad input.
        return Err(malformed(
            path,
            format!("SPZ arrays decode to {lengths:?} Gaussians, {n} expected"),
        ));
    }
    Ok(Scene {
        means,
        scales,
        rotations,
        opacities,
        sh_degree,
        sh,
        extras: Default::default(),
    })
}

/// Versions 1-2: x, y, z as u8 in [-1, 1]; w ≥ 0 from the unit norm. Returns (x, y, z, w).
fn quaternion_first_three(r: &[u8]) -> [f32; 4] {
    let [x, y, z] = [r[0], r[1], r[2]].map(|b| f32::from(b) / 127.5 - 1.0);
    let w = (1.0 - (x * x + y * y + z * z)).max(0.0).sqrt();
    [x, y, z, w]
}

/// Versions 3-4: "smallest three" in a little-endian u32 (see the module docs). Returns
/// (x, y, z, w).
fn quaternion_smallest_three(r: &[u8]) -> [f32; 4] {
    let mut bits = u32::from_le_bytes([r[0], r[1], r[2], r[3]]);
    let largest = (bits >> 30) as usize;
    let mut q = [0.0f32; 4];
    let mut sum_sq = 0.0;
    for i in (0..4).rev().filter(|&i| i != largest) {
        let magnitude = (bits & 0x1ff) as f32 / 511.0 * FRAC_1_SQRT_2;
        let value = if bits & 0x200 != 0 {
            -magnitude
        } else {
            magnitude
        };
        bits >>= 10;
        q[i] = value;
        sum_sq += value * value;
    }
    q[largest] = (1.0 - sum_sq).max(0.0).sqrt();
    q
}

/// Rounds to the nearest byte, saturating: how the reference writer stores every 8-bit value.
pub(crate) fn to_byte(x: f32) -> u8 {
    x.round().clamp(0.0, 255.0) as u8
}

/// A log-scale from its byte.
pub(crate) fn log_scale_from_byte(byte: u8) -> f32 {
    f32::from(byte) / LOG_SCALE_STEPS - LOG_SCALE_OFFSET
}

/// The byte of a log-scale (saturating outside about [-10, 5.9], i.e. scales e⁻¹⁰ to 380).
pub(crate) fn log_scale_to_byte(log_scale: f32) -> u8 {
    to_byte((log_scale + LOG_SCALE_OFFSET) * LOG_SCALE_STEPS)
}

/// The SH DC term from its colour byte.
pub(crate) fn dc_from_byte(byte: u8) -> f32 {
    (f32::from(byte) / 255.0 - 0.5) / COLOR_SCALE
}

/// The colour byte of an SH DC term.
pub(crate) fn dc_to_byte(dc: f32) -> u8 {
    to_byte(dc * (COLOR_SCALE * 255.0) + 0.5 * 255.0)
}

/// An SH coefficient (degree ≥ 1) from its byte.
pub(crate) fn sh_from_byte(byte: u8) -> f32 {
    (f32::from(byte) - SH_STEPS) / SH_STEPS
}

/// The byte of an SH coefficient kept to `bits` significant bits: the 8-bit value is rounded to
/// a multiple of 2^(8 − bits), so 0 stays exact and gzip finds more repeats.
pub(crate) fn sh_to_byte(value: f32, bits: u32) -> u8 {
    let bucket = 1i32 << (8 - bits);
    let q = (value * SH_STEPS).round() as i32 + SH_STEPS as i32;
    // Below zero everything saturates to 0 whichever way the division rounds.
    ((q + bucket / 2).max(0) / bucket * bucket).clamp(0, 255) as u8
}

/// Versions 3-4: packs a unit quaternion (x, y, z, w) as "smallest three" (see the module docs);
/// the inverse of [`quaternion_smallest_three`]. `q` and −q are the same rotation, so the sign
/// is chosen to make the dropped largest component positive.
pub(crate) fn pack_quaternion_smallest_three(q: [f32; 4]) -> [u8; 4] {
    let largest = (1..4).fold(0, |l, i| if q[i].abs() > q[l].abs() { i } else { l });
    let negate = q[largest] < 0.0;
    let mut bits = largest as u32;
    for (_, &v) in q.iter().enumerate().filter(|&(i, _)| i != largest) {
        let sign = u32::from((v < 0.0) != negate);
        // Truncating `+ 0.5` rounds half up, as the reference writer does; at most 511 for a
        // unit quaternion's non-largest components (|v| ≤ 1/√2), clamped against rounding.
        let magnitude = ((v.abs() / FRAC_1_SQRT_2 * 511.0 + 0.5) as u32).min(511);
        bits = (bits << 10) | (sign << 9) | magnitude;
    }
    bits.to_le_bytes()
}

fn checked_sum(sizes: &[usize]) -> Option<usize> {
    sizes.iter().try_fold(0usize, |acc, &s| acc.checked_add(s))
}

fn malformed(path: &Path, detail: impl Into<String>) -> SceneError {
    SceneError::malformed(path, detail)
}

fn unsupported_version(path: &Path, version: u32) -> SceneError {
    malformed(
        path,
        format!("SPZ version {version} is not supported (1-4 are)"),
    )
}

fn too_large(path: &Path, count: u32) -> SceneError {
    malformed(
        path,
        format!("the SPZ header claims {count} Gaussians, too many to hold in memory here"),
    )
}
