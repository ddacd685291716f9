//! What several of the CLI tests share.

use std::path::{Path, PathBuf};

/// A fresh directory `<temp>/<name>-<pid>` for a test's inputs and outputs,
/// removed with everything in it when dropped: the files of one run of the
/// tests (a 17 MB URDF among them) do not pile up in the temporary
/// directory, run after run.
#[derive(Debug)]
pub struct Scratch(PathBuf);

impl Scratch {
    /// The directory, empty.
    pub fn new(name: &str) -> Self {
        let d = std::env::temp_dir().join(format!("{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        Self(d)
    }
}

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
