//! Measurement CSV (data contract section 3): reading into SI
//! [`Observation`]s and elastostatic [`Deflection`]s, and writing the same
//! format back.
//!
//! Header `config,rep,marker,load_kg,<joint columns>,x,y,z[,t]`, columns in
//! any order, one joint column per movable joint of the chain named by its
//! URDF joint name. Cells are trimmed. Joint columns and `x,y,z` are in the
//! setup's `[units]` (prismatic joints in the length unit); `load_kg` in kg,
//! `t` in s; `sx, sy, sz` (optional, all three or none), the instrument's
//! standard deviation of the point per axis, in the length unit; `rx, ry,
//! rz` (optional, all three or none), the measured orientation of the
//! marker's link frame as a rotation vector in the angle unit (a 6-D pose),
//! with `srx, sry, srz` (optional, only with them) its σ per axis. Data
//! contract 7.2: `rep` may be left out (every row is
//! repetition 1), `marker` when the setup declares one marker, `load_kg`
//! when it has no `[load]` (every row unloaded); a column named in the
//! setup's `ignore_columns` is skipped, empty cells included.
//!
//! Conversion to SI, exact to the decimal: `io::cells`; the writer:
//! [`crate::io::writer`].
//!
//! Rejected, with file, line and column: an unreadable file, a missing,
//! unknown or duplicate column, a row of the wrong length, a cell that is
//! empty or not a number (integer for `config`, `rep`, `marker`), a
//! non-finite number, a negative `load_kg` or one above [`MAX_LOAD_KG`], a
//! position beyond [`MAX_POSITION_M`] in any unit, a time beyond
//! [`MAX_TIME_S`], a loaded row when the setup has
//! no `[load]`, a marker the setup does not declare, two unloaded rows (or
//! two loaded rows of the same load) with the same `config`, `rep`,
//! `marker`, a loaded row without its unloaded row, no data row, and
//! numbers that contradict `[units]` beyond doubt: a limited revolute joint
//! (limits within ±2π) beyond ±2π with `angle = "rad"`, a position more than
//! 100 m from the origin with `length = "m"`. A pose's orientation is
//! refused when its rotation vector is longer than π (another unit, or
//! not a rotation vector) and on a loaded row (a deflection is of positions
//! only).
//!
//! Warnings ([`Measurements::warnings`]): joint values outside the URDF
//! limits by more than 10 % of the range (one warning per column, first
//! line given), every revolute value within ±π with `angle = "deg"`, every
//! position within ±10 with `length = "mm"`, paired rows whose joint values
//! differ by more than [`PAIR_Q_TOLERANCE`], and unloaded rows that several
//! loaded rows (several payloads, one `rep`) are paired with: their
//! deflections share the unloaded point's noise, which the estimator takes
//! as independent rows (a helper's generator, 3 payloads a configuration:
//! the compliances' errors over their σ had an RMS of 1.40 where 1 is
//! right, and the lack-of-fit test fired on a true model in 60 of 60 seeds).

use std::path::{Path, PathBuf};

use crate::io::cells::{self, Scale};
use crate::io::error::{ErrorKind, InputError, InputWarning};
use crate::io::setup::Setup;
pub use crate::io::units::{
    MAX_LOAD_KG, MAX_POSITION_M, MAX_SIGMA_RAD, MAX_TEMPERATURE_C, MAX_TIME_S, MIN_TEMPERATURE_C,
};
use crate::io::urdf::Robot;

mod header;
mod pairing;
mod records;
mod stream;
use header::Header;
use pairing::{pair, warnings, Stats};
use records::chunked;

/// Largest difference (rad or m) between the joint values of a loaded row
/// and its unloaded row before a warning says the robot moved in between.
pub const PAIR_Q_TOLERANCE: f64 = 1e-3;

/// One CSV row, in SI units.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Observation {
    /// Configuration id (the group for per-axis noise estimation).
    pub config: i64,
    /// Repetition index within the configuration.
    pub rep: i64,
    /// Marker id.
    pub marker: u32,
    /// Hanging mass \[kg\]; `0` means unloaded.
    pub load_kg: f64,
    /// Joint values \[rad or m\], chain order.
    pub q: JointValues,
    /// Joint cells as written in the CSV (trimmed), chain order: the
    /// contract names angle-dependent compliances after them. Empty for rows
    /// not read from a file; the writer ignores it.
    pub q_written: WrittenCells,
    /// Marker position \[m\].
    pub p_m: [f64; 3],
    /// Time \[s\], when the file has a `t` column.
    pub t_s: Option<f64>,
    /// Temperature \[°C\], when the setup names its column
    /// (`[model] temperature_column`).
    pub temp_c: Option<f64>,
    /// The instrument's standard deviation of this point per axis \[m\],
    /// when the file has `sx, sy, sz` (data contract 7.2).
    pub sigma_m: Option<[f64; 3]>,
    /// The measured orientation of the marker's link frame in the
    /// measurement frame, as a rotation vector (axis times angle, `|r| ≤ π`)
    /// \[rad\], when the file has `rx, ry, rz` (a 6-D pose: a tracker's
    /// 6-D probe, a motion-capture rigid body).
    pub r_rad: Option<[f64; 3]>,
    /// The instrument's standard deviation of the orientation per axis
    /// \[rad\], when the file has `srx, sry, srz`.
    pub sigma_rad: Option<[f64; 3]>,
    /// What the row measures when it is not a point (its `x, y, z` empty):
    /// one number about the marker's point, a plane contact or a distance
    /// (columns `plane`, `anchor`, `distance`; its σ `sd` is then
    /// `sigma_m[0]`, the other two 0). `None`: a point (`p_m`).
    pub scalar: Option<Scalar>,
    /// 1-based line in the file (header is line 1); ignored by the writer.
    pub line: usize,
}

/// One number measured about a marker's point, in place of the point
/// (issue 53): what a touch probe, a ballbar or a draw-wire sensor gives
/// without a tracker. The plane and the anchor are the setup's, fixed in
/// the measurement frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Scalar {
    /// The point's signed distance `value_m` \[m\] from the setup's
    /// `[[plane]]` `id` along its unit normal `normal`: `n · p − offset_m`
    /// (0 for a contact; a probe's radius for a sphere touching it).
    Plane {
        /// The plane's id.
        id: u32,
        /// Its unit normal \[measurement frame\].
        normal: [f64; 3],
        /// `n · p` of its points \[m\].
        offset_m: f64,
        /// The measured signed distance \[m\].
        value_m: f64,
    },
    /// The point's distance `value_m` \[m\] from the setup's `[[anchor]]`
    /// `id` at `anchor_m` \[m, measurement frame\].
    Distance {
        /// The anchor's id.
        id: u32,
        /// Its position \[m, measurement frame\].
        anchor_m: [f64; 3],
        /// The measured distance \[m\].
        value_m: f64,
    },
}

impl Scalar {
    /// The measured number \[m\].
    pub fn value_m(&self) -> f64 {
        match *self {
            Scalar::Plane { value_m, .. } | Scalar::Distance { value_m, .. } => value_m,
        }
    }
}

/// Joints whose values a row holds inline ([`JointValues`]): a 7-joint arm.
pub const INLINE_JOINTS: usize = 7;

/// A row's joint values \[rad or m\], inline up to [`INLINE_JOINTS`] joints:
/// a vector was an allocation per row, and at 10⁶ rows the freed blocks
/// of the parsed rows kept ~200 MB of heap that the rows built from them
/// were interleaved with.
pub type JointValues = smallvec::SmallVec<[f64; INLINE_JOINTS]>;

/// A row's joint cells as written in the CSV, in chain order: a range of a
/// text shared by the rows read with it (one allocation for the whole
/// file's cells up to 2 GiB of them, not one per row: a file of a million
/// rows held ~300 MB of cells as separate strings, then ~130 MB as one
/// string per row, whose freed blocks the heap kept; then ~115 MB in texts
/// of ~1 MiB, which the heap kept too once freed). The cells are joined by
/// the unit separator `\u{1f}`, which a cell that parsed as a number
/// cannot hold.
#[derive(Clone, Default)]
pub struct WrittenCells {
    /// The shared text (`None`: no cell, or not yet attached by the
    /// reader). An `Arc<String>`, not an `Arc<str>`: the text is not
    /// copied when attached.
    text: Option<std::sync::Arc<String>>,
    /// This row's part of `text`.
    start: u32,
    /// End of this row's part of `text`.
    end: u32,
}

impl std::fmt::Debug for WrittenCells {
    /// This row's cells (not the whole shared text).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

impl PartialEq for WrittenCells {
    fn eq(&self, other: &Self) -> bool {
        self.as_str() == other.as_str()
    }
}

impl Eq for WrittenCells {}

impl WrittenCells {
    const SEPARATOR: char = '\u{1f}';

    /// The cells, in order, in a text of their own.
    pub fn new<'a, I>(cells: I) -> Self
    where
        I: IntoIterator<Item = &'a str>,
    {
        let mut text = String::new();
        let mut cells = Self::pending(&mut text, cells);
        cells.text = Some(std::sync::Arc::new(text));
        cells
    }

    /// The cells appended to `text`, a batch's shared text: this row's
    /// range of it, without the text until [`WrittenCells::attach`].
    /// (`text` stays under 4 GiB: the reader attaches before
    /// [`WrittenCells::JOINED_BYTES`].)
    pub(crate) fn pending<'a, I>(text: &mut String, cells: I) -> Self
    where
        I: IntoIterator<Item = &'a str>,
    {
        let start = text.len();
        for (k, c) in cells.into_iter().enumerate() {
            if k > 0 {
                text.push(Self::SEPARATOR);
            }
            text.push_str(c);
        }
        let at = |n: usize| u32::try_from(n).unwrap_or(u32::MAX);
        Self {
            text: None,
            start: at(start),
            end: at(text.len()),
        }
    }

    /// Bytes of cells past which a reader gives its text to its rows
    /// (the offsets are `u32`).
    pub(crate) const JOINED_BYTES: usize = (u32::MAX / 2) as usize;

    /// The cells made by [`WrittenCells::pending`] into a text that is
    /// then appended at byte `by` of another (not attached yet).
    pub(crate) fn shift(&mut self, by: u32) {
        self.start = self.start.saturating_add(by);
        self.end = self.end.saturating_add(by);
    }

    /// Gives `text` (the batch's, emptied) to every row's cells in `rows`,
    /// each made by [`WrittenCells::pending`] into it.
    pub(crate) fn attach<'r>(text: &mut String, rows: impl Iterator<Item = &'r mut Self>) {
        let mut text = std::mem::take(text);
        text.shrink_to_fit();
        let shared = std::sync::Arc::new(text);
        for r in rows {
            r.text = Some(std::sync::Arc::clone(&shared));
        }
    }

    /// The cells joined by the separator (empty without any).
    fn as_str(&self) -> &str {
        self.text
            .as_deref()
            .and_then(|t| t.get(self.start as usize..self.end as usize))
            .unwrap_or("")
    }

    /// Cell `j` (`None` past the last, or when there is none).
    pub fn get(&self, j: usize) -> Option<&str> {
        self.iter().nth(j)
    }

    /// The cells, in order (none for a row not read from a file).
    pub fn iter(&self) -> impl Iterator<Item = &str> {
        let s = self.as_str();
        (!s.is_empty())
            .then(|| s.split(Self::SEPARATOR))
            .into_iter()
            .flatten()
    }

    /// The number of cells.
    pub fn len(&self) -> usize {
        self.iter().count()
    }

    /// Whether there is no cell.
    pub fn is_empty(&self) -> bool {
        self.as_str().is_empty()
    }
}

/// A loaded row minus the unloaded row with the same `config`, `rep`,
/// `marker`: one elastostatic deflection (3 equations).
#[derive(Debug, Clone, PartialEq)]
pub struct Deflection {
    /// Configuration id.
    pub config: i64,
    /// Repetition.
    pub rep: i64,
    /// Marker id.
    pub marker: u32,
    /// Hanging mass \[kg\], `> 0`.
    pub load_kg: f64,
    /// Joint values \[rad or m\] of the unloaded row (the configuration).
    pub q: JointValues,
    /// `p_loaded − p_unloaded` \[m\].
    pub dp_m: [f64; 3],
    /// Lines of the loaded and the unloaded row.
    pub lines: [usize; 2],
    /// Indices of the loaded and the unloaded row in [`Measurements::observations`].
    pub rows: [usize; 2],
}

/// A measurement file, read.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurements {
    /// The file.
    pub file: PathBuf,
    /// Every row, in file order.
    pub observations: Vec<Observation>,
    /// One per loaded row, in file order.
    pub deflections: Vec<Deflection>,
    /// Whether the file has a `t` column.
    pub has_time: bool,
    /// Suspicious but accepted input.
    pub warnings: Vec<InputWarning>,
    /// For a file read a block at a time, which keeps no joint cell as
    /// written: where they are in it ([`Measurements::written_cells`]).
    pub(crate) cells_in_file: Option<CellsInFile>,
}

/// Where the joint cells of a file's records are, to read them again
/// ([`Measurements::written_cells`]).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct CellsInFile {
    /// Fields of a record.
    fields: usize,
    /// Each joint's field.
    joint_field: Vec<Option<usize>>,
    /// Each joint's unit.
    scale: Vec<Scale>,
}

impl CellsInFile {
    /// The cells of the file whose header is `head`.
    fn of(head: &Header, robot: &Robot, setup: &Setup) -> Self {
        Self {
            fields: head.record.len(),
            joint_field: head.joint_field.clone(),
            scale: (robot.joint_kinds.iter())
                .map(|k| {
                    if k.is_angular() {
                        Scale::Angle(setup.units.angle)
                    } else {
                        Scale::Length(setup.units.length)
                    }
                })
                .collect(),
        }
    }
}

impl Measurements {
    /// The joint cells as written (trimmed) of each of `wanted` (one of
    /// these observations and a joint): its [`Observation::q_written`]'s;
    /// for a file read a block at a time (at least 32 MiB), which keeps
    /// none, read again from the file, each checked to be the value read.
    /// `None` where there is no cell (measurements not read from a file).
    ///
    /// # Errors
    /// [`ErrorKind::Io`] when the file cannot be read again, or its line
    /// no longer holds the value read.
    pub fn written_cells(
        &self,
        wanted: &[(&Observation, usize)],
    ) -> Result<Vec<Option<String>>, InputError> {
        // (Nothing wanted: the file is not opened again, as it may be gone.)
        let Some(cells) = self.cells_in_file.as_ref().filter(|_| !wanted.is_empty()) else {
            return Ok(wanted
                .iter()
                .map(|(o, j)| o.q_written.get(*j).map(|w| w.trim().to_string()))
                .collect());
        };
        let mut lines: Vec<usize> = wanted.iter().map(|(o, _)| o.line).collect();
        lines.sort_unstable();
        lines.dedup();
        let texts = stream::lines_of(&self.file, &lines, stream::BLOCK_BYTES)?;
        wanted
            .iter()
            .map(|&(o, j)| {
                let at = lines.binary_search(&o.line).ok();
                let text = at.and_then(|k| texts.get(k)).map_or("", String::as_str);
                let fields: Vec<&str> = text.split(',').map(str::trim).collect();
                let cell = (fields.len() == cells.fields)
                    .then(|| cells.joint_field.get(j).copied().flatten())
                    .flatten()
                    .and_then(|f| fields.get(f).copied());
                let value = cell.zip(cells.scale.get(j)).and_then(|(c, &scale)| {
                    cells::parse_real_written(c, scale).ok().map(|(_, v)| v)
                });
                match (cell, value, o.q.get(j)) {
                    (Some(c), Some(v), Some(q)) if v.to_bits() == q.to_bits() => {
                        Ok(Some(c.to_string()))
                    }
                    _ => Err(InputError::new(
                        &self.file,
                        ErrorKind::Io,
                        format!(
                            "the file changed while it was read: its joint {} no longer \
                             holds the value read",
                            j + 1
                        ),
                    )
                    .at_line(o.line)),
                }
            })
            .collect()
    }

    /// The unloaded rows: absolute positions (geometric data).
    pub fn unloaded(&self) -> impl Iterator<Item = &Observation> {
        self.observations.iter().filter(|o| o.is_unloaded())
    }

    /// These measurements without the observations `drop` says, nor any
    /// deflection one of whose rows is dropped or that `drop_deflection`
    /// says (its loaded row goes too); the rest as read, in file order,
    /// lines kept.
    pub fn without(
        &self,
        drop: impl Fn(&Observation) -> bool,
        drop_deflection: impl Fn(&Deflection) -> bool,
    ) -> Self {
        let mut keep: Vec<bool> = self.observations.iter().map(|o| !drop(o)).collect();
        let deflections: Vec<&Deflection> = self
            .deflections
            .iter()
            .filter(|d| {
                d.rows
                    .iter()
                    .all(|&r| keep.get(r).copied().unwrap_or(false))
            })
            .collect();
        for d in &self.deflections {
            if drop_deflection(d) {
                if let Some(k) = keep.get_mut(d.rows[0]) {
                    *k = false;
                }
            }
        }
        // Old index → new index of each kept observation.
        let mut index = vec![usize::MAX; self.observations.len()];
        let mut observations = Vec::new();
        for (i, o) in self.observations.iter().enumerate() {
            if keep[i] {
                index[i] = observations.len();
                observations.push(o.clone());
            }
        }
        let deflections = deflections
            .into_iter()
            .filter(|d| d.rows.iter().all(|&r| keep[r]))
            .map(|d| Deflection {
                rows: d.rows.map(|r| index[r]),
                ..d.clone()
            })
            .collect();
        Self {
            file: self.file.clone(),
            observations,
            deflections,
            has_time: self.has_time,
            warnings: self.warnings.clone(),
            cells_in_file: self.cells_in_file.clone(),
        }
    }
}

impl Observation {
    /// Whether the row is unloaded (`load_kg` 0): an absolute position.
    pub fn is_unloaded(&self) -> bool {
        self.load_kg == 0.0
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Col {
    /// A column of the setup's `ignore_columns`.
    Ignored,
    Config,
    Rep,
    Marker,
    Load,
    Joint(usize),
    Pos(usize),
    Time,
    /// `sx, sy, sz`: the instrument's σ per axis.
    Sigma(usize),
    /// The setup's `[model] temperature_column` \[°C\].
    Temperature,
    /// `rx, ry, rz`: the measured orientation (rotation vector).
    Rot(usize),
    /// `srx, sry, srz`: the instrument's σ of the orientation per axis.
    SigmaRot(usize),
    /// `plane`: the id of the setup's plane the marker touches.
    Plane,
    /// `anchor`: the id of the setup's anchor a distance is measured from.
    Anchor,
    /// `distance`: the measured distance (from the anchor, or the plane).
    Distance,
    /// `sd`: the instrument's σ of that distance.
    SigmaScalar,
}

const FIXED: [(&str, Col); 21] = [
    ("config", Col::Config),
    ("rep", Col::Rep),
    ("marker", Col::Marker),
    ("load_kg", Col::Load),
    ("x", Col::Pos(0)),
    ("y", Col::Pos(1)),
    ("z", Col::Pos(2)),
    ("t", Col::Time),
    ("sx", Col::Sigma(0)),
    ("sy", Col::Sigma(1)),
    ("sz", Col::Sigma(2)),
    ("rx", Col::Rot(0)),
    ("ry", Col::Rot(1)),
    ("rz", Col::Rot(2)),
    ("srx", Col::SigmaRot(0)),
    ("sry", Col::SigmaRot(1)),
    ("srz", Col::SigmaRot(2)),
    ("plane", Col::Plane),
    ("anchor", Col::Anchor),
    ("distance", Col::Distance),
    ("sd", Col::SigmaScalar),
];

/// Reads a measurement file for `robot` and `setup` (units, markers, load).
///
/// # Errors
/// See the module doc; every error names `path`, and the line and column
/// where there is one.
pub fn read_measurements(
    path: impl AsRef<Path>,
    robot: &Robot,
    setup: &Setup,
) -> Result<Measurements, InputError> {
    read_measurements_limited(path, robot, setup, crate::io::input::MAX_DATA_BYTES)
}

/// As [`read_measurements`], refusing a file larger than `max_bytes`.
///
/// # Errors
/// See [`read_measurements`]; [`ErrorKind::Io`] for a file larger than
/// `max_bytes` or one that is not a regular file ([`crate::io::input`]).
pub fn read_measurements_limited(
    path: impl AsRef<Path>,
    robot: &Robot,
    setup: &Setup,
    max_bytes: u64,
) -> Result<Measurements, InputError> {
    let path = path.as_ref();
    // A large file a block at a time, not all its bytes in memory.
    if let Some(read) = stream::read(path, max_bytes, robot, setup) {
        return read;
    }
    let bytes = crate::io::input::read_limited(path, "the measurements", max_bytes)?;
    parse_bytes(&bytes, path.to_path_buf(), robot, setup)
}

/// As [`read_measurements`], from any reader; `file` names it in errors.
///
/// # Errors
/// See [`read_measurements`].
pub fn parse_measurements<R: std::io::Read>(
    reader: R,
    file: impl Into<PathBuf>,
    robot: &Robot,
    setup: &Setup,
) -> Result<Measurements, InputError> {
    let file = file.into();
    let mut bytes = Vec::new();
    let mut reader = reader;
    reader.read_to_end(&mut bytes).map_err(|e| {
        InputError::new(
            file.clone(),
            ErrorKind::Io,
            format!("cannot read the measurements: {e}"),
        )
    })?;
    parse_bytes(&bytes, file, robot, setup)
}

/// As [`parse_measurements`], from the file's bytes (not copied again: a
/// file of a million rows is ~200 MB).
fn parse_bytes(
    bytes: &[u8],
    file: PathBuf,
    robot: &Robot,
    setup: &Setup,
) -> Result<Measurements, InputError> {
    // Line numbers from byte offsets: the csv crate's own line count is off
    // after CRLF line ends and does not count blank lines. A line ends at
    // `\n`, `\r\n` or a lone `\r` (old Mac files), as the csv crate's
    // records do.
    let threads = crate::parallel::threads();
    let newlines: Vec<usize> = if threads > 1 && bytes.len() >= 1 << 21 {
        let n = bytes.len();
        crate::parallel::map(threads, threads, |k| {
            records::line_ends(bytes, k * n / threads..(k + 1) * n / threads)
        })
        .concat()
    } else {
        records::line_ends(bytes, 0..bytes.len())
    };
    let line_at = |pos: Option<&csv::Position>| match pos {
        Some(pos) => records::line_at(bytes, &newlines, pos.byte() as usize),
        None => 1,
    };
    let err = |kind, line: usize, message: String| {
        InputError::new(file.clone(), kind, message).at_line(line)
    };
    let csv_err = |e: csv::Error| {
        let line = line_at(e.position());
        let kind = match e.kind() {
            csv::ErrorKind::Io(_) => ErrorKind::Io,
            _ => ErrorKind::Syntax,
        };
        let message = match e.kind() {
            csv::ErrorKind::UnequalLengths {
                expected_len, len, ..
            } => format!("row has {len} fields, the header has {expected_len}"),
            _ => e.to_string(),
        };
        err(kind, line, message)
    };

    let mut rdr = Header::reader(bytes);
    let head = Header::read(&mut rdr, &file, robot, setup, &csv_err)?;
    let layout = head.layout(&file, robot, setup);
    let data_start = head.data_start;
    let (observations, stats) = match chunked(bytes, data_start, &newlines, &layout, threads) {
        Some(done) => done,
        None => {
            // One reader over the whole file (small files, quoted cells,
            // and every file with an error: its message is this
            // reader's, with the file's own record numbers).
            let mut stats = Stats::new(robot.dof());
            let mut observations = records::Batch::default();
            let mut record = csv::StringRecord::new();
            while rdr.read_record(&mut record).map_err(csv_err)? {
                let line = line_at(record.position());
                let cells: Vec<&str> = record.iter().collect();
                observations.read(&layout, &cells, line, &mut stats)?;
            }
            (observations.finish(), stats)
        }
    };
    finish(file, robot, setup, observations, &stats, head.has_time)
}

/// The measurements of `file` from its `observations` and their `stats`:
/// its deflections paired, its warnings.
///
/// # Errors
/// No observation; as [`pair`].
fn finish(
    file: PathBuf,
    robot: &Robot,
    setup: &Setup,
    observations: Vec<Observation>,
    stats: &Stats,
    has_time: bool,
) -> Result<Measurements, InputError> {
    if observations.is_empty() {
        return Err(
            InputError::new(file, ErrorKind::InvalidValue, "no measurement rows").at_line(1),
        );
    }

    let (deflections, moved, shared) = pair(&observations, &file)?;
    let warnings = warnings(&file, robot, setup.units, stats, moved, shared);

    Ok(Measurements {
        file,
        observations,
        deflections,
        has_time,
        warnings,
        cells_in_file: None,
    })
}
