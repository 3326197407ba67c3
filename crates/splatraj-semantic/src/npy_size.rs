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

/// Longest header read to check its shape (numpy writes tens of bytes; a longer one is left to
/// npyz's own checks).
const MAX_HEADER_BYTES: u64 = 1 << 20;

/// The header text of a `.npy` file starting with `bytes` (magic, version, length, header),
/// as far as `bytes` hold it; None when they do not start a `.npy` file.
fn header_text(bytes: &[u8]) -> Option<String> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return None;
    }
    let (length, start) = if bytes[6] == 1 {
        (
            usize::from(u16::from_le_bytes([bytes[8], bytes[9]])),
            10usize,
        )
    } else {
        let length: [u8; 4] = bytes.get(8..12)?.try_into().ok()?;
        (usize::try_from(u32::from_le_bytes(length)).ok()?, 12)
    };
    let end = start.checked_add(length)?.min(bytes.len());
    Some(String::from_utf8_lossy(bytes.get(start..end)?).into_owned())
}

/// The dimensions in the `'shape': (…)` of a header text; None when it has none that parse
/// (npyz reports those).
fn header_shape(text: &str) -> Option<Vec<u64>> {
    let after = &text[text.find("'shape'")?..];
    let open = after.find('(')?;
    let close = after.find(')')?;
    after
        .get(open + 1..close)?
        .split(',')
        .map(str::trim)
        .filter(|d| !d.is_empty())
        .map(|d| d.trim_end_matches('L').parse().ok())
        .collect()
}

/// Refuses a header (at the start of `bytes`) whose shape has more elements than 2^64: npyz
/// multiplies the dimensions unchecked, which panics in a debug build and wraps in a release
/// one. Run it before [`npyz::NpyFile::new`]; a header it cannot parse is left to npyz.
pub(crate) fn check_shape_product(bytes: &[u8]) -> Result<(), String> {
    let Some(shape) = header_text(bytes).as_deref().and_then(header_shape) else {
        return Ok(());
    };
    // npyz also multiplies every run of dimensions (its strides), so zeros do not excuse
    // the others.
    let fits = shape
        .iter()
        .try_fold(1u64, |n, &d| n.checked_mul(d.max(1)))
        .is_some();
    if fits {
        Ok(())
    } else {
        Err(format!(
            "the header's shape {shape:?} has more elements than 2^64: the header is corrupt"
        ))
    }
}

/// [`check_shape_product`] for the `.npy` file at `path` (its header read).
pub(crate) fn check_shape_product_file(path: &Path) -> Result<(), String> {
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|file| {
            file.take(12 + MAX_HEADER_BYTES)
                .read_to_end(&mut bytes)
                .map(|_| ())
        })
        .map_err(|e| e.to_string())?;
    check_shape_product(&bytes)
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

    #[test]
    fn a_shape_whose_product_overflows_is_refused_before_npyz_multiplies_it() {
        // 2^32 · 2^32 · 2 = 2^65 elements: npyz's unchecked product would panic (debug).
        let bytes = npy("(4294967296, 4294967296, 2)", &[1.0]);
        let err = check_shape_product(&bytes).unwrap_err();
        assert!(err.contains("[4294967296, 4294967296, 2]"), "{err}");
        assert!(err.contains("more elements than 2^64"), "{err}");
        // A zero dimension does not hide the overflow of the others' running products.
        assert!(check_shape_product(&npy("(0, 4294967296, 4294967296, 2)", &[])).is_err());
        // Shapes that fit pass, as does a header this check cannot parse (npyz reports it).
        check_shape_product(&npy("(3,)", &[1.0, 2.0, 3.0])).unwrap();
        check_shape_product(&npy("(2, 2)", &[1.0; 4])).unwrap();
        check_shape_product(b"not a npy file").unwrap();
    }
}
