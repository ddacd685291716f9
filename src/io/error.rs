//! What is wrong with an input, and where: one [`InputError`] (or
//! [`InputWarning`]) naming the file, and where known the line and the CSV
//! column, with every quoted text cut short so that no message echoes a
//! megabyte cell, name or line.

use std::fmt;
use std::path::PathBuf;

/// Characters of offending text an error quotes at most.
pub const MAX_QUOTE_CHARS: usize = 80;

/// What kind of input problem an [`InputError`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum ErrorKind {
    /// The file cannot be read or written.
    Io,
    /// Malformed syntax: XML, TOML, CSV structure, or a cell that is not a
    /// number of the expected type.
    Syntax,
    /// A number is NaN or ±∞.
    NonFinite,
    /// A value is out of its allowed domain (negative mass or load, σ0 ≤ 0, …).
    InvalidValue,
    /// A setup key is unknown, or a key names something that does not exist
    /// (a joint of `[model]` that is not a movable joint of the chain).
    UnknownKey,
    /// A required CSV column is missing.
    MissingColumn,
    /// A CSV column is neither a fixed column nor a movable joint of the chain.
    UnknownColumn,
    /// A CSV column appears twice.
    DuplicateColumn,
    /// A row names a marker that the setup does not declare.
    UnknownMarker,
    /// A loaded row has no unloaded row with the same `config`, `rep`, `marker`.
    Unpaired,
    /// Two rows (or two markers) share the key that must be unique.
    Duplicate,
    /// The numbers contradict the declared `[units]` (e.g. 90 read as rad).
    Units,
    /// The URDF does not give a usable chain: unknown link, no path from base
    /// to tip, planar/floating/spherical or mimic joint on the path, too many
    /// joints, zero axis, no movable joint.
    Robot,
}

/// A message about an input file: which file, where, what kind, and what.
///
/// `Display`: `file:line: column 'x': message`, leaving out the parts that
/// are not known (e.g. `robot.urdf: joint 'j2': zero axis`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Located<K> {
    /// The file.
    pub file: PathBuf,
    /// 1-based line, if known (the CSV header is line 1); for a warning
    /// about rows, the first occurrence.
    pub line: Option<usize>,
    /// CSV column name, if the message is about one column.
    pub column: Option<String>,
    /// What kind of problem.
    pub kind: K,
    /// What is wrong, for a human.
    pub message: String,
}

/// A rejected input ([`ErrorKind`]).
pub type InputError = Located<ErrorKind>;

/// Suspicious but usable input, reported next to the data it was found in
/// ([`WarningKind`]).
pub type InputWarning = Located<WarningKind>;

/// What kind of suspicious input an [`InputWarning`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum WarningKind {
    /// Joint values far outside the URDF's limits.
    Limits,
    /// Numbers that look like another unit than `[units]` says.
    Units,
    /// The robot moved between a loaded row and its unloaded row.
    Moved,
    /// Several loaded rows are measured against one unloaded row: their
    /// deflections share its noise.
    Shared,
}

impl<K> Located<K> {
    /// A message about `file` as a whole.
    pub fn new(file: impl Into<PathBuf>, kind: K, message: impl Into<String>) -> Self {
        Self {
            file: file.into(),
            line: None,
            column: None,
            kind,
            message: message.into(),
        }
    }

    /// The same message, located at a 1-based `line`.
    #[must_use]
    pub fn at_line(mut self, line: usize) -> Self {
        self.line = Some(line);
        self
    }

    /// The same message, located in CSV column `column`.
    #[must_use]
    pub fn in_column(mut self, column: impl Into<String>) -> Self {
        self.column = Some(column.into());
        self
    }
}

impl<K> fmt::Display for Located<K> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
        }
        if let Some(column) = &self.column {
            write!(f, ": column {}", quote(column))?;
        }
        write!(f, ": {}", shorten(&self.message))
    }
}

impl<K: fmt::Debug> std::error::Error for Located<K> {}

/// 1-based line of byte offset `offset` in `text`.
pub(crate) fn line_of_offset(text: &str, offset: usize) -> usize {
    let end = offset.min(text.len());
    text.as_bytes()[..end]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// `text` in single quotes, cut to [`MAX_QUOTE_CHARS`] characters (`…`
/// and the full length when cut): what an error echoes of the input.
pub fn quote(text: &str) -> String {
    let mut chars = text.char_indices();
    match chars.nth(MAX_QUOTE_CHARS) {
        None => format!("'{text}'"),
        Some((end, _)) => format!("'{}…' ({} bytes)", &text[..end], text.len()),
    }
}

/// Most characters of one error message.
pub const MAX_MESSAGE_CHARS: usize = 600;

/// `message` with every quoted text (between two `'`) cut to
/// [`MAX_QUOTE_CHARS`] characters, and the whole cut to
/// [`MAX_MESSAGE_CHARS`]: what [`crate::io::error::Located`] displays, so that no
/// error echoes a megabyte cell, name or line.
pub fn shorten(message: &str) -> String {
    let mut out = String::with_capacity(message.len().min(MAX_MESSAGE_CHARS + 8));
    for (i, part) in message.split('\'').enumerate() {
        if i > 0 {
            out.push('\'');
        }
        // Odd parts are inside quotes.
        match part.char_indices().nth(MAX_QUOTE_CHARS) {
            Some((end, _)) if i % 2 == 1 => {
                out.push_str(&part[..end]);
                out.push('…');
            }
            _ => out.push_str(part),
        }
        if out.len() > 4 * MAX_MESSAGE_CHARS {
            break;
        }
    }
    match out.char_indices().nth(MAX_MESSAGE_CHARS) {
        Some((end, _)) => format!("{}…", &out[..end]),
        None => out,
    }
}
