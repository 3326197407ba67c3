//! The size check every `.npy` reader runs before it reads the data: the header's shape and
//! dtype must account for exactly the bytes after the header. A shape that claims more than
//! the file holds would otherwise surface as "failed to fill whole buffer" (or, with a huge
//! claim, as an allocation of that size), and one that claims less would silently drop data.

use std::io::Read;
use std::path::Path;

use npyz::NpyHeader;

/// Bytes of data after the header of a `.npy` file of `total` bytes that starts with `prefix`
/// (its first 12 bytes or more): magic (6 bytes), version (2), header length (2 bytes in
/// version 1, 4 in versions 2 and 3), header. `None` if the prefix is not a `.npy` start or
/// the header runs past the end.
fn data_bytes(prefix: &[u8], total: u64) -> Option<u64> {
    if prefix.len() < 10 || &prefix[..6] != b"\x93NUMPY" {
        return None;
    }
    let (length, start) = if prefix[6] == 1 {
        (u64::from(u16::from_le_bytes([prefix[8], prefix[9]])), 10)
    } else {
        let bytes: [u8; 4] = prefix.get(8..12)?.try_into().ok()?;
        (u64::from(u32::from_le_bytes(bytes)), 12)
    };
    total.checked_sub(start + length)
}

/// Checks that `header`'s shape × item size is the `data` bytes the file holds after it.
fn check(header: &NpyHeader, data: Option<u64>) -> Result<(), String> {
    let shape = header.shape();
    let item = header.dtype().num_bytes().map(|b| b as u64);
    let needed = item.and_then(|item| shape.iter().try_fold(item, |n, &d| n.checked_mul(d)));
    let Some(data) = data else {
        return Err("the header runs past the end of the file".into());
    };
    match needed {
        Some(needed) if needed == data => Ok(()),
        needed => Err(format!(
            "the header's shape {shape:?} of dtype {} needs {} bytes of data but the file \
             holds {data} after its header",
            header.dtype().descr(),
            needed.map_or("more than 2^64".to_string(), |n| n.to_string()),
        )),
    }
}

/// [`check`] for the `.npy` file at `path` (its size and first bytes read again).
pub(crate) fn check_npy_file(path: &Path, header: &NpyHeader) -> Result<(), String> {
    let read = || -> std::io::Result<(Vec<u8>, u64)> {
        let file = std::fs::File::open(path)?;
        let total = file.metadata()?.len();
        let mut prefix = Vec::with_capacity(12);
        file.take(12).read_to_end(&mut prefix)?;
        Ok((prefix, total))
    };
    let (prefix, total) = read().map_err(|e| e.to_string())?;
    check(header, data_bytes(&prefix, total))
}

/// [`check`] for a `.npy` file held in memory.
pub(crate) fn check_npy_bytes(bytes: &[u8], header: &NpyHeader) -> Result<(), String> {
    check(header, data_bytes(bytes, bytes.len() as u64))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A version-1 `.npy` of little-endian f32 values with the header claiming `shape`.
    fn npy(shape: &str, values: &[f32]) -> Vec<u8> {
        let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}");
        while (10 + header.len() + 1) % 64 != 0 {
            header.push(' ');
        }
        header.push('\n');
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        bytes.extend((header.len() as u16).to_le_bytes());
        bytes.extend(header.as_bytes());
        for v in values {
            bytes.extend(v.to_le_bytes());
        }
        bytes
    }

    fn checked(shape: &str, values: &[f32]) -> Result<(), String> {
        let bytes = npy(shape, values);
        let file = npyz::NpyFile::new(&bytes[..]).unwrap();
        check_npy_bytes(&bytes, file.header())
    }

    #[test]
    fn a_shape_that_matches_the_data_passes() {
        checked("(3,)", &[1.0, 2.0, 3.0]).unwrap();
        checked("(2, 2)", &[1.0, 2.0, 3.0, 4.0]).unwrap();
    }

    #[test]
    fn a_shape_claiming_more_or_less_than_the_data_is_refused_with_both_sizes() {
        let err = checked("(4,)", &[1.0, 2.0, 3.0]).unwrap_err();
        assert!(
            err.contains("[4]") && err.contains("16 bytes") && err.contains("holds 12"),
            "{err}"
        );
        let err = checked("(2,)", &[1.0, 2.0, 3.0]).unwrap_err();
        assert!(err.contains("needs 8 bytes"), "{err}");
        let err = checked("(2147483648, 2147483648)", &[1.0]).unwrap_err();
        assert!(err.contains("more than 2^64"), "{err}");
    }
}
