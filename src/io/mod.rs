//! The data contract's files (`shared/spec/data-contract.md`): the robot
//! (URDF), the setup (TOML) and the measurements (CSV). Host only (`std`).
//!
//! ```text
//!   setup.toml ──Setup::load──► Setup ─┐
//!   robot.urdf ──Robot::load──► Robot ─┴─► Job ──read_measurements──► Measurements
//!                                                 (Observation, Deflection)
//!   FIGAROH mocap CSV ──figaroh::import_mocap──► measurement CSV (write_atomic)
//!   wide pose CSV (shared/datasets) ──poses::import_poses──► measurement CSV
//!   points CSV ──points::parse_points──► PointRow (robcal predict / compensate)
//!   Robot ──template::setup_template──► a commented setup (robcal init)
//! ```
//!
//! Everything is converted to SI on reading (rad, m, kg, s); the CSV's
//! `[units]` apply only to its joint and position columns.
//!
//! Every file is read through [`input`] (regular files only, a size limit
//! checked before reading) and written through [`atomic`] (all or nothing,
//! never onto an input, a link or a device); the limits are in
//! `docs/inputs.md`.
//!
//! Every rejected input is one [`InputError`] naming the file, and where
//! known the line (1-based; the CSV header is line 1) and the CSV column.
//! Suspicious but usable input (a joint value far outside its URDF limits,
//! numbers that look like the wrong unit) is returned as [`InputWarning`]s
//! next to the data instead.
//!
//! ```
//! use robcal::io::{parse_measurements, Robot, Setup};
//!
//! let urdf = r#"<robot name="r">
//!   <link name="base"/> <link name="arm"/> <link name="flange"/>
//!   <joint name="a1" type="continuous">
//!     <parent link="base"/> <child link="arm"/> <axis xyz="0 0 1"/>
//!   </joint>
//!   <joint name="tool" type="fixed">
//!     <parent link="arm"/> <child link="flange"/> <origin xyz="0.5 0 0"/>
//!   </joint>
//! </robot>"#;
//! let robot = Robot::parse(urdf, "r.urdf", Some("base"), Some("flange"))?;
//! assert_eq!(robot.joint_names, ["a1"]);
//! assert_eq!(robot.chain.tip().translation.vector.x, 0.5);
//!
//! let setup = Setup::parse(
//!     "robot = \"r.urdf\"\n[units]\nangle = \"deg\"\nlength = \"mm\"\n[load]\n",
//!     "s.toml",
//! )?;
//! let csv = "config,rep,marker,load_kg,a1,x,y,z\n\
//!            1,0,1,0,90,500,0,0\n\
//!            1,0,1,20,90,500,-0.25,0\n";
//! let data = parse_measurements(csv.as_bytes(), "d.csv", &robot, &setup)?;
//! assert_eq!(data.observations[0].q.as_slice(), [std::f64::consts::FRAC_PI_2]);
//! assert_eq!(data.observations[0].p_m, [0.5, 0.0, 0.0]);
//! assert_eq!(data.deflections[0].dp_m, [0.0, -0.00025, 0.0]);
//!
//! // Errors name the file, line and column.
//! let bad = "config,rep,marker,load_kg,a1,x,y,z\n1,0,2,0,90,500,0,0\n";
//! let e = parse_measurements(bad.as_bytes(), "d.csv", &robot, &setup).unwrap_err();
//! assert_eq!(e.to_string(), "d.csv:2: column 'marker': marker 2 is not declared in the setup");
//! # Ok::<(), robcal::io::InputError>(())
//! ```

use std::fmt;
use std::path::PathBuf;

pub mod atomic;
mod cells;
pub mod figaroh;
pub mod input;
pub mod job;
pub mod measurements;
pub mod points;
pub mod poses;
pub mod setup;
pub mod template;
pub mod urdf;
pub mod writer;

pub use atomic::{write_all_atomic, write_atomic};
pub use job::Job;
pub use measurements::{
    parse_measurements, read_measurements, read_measurements_limited, Deflection, JointValues,
    Measurements, Observation, WrittenCells, INLINE_JOINTS,
};
pub use setup::{
    AngleUnit, GeometryModel, LengthUnit, Load, Marker, MarkerModel, Model, Noise, Setup, Units,
    Weighting,
};
pub use urdf::{JointLimits, OffChainBranch, Robot, UrdfJointKind, MAX_JOINTS};
pub use writer::write_measurements;

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
            write!(f, ": column {}", input::quote(column))?;
        }
        write!(f, ": {}", input::shorten(&self.message))
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
