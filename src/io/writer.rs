//! Writing a measurement file (data contract §3), the reader's inverse.

use std::path::Path;

use crate::io::cells::{format_real, Scale};
use crate::io::measurements::Observation;
use crate::io::setup::Units;
use crate::io::urdf::Robot;
use crate::io::{error::ErrorKind, error::InputError};

/// Writes `rows` (SI) as a measurement file for `robot` in `units`:
/// header `config,rep,marker,load_kg,<joints in chain order>,x,y,z[,t][,sx,sy,sz]`
/// (`t` when the rows have times, `sx, sy, sz` when they have the
/// instrument's σ). [`crate::io::measurements::read_measurements`] reads it back to
/// the same values (see the module doc for deg).
///
/// The file is written to a temporary file next to `path` and renamed over
/// it, so `path` is either untouched or complete.
///
/// # Errors
/// A row with the wrong number of joint values, a non-finite number, a
/// negative load, some rows with a time and some without (naming the line
/// the row would have); or the file cannot be written. Nothing is written
/// on error.
pub fn write_measurements(
    path: impl AsRef<Path>,
    robot: &Robot,
    units: Units,
    rows: &[Observation],
) -> Result<(), InputError> {
    write_measurements_with(path, robot, units, None, rows)
}

/// [`write_measurements`], each row's temperature \[°C\] in the column
/// `temperature_column` (the setup's `[model] temperature_column`) after
/// the others.
///
/// # Errors
/// As [`write_measurements`]; also some rows with a temperature and some
/// without, or rows with one and no column to write it in.
pub fn write_measurements_with(
    path: impl AsRef<Path>,
    robot: &Robot,
    units: Units,
    temperature_column: Option<&str>,
    rows: &[Observation],
) -> Result<(), InputError> {
    let path = path.as_ref();
    let has_temperature = rows.first().is_some_and(|r| r.temp_c.is_some());
    let has_time = rows.first().is_some_and(|r| r.t_s.is_some());
    let has_sigma = rows.first().is_some_and(|r| r.sigma_m.is_some());
    let has_rot = rows.first().is_some_and(|r| r.r_rad.is_some());
    let has_sigma_rot = rows.first().is_some_and(|r| r.sigma_rad.is_some());
    let dof = robot.dof();
    let scales: Vec<Scale> = robot
        .joint_kinds
        .iter()
        .map(|k| {
            if k.is_angular() {
                Scale::Angle(units.angle)
            } else {
                Scale::Length(units.length)
            }
        })
        .collect();

    let mut out = csv::Writer::from_writer(Vec::new());
    let mut header: Vec<&str> = vec!["config", "rep", "marker", "load_kg"];
    header.extend(robot.joint_names.iter().map(String::as_str));
    header.extend(["x", "y", "z"]);
    if has_time {
        header.push("t");
    }
    if has_sigma {
        header.extend(["sx", "sy", "sz"]);
    }
    if has_rot {
        header.extend(["rx", "ry", "rz"]);
    }
    if has_sigma_rot {
        header.extend(["srx", "sry", "srz"]);
    }
    if has_temperature {
        match temperature_column {
            Some(c) => header.push(c),
            None => {
                return Err(InputError::new(
                    path,
                    ErrorKind::InvalidValue,
                    "the rows have temperatures and no column is named for them (the \
                     setup's temperature_column)"
                        .to_string(),
                ))
            }
        }
    }
    let io_err = |e: &dyn std::fmt::Display| {
        InputError::new(
            path,
            ErrorKind::Io,
            format!("cannot write the measurements: {e}"),
        )
    };
    out.write_record(&header).map_err(|e| io_err(&e))?;
    for (i, r) in rows.iter().enumerate() {
        let line = i + 2;
        let err = |kind, message: String| {
            Err(InputError::new(path, kind, format!("row {i}: {message}")).at_line(line))
        };
        if r.q.len() != dof {
            return err(
                ErrorKind::InvalidValue,
                format!("{} joint values for {dof} joints", r.q.len()),
            );
        }
        if r.t_s.is_some() != has_time {
            return err(
                ErrorKind::InvalidValue,
                "some rows have a time and some do not".into(),
            );
        }
        if r.temp_c.is_some() != has_temperature {
            return err(
                ErrorKind::InvalidValue,
                "some rows have a temperature and some do not".into(),
            );
        }
        if r.scalar.is_some() {
            return err(
                ErrorKind::InvalidValue,
                "a plane contact or a distance: the writer writes points and poses".into(),
            );
        }
        if r.sigma_m.is_some() != has_sigma {
            return err(
                ErrorKind::InvalidValue,
                "some rows have the instrument's σ and some do not".into(),
            );
        }
        if r.r_rad.is_some() != has_rot || r.sigma_rad.is_some() != has_sigma_rot {
            return err(
                ErrorKind::InvalidValue,
                "some rows have an orientation (or its σ) and some do not".into(),
            );
        }
        let sigma = r.sigma_m.iter().flatten();
        let rot = r.r_rad.iter().flatten().chain(r.sigma_rad.iter().flatten());
        let numbers =
            r.q.iter()
                .chain(&r.p_m)
                .chain(&r.t_s)
                .chain(&r.temp_c)
                .chain([&r.load_kg])
                .chain(sigma.clone())
                .chain(rot.clone());
        if numbers.clone().any(|v| !v.is_finite()) {
            return err(ErrorKind::NonFinite, "non-finite value".into());
        }
        if r.load_kg < 0.0 {
            return err(
                ErrorKind::InvalidValue,
                format!("negative load {}", r.load_kg),
            );
        }
        let mut fields = vec![
            r.config.to_string(),
            r.rep.to_string(),
            r.marker.to_string(),
            format_real(r.load_kg, Scale::One),
        ];
        fields.extend(r.q.iter().zip(&scales).map(|(&v, &s)| format_real(v, s)));
        fields.extend(
            r.p_m
                .iter()
                .map(|&v| format_real(v, Scale::Length(units.length))),
        );
        fields.extend(r.t_s.map(|t| format_real(t, Scale::One)));
        fields.extend(sigma.map(|&v| format_real(v, Scale::Length(units.length))));
        fields.extend(rot.map(|&v| format_real(v, Scale::Angle(units.angle))));
        fields.extend(r.temp_c.map(|t| format_real(t, Scale::One)));
        out.write_record(&fields).map_err(|e| io_err(&e))?;
    }
    let bytes = out.into_inner().map_err(|e| io_err(&e))?;

    crate::io::atomic::write_atomic(path, &bytes).map_err(|e| io_err(&e))
}

/// A CSV cell of `text`: quoted (its quotes doubled) when it holds a
/// separator, a quote or a line end, as the csv crate reads it back.
pub fn csv_cell(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}
