//! Reading an input file safely: regular files only, a size limit checked
//! before reading, and offending text quoted short.
//!
//! | input | limit |
//! |---|---|
//! | setup (TOML) | [`MAX_SETUP_BYTES`] = 1 MiB |
//! | robot (URDF) | [`MAX_URDF_BYTES`] = 16 MiB; at most [`crate::io::urdf::MAX_XML_ELEMENTS`] = 100,000 elements, nested at most [`crate::io::urdf::MAX_XML_DEPTH`] = 64 deep (checked in one pass before the parser) |
//! | measurements (CSV), FIGAROH mocap export | [`MAX_DATA_BYTES`] = 1 GiB by default (`robcal calibrate --max-data-mib`) |
//!
//! A FIFO, a device (`/dev/zero`), a socket or a directory is refused from
//! its metadata, before it is opened: nothing blocks and nothing is read
//! without bound. A symbolic link is followed to what it names, which must
//! be a regular file.

use std::io::Read;
use std::path::Path;

pub use crate::io::error::{quote, shorten, MAX_MESSAGE_CHARS, MAX_QUOTE_CHARS};
use crate::io::error::{ErrorKind, InputError};

/// Largest setup file \[bytes\].
pub const MAX_SETUP_BYTES: u64 = 1 << 20;
/// Largest URDF file \[bytes\].
pub const MAX_URDF_BYTES: u64 = 16 << 20;
/// Largest measurement or mocap file by default \[bytes\].
pub const MAX_DATA_BYTES: u64 = 1 << 30;

/// What a path is, for an error.
fn kind_of(meta: &std::fs::Metadata) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let t = meta.file_type();
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if meta.is_dir() {
        "a directory"
    } else {
        "not a regular file"
    }
}

/// The bytes of the regular file `path`, at most `limit` of them; `what`
/// names the input in errors ("the URDF").
///
/// # Errors
/// [`ErrorKind::Io`]: the path does not exist or cannot be read, is not a
/// regular file, or is larger than `limit`.
pub fn read_limited(path: &Path, what: &str, limit: u64) -> Result<Vec<u8>, InputError> {
    let io = |m: String| InputError::new(path, ErrorKind::Io, m);
    let meta = std::fs::metadata(path).map_err(|e| io(format!("cannot read {what}: {e}")))?;
    if !meta.is_file() {
        return Err(io(format!(
            "cannot read {what}: it is {}, not a regular file",
            kind_of(&meta)
        )));
    }
    let too_large = |n: u64| {
        io(format!(
            "{what} is {} bytes, more than the limit of {limit} bytes",
            n
        ))
    };
    if meta.len() > limit {
        return Err(too_large(meta.len()));
    }
    let file = std::fs::File::open(path).map_err(|e| io(format!("cannot read {what}: {e}")))?;
    if let Some(bytes) = read_in_pieces(&file, meta.len(), crate::parallel::threads()) {
        return Ok(bytes);
    }
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len()).unwrap_or(0));
    // The file may grow between the check and the read.
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| io(format!("cannot read {what}: {e}")))?;
    if bytes.len() as u64 > limit {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// Files at least this large are read in pieces on the engine's threads
/// ([`read_in_pieces`]).
const PIECES_FROM_BYTES: u64 = 32 << 20;

/// The `len` bytes of `file` read in one piece per thread (`threads`: the
/// engine's), each at its own offset, into one buffer
/// ([`crate::parallel::for_runs_mut`]: a piece whose thread the
/// system refuses is read on this one). The kernel's copy into fresh pages
/// (and their faults) was ~0.3 s of one thread for a file of 10⁶ rows
/// (187 MB), before anything else could start. `None` (the caller reads
/// the file from the start, as for a small file) on one thread, for a
/// file below [`PIECES_FROM_BYTES`], on any error, or when the file is not
/// exactly `len` bytes long any more.
#[cfg(unix)]
fn read_in_pieces(file: &std::fs::File, len: u64, threads: usize) -> Option<Vec<u8>> {
    use std::os::unix::fs::FileExt;
    if threads < 2 || len < PIECES_FROM_BYTES {
        return None;
    }
    let len = usize::try_from(len).ok()?;
    // Zeroed by the allocator (fresh pages for a buffer this large): each
    // page is first touched by the thread that reads into it.
    let mut bytes = vec![0_u8; len];
    crate::parallel::for_runs_mut(&mut bytes, threads, |first, piece| {
        file.read_exact_at(piece, first as u64)
    })
    .ok()?;
    // Grown since its metadata was read: the caller's read sees its limit.
    let mut past = [0_u8; 1];
    let ended = file.read_at(&mut past, len as u64).ok()? == 0;
    ended.then_some(bytes)
}

/// [`read_in_pieces`] where there is no positioned read: never.
#[cfg(not(unix))]
fn read_in_pieces(_file: &std::fs::File, _len: u64, _threads: usize) -> Option<Vec<u8>> {
    None
}

/// As [`read_limited`], as UTF-8 text.
///
/// # Errors
/// As [`read_limited`]; [`ErrorKind::Syntax`] for text that is not UTF-8.
pub fn read_text(path: &Path, what: &str, limit: u64) -> Result<String, InputError> {
    String::from_utf8(read_limited(path, what, limit)?).map_err(|e| {
        InputError::new(
            path,
            ErrorKind::Syntax,
            format!(
                "{what} is not UTF-8 text (byte {})",
                e.utf8_error().valid_up_to()
            ),
        )
    })
}

#[cfg(test)]
mod tests {
    use crate::io::input::*;

    #[test]
    fn quotes_are_short() {
        assert_eq!(quote("abc"), "'abc'");
        let long = "x".repeat(1_000_000);
        let q = quote(&long);
        assert!(q.chars().count() < 120, "{q}");
        assert!(q.ends_with("(1000000 bytes)"));
        // Cut on a character boundary.
        let q = quote(&"é".repeat(100));
        assert!(q.starts_with("'éé"));
    }

    #[test]
    fn messages_are_short() {
        let cell = "1".repeat(1_000_000);
        let m = shorten(&format!("column 'x': '{cell}' is not a number"));
        assert!(m.chars().count() < 200, "{m}");
        assert!(m.ends_with("' is not a number"), "{m}");
        assert!(shorten(&"word ".repeat(1000)).chars().count() <= MAX_MESSAGE_CHARS + 1);
        assert_eq!(shorten("joint 'a1': zero axis"), "joint 'a1': zero axis");
    }

    /// A large file read in pieces on 2 and 3 threads is the file, byte for
    /// byte (pieces of unequal length, the last one short); one that is
    /// not `len` bytes long any more, or a small one, is left to the
    /// caller's read.
    #[cfg(unix)]
    #[test]
    fn pieces_are_the_file() {
        let dir = std::env::temp_dir().join(format!("robcal-pieces-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("big.csv");
        let len = PIECES_FROM_BYTES as usize + 12_345;
        let bytes: Vec<u8> = (0..len).map(|i| (i * 7 % 251) as u8).collect();
        std::fs::write(&path, &bytes).unwrap();
        let file = std::fs::File::open(&path).unwrap();
        for threads in [2, 3] {
            let got = read_in_pieces(&file, len as u64, threads).expect("read in pieces");
            assert!(got == bytes, "{threads} threads");
        }
        assert!(read_in_pieces(&file, len as u64, 1).is_none());
        // Grown, or shrunk, since its length was read.
        assert!(read_in_pieces(&file, len as u64 - 1, 2).is_none());
        assert!(read_in_pieces(&file, len as u64 + 1, 2).is_none());
        assert!(read_limited(&path, "the measurements", len as u64).unwrap() == bytes);
        drop(file);
        std::fs::remove_dir_all(&dir).unwrap();
        let small = std::env::temp_dir().join(format!("robcal-small-{}", std::process::id()));
        std::fs::write(&small, b"x").unwrap();
        let file = std::fs::File::open(&small).unwrap();
        assert!(read_in_pieces(&file, 1, 2).is_none());
        std::fs::remove_file(&small).unwrap();
    }
}
