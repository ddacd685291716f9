//! Importer for the wide one-row-per-pose layout of the real data sets
//! (`shared/datasets/*/`, data contract 7.3) into the measurement CSV.
//!
//! Input: one row per pose, header (columns in any order)
//!
//! ```text
//! [pose_id,][split,]<joint>_rad|<joint>_m ...,x<i>_m,y<i>_m,z<i>_m ...[,ux<i>_m,uy<i>_m,uz<i>_m | std_x<i>_m,...]
//! ```
//!
//! - `<joint>_rad` \[rad\] (revolute) or `<joint>_m` \[m\] (prismatic): the
//!   joint named `<joint>` in the URDF;
//! - `x<i>_m, y<i>_m, z<i>_m` \[m\]: marker `i` in the measurement frame; all
//!   three cells empty = that marker was not measured in that pose;
//! - `ux<i>_m, uy<i>_m, uz<i>_m` or `std_x<i>_m, std_y<i>_m, std_z<i>_m`
//!   \[m\]: the instrument's standard deviation of marker `i` per axis,
//!   written as the contract's `sx, sy, sz` (7.2);
//! - `pose_id` (integer): the contract's `config`; without it the 1-based
//!   row number;
//! - `split`: kept or not by [`ImportOptions::split`];
//! - 6-D exports: marker `i`'s orientation as a unit quaternion `qw<i>,
//!   qx<i>, qy<i>, qz<i>` (a motion-capture rigid body) or as Euler angles
//!   `rx<i>_deg, ry<i>_deg, rz<i>_deg` (or `_rad`; a laser tracker's 6-D
//!   probe), composed as [`ImportOptions::euler`] names ([`Euler`]);
//!   written as the contract's rotation vector `rx, ry, rz` \[rad\].
//!
//! Every other column (`test_set`, `toolbox_excluded`, a total uncertainty
//! `u<i>_m`, a temperature, …) is not needed by the model: it is left out
//! and listed in [`ImportedPoses::left_out`] (the CLI names them once on
//! stderr).
//!
//! Output: one contract row per measured point, `config` as above,
//! `rep = 1`, `marker = i`, `load_kg = 0`, joint columns named by their URDF
//! joint in file order, `x, y, z` and, when the file has uncertainty
//! columns, `sx, sy, sz`; SI units (`angle = "rad"`, `length = "m"`).
//! Numbers are written as the shortest text that reads back to the same
//! `f64`: the import is exact.
//!
//! Rejected, with file, line and column ([`InputError`]): an unreadable
//! file, a duplicate or unnamed column, no joint column, no marker column,
//! a marker with only some of `x, y, z` columns, uncertainty columns of a
//! marker without all three axes or without its position, a row of the
//! wrong length, a joint cell that is empty or not a finite number, a
//! marker with some but not all of its three cells, a negative or
//! non-finite uncertainty, a `pose_id` that is not an integer or repeats,
//! `--split` without a `split` column, and no point left to write; for
//! orientations, a quaternion whose norm is off 1 by more than
//! [`QUATERNION_NORM_TOLERANCE`], some of a marker's orientation columns or
//! cells but not all, two orientations of one marker, Euler angles without
//! a convention, an orientation without its point, an angle beyond ±2π in a
//! `_rad` column. Warnings ([`ImportedPoses::warnings`]): Euler angles near
//! gimbal lock ([`GIMBAL_LOCK_RAD`]), `_deg` columns all within ±π. Nothing
//! is written when the input is rejected.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use crate::io::{error::ErrorKind, error::InputError};

/// What to keep, and how to read it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ImportOptions {
    /// Keep only the rows whose `split` column equals this; `None`: all rows.
    pub split: Option<String>,
    /// How the Euler angle columns compose; required when the file has
    /// them (there is no default: a convention guessed is the classic
    /// error of a 6-D export).
    pub euler: Option<Euler>,
}

/// How the Euler angle columns `rx<i>_deg, ry<i>_deg, rz<i>_deg` (or
/// `_rad`) make a rotation. Each angle turns about the axis its column
/// names; the convention is their order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Euler {
    /// `R = Rz(rz) Ry(ry) Rx(rx)`: about the fixed x, then y, then z
    /// (the same rotation as about the moving z, y′, x″). URDF's `rpy`,
    /// SpatialAnalyzer's "Fixed XYZ" (a Leica T-Mac's usual export), KUKA's
    /// A, B, C (A = rz, B = ry, C = rx). Names: `fixed-xyz`, `moving-zyx`.
    FixedXyz,
    /// `R = Rx(rx) Ry(ry) Rz(rz)`: about the moving x, y′, z″ (the same
    /// rotation as about the fixed z, then y, then x). Names: `moving-xyz`,
    /// `fixed-zyx`.
    MovingXyz,
}

impl core::str::FromStr for Euler {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "fixed-xyz" | "moving-zyx" => Ok(Self::FixedXyz),
            "moving-xyz" | "fixed-zyx" => Ok(Self::MovingXyz),
            _ => Err(format!(
                "'{s}' is not an Euler convention: fixed-xyz (= moving-zyx: R = Rz Ry Rx) \
                 or moving-xyz (= fixed-zyx: R = Rx Ry Rz)"
            )),
        }
    }
}

impl Euler {
    /// The rotation vector (axis × angle, \[rad\], angle in \[0, π\]) of
    /// the angles `[rx, ry, rz]` \[rad\] about x, y and z.
    pub fn rotation_vector(self, [rx, ry, rz]: [f64; 3]) -> [f64; 3] {
        use nalgebra::{UnitQuaternion, Vector3};
        let (x, y, z) = (
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), rx),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), ry),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rz),
        );
        let r = match self {
            Self::FixedXyz => z * y * x,
            Self::MovingXyz => x * y * z,
        };
        r.scaled_axis().into()
    }
}

/// Euler angles whose middle angle `ry` is within this of ±90° \[rad\]
/// (0.1°) are near gimbal lock: `rx` and `rz` turn about nearly one axis,
/// and the exporter's split between them is ill-conditioned (a warning).
pub const GIMBAL_LOCK_RAD: f64 = 0.1 * core::f64::consts::PI / 180.0;

/// A quaternion whose norm is farther than this from 1 is not a rotation
/// (an error); closer, it is normalised (an export's rounding).
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// Summary of an import.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImportedPoses {
    /// Poses kept (configurations written).
    pub poses: usize,
    /// Contract rows written (one per measured point).
    pub rows: usize,
    /// Markers that have at least one point, ascending.
    pub markers: Vec<u32>,
    /// Joint names (URDF), in file order.
    pub joints: Vec<String>,
    /// Whether `sx, sy, sz` were written.
    pub has_sigma: bool,
    /// Rows written with an orientation (`rx, ry, rz`, a rotation vector in
    /// rad).
    pub orientations: usize,
    /// Columns not needed by the model, in file order.
    pub left_out: Vec<String>,
    /// Plausibility findings that did not stop the import (gimbal lock,
    /// radians in a `_deg` column), one line each.
    pub warnings: Vec<String>,
}

/// How a header cell is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Col {
    PoseId,
    Split,
    Joint(usize),
    /// Marker index into `markers`, axis 0..3.
    Pos(usize, usize),
    Sigma(usize, usize),
    /// Quaternion component `w, x, y, z` (0..4).
    Quat(usize, usize),
    /// Euler angle about `x, y, z` (0..3); `true`: in degrees.
    Euler(usize, usize, bool),
    Other,
}

/// `qw3` → (0, 3) … `qz3` → (3, 3).
fn quaternion_marker(name: &str) -> Option<(usize, u32)> {
    let rest = name.strip_prefix('q')?;
    let c = ["w", "x", "y", "z"]
        .iter()
        .position(|a| rest.starts_with(a))?;
    Some((c, marker_id(&rest[1..])?))
}

/// `rx3_deg` → (0, 3, true); `rz3_rad` → (2, 3, false).
fn euler_marker(name: &str) -> Option<(usize, u32, bool)> {
    let rest = name.strip_prefix('r')?;
    let axis = ["x", "y", "z"].iter().position(|a| rest.starts_with(a))?;
    let (digits, deg) = match rest[1..].strip_suffix("_deg") {
        Some(d) => (d, true),
        None => (rest[1..].strip_suffix("_rad")?, false),
    };
    Some((axis, marker_id(digits)?, deg))
}

/// A marker id of 1 to 6 digits, not 0.
fn marker_id(digits: &str) -> Option<u32> {
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) || digits.len() > 6 {
        return None;
    }
    let id: u32 = digits.parse().ok()?;
    (id > 0).then_some(id)
}

/// `x3_m` → (0, 3); `std_y12_m` → (1, 12) with `prefix = "std_"`.
fn axis_marker(name: &str, prefix: &str) -> Option<(usize, u32)> {
    let rest = name.strip_prefix(prefix)?.strip_suffix("_m")?;
    let axis = ["x", "y", "z"].iter().position(|a| rest.starts_with(a))?;
    Some((axis, marker_id(&rest[1..])?))
}

fn is_total_uncertainty(name: &str) -> bool {
    name.strip_prefix('u')
        .and_then(|r| r.strip_suffix("_m"))
        .is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
}

/// Converts the wide pose file `in_csv` into the contract CSV `out_csv`
/// (see the [module docs](self)).
///
/// # Errors
/// See the module docs; `out_csv` is untouched on error.
pub fn import_poses(
    in_csv: impl AsRef<Path>,
    out_csv: impl AsRef<Path>,
    options: &ImportOptions,
) -> Result<ImportedPoses, InputError> {
    let (input, out) = (in_csv.as_ref(), out_csv.as_ref());
    crate::io::atomic::check_target(out, &[input]).map_err(|e| {
        let why = format!("cannot write: {}", crate::io::atomic::reason(out, &e));
        InputError::new(out, ErrorKind::Io, why)
    })?;
    let text =
        crate::io::input::read_text(input, "the pose file", crate::io::input::MAX_DATA_BYTES)?;
    let (csv_text, summary) = convert_poses(&text, input, options)?;
    crate::io::atomic::write_atomic(out, csv_text.as_bytes()).map_err(|e| {
        InputError::new(
            out,
            ErrorKind::Io,
            format!("cannot write the measurements: {e}"),
        )
    })?;
    Ok(summary)
}

/// As [`import_poses`], from the file's text to the contract CSV's text;
/// `file` names the input in errors.
///
/// # Errors
/// See the module docs.
pub fn convert_poses(
    text: &str,
    file: impl Into<PathBuf>,
    options: &ImportOptions,
) -> Result<(String, ImportedPoses), InputError> {
    use std::fmt::Write as _;
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

    // Header → layout.
    let mut joints: Vec<String> = Vec::new();
    let mut markers: Vec<u32> = Vec::new();
    let mut cols = Vec::with_capacity(header.len());
    let mut left_out = Vec::new();
    let marker_slot = |markers: &mut Vec<u32>, id: u32| match markers.iter().position(|&m| m == id)
    {
        Some(k) => k,
        None => {
            markers.push(id);
            markers.len() - 1
        }
    };
    for (i, name) in header.iter().enumerate() {
        if name.is_empty() {
            return Err(err(
                ErrorKind::Syntax,
                1,
                format!("column {} has no name", i + 1),
            ));
        }
        if header[..i].contains(name) {
            return Err(
                err(ErrorKind::DuplicateColumn, 1, "duplicate column".into())
                    .in_column(name.clone()),
            );
        }
        let col = if name == "pose_id" {
            Col::PoseId
        } else if name == "split" {
            Col::Split
        } else if let Some((axis, id)) = axis_marker(name, "") {
            Col::Pos(marker_slot(&mut markers, id), axis)
        } else if let Some((axis, id)) =
            axis_marker(name, "u").or_else(|| axis_marker(name, "std_"))
        {
            Col::Sigma(marker_slot(&mut markers, id), axis)
        } else if let Some((c, id)) = quaternion_marker(name) {
            Col::Quat(marker_slot(&mut markers, id), c)
        } else if let Some((axis, id, deg)) = euler_marker(name) {
            Col::Euler(marker_slot(&mut markers, id), axis, deg)
        } else if is_total_uncertainty(name) {
            Col::Other
        } else if let Some(joint) = name
            .strip_suffix("_rad")
            .or_else(|| name.strip_suffix("_m"))
            .filter(|j| !j.is_empty())
        {
            joints.push(joint.to_owned());
            Col::Joint(joints.len() - 1)
        } else {
            Col::Other
        };
        if col == Col::Other {
            left_out.push(name.clone());
        }
        cols.push(col);
    }
    if joints.is_empty() {
        return Err(err(
            ErrorKind::MissingColumn,
            1,
            "no joint column (<urdf joint>_rad or <urdf joint>_m)".into(),
        ));
    }
    if let Some(j) = joints
        .iter()
        .enumerate()
        .find_map(|(a, j)| joints[..a].contains(j).then_some(j))
    {
        return Err(err(
            ErrorKind::DuplicateColumn,
            1,
            format!("joint '{j}' has both a _rad and a _m column"),
        ));
    }
    // Every marker: its three position columns; uncertainty all or none.
    let find = |k: usize, sigma: bool, axis: usize| {
        cols.iter().position(|&c| {
            c == if sigma {
                Col::Sigma(k, axis)
            } else {
                Col::Pos(k, axis)
            }
        })
    };
    let mut pos_cols = Vec::with_capacity(markers.len());
    let mut sigma_cols = Vec::with_capacity(markers.len());
    for (k, &id) in markers.iter().enumerate() {
        let mut p = [0; 3];
        let mut s = [None; 3];
        for axis in 0..3 {
            p[axis] = find(k, false, axis).ok_or_else(|| {
                err(
                    ErrorKind::MissingColumn,
                    1,
                    format!("marker {id} has not all of x{id}_m, y{id}_m, z{id}_m"),
                )
                .in_column(format!("{}{id}_m", ["x", "y", "z"][axis]))
            })?;
            s[axis] = find(k, true, axis);
        }
        let sigma = match s {
            [Some(a), Some(b), Some(c)] => Some([a, b, c]),
            [None, None, None] => None,
            _ => {
                return Err(err(
                    ErrorKind::MissingColumn,
                    1,
                    format!("marker {id}: an uncertainty column for some axes only"),
                ))
            }
        };
        pos_cols.push(p);
        sigma_cols.push(sigma);
    }
    if markers.is_empty() {
        return Err(err(
            ErrorKind::MissingColumn,
            1,
            "no marker column (x<i>_m, y<i>_m, z<i>_m)".into(),
        ));
    }
    // Every marker's orientation: a quaternion or Euler angles, all their
    // columns or none.
    let mut rot_cols = Vec::with_capacity(markers.len());
    for (k, &id) in markers.iter().enumerate() {
        let quat: Vec<Option<usize>> = (0..4)
            .map(|c| cols.iter().position(|&col| col == Col::Quat(k, c)))
            .collect();
        let euler: Vec<Option<(usize, bool)>> = (0..3)
            .map(|a| {
                cols.iter().enumerate().find_map(|(i, &col)| match col {
                    Col::Euler(m, axis, deg) if m == k && axis == a => Some((i, deg)),
                    _ => None,
                })
            })
            .collect();
        let has_quat = quat.iter().any(Option::is_some);
        let has_euler = euler.iter().any(Option::is_some);
        let missing = |what: String| err(ErrorKind::MissingColumn, 1, what);
        let rot = match (has_quat, has_euler) {
            (false, false) => None,
            (true, true) => {
                return Err(missing(format!(
                    "marker {id} has both a quaternion (q*{id}) and Euler angles (r*{id}_deg): \
                     give one orientation"
                )))
            }
            (true, false) => {
                let all: Option<Vec<usize>> = quat.into_iter().collect();
                let all = all.ok_or_else(|| {
                    missing(format!(
                        "marker {id} has not all of qw{id}, qx{id}, qy{id}, qz{id}"
                    ))
                })?;
                Some(Rot::Quat([all[0], all[1], all[2], all[3]]))
            }
            (false, true) => {
                let all: Option<Vec<(usize, bool)>> = euler.into_iter().collect();
                let all = all.ok_or_else(|| {
                    missing(format!(
                        "marker {id} has not all of rx{id}, ry{id}, rz{id} (_deg or _rad)"
                    ))
                })?;
                let convention = options.euler.ok_or_else(|| {
                    missing(format!(
                        "marker {id} has Euler angles: name their convention with --euler \
                         (fixed-xyz: R = Rz Ry Rx, or moving-xyz: R = Rx Ry Rz)"
                    ))
                    .in_column(header[all[0].0].clone())
                })?;
                Some(Rot::Euler(
                    convention,
                    [all[0].0, all[1].0, all[2].0],
                    [all[0].1, all[1].1, all[2].1],
                ))
            }
        };
        rot_cols.push(rot);
    }
    let has_rot = rot_cols.iter().any(Option::is_some);
    let has_sigma = sigma_cols.iter().any(Option::is_some);
    let split_col = cols.iter().position(|&c| c == Col::Split);
    let id_col = cols.iter().position(|&c| c == Col::PoseId);
    if options.split.is_some() && split_col.is_none() {
        return Err(err(
            ErrorKind::MissingColumn,
            1,
            "--split given but the file has no split column".into(),
        )
        .in_column("split"));
    }

    let mut out = String::from("config,rep,marker,load_kg");
    for j in &joints {
        let _ = write!(out, ",{j}");
    }
    out.push_str(",x,y,z");
    if has_sigma {
        out.push_str(",sx,sy,sz");
    }
    if has_rot {
        out.push_str(",rx,ry,rz");
    }
    out.push('\n');
    let mut gimbal: Option<(usize, usize)> = None;
    let mut deg_max = vec![0.0_f64; header.len()];
    let mut orientations = 0;
    let mut seen_ids = HashSet::new();
    let mut seen_markers = vec![false; markers.len()];
    let (mut poses, mut rows) = (0, 0);
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
        let config: i64 = match id_col {
            Some(c) => {
                let s = &record[c];
                let id = s.parse().map_err(|_| {
                    err(ErrorKind::Syntax, line, format!("'{s}' is not an integer"))
                        .in_column("pose_id")
                })?;
                if !seen_ids.insert(id) {
                    return Err(err(
                        ErrorKind::InvalidValue,
                        line,
                        format!("pose_id {id} appears twice"),
                    )
                    .in_column("pose_id"));
                }
                id
            }
            None => (i + 1) as i64,
        };
        if let (Some(want), Some(c)) = (&options.split, split_col) {
            if &record[c] != want {
                continue;
            }
        }
        let number = |c: usize| -> Result<Option<f64>, InputError> {
            let s = &record[c];
            if s.is_empty() {
                return Ok(None);
            }
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
            Ok(Some(v))
        };
        let mut q = vec![0.0; joints.len()];
        for (c, col) in cols.iter().enumerate() {
            if let Col::Joint(j) = *col {
                q[j] = number(c)?.ok_or_else(|| {
                    err(
                        ErrorKind::Syntax,
                        line,
                        "empty joint cell: a pose needs every joint".into(),
                    )
                    .in_column(header[c].clone())
                })?;
            }
        }
        let mut any = false;
        for (k, &id) in markers.iter().enumerate() {
            let p = [
                number(pos_cols[k][0])?,
                number(pos_cols[k][1])?,
                number(pos_cols[k][2])?,
            ];
            let r = match rot_cols[k] {
                None => None,
                Some(rot) => {
                    let columns = rot.columns();
                    let cells = (columns.iter())
                        .map(|&c| number(c))
                        .collect::<Result<Vec<_>, _>>()?;
                    match cells.iter().position(Option::is_none) {
                        Some(_) if cells.iter().all(Option::is_none) => None,
                        Some(i) => {
                            return Err(err(
                                ErrorKind::Syntax,
                                line,
                                format!(
                                    "marker {id}: some of its orientation's cells empty, not all"
                                ),
                            )
                            .in_column(header[columns[i]].clone()))
                        }
                        None => {
                            let values: Vec<f64> = cells.into_iter().flatten().collect();
                            let r = rot.rotation_vector(&values).map_err(|(i, kind, why)| {
                                err(kind, line, why).in_column(header[columns[i]].clone())
                            })?;
                            // Euler angles: the largest in each `_deg`
                            // column, and gimbal lock (`ry` near ±90°).
                            if let Rot::Euler(_, c, deg) = rot {
                                for ((&c, &deg), v) in c.iter().zip(&deg).zip(&values) {
                                    if deg {
                                        deg_max[c] = deg_max[c].max(v.abs());
                                    }
                                }
                                let ry = if deg[1] {
                                    values[1].to_radians()
                                } else {
                                    values[1]
                                };
                                if ry.cos().abs() < GIMBAL_LOCK_RAD.sin() {
                                    gimbal.get_or_insert((0, line)).0 += 1;
                                }
                            }
                            Some(r)
                        }
                    }
                }
            };
            let p = match p {
                [Some(x), Some(y), Some(z)] => [x, y, z],
                [None, None, None] if r.is_none() => continue,
                [None, None, None] => {
                    return Err(err(
                        ErrorKind::Syntax,
                        line,
                        format!("marker {id}: an orientation without its point (x, y, z empty)"),
                    ))
                }
                _ => {
                    return Err(err(
                        ErrorKind::Syntax,
                        line,
                        format!("marker {id}: some of x, y, z empty, not all"),
                    ))
                }
            };
            let _ = write!(out, "{config},1,{id},0");
            for v in &q {
                let _ = write!(out, ",{v}");
            }
            let _ = write!(out, ",{},{},{}", p[0], p[1], p[2]);
            if has_sigma {
                let sigma = match sigma_cols[k] {
                    Some(cs) => {
                        let mut s = [0.0; 3];
                        for (v, &c) in s.iter_mut().zip(&cs) {
                            *v = number(c)?.filter(|v| *v >= 0.0).ok_or_else(|| {
                                err(
                                    ErrorKind::InvalidValue,
                                    line,
                                    "the uncertainty of a measured point must be a number ≥ 0"
                                        .into(),
                                )
                                .in_column(header[c].clone())
                            })?;
                        }
                        s
                    }
                    None => {
                        return Err(err(
                            ErrorKind::MissingColumn,
                            line,
                            format!(
                                "marker {id} has no uncertainty columns while others have: \
                                 the contract's sx, sy, sz are per row"
                            ),
                        ))
                    }
                };
                let _ = write!(out, ",{},{},{}", sigma[0], sigma[1], sigma[2]);
            }
            if has_rot {
                match r {
                    Some(r) => {
                        let _ = write!(out, ",{},{},{}", r[0], r[1], r[2]);
                        orientations += 1;
                    }
                    None => out.push_str(",,,"),
                }
            }
            out.push('\n');
            rows += 1;
            any = true;
            seen_markers[k] = true;
        }
        if any {
            poses += 1;
        }
    }
    if rows == 0 {
        let why = match &options.split {
            Some(s) => format!("no measured point in a row with split = '{s}'"),
            None => "no measured point".into(),
        };
        return Err(InputError::new(&file, ErrorKind::Syntax, why));
    }
    let mut used: Vec<u32> = markers
        .iter()
        .zip(&seen_markers)
        .filter(|(_, &s)| s)
        .map(|(&m, _)| m)
        .collect();
    used.sort_unstable();
    let mut warnings = Vec::new();
    if let Some((n, line)) = gimbal {
        warnings.push(format!(
            "{}: {n} orientation(s) with ry within 0.1° of ±90° (the first on line {line}): \
             at gimbal lock rx and rz turn about one axis, and an exporter's split between \
             them is ill-conditioned; the rotations are written as the angles give them",
            file.display()
        ));
    }
    let small: Vec<&str> = (header.iter().zip(&deg_max))
        .filter(|&(h, &m)| euler_marker(h).is_some_and(|e| e.2) && m <= core::f64::consts::PI)
        .map(|(h, _)| h.as_str())
        .collect();
    if !small.is_empty() && orientations >= 3 {
        warnings.push(format!(
            "{}: every value of {} is within ±π: radians in a _deg column?",
            file.display(),
            small.join(", ")
        ));
    }
    Ok((
        out,
        ImportedPoses {
            poses,
            rows,
            markers: used,
            joints,
            has_sigma,
            orientations,
            left_out,
            warnings,
        },
    ))
}

/// Where a marker's orientation is in a row.
#[derive(Debug, Clone, Copy)]
enum Rot {
    /// Columns of `w, x, y, z`.
    Quat([usize; 4]),
    /// The convention, the columns about `x, y, z`, and whether each is in
    /// degrees.
    Euler(Euler, [usize; 3], [bool; 3]),
}

impl Rot {
    /// Its columns, in the order [`Rot::rotation_vector`] takes the values.
    fn columns(self) -> Vec<usize> {
        match self {
            Self::Quat(c) => c.to_vec(),
            Self::Euler(_, c, _) => c.to_vec(),
        }
    }

    /// The rotation vector \[rad\] of a row's values (in the order of
    /// [`Rot::columns`]).
    ///
    /// # Errors
    /// `(index of the value, kind, why)`: a quaternion whose norm is off 1
    /// by more than [`QUATERNION_NORM_TOLERANCE`]; an angle in a `_rad`
    /// column beyond ±2π.
    fn rotation_vector(self, v: &[f64]) -> Result<[f64; 3], (usize, ErrorKind, String)> {
        match self {
            Self::Quat(_) => {
                let q = nalgebra::Quaternion::new(v[0], v[1], v[2], v[3]);
                let norm = q.norm();
                if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
                    return Err((
                        0,
                        ErrorKind::InvalidValue,
                        format!(
                            "(qw, qx, qy, qz) has norm {norm:.6}: not a unit quaternion \
                             (a rotation's norm is 1; within {QUATERNION_NORM_TOLERANCE} it is \
                             normalised)"
                        ),
                    ));
                }
                Ok(nalgebra::UnitQuaternion::from_quaternion(q)
                    .scaled_axis()
                    .into())
            }
            Self::Euler(convention, _, deg) => {
                let mut a = [0.0; 3];
                for (i, (a, (&v, &deg))) in a.iter_mut().zip(v.iter().zip(&deg)).enumerate() {
                    if !deg && v.abs() > core::f64::consts::TAU + 1e-9 {
                        return Err((
                            i,
                            ErrorKind::Units,
                            format!("{v} rad is beyond ±2π: degrees in a _rad column?"),
                        ));
                    }
                    *a = if deg { v.to_radians() } else { v };
                }
                Ok(convention.rotation_vector(a))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::io::poses::*;

    fn opts(split: Option<&str>) -> ImportOptions {
        ImportOptions {
            split: split.map(str::to_owned),
            euler: None,
        }
    }

    #[test]
    fn one_row_per_measured_point_and_split() {
        let text = "pose_id,split,test_set,j1_rad,slide_m,x1_m,y1_m,z1_m,x2_m,y2_m,z2_m\n\
                    7,cal,,0.5,0.1,1,2,3,,,\n\
                    9,test,t1,-0.25,0.2,4,5,6,7,8,9\n";
        let (csv, s) = convert_poses(text, "p.csv", &opts(None)).unwrap();
        assert_eq!(
            csv,
            "config,rep,marker,load_kg,j1,slide,x,y,z\n\
             7,1,1,0,0.5,0.1,1,2,3\n\
             9,1,1,0,-0.25,0.2,4,5,6\n\
             9,1,2,0,-0.25,0.2,7,8,9\n"
        );
        assert_eq!((s.poses, s.rows), (2, 3));
        assert_eq!(s.markers, [1, 2]);
        assert_eq!(s.left_out, ["test_set"]);
        let (csv, s) = convert_poses(text, "p.csv", &opts(Some("cal"))).unwrap();
        assert_eq!(csv.lines().count(), 2);
        assert_eq!((s.poses, s.rows, s.markers.as_slice()), (1, 1, &[1][..]));
        let e = convert_poses(text, "p.csv", &opts(Some("nope"))).unwrap_err();
        assert_eq!(
            e.to_string(),
            "p.csv: no measured point in a row with split = 'nope'"
        );
    }

    #[test]
    fn uncertainty_columns_become_sx_sy_sz() {
        let text = "pose_id,a_rad,x1_m,y1_m,z1_m,u1_m,ux1_m,uy1_m,uz1_m\n\
                    1,0.1,1,2,3,0.5,0.1,0.2,0.3\n";
        let (csv, s) = convert_poses(text, "p.csv", &opts(None)).unwrap();
        assert_eq!(
            csv,
            "config,rep,marker,load_kg,a,x,y,z,sx,sy,sz\n1,1,1,0,0.1,1,2,3,0.1,0.2,0.3\n"
        );
        assert!(s.has_sigma);
        assert_eq!(s.left_out, ["u1_m"]);
        let text = "a_rad,x1_m,y1_m,z1_m,std_x1_m,std_y1_m,std_z1_m\n0.1,1,2,3,0.1,0.2,-1\n";
        let e = convert_poses(text, "p.csv", &opts(None)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "p.csv:2: column 'std_z1_m': the uncertainty of a measured point must be a number ≥ 0"
        );
    }

    #[test]
    fn errors_name_line_and_column() {
        let head = "pose_id,split,a_rad,x1_m,y1_m,z1_m\n";
        let cases = [
            (
                format!("{head}1,cal,,1,2,3\n"),
                "p.csv:2: column 'a_rad': empty joint cell: a pose needs every joint",
            ),
            (
                format!("{head}1,cal,0,1,,3\n"),
                "p.csv:2: marker 1: some of x, y, z empty, not all",
            ),
            (
                format!("{head}1,cal,0,1,2,3\n1,cal,0,1,2,3\n"),
                "p.csv:3: column 'pose_id': pose_id 1 appears twice",
            ),
            (
                format!("{head}x,cal,0,1,2,3\n"),
                "p.csv:2: column 'pose_id': 'x' is not an integer",
            ),
            (
                format!("{head}1,cal,0,1,2,inf\n"),
                "p.csv:2: column 'z1_m': 'inf' is not finite",
            ),
            (
                "pose_id,a_rad,x1_m,y1_m\n1,0,1,2\n".into(),
                "p.csv:1: column 'z1_m': marker 1 has not all of x1_m, y1_m, z1_m",
            ),
            (
                "pose_id,x1_m,y1_m,z1_m\n1,0,1,2\n".into(),
                "p.csv:1: no joint column (<urdf joint>_rad or <urdf joint>_m)",
            ),
            (
                format!("{head}1,cal,0,1,2\n"),
                "p.csv:2: 5 cells for 6 columns",
            ),
        ];
        for (text, want) in cases {
            let e = convert_poses(&text, "p.csv", &opts(None)).unwrap_err();
            assert_eq!(e.to_string(), want, "{text}");
        }
        let e = convert_poses(
            "a_rad,x1_m,y1_m,z1_m\n0,1,2,3\n",
            "p.csv",
            &opts(Some("cal")),
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "p.csv:1: column 'split': --split given but the file has no split column"
        );
    }
}
