//! Writing a file all or nothing: the one atomic write of robcal.
//!
//! The bytes go to a temporary file next to the target (`.NAME.tmpPID`),
//! are flushed to disk, and the temporary file is renamed over the target:
//! a reader sees the old file or the complete new one, never a part. On
//! error the temporary file is removed and the target is untouched.

use std::io::Write;
use std::path::Path;

/// Writes `bytes` to `path` atomically (see the [module docs](self)).
///
/// # Errors
/// The I/O error of creating, writing, syncing or renaming; `path` is then
/// unchanged.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let name = path
        .file_name()
        .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file path"))?;
    let tmp = path.with_file_name(format!(
        ".{}.tmp{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    let written = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}
