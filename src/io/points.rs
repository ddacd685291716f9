//! The CSV of `robcal predict` and `robcal compensate`: one row per point
//! of the calibrated robot to predict, or per target to reach. SI units,
//! named in the headers:
//!
//! | column | what | |
//! |---|---|---|
//! | `id` | any text, copied to the output | optional |
//! | `marker` | the marker (tool point) id of the model file | optional with one marker |
//! | `load_kg` | the payload's mass \[kg\], ≥ 0 | optional, default 0 |
//! | `com_x_m`, `com_y_m`, `com_z_m` | the payload's centre of mass \[m, tip frame\] | required with a payload |
//! | `<joint>_rad` / `<joint>_m` | joint values \[rad, or m for a prismatic joint\] by URDF name: the pose to predict, or the start of a compensation (e.g. the nominal inverse kinematics of the target) | one per joint |
//! | `x_m`, `y_m`, `z_m` | the target \[m, measurement frame\] | `compensate` only |
//! | `rx_rad`, `ry_rad`, `rz_rad` | the target orientation of the tip frame, a rotation vector (axis × angle) \[rad, measurement frame\]: a pose target | `compensate`, optional |
//!
//! Any other column is an error; so is a non-finite or malformed cell,
//! with its line and column, and a value no robot has: a payload above
//! [`MAX_LOAD_KG`], a length (centre of mass, target, prismatic joint)
//! beyond ±[`MAX_POSITION_M`] (the measurement reader's bounds,
//! [`crate::io::measurements`]), an angle beyond ±[`MAX_JOINT_RAD`] (this
//! reader's own: the measurement reader bounds a limited joint by ±2π).

use std::path::Path;

use crate::io::units::{MAX_LOAD_KG, MAX_POSITION_M};
use crate::io::{error::ErrorKind, error::InputError};
use crate::robot::JointKind;

/// Largest joint angle \[rad\] read (1 591 turns: a continuous joint's
/// count of turns, not an angle's unit mistaken).
pub const MAX_JOINT_RAD: f64 = 1e4;

/// One row.
#[derive(Debug, Clone, PartialEq)]
pub struct PointRow {
    /// Its line in the file (the header is line 1).
    pub line: usize,
    /// The `id` cell, if there is that column.
    pub id: Option<String>,
    /// Marker id (`None`: no `marker` column).
    pub marker: Option<u32>,
    /// Payload mass \[kg\].
    pub load_kg: f64,
    /// Payload centre of mass \[m, tip frame\] (with the `com_*` columns).
    pub com_m: Option<[f64; 3]>,
    /// Joint values \[rad or m\], chain order.
    pub q: Vec<f64>,
    /// The target \[m, measurement frame\] (with the `x_m…` columns).
    pub target_m: Option<[f64; 3]>,
    /// The tip frame's target orientation, rotation vector \[rad,
    /// measurement frame\] (with the `rx_rad…` columns).
    pub target_rotation_rad: Option<[f64; 3]>,
}

/// The joint value column of a joint: `<name>_rad` or `<name>_m`.
pub fn joint_column(name: &str, kind: JointKind) -> String {
    match kind {
        JointKind::Revolute => format!("{name}_rad"),
        JointKind::Prismatic => format!("{name}_m"),
    }
}

/// Reads the points CSV `text` of `file` for a chain with `joints` (name
/// and kind, chain order); `target` says whether the `x_m, y_m, z_m`
/// columns are required (`compensate`) or refused (`predict`).
///
/// # Errors
/// [`InputError`] with the line and column: a missing, unknown or repeated
/// column, a malformed or non-finite cell, a negative mass, a value beyond
/// its bound (module docs), a payload without its centre of mass, no row.
pub fn parse_points(
    text: &str,
    file: &Path,
    joints: &[(String, JointKind)],
    target: bool,
) -> Result<Vec<PointRow>, InputError> {
    let err = |kind, m: String| InputError::new(file, kind, m);
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| err(ErrorKind::Syntax, format!("header: {e}")).at_line(1))?
        .iter()
        .map(str::to_string)
        .collect();
    let find = |name: &str| header.iter().position(|h| h == name);
    for (i, h) in header.iter().enumerate() {
        if header[..i].contains(h) {
            return Err(
                err(ErrorKind::DuplicateColumn, "column appears twice".into())
                    .at_line(1)
                    .in_column(h),
            );
        }
    }
    let xyz = |prefix: &str| ["x", "y", "z"].map(|a| format!("{prefix}{a}_m"));
    let (com_names, target_names) = (xyz("com_"), xyz(""));
    let rot_names = ["rx_rad", "ry_rad", "rz_rad"].map(String::from);
    let joint_names: Vec<String> = joints.iter().map(|(n, k)| joint_column(n, *k)).collect();
    let mut known: Vec<&str> = vec!["id", "marker", "load_kg"];
    known.extend(com_names.iter().map(String::as_str));
    known.extend(joint_names.iter().map(String::as_str));
    if target {
        known.extend(target_names.iter().map(String::as_str));
        known.extend(rot_names.iter().map(String::as_str));
    }
    if let Some(h) = header.iter().find(|h| !known.contains(&h.as_str())) {
        let why = if target_names.contains(h) {
            "a target belongs to `robcal compensate`, not `predict`".to_string()
        } else {
            format!("not a column of this file (expected: {})", known.join(", "))
        };
        return Err(err(ErrorKind::UnknownColumn, why).at_line(1).in_column(h));
    }
    let required = |names: &[String]| -> Result<Vec<usize>, InputError> {
        names
            .iter()
            .map(|n| {
                find(n).ok_or_else(|| {
                    err(
                        ErrorKind::MissingColumn,
                        "required column is missing".into(),
                    )
                    .at_line(1)
                    .in_column(n)
                })
            })
            .collect()
    };
    let q_cols = required(&joint_names)?;
    let target_cols = if target {
        Some(required(&target_names)?)
    } else {
        None
    };
    let rot_present: Vec<usize> = rot_names.iter().filter_map(|n| find(n)).collect();
    let rot_cols = match rot_present.len() {
        0 => None,
        3 => Some(rot_present),
        _ => {
            return Err(err(
                ErrorKind::MissingColumn,
                "rx_rad, ry_rad and rz_rad come together".into(),
            )
            .at_line(1))
        }
    };
    let com_present: Vec<Option<usize>> = com_names.iter().map(|n| find(n)).collect();
    let com_cols = match com_present.iter().flatten().count() {
        0 => None,
        3 => Some(com_present.iter().flatten().copied().collect::<Vec<_>>()),
        _ => {
            return Err(err(
                ErrorKind::MissingColumn,
                "com_x_m, com_y_m and com_z_m come together".into(),
            )
            .at_line(1))
        }
    };
    let (id_col, marker_col, load_col) = (find("id"), find("marker"), find("load_kg"));
    let mut rows = Vec::new();
    for (i, record) in reader.records().enumerate() {
        let line = i + 2;
        let record = record.map_err(|e| err(ErrorKind::Syntax, e.to_string()).at_line(line))?;
        let cell = |c: usize| record.get(c).unwrap_or("");
        let real = |c: usize| -> Result<f64, InputError> {
            let text = cell(c);
            let v: f64 = text.parse().map_err(|_| {
                err(
                    ErrorKind::Syntax,
                    format!("{} is not a number", crate::io::input::quote(text)),
                )
                .at_line(line)
                .in_column(&header[c])
            })?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(err(ErrorKind::NonFinite, "non-finite value".into())
                    .at_line(line)
                    .in_column(&header[c]))
            }
        };
        // A value beyond `limit` in magnitude is not one of a robot's
        // (the measurement reader's bounds): an error, not a prediction.
        let within = |c: usize, limit: f64, unit: &str| -> Result<f64, InputError> {
            let v = real(c)?;
            if v.abs() <= limit {
                return Ok(v);
            }
            Err(err(
                ErrorKind::InvalidValue,
                format!("{v:e} {unit} is beyond {limit:e} {unit} in magnitude: not a robot's"),
            )
            .at_line(line)
            .in_column(&header[c]))
        };
        let three = |cols: &[usize], limit: f64, unit: &str| -> Result<[f64; 3], InputError> {
            Ok([
                within(cols[0], limit, unit)?,
                within(cols[1], limit, unit)?,
                within(cols[2], limit, unit)?,
            ])
        };
        let (length, angle) = (MAX_POSITION_M, MAX_JOINT_RAD);
        let marker = match marker_col {
            Some(c) => Some(cell(c).parse::<u32>().map_err(|_| {
                err(
                    ErrorKind::Syntax,
                    format!("{} is not a marker id", crate::io::input::quote(cell(c))),
                )
                .at_line(line)
                .in_column("marker")
            })?),
            None => None,
        };
        let load_kg = match load_col {
            Some(c) => within(c, MAX_LOAD_KG, "kg")?,
            None => 0.0,
        };
        if load_kg < 0.0 {
            return Err(err(
                ErrorKind::InvalidValue,
                format!("negative mass {load_kg} kg"),
            )
            .at_line(line)
            .in_column("load_kg"));
        }
        let com_m = (com_cols.as_deref())
            .map(|c| three(c, length, "m"))
            .transpose()?;
        if load_kg > 0.0 && com_m.is_none() {
            return Err(err(
                ErrorKind::MissingColumn,
                "a payload needs its centre of mass (com_x_m, com_y_m, com_z_m)".into(),
            )
            .at_line(line));
        }
        rows.push(PointRow {
            line,
            id: id_col.map(|c| cell(c).to_string()),
            marker,
            load_kg,
            com_m,
            q: (q_cols.iter().zip(joints))
                .map(|(&c, (_, kind))| match kind {
                    JointKind::Revolute => within(c, angle, "rad"),
                    JointKind::Prismatic => within(c, length, "m"),
                })
                .collect::<Result<_, _>>()?,
            target_m: (target_cols.as_deref())
                .map(|c| three(c, length, "m"))
                .transpose()?,
            target_rotation_rad: (rot_cols.as_deref())
                .map(|c| three(c, angle, "rad"))
                .transpose()?,
        });
    }
    if rows.is_empty() {
        return Err(err(ErrorKind::InvalidValue, "no row".into()));
    }
    Ok(rows)
}
