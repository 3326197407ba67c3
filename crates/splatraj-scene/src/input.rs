//! Reading input files bounded by their real size.
//!
//! A path given as an input may be a device (`/dev/zero` never ends, `/dev/stdin` waits), a
//! pipe (opening it waits for a writer) or a folder. Every reader goes through [`open`],
//! [`read_bytes`] or [`read_text`], which accept only a regular file (a link to one is
//! followed), and read at most the length its metadata gives, so a file that grows while it
//! is read cannot make the reader run on. The buffer is reserved fallibly: a file larger than
//! the memory gives an error naming it, not an abort.

use std::fs::File;
use std::io::{Error, ErrorKind, Read};
use std::path::Path;

/// The file at `path`, open for reading, and its length in bytes; an error unless it is a
/// regular file (checked before opening, since opening a pipe waits for a writer, and again on
/// the open file).
pub fn open(path: &Path) -> std::io::Result<(File, u64)> {
    refuse_non_regular(&std::fs::metadata(path)?)?;
    let file = File::open(path)?;
    let meta = file.metadata()?;
    refuse_non_regular(&meta)?;
    Ok((file, meta.len()))
}

/// The whole content of the regular file at `path` (at most its length when opened).
pub fn read_bytes(path: &Path) -> std::io::Result<Vec<u8>> {
    let (file, len) = open(path)?;
    let len = usize::try_from(len).map_err(|_| too_large(len))?;
    let mut bytes = Vec::new();
    bytes
        .try_reserve_exact(len)
        .map_err(|_| too_large(len as u64))?;
    file.take(len as u64).read_to_end(&mut bytes)?;
    Ok(bytes)
}

/// The whole content of the regular file at `path` as UTF-8 text.
pub fn read_text(path: &Path) -> std::io::Result<String> {
    String::from_utf8(read_bytes(path)?)
        .map_err(|_| Error::new(ErrorKind::InvalidData, "the file is not UTF-8 text"))
}

fn too_large(len: u64) -> Error {
    Error::new(
        ErrorKind::OutOfMemory,
        format!("the file's {len} bytes do not fit in memory"),
    )
}

fn refuse_non_regular(meta: &std::fs::Metadata) -> std::io::Result<()> {
    let kind = meta.file_type();
    if kind.is_file() {
        return Ok(());
    }
    let what = if kind.is_dir() {
        "a folder"
    } else {
        "not a regular file (a device, a pipe or a socket)"
    };
    Err(Error::new(
        ErrorKind::InvalidInput,
        format!("it is {what}: an input must be a regular file"),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_and_folders_are_refused_without_reading() {
        // /dev/zero would be read forever.
        let error = read_bytes(Path::new("/dev/zero")).unwrap_err();
        assert_eq!(error.kind(), ErrorKind::InvalidInput, "{error}");
        assert!(error.to_string().contains("regular file"), "{error}");
        let dir = tempfile::tempdir().unwrap();
        let error = read_text(dir.path()).unwrap_err();
        assert!(error.to_string().contains("a folder"), "{error}");
    }

    #[test]
    fn a_regular_file_is_read_whole() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.txt");
        std::fs::write(&path, "hello").unwrap();
        assert_eq!(read_text(&path).unwrap(), "hello");
        assert_eq!(open(&path).unwrap().1, 5);
        assert!(read_bytes(&dir.path().join("missing")).is_err());
    }
}
