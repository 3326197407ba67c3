//! Little helpers the binary readers share: bounded little-endian reads, half floats, the
//! colour-byte convention of the web viewers' formats, and how bytes are shown in errors.

use crate::scene::SH_C0;

/// Little-endian u16 at byte `at`, or `None` past the end.
pub fn read_u16(bytes: &[u8], at: usize) -> Option<u16> {
    let b = bytes.get(at..at.checked_add(2)?)?;
    Some(u16::from_le_bytes([b[0], b[1]]))
}

/// Little-endian u32 at byte `at`, or `None` past the end.
pub fn read_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let b = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// Little-endian u64 at byte `at`, or `None` past the end.
pub fn read_u64(bytes: &[u8], at: usize) -> Option<u64> {
    let b = bytes.get(at..at.checked_add(8)?)?;
    let mut le = [0u8; 8];
    le.copy_from_slice(b);
    Some(u64::from_le_bytes(le))
}

/// Little-endian f32 at byte `at`, or `None` past the end.
pub fn read_f32(bytes: &[u8], at: usize) -> Option<f32> {
    read_u32(bytes, at).map(f32::from_bits)
}

/// IEEE 754 half precision to f32 (exact: every half is an f32).
pub fn f16_to_f32(bits: u16) -> f32 {
    let sign = if bits & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exponent = i32::from((bits >> 10) & 0x1f);
    let mantissa = f32::from(bits & 0x3ff);
    let magnitude = match exponent {
        0 => mantissa * 2f32.powi(-24),
        31 if mantissa == 0.0 => f32::INFINITY,
        31 => f32::NAN,
        e => (1.0 + mantissa / 1024.0) * 2f32.powi(e - 15),
    };
    sign * magnitude
}

/// The SH DC term from a colour byte written as `(0.5 + C0 · f_dc) · 255` (antimatter15
/// `.splat`, GaussianSplats3D `.ksplat`): the inverse, exact up to the byte's rounding.
pub fn dc_from_color_byte(byte: u8) -> f32 {
    (f32::from(byte) / 255.0 - 0.5) / SH_C0
}

/// The first bytes of a file as hex and text, for error messages.
pub fn show_bytes(bytes: &[u8]) -> String {
    let head = &bytes[..bytes.len().min(8)];
    if head.is_empty() {
        return "nothing (the file is empty)".into();
    }
    let hex: Vec<String> = head.iter().map(|b| format!("{b:02x}")).collect();
    let text: String = head
        .iter()
        .map(|&b| if b.is_ascii_graphic() { b as char } else { '.' })
        .collect();
    format!("{} ({text:?})", hex.join(" "))
}
