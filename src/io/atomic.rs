//! Writing files all or nothing: the one output path of robcal.
//!
//! Every file of a run is first written in full to a temporary file next to
//! its target (`.NAME.tmpPID`, created new, never through an existing
//! path), flushed to disk; only when every one of them is written are they
//! renamed over their targets. On an error before that point every
//! temporary file is removed and no target is touched. A reader sees the
//! old file or the complete new one, never a part.
//!
//! A target must be a regular file or a new path: a symbolic link, a FIFO,
//! a device or a directory in its place is refused (a rename would replace
//! it), and so is a target that is one of the run's input files.

use std::io::Write;
use std::path::{Path, PathBuf};

fn refuse(path: &Path, why: String) -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!("{}: {why}", path.display()),
    )
}

/// The checks of the [module docs](self) on one target, for a caller that
/// wants them before it does the work.
///
/// # Errors
/// The refusal, or the I/O error of reading the target's metadata.
pub fn check_target(path: &Path, inputs: &[&Path]) -> std::io::Result<()> {
    if path.file_name().is_none() {
        return Err(refuse(path, "not a file path".into()));
    }
    match std::fs::symlink_metadata(path) {
        Ok(meta) if meta.file_type().is_symlink() => {
            return Err(refuse(
                path,
                "is a symbolic link: refusing to replace it".into(),
            ));
        }
        Ok(meta) if !meta.is_file() => {
            return Err(refuse(
                path,
                "is not a regular file (a directory, FIFO or device): refusing to replace it"
                    .into(),
            ));
        }
        Ok(_) => {
            for input in inputs {
                if same_file(input, path) {
                    // The input by another name is named; by the same one,
                    // not twice.
                    let which = if *input == path {
                        "an input of this command".to_string()
                    } else {
                        format!("the input {}", input.display())
                    };
                    return Err(refuse(
                        path,
                        format!("is {which}: refusing to overwrite it"),
                    ));
                }
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(e),
    }
    Ok(())
}

/// `e`'s message without the `path: ` it may start with (this module's
/// refusals name their file), for a caller that names the file itself.
pub fn reason(path: &Path, e: &std::io::Error) -> String {
    let m = e.to_string();
    m.strip_prefix(&format!("{}: ", path.display()))
        .map_or_else(|| m.clone(), str::to_string)
}

/// `e` as a message about `path`, the path named once.
pub fn about(path: &Path, e: &std::io::Error) -> String {
    format!("{}: {}", path.display(), reason(path, e))
}

/// Whether `a` and `b` name the same existing file.
pub fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

fn temporary(path: &Path) -> PathBuf {
    let name = path.file_name().unwrap_or_default().to_string_lossy();
    path.with_file_name(format!(".{name}.tmp{}", std::process::id()))
}

/// Writes every `(path, bytes)` of `files` all or nothing (see the
/// [module docs](self)), refusing a target that is one of `inputs`.
///
/// # Errors
/// A refused target, or the I/O error of creating, writing or syncing a
/// temporary file: no target is then changed. A rename that fails after
/// others succeeded (which needs the file system to fail between two
/// renames in one directory) is returned too; the files not yet renamed are
/// then removed.
pub fn write_all_atomic(files: &[(PathBuf, Vec<u8>)], inputs: &[&Path]) -> std::io::Result<()> {
    for (path, _) in files {
        check_target(path, inputs)?;
    }
    let mut staged: Vec<PathBuf> = Vec::with_capacity(files.len());
    let written = files.iter().try_for_each(|(path, bytes)| {
        let tmp = temporary(path);
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)?;
        staged.push(tmp);
        f.write_all(bytes)?;
        f.sync_all()
    });
    let renamed = written.and_then(|()| {
        files
            .iter()
            .zip(&staged)
            .try_for_each(|((path, _), tmp)| std::fs::rename(tmp, path))
    });
    if renamed.is_err() {
        for tmp in &staged {
            let _ = std::fs::remove_file(tmp);
        }
    }
    renamed
}

/// Writes `bytes` to `path` atomically ([`write_all_atomic`] of one file,
/// no input named).
///
/// # Errors
/// As [`write_all_atomic`]; `path` is then unchanged.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_all_atomic(&[(path.to_owned(), bytes.to_vec())], &[])
}

/// Files to write: each path with its bytes.
pub type Files = Vec<(PathBuf, Vec<u8>)>;

/// The files of every `(dir, files)` by one [`write_all_atomic`]
/// (all or nothing); each `dir` is created when missing and removed again
/// when the writing fails. The command's `--plots` and `--output`, the
/// Python package's `write`.
///
/// # Errors
/// A directory that cannot be made or is not one, or a file that cannot be
/// written ([`write_all_atomic`]): one line naming the directories.
pub fn write_dirs(dirs: Vec<(&Path, Files)>, inputs: &[&Path]) -> Result<(), String> {
    let names: Vec<String> = dirs.iter().map(|d| d.0.display().to_string()).collect();
    // The directories this run creates, shallowest first: removed again,
    // deepest first and only while empty, when the writing fails.
    let mut created: Vec<PathBuf> = Vec::new();
    let mut all: Files = Vec::new();
    // One directory named two ways (`o`, `./o`, a link to it): each of its
    // files once, by the directory's canonical path.
    let mut seen = std::collections::HashSet::new();
    let mut result = Ok(());
    for (dir, files) in dirs {
        let missing: Vec<PathBuf> = dir
            .ancestors()
            .take_while(|a| !a.as_os_str().is_empty() && !a.exists())
            .map(Path::to_path_buf)
            .collect();
        if !missing.is_empty() {
            if let Err(e) = std::fs::create_dir_all(dir) {
                result = Err(format!("{}: {e}", dir.display()));
                break;
            }
            created.extend(missing.into_iter().rev());
        } else if !dir.is_dir() {
            result = Err(format!("{}: exists and is not a directory", dir.display()));
            break;
        }
        let canonical = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
        for (path, bytes) in files {
            let key = path.file_name().map(|n| canonical.join(n));
            if key.is_none_or(|k| seen.insert(k)) {
                all.push((path, bytes));
            }
        }
    }
    if result.is_ok() {
        result = write_all_atomic(&all, inputs)
            .map_err(|e| format!("{}: cannot write: {e}", names.join(", ")));
    }
    if result.is_err() {
        for dir in created.iter().rev() {
            let _ = std::fs::remove_dir(dir);
        }
    }
    result
}

#[cfg(test)]
mod tests {
    use crate::io::atomic::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("robcal-atomic-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("temp dir");
        d
    }

    #[test]
    fn nothing_is_written_when_one_target_is_refused() {
        let d = dir("refused");
        std::fs::create_dir(d.join("b.svg")).expect("a directory in the way");
        let files = vec![
            (d.join("a.svg"), b"a".to_vec()),
            (d.join("b.svg"), b"b".to_vec()),
        ];
        assert!(write_all_atomic(&files, &[]).is_err());
        let left: Vec<_> = std::fs::read_dir(&d).expect("dir").collect();
        assert_eq!(left.len(), 1, "only the directory: {left:?}");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn an_input_is_not_overwritten() {
        let d = dir("input");
        let input = d.join("in.csv");
        std::fs::write(&input, "x").expect("input");
        let same = d.join(".").join("in.csv");
        let e = write_all_atomic(&[(same, b"y".to_vec())], &[&input]).unwrap_err();
        assert!(e.to_string().contains("is an input of this command"), "{e}");
        assert_eq!(std::fs::read_to_string(&input).expect("read"), "x");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[cfg(unix)]
    #[test]
    fn links_and_devices_are_not_replaced() {
        let d = dir("links");
        let target = d.join("target");
        std::fs::write(&target, "t").expect("target");
        std::os::unix::fs::symlink(&target, d.join("link")).expect("symlink");
        assert!(write_atomic(&d.join("link"), b"x").is_err());
        assert!(write_atomic(Path::new("/dev/null"), b"x").is_err());
        assert_eq!(std::fs::read_to_string(&target).expect("read"), "t");
        write_atomic(&d.join("new"), b"n").expect("a new path");
        assert_eq!(std::fs::read_to_string(d.join("new")).expect("read"), "n");
        let _ = std::fs::remove_dir_all(&d);
    }
}
