//! Importer for FIGAROH's motion-capture layout (the TIAGo recordings of
//! `shared/datasets/tiago-mocap/`) into the data contract's measurement CSV.
//!
//! Input: one row per static posture, header (columns in any order)
//!
//! ```text
//! x1,y1,z1,x2,y2,z2,x3,y3,z3,x4,y4,z4,<joint columns>[,shipped_row][,t_start_robot,t_end_robot][,marker_std_mm]
//! ```
//!
//! - `xk, yk, zk` \[m\]: point `k` of the tracked body (TIAGo: 1 = BL,
//!   2 = BR, 3 = TR, 4 = TL) in the measurement frame;
//! - joint columns: every other column, named by its URDF joint name, in
//!   rad (revolute) or m (prismatic) — FIGAROH's `torso_lift_joint`,
//!   `arm_1_joint` … `arm_7_joint`;
//! - `t_start_robot`, `t_end_robot` \[s\]: the plateau (both or neither);
//!   `shipped_row`, `marker_std_mm`: bookkeeping, checked to be numbers and
//!   otherwise ignored.
//!
//! Output, per posture `i` (1-based row index) and point `k`: one contract row
//! `config = i, rep = 1, marker = k, load_kg = 0`, the joint values, the
//! point's `x, y, z`, and `t` = the plateau's middle when the input has the
//! timing columns. Units are SI (`angle = "rad"`, `length = "m"`), so a setup
//! reading the output declares those units (`data/tiago/setup.toml` does).
//! Numbers are written as the shortest text that reads back to the same
//! `f64`: the import is exact.
//!
//! Rejected, with file, line and column ([`InputError`]): an unreadable
//! file, a missing point column, only one of the two timing columns, no
//! joint column, a duplicate column, a row of the wrong length, a cell that
//! is not a finite number, no data row; with a robot, a joint column that is
//! not a movable joint of its chain or a chain joint without a column.
//! Nothing is written when the input is rejected.

use std::path::{Path, PathBuf};

use crate::io::measurements::Observation;
use crate::io::setup::Units;
use crate::io::urdf::Robot;
use crate::io::writer::write_measurements;
use crate::io::{error::ErrorKind, error::InputError};

/// Number of tracked points per posture (BL, BR, TR, TL).
pub const POINTS: usize = 4;

/// Names of the tracked points, in marker-id order (`marker = k + 1`).
pub const POINT_NAMES: [&str; POINTS] = ["BL", "BR", "TR", "TL"];

const BOOKKEEPING: [&str; 4] = [
    "shipped_row",
    "t_start_robot",
    "t_end_robot",
    "marker_std_mm",
];

/// One static posture of a FIGAROH mocap file, SI units.
#[derive(Debug, Clone, PartialEq)]
pub struct Posture {
    /// 1-based row index in the file (the contract's `config`).
    pub index: usize,
    /// 1-based line in the file (the header is line 1).
    pub line: usize,
    /// Joint values \[rad or m\], in [`MocapFile::joint_names`] order.
    pub q: Vec<f64>,
    /// The four points \[m\], BL, BR, TR, TL.
    pub points_m: [[f64; 3]; POINTS],
    /// Middle of the plateau \[s\], when the file has the timing columns.
    pub t_mid_s: Option<f64>,
    /// `shipped_row`, when the file has it.
    pub shipped_row: Option<f64>,
    /// `marker_std_mm`, when the file has it.
    pub marker_std_mm: Option<f64>,
}

/// A FIGAROH mocap file, read.
#[derive(Debug, Clone, PartialEq)]
pub struct MocapFile {
    /// The file.
    pub file: PathBuf,
    /// Joint column names, in file order.
    pub joint_names: Vec<String>,
    /// The postures, in file order.
    pub postures: Vec<Posture>,
}

impl MocapFile {
    /// Contract rows (SI), four per posture (markers 1..=4), joint values in
    /// the order of `joint_order` (e.g. [`Robot::joint_names`]); `None`
    /// keeps the file's order.
    ///
    /// # Errors
    /// A name of `joint_order` that is not a joint column of the file, or a
    /// joint column `joint_order` does not name ([`ErrorKind::UnknownColumn`]).
    pub fn observations(
        &self,
        joint_order: Option<&[String]>,
    ) -> Result<Vec<Observation>, InputError> {
        let perm: Vec<usize> = match joint_order {
            None => (0..self.joint_names.len()).collect(),
            Some(order) => {
                let mut perm = Vec::with_capacity(order.len());
                for name in order {
                    let i = self
                        .joint_names
                        .iter()
                        .position(|n| n == name)
                        .ok_or_else(|| {
                            InputError::new(
                                &self.file,
                                ErrorKind::MissingColumn,
                                format!("no column for the chain's joint '{name}'"),
                            )
                            .at_line(1)
                        })?;
                    perm.push(i);
                }
                if let Some(extra) = self.joint_names.iter().find(|n| !order.contains(n)) {
                    return Err(InputError::new(
                        &self.file,
                        ErrorKind::UnknownColumn,
                        "not a movable joint of the chain",
                    )
                    .at_line(1)
                    .in_column(extra.clone()));
                }
                perm
            }
        };
        let mut rows = Vec::with_capacity(self.postures.len() * POINTS);
        for p in &self.postures {
            for (k, point) in p.points_m.iter().enumerate() {
                rows.push(Observation {
                    config: p.index as i64,
                    rep: 1,
                    marker: (k + 1) as u32,
                    load_kg: 0.0,
                    q: perm.iter().map(|&i| p.q[i]).collect(),
                    q_written: Default::default(),
                    p_m: *point,
                    t_s: p.t_mid_s,
                    temp_c: None,
                    sigma_m: None,
                    r_rad: None,
                    sigma_rad: None,
                    scalar: None,
                    line: p.line,
                });
            }
        }
        Ok(rows)
    }
}

/// Reads a FIGAROH mocap file (see the [module docs](self)).
///
/// # Errors
/// See the module docs; the error names `path`, the line and the column.
pub fn read_mocap(path: impl AsRef<Path>) -> Result<MocapFile, InputError> {
    let path = path.as_ref();
    let text =
        crate::io::input::read_text(path, "the mocap file", crate::io::input::MAX_DATA_BYTES)?;
    parse_mocap(&text, path)
}

/// As [`read_mocap`], from the file's text; `file` names it in errors.
///
/// # Errors
/// See [`read_mocap`].
pub fn parse_mocap(text: &str, file: impl Into<PathBuf>) -> Result<MocapFile, InputError> {
    let file = file.into();
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let err =
        |kind, line: usize, message: String| InputError::new(&file, kind, message).at_line(line);
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .flexible(true)
        .from_reader(text.as_bytes());
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| err(ErrorKind::Syntax, 1, format!("cannot read the header: {e}")))?
        .iter()
        .map(str::to_owned)
        .collect();
    for (i, name) in header.iter().enumerate() {
        if header[..i].contains(name) {
            return Err(
                err(ErrorKind::DuplicateColumn, 1, "duplicate column".into())
                    .in_column(name.clone()),
            );
        }
        if name.is_empty() {
            return Err(err(
                ErrorKind::Syntax,
                1,
                format!("column {} has no name", i + 1),
            ));
        }
    }
    let find = |name: &str| header.iter().position(|h| h == name);
    let mut point_cols = [[0usize; 3]; POINTS];
    let mut is_point = vec![false; header.len()];
    for (k, cols) in point_cols.iter_mut().enumerate() {
        for (a, axis) in ["x", "y", "z"].iter().enumerate() {
            let name = format!("{axis}{}", k + 1);
            let c = find(&name).ok_or_else(|| {
                err(ErrorKind::MissingColumn, 1, "missing point column".into()).in_column(name)
            })?;
            cols[a] = c;
            is_point[c] = true;
        }
    }
    let optional = |name: &str| find(name);
    let (t_start, t_end) = (optional("t_start_robot"), optional("t_end_robot"));
    if t_start.is_some() != t_end.is_some() {
        let missing = if t_start.is_none() {
            "t_start_robot"
        } else {
            "t_end_robot"
        };
        return Err(err(
            ErrorKind::MissingColumn,
            1,
            "the timing columns come in pairs (t_start_robot, t_end_robot)".into(),
        )
        .in_column(missing));
    }
    let (shipped, std_mm) = (optional("shipped_row"), optional("marker_std_mm"));
    let joint_cols: Vec<usize> = (0..header.len())
        .filter(|&c| !is_point[c] && !BOOKKEEPING.contains(&header[c].as_str()))
        .collect();
    if joint_cols.is_empty() {
        return Err(err(ErrorKind::MissingColumn, 1, "no joint column".into()));
    }

    let mut postures = Vec::new();
    for (i, record) in reader.records().enumerate() {
        let record = record.map_err(|e| {
            let line = e.position().map_or(i + 2, |p| p.line() as usize);
            err(ErrorKind::Syntax, line, format!("{e}"))
        })?;
        let line = record.position().map_or(i + 2, |p| p.line() as usize);
        if record.len() != header.len() {
            return Err(err(
                ErrorKind::Syntax,
                line,
                format!("{} cells for {} columns", record.len(), header.len()),
            ));
        }
        let cell = |c: usize| -> Result<f64, InputError> {
            let s = &record[c];
            let v: f64 = s.parse().map_err(|_| {
                err(ErrorKind::Syntax, line, format!("'{s}' is not a number"))
                    .in_column(header[c].clone())
            })?;
            if !v.is_finite() {
                return Err(
                    err(ErrorKind::NonFinite, line, format!("'{s}' is not finite"))
                        .in_column(header[c].clone()),
                );
            }
            Ok(v)
        };
        let mut points_m = [[0.0; 3]; POINTS];
        for (p, cols) in points_m.iter_mut().zip(&point_cols) {
            for (v, &c) in p.iter_mut().zip(cols) {
                *v = cell(c)?;
            }
        }
        let q = joint_cols
            .iter()
            .map(|&c| cell(c))
            .collect::<Result<_, _>>()?;
        let t_mid_s = match (t_start, t_end) {
            (Some(a), Some(b)) => Some(0.5 * (cell(a)? + cell(b)?)),
            _ => None,
        };
        postures.push(Posture {
            index: i + 1,
            line,
            q,
            points_m,
            t_mid_s,
            shipped_row: shipped.map(cell).transpose()?,
            marker_std_mm: std_mm.map(cell).transpose()?,
        });
    }
    if postures.is_empty() {
        return Err(InputError::new(&file, ErrorKind::Syntax, "no data row"));
    }
    Ok(MocapFile {
        joint_names: joint_cols.iter().map(|&c| header[c].clone()).collect(),
        file,
        postures,
    })
}

/// Summary of an import.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Imported {
    /// Postures read (configurations written).
    pub postures: usize,
    /// Contract rows written (`4 ×` postures).
    pub rows: usize,
    /// Whether the rows carry a time `t`.
    pub has_time: bool,
}

/// Converts the FIGAROH mocap file `in_csv` into the contract CSV `out_csv`
/// (rad, m; see the [module docs](self)).
///
/// With a `robot`, the joint columns must be exactly the chain's movable
/// joints and are written in chain order (through
/// [`crate::io::writer::write_measurements`]); without one, in the file's order.
///
/// # Errors
/// Any [`read_mocap`] error; a joint column set that does not match the
/// robot's chain; `out_csv` cannot be written. `out_csv` is untouched on
/// error.
pub fn import_mocap(
    in_csv: impl AsRef<Path>,
    out_csv: impl AsRef<Path>,
    robot: Option<&Robot>,
) -> Result<Imported, InputError> {
    let out = out_csv.as_ref();
    crate::io::atomic::check_target(out, &[in_csv.as_ref()]).map_err(|e| {
        let why = format!("cannot write: {}", crate::io::atomic::reason(out, &e));
        InputError::new(out, ErrorKind::Io, why)
    })?;
    let mocap = read_mocap(in_csv)?;
    let rows = mocap.observations(robot.map(|r| r.joint_names.as_slice()))?;
    match robot {
        Some(robot) => write_measurements(out, robot, Units::SI, &rows)?,
        None => write_plain(out, &mocap.joint_names, &rows)?,
    }
    Ok(Imported {
        postures: mocap.postures.len(),
        rows: rows.len(),
        has_time: rows.first().is_some_and(|r| r.t_s.is_some()),
    })
}

/// The contract CSV in SI without a robot: joint columns named `names`.
fn write_plain(path: &Path, names: &[String], rows: &[Observation]) -> Result<(), InputError> {
    use std::fmt::Write as _;
    let mut text = String::from("config,rep,marker,load_kg");
    for n in names {
        text.push(',');
        text.push_str(n);
    }
    text.push_str(",x,y,z");
    let has_time = rows.first().is_some_and(|r| r.t_s.is_some());
    if has_time {
        text.push_str(",t");
    }
    text.push('\n');
    for r in rows {
        let _ = write!(text, "{},{},{},{}", r.config, r.rep, r.marker, r.load_kg);
        for v in r.q.iter().chain(&r.p_m).chain(&r.t_s) {
            let _ = write!(text, ",{v}");
        }
        text.push('\n');
    }
    crate::io::atomic::write_atomic(path, text.as_bytes()).map_err(|e| {
        InputError::new(
            path,
            ErrorKind::Io,
            format!("cannot write the measurements: {e}"),
        )
    })
}

#[cfg(test)]
mod tests {
    use crate::io::figaroh::*;

    const HEAD: &str = "x1,y1,z1,x2,y2,z2,x3,y3,z3,x4,y4,z4,j1,j2,t_start_robot,t_end_robot";

    #[test]
    fn reads_points_joints_and_mid_time() {
        let text = format!("{HEAD}\n1,2,3,4,5,6,7,8,9,10,11,12,0.5,-0.25,100,101\n");
        let m = parse_mocap(&text, "m.csv").unwrap();
        assert_eq!(m.joint_names, ["j1", "j2"]);
        let p = &m.postures[0];
        assert_eq!((p.index, p.line), (1, 2));
        assert_eq!(p.points_m[3], [10.0, 11.0, 12.0]);
        assert_eq!(p.q, [0.5, -0.25]);
        assert_eq!(p.t_mid_s, Some(100.5));
        let rows = m.observations(Some(&["j2".into(), "j1".into()])).unwrap();
        assert_eq!(rows.len(), 4);
        assert_eq!((rows[2].config, rows[2].marker), (1, 3));
        assert_eq!(rows[2].q.as_slice(), [-0.25, 0.5]);
        assert_eq!(rows[2].p_m, [7.0, 8.0, 9.0]);
    }

    #[test]
    fn errors_name_line_and_column() {
        let text = format!("{HEAD}\n1,2,3,4,5,6,7,8,9,10,11,12,0.5,-0.25,100,101\n1,2,3,4,5,6,7,8,9,10,11,12,0.5,x,100,101\n");
        let e = parse_mocap(&text, "m.csv").unwrap_err();
        assert_eq!(e.to_string(), "m.csv:3: column 'j2': 'x' is not a number");
        let e = parse_mocap("x1,y1,z1\n", "m.csv").unwrap_err();
        assert_eq!(e.to_string(), "m.csv:1: column 'x2': missing point column");
        let text = format!("{HEAD}\n1,2,3,4,5,6,7,8,9,10,11,12,0.5,NaN,100,101\n");
        let e = parse_mocap(&text, "m.csv").unwrap_err();
        assert_eq!(e.kind, ErrorKind::NonFinite);
        let text = format!("{HEAD}\n1,2,3\n");
        let e = parse_mocap(&text, "m.csv").unwrap_err();
        assert_eq!(e.to_string(), "m.csv:2: 3 cells for 16 columns");
    }
}
