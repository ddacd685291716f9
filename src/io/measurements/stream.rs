//! A large measurement file read a block at a time (issue 16): the file's
//! bytes are never all in memory, only [`BLOCK_BYTES`] of them and the
//! observations read so far (a file of 10⁶ rows is 187 MB of text, a
//! file at the default limit 1 GiB).
//!
//! Each block is cut after its last line end `\n`; its records are read as
//! the whole file's are ([`crate::io::measurements::records::in_chunks`]: in chunks on the
//! engine's threads, joined in file order), the line numbers counted on
//! from the blocks before, and the rest of the block carried to the next.
//! The observations, stats and therefore the measurements are the ones the
//! reading of the whole file makes (`tests` compare them). Anything else —
//! a quote anywhere (a quoted cell may hold a line end), an error in any
//! record or the header, a block without a `\n`, a file that grew past the
//! limit, a read that fails — gives `None`, and the caller reads the whole
//! file as before, which gives the error with its line and column.

use std::io::Read;
use std::path::{Path, PathBuf};

use crate::io::error::ErrorKind;
use crate::io::error::InputError;
use crate::io::measurements::records::{in_chunks, line_ends, Read as Records};
use crate::io::measurements::{finish, CellsInFile, Header, Measurements};
use crate::io::setup::Setup;
use crate::io::urdf::Robot;

/// Files at least this large are read a block at a time ([`read`]).
pub(super) const STREAM_FROM_BYTES: u64 = 32 << 20;

/// Bytes read from the file at a time.
pub(super) const BLOCK_BYTES: usize = 4 << 20;

/// Chunks of a block per thread: the threads take them in turn. (In
/// chunks of at least 1 MiB, as the whole file's, a block of 2 MiB was one
/// chunk: the parse of 10⁶ rows ran on one thread.)
const CHUNKS_PER_THREAD: usize = 4;

/// The measurements of the file `path` (at most `limit` bytes) read a
/// block at a time, on the engine's threads (or its one: the same
/// measurements, the records split as on several); `None` when the file is
/// not a regular file of at least [`STREAM_FROM_BYTES`] and at most `limit`
/// bytes, or is not one the blocks can read (module doc): the caller reads
/// the whole file.
pub(super) fn read(
    path: &Path,
    limit: u64,
    robot: &Robot,
    setup: &Setup,
) -> Option<Result<Measurements, InputError>> {
    let threads = crate::parallel::threads();
    let blocks = Blocks::of(path, limit, threads, STREAM_FROM_BYTES)?;
    let file = std::fs::File::open(path).ok()?;
    blocks.read(file, robot, setup)
}

/// How a file is read a block at a time.
struct Blocks {
    /// The file, for the measurements and their errors.
    file: PathBuf,
    /// Its length as its metadata gave it \[bytes\] (for the room the
    /// observations are given).
    len: u64,
    /// The most bytes it may have.
    limit: u64,
    /// Threads a block's records are read on.
    threads: usize,
    /// Bytes read at a time.
    block: usize,
}

impl Blocks {
    /// How the file `path` is read, in blocks of [`BLOCK_BYTES`] on
    /// `threads` threads: `None` unless it is a regular file of at least
    /// `from` and at most `limit` bytes.
    fn of(path: &Path, limit: u64, threads: usize, from: u64) -> Option<Self> {
        let meta = std::fs::metadata(path).ok()?;
        let read = meta.is_file() && (from..=limit).contains(&meta.len());
        read.then(|| Self {
            file: path.to_path_buf(),
            len: meta.len(),
            limit,
            threads,
            block: BLOCK_BYTES,
        })
    }

    /// The measurements `reader` gives, read a block at a time; `None` as
    /// [`read`].
    fn read(
        &self,
        mut reader: impl Read,
        robot: &Robot,
        setup: &Setup,
    ) -> Option<Result<Measurements, InputError>> {
        let mut buf = Vec::with_capacity(2 * self.block);
        let mut total = 0;
        let mut eof = self.fill(&mut reader, &mut buf, &mut total)?;
        // The header: the csv crate's reading of it, as for the whole file
        // (its first line must be whole in the block).
        memchr::memchr(b'\n', &buf)?;
        let mut rdr = Header::reader(&buf);
        let no = |_: csv::Error| {
            InputError::new(&self.file, crate::io::measurements::ErrorKind::Syntax, "")
        };
        let head = Header::read(&mut rdr, &self.file, robot, setup, &no).ok()?;
        let layout = head.layout(&self.file, robot, setup);
        // The joint cells as written are not kept (~115 MB at 10⁶ rows,
        // held with the observations: the peak of the parse), but read
        // again where the bins need them (`Measurements::written_cells`).
        let mut read = Records::new(robot.dof(), true).without_cells();
        let (mut start, mut line0) = (head.data_start, 0);
        loop {
            // Up to the last `\n` (a line end whatever follows it), or to
            // the end of the file.
            let cut = if eof {
                buf.len()
            } else {
                memchr::memrchr(b'\n', &buf)? + 1
            };
            let piece = &buf[..cut];
            let newlines = line_ends(piece, 0..cut);
            if cut > start {
                let chunks = (self.threads, CHUNKS_PER_THREAD * self.threads);
                let before = read.observations.len();
                in_chunks(piece, start, &newlines, line0, &layout, chunks, &mut read)?;
                if before == 0 && read.observations.capacity() < 2 * read.observations.len() {
                    // Room for the file's rows at the first block's bytes
                    // a row, and a tenth more (pages not written are not
                    // memory used); where the system refuses that much (an
                    // estimate from short first rows), the vector grows as
                    // the rows come instead.
                    let per = (cut - start) as f64 / read.observations.len().max(1) as f64;
                    let rows = (self.len as f64 / per * 1.1) as usize + 16;
                    let _ = read.observations.try_reserve(rows);
                }
            }
            line0 += newlines.len();
            if eof {
                break;
            }
            buf.drain(..cut);
            start = 0;
            eof = self.fill(&mut reader, &mut buf, &mut total)?;
        }
        let (observations, stats) = read.finish();
        let measurements = finish(
            self.file.clone(),
            robot,
            setup,
            observations,
            &stats,
            head.has_time,
        );
        Some(measurements.map(|m| Measurements {
            cells_in_file: Some(CellsInFile::of(&head, robot, setup)),
            ..m
        }))
    }

    /// The next block of `reader` appended to `buf`: whether the file
    /// ended. `None` when the read fails, the file has more than `limit`
    /// bytes (`total` so far) or a quote.
    fn fill(&self, reader: &mut impl Read, buf: &mut Vec<u8>, total: &mut u64) -> Option<bool> {
        let old = buf.len();
        buf.reserve(self.block);
        let n = reader
            .by_ref()
            .take(self.block as u64)
            .read_to_end(buf)
            .ok()?;
        *total += n as u64;
        let fresh = &buf[old..];
        if *total > self.limit || memchr::memchr(b'"', fresh).is_some() {
            return None;
        }
        Some(n < self.block)
    }
}

/// The text of each of `lines` (ascending line numbers, the header's 1,
/// line ends as [`line_ends`] counts them) of the file `path`, without its
/// line end: read again `block` bytes at a time up to the last of them
/// (empty for a line the file no longer has).
///
/// # Errors
/// [`ErrorKind::Io`] when the file cannot be read.
pub(super) fn lines_of(
    path: &Path,
    lines: &[usize],
    block: usize,
) -> Result<Vec<String>, InputError> {
    let io = |e: std::io::Error| {
        InputError::new(
            path,
            ErrorKind::Io,
            format!("cannot read the measurements again for their joint cells as written: {e}"),
        )
    };
    let mut file = std::fs::File::open(path).map_err(io)?;
    let mut out = Vec::with_capacity(lines.len());
    let mut want = lines.iter().copied().peekable();
    let block = block.max(1);
    let mut buf: Vec<u8> = Vec::with_capacity(2 * block);
    // Line ends before `buf`.
    let mut line0 = 0;
    while want.peek().is_some() {
        let n = (&mut file)
            .take(block as u64)
            .read_to_end(&mut buf)
            .map_err(io)?;
        let eof = n < block;
        // Up to the last `\n`, as the blocks are read.
        let cut = match memchr::memrchr(b'\n', &buf) {
            _ if eof => buf.len(),
            Some(k) => k + 1,
            None => continue,
        };
        let ends = line_ends(&buf, 0..cut);
        // Line `line0 + k` starts after the piece's line end `k - 1`.
        while let Some(k) = want.peek().map(|&l| l.saturating_sub(line0)) {
            if k == 0 || (k > ends.len() && !eof) {
                break;
            }
            let start = if k == 1 {
                Some(0)
            } else {
                ends.get(k - 2).map(|e| e + 1)
            };
            let text = start.filter(|&s| s <= cut).map_or_else(String::new, |s| {
                let rest = &buf[s..cut];
                let end = memchr::memchr2(b'\r', b'\n', rest).unwrap_or(rest.len());
                String::from_utf8_lossy(&rest[..end]).into_owned()
            });
            out.push(text);
            want.next();
        }
        if eof || want.peek().is_some_and(|&l| l <= line0) {
            break;
        }
        line0 += ends.len();
        buf.drain(..cut);
    }
    out.resize(lines.len(), String::new());
    Ok(out)
}

#[cfg(test)]
mod tests;
