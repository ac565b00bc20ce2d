//! Reading input files that someone else may have planted: only regular files are opened,
//! the open itself never blocks, and every kind of file has a size limit.
//!
//! This is the one way raypack reads a file a user names: scenes, camera files, MTL
//! libraries, BVH cache files, `bench --rays` ray files, `raypack report`'s bench JSON and the
//! report's font all go through [`open_regular`] (and [`read_regular`], which reads what it
//! opens). The only other files read are the kernel's own (`/proc`, `/sys`).
//! `tests/one_reader_one_writer.rs` fails when a new read elsewhere bypasses it.
//!
//! A path that is (or links to) a FIFO would block `open(2)` until a writer appears, and one
//! that is `/dev/zero` would be read until memory runs out. [`open_regular`] checks the type
//! before opening (so a device is not even opened), opens with `O_NONBLOCK | O_NOCTTY` (so a
//! FIFO swapped in after the check cannot block the open) and checks the type and size again
//! on the open descriptor, which is what is then read.

use std::fs::File;
use std::io::Read;
use std::path::Path;

/// Scene files (`.dae`, `.obj`, `.ply`) larger than this are refused (a 100M-triangle binary
/// PLY is about 1.9 GB).
pub const MAX_SCENE_BYTES: u64 = 4 << 30;
/// CS184 camera settings files larger than this are refused (real ones are 300 bytes).
pub const MAX_CAMERA_FILE_BYTES: u64 = 64 << 10;
/// Material libraries larger than this are refused (real ones are kilobytes).
pub const MAX_MTL_BYTES: u64 = 64 << 20;
/// Ray files (`bench --rays`) larger than this are refused: 134 million rays of 32 bytes.
pub const MAX_RAY_FILE_BYTES: u64 = 4 << 30;
/// Bench JSON files (`raypack report`) larger than this are refused (a bench of every method
/// at many thread counts writes tens of kilobytes).
pub const MAX_BENCH_JSON_BYTES: u64 = 64 << 20;
/// Font files larger than this are refused (a TrueType font is well under a megabyte).
pub const MAX_FONT_BYTES: u64 = 64 << 20;

/// What a file that is not a regular file is, for messages: "a FIFO (named pipe)", "a
/// character device", ….
pub fn describe_type(meta: &std::fs::Metadata) -> &'static str {
    let t = meta.file_type();
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a directory"
    } else if t.is_symlink() {
        "a symbolic link"
    } else if t.is_file() {
        "a regular file"
    } else {
        "not a regular file"
    }
}

fn not_regular(meta: &std::fs::Metadata) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("is {}, not a regular file", describe_type(meta)))
}

fn too_large(len: u64, max_bytes: u64, what: &str) -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::InvalidData,
        format!("is {len} bytes, more than the {max_bytes}-byte limit for {what}"),
    )
}

/// Opens `path` for reading if it is a regular file (symbolic links followed) of at most
/// `max_bytes`, named `what` in the error ("scene files"). Returns the file and its length.
/// Never blocks: a FIFO or a device at `path` is an error, not an open.
pub fn open_regular(path: &Path, max_bytes: u64, what: &str) -> std::io::Result<(File, u64)> {
    // Checked before opening, so that a device is never opened (opening some has effects).
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(not_regular(&meta));
    }
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        // A FIFO swapped in after the check: the open returns at once instead of waiting
        // for a writer (reads of regular files ignore O_NONBLOCK).
        options.custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY);
    }
    let file = options.open(path)?;
    // The descriptor's own type and size, whatever the path names by now.
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(not_regular(&meta));
    }
    if meta.len() > max_bytes {
        return Err(too_large(meta.len(), max_bytes, what));
    }
    Ok((file, meta.len()))
}

/// The bytes of the regular file at `path`, at most `max_bytes` of them (see
/// [`open_regular`]); a file that grows past the limit while it is read is an error too.
pub fn read_regular(path: &Path, max_bytes: u64, what: &str) -> std::io::Result<Vec<u8>> {
    let (file, len) = open_regular(path, max_bytes, what)?;
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(max_bytes.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_large(bytes.len() as u64, max_bytes, what));
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_files_are_read_and_everything_else_refused() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("f");
        std::fs::write(&f, b"hello").unwrap();
        assert_eq!(read_regular(&f, 5, "tests").unwrap(), b"hello");
        let e = read_regular(&f, 4, "tests").unwrap_err();
        assert!(e.to_string().contains("5 bytes, more than the 4-byte limit for tests"), "{e}");
        let e = read_regular(dir.path(), 1 << 20, "tests").unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
        #[cfg(unix)]
        {
            let e = read_regular(Path::new("/dev/zero"), 1 << 20, "tests").unwrap_err();
            assert!(e.to_string().contains("character device"), "{e}");
            let link = dir.path().join("zero");
            std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
            assert!(read_regular(&link, 1 << 20, "tests").is_err());
        }
    }
}
