//! The second pass over a measurement file's rows: loaded rows paired
//! with their unloaded rows into deflections, and the file's warnings
//! (limits, units, moved joints; see [`super`]).

use std::path::Path;

use crate::io::measurements::{Deflection, Observation, PAIR_Q_TOLERANCE};
use crate::io::units::{AngleUnit, LengthUnit, Units};
use crate::io::urdf::Robot;
use crate::io::{error::ErrorKind, error::InputError, error::InputWarning, error::WarningKind};

/// Each loaded row paired with the unloaded row of the same config, rep and
/// marker: the deflections, and how many pairs moved between their two rows
/// (with the first pair's lines).
///
/// # Errors
/// A row twice (same config, rep, marker and load), or a loaded row without
/// its unloaded row, naming its line.
#[allow(clippy::type_complexity)]
pub(super) fn pair(
    observations: &[Observation],
    file: &Path,
) -> Result<(Vec<Deflection>, Moved, Shared), InputError> {
    let err =
        |kind, line: usize, message: String| InputError::new(file, kind, message).at_line(line);
    let cell_err = |kind, line: usize, column: &str, message: String| {
        err(kind, line, message).in_column(column)
    };
    // Each kind's keys with their row, sorted: a row twice is two equal keys
    // side by side. (A map of a million keys was 0.2 s of a run; sorting
    // a file that is in order already is one pass.) The error is the first
    // row in file order whose key came before, against that earlier row,
    // as one pass in file order finds it.
    let mut unloaded: Vec<((i64, i64, u32), usize)> = Vec::with_capacity(observations.len());
    let mut loaded: Vec<((i64, i64, u32, u64), usize)> = Vec::new();
    for (i, o) in observations.iter().enumerate() {
        if o.load_kg > 0.0 {
            loaded.push(((o.config, o.rep, o.marker, o.load_kg.to_bits()), i));
        } else {
            unloaded.push(((o.config, o.rep, o.marker), i));
        }
    }
    unloaded.sort_unstable();
    loaded.sort_unstable();
    let again = unloaded
        .windows(2)
        .filter(|w| w[0].0 == w[1].0)
        .map(|w| (w[1].1, w[0].1))
        .chain(
            loaded
                .windows(2)
                .filter(|w| w[0].0 == w[1].0)
                .map(|w| (w[1].1, w[0].1)),
        )
        .min();
    if let Some((i, p)) = again {
        let o = &observations[i];
        return Err(err(
            ErrorKind::Duplicate,
            o.line,
            format!(
                "config {}, rep {}, marker {}, load {} kg already at line {}",
                o.config, o.rep, o.marker, o.load_kg, observations[p].line
            ),
        ));
    }
    drop(loaded);
    let mut deflections = Vec::new();
    let mut moved: Option<(usize, [usize; 2])> = None;
    for (i, o) in observations.iter().enumerate() {
        if o.load_kg <= 0.0 {
            continue;
        }
        let key = (o.config, o.rep, o.marker);
        let Some(u) = unloaded
            .binary_search_by(|(k, _)| k.cmp(&key))
            .ok()
            .map(|at| unloaded[at].1)
        else {
            return Err(cell_err(
                ErrorKind::Unpaired,
                o.line,
                "load_kg",
                format!(
                    "loaded row (config {}, rep {}, marker {}) has no unloaded row \
                     with the same config, rep and marker",
                    o.config, o.rep, o.marker
                ),
            ));
        };
        let b = &observations[u];
        if o.q
            .iter()
            .zip(&b.q)
            .any(|(x, y)| (x - y).abs() > PAIR_Q_TOLERANCE)
        {
            let (count, _) = moved.get_or_insert((0, [o.line, b.line]));
            *count += 1;
        }
        deflections.push(Deflection {
            config: o.config,
            rep: o.rep,
            marker: o.marker,
            load_kg: o.load_kg,
            q: b.q.clone(),
            dp_m: [0, 1, 2].map(|k| o.p_m[k] - b.p_m[k]),
            lines: [o.line, b.line],
            rows: [i, u],
        });
    }
    // Unloaded rows that more than one loaded row is measured against, by
    // runs of the same unloaded row (its index: file order).
    let mut refs: Vec<(usize, usize, usize)> = deflections
        .iter()
        .map(|d| (d.rows[1], d.lines[1], d.lines[0]))
        .collect();
    refs.sort_unstable();
    let mut shared: Shared = None;
    for run in refs.chunk_by(|x, y| x.0 == y.0).filter(|r| r.len() > 1) {
        let s = shared.get_or_insert((0, [run[0].1, run[0].2, run[1].2]));
        s.0 += 1;
    }
    Ok((deflections, moved, shared))
}

/// Loaded rows whose joints moved from their unloaded row's: how many, and
/// the first pair's lines.
pub(super) type Moved = Option<(usize, [usize; 2])>;

/// Unloaded rows that several loaded rows are measured against: how many,
/// and the lines of the first (in file order) and two of its loaded rows.
pub(super) type Shared = Option<(usize, [usize; 3])>;

/// The file's warnings: values outside the URDF limits, numbers that look
/// like the other unit, loaded rows whose joints moved.
pub(super) fn warnings(
    file: &Path,
    robot: &Robot,
    units: Units,
    stats: &Stats,
    moved: Moved,
    shared: Shared,
) -> Vec<InputWarning> {
    let mut warnings = Vec::new();
    let mut warn = |kind, line: Option<usize>, column: Option<&str>, message: String| {
        warnings.push(InputWarning {
            file: file.to_path_buf(),
            line,
            column: column.map(str::to_owned),
            kind,
            message,
        });
    };
    for (j, outside) in stats.outside.iter().enumerate() {
        if let (Some((count, first)), Some(l)) = (outside, robot.limits[j]) {
            warn(
                WarningKind::Limits,
                Some(*first),
                Some(&robot.joint_names[j]),
                format!(
                    "{count} value(s) outside the URDF limits [{}, {}] by more than 10 % \
                     of the range (first here)",
                    l.lower, l.upper
                ),
            );
        }
    }
    let angular = robot.joint_kinds.iter().any(|k| k.is_angular());
    if units.angle == AngleUnit::Deg
        && angular
        && stats.max_angle_written > 0.0
        && stats.max_angle_written <= std::f64::consts::PI
    {
        warn(
            WarningKind::Units,
            None,
            None,
            "every revolute joint value is within ±π although [units] angle = \"deg\": \
             are the joint columns in radians?"
                .into(),
        );
    }
    if units.angle == AngleUnit::Deg
        && stats.max_rot_written > 0.0
        && stats.max_rot_written <= std::f64::consts::PI
    {
        warn(
            WarningKind::Units,
            None,
            None,
            "every rx, ry, rz is within ±π although [units] angle = \"deg\": \
             are the orientations in radians?"
                .into(),
        );
    }
    if units.length == LengthUnit::Mm && stats.max_pos_written > 0.0 && stats.max_pos_written < 10.0
    {
        warn(
            WarningKind::Units,
            None,
            None,
            "every x, y, z is within ±10 although [units] length = \"mm\": \
             are the positions in metres?"
                .into(),
        );
    }
    if let Some((count, [a, b])) = moved {
        warn(
            WarningKind::Moved,
            Some(a),
            None,
            format!(
                "{count} loaded row(s) whose joint values differ from their unloaded row's by \
                 more than {PAIR_Q_TOLERANCE} (first: lines {a} and {b})"
            ),
        );
    }
    if let Some((count, [u, a, b])) = shared {
        warn(
            WarningKind::Shared,
            Some(u),
            None,
            format!(
                "{count} unloaded row(s) are each the reference of several loaded rows (first: \
                 line {u}, for lines {a} and {b}): their deflections share its measurement \
                 noise, which the fit takes as independent, so the sigma of the compliances \
                 are understated and the lack-of-fit test reads structure that is not there; \
                 measure an unloaded point with each load (a rep of its own)"
            ),
        );
    }
    warnings
}

pub(super) struct Stats {
    /// Per joint: (values outside limits, first line).
    pub(super) outside: Vec<Option<(usize, usize)>>,
    pub(super) max_angle_written: f64,
    pub(super) max_pos_written: f64,
    /// Largest `|rx|, |ry|, |rz|` as written.
    pub(super) max_rot_written: f64,
}

impl Stats {
    pub(super) fn new(dof: usize) -> Self {
        Self {
            outside: vec![None; dof],
            max_angle_written: 0.0,
            max_pos_written: 0.0,
            max_rot_written: 0.0,
        }
    }

    /// Adds the stats of the rows after these (the first line outside a
    /// joint's limits stays the earlier one).
    pub(super) fn merge(&mut self, later: Stats) {
        self.max_angle_written = self.max_angle_written.max(later.max_angle_written);
        self.max_pos_written = self.max_pos_written.max(later.max_pos_written);
        self.max_rot_written = self.max_rot_written.max(later.max_rot_written);
        for (all, chunk) in self.outside.iter_mut().zip(later.outside) {
            *all = match (*all, chunk) {
                (Some((n, first)), Some((m, _))) => Some((n + m, first)),
                (a, b) => a.or(b),
            };
        }
    }
}
