//! A measurement file's header: its columns checked against the robot and
//! the setup ([`Header::read`]), and the [`Layout`] its records are read
//! with.

use std::path::Path;

use crate::io::measurements::records::Layout;
use crate::io::measurements::{Col, FIXED};
use crate::io::setup::Setup;
use crate::io::urdf::Robot;
use crate::io::{error::ErrorKind, error::InputError};

/// A file's header as read: what its columns are, and where its records
/// start.
pub(super) struct Header {
    /// The header's cells.
    pub(super) record: csv::StringRecord,
    /// Each field's column.
    pub(super) cols: Vec<Col>,
    /// Each joint's field.
    pub(super) joint_field: Vec<Option<usize>>,
    /// Whether there is a `t` column.
    pub(super) has_time: bool,
    /// The byte the records start at.
    pub(super) data_start: usize,
}

impl Header {
    /// The csv crate's reader of a measurement file's `bytes` from its
    /// start, as [`Header::read`] takes it: the whole file's and the first
    /// block's ([`crate::io::measurements::stream`]) alike, so that both read the same header.
    pub(super) fn reader(bytes: &[u8]) -> csv::Reader<&[u8]> {
        csv::ReaderBuilder::new()
            .has_headers(true)
            .trim(csv::Trim::All)
            .from_reader(bytes)
    }

    /// The header of the file `rdr` reads (at its start), checked against
    /// `robot` and `setup`; `csv_err` makes the csv reader's errors ours.
    ///
    /// # Errors
    /// A missing, unknown or duplicate column, no header row.
    pub(super) fn read(
        rdr: &mut csv::Reader<&[u8]>,
        file: &Path,
        robot: &Robot,
        setup: &Setup,
        csv_err: &dyn Fn(csv::Error) -> InputError,
    ) -> Result<Self, InputError> {
        let err =
            |kind, line: usize, message: String| InputError::new(file, kind, message).at_line(line);
        let cell_err = |kind, line: usize, column: &str, message: String| {
            err(kind, line, message).in_column(column)
        };
        let header = rdr.headers().map_err(csv_err)?.clone();
        if header.iter().all(str::is_empty) {
            return Err(err(ErrorKind::Syntax, 1, "no header row".into()));
        }

        // Header → column layout.
        for name in &robot.joint_names {
            if FIXED.iter().any(|(f, _)| f == name) {
                return Err(cell_err(
                    ErrorKind::DuplicateColumn,
                    1,
                    name,
                    "a joint of the robot has the name of a fixed column".into(),
                ));
            }
        }
        let temperature = setup.model.temperature_column.as_deref();
        if let Some(name) = temperature {
            if FIXED.iter().any(|(f, _)| *f == name) || robot.joint_index(name).is_some() {
                return Err(cell_err(
                    ErrorKind::DuplicateColumn,
                    1,
                    name,
                    "the setup's temperature_column names a fixed column or a joint".into(),
                ));
            }
            if !header.iter().any(|n| n == name) {
                return Err(cell_err(
                    ErrorKind::MissingColumn,
                    1,
                    name,
                    "missing column (the setup's temperature_column)".into(),
                ));
            }
        }
        let mut cols = Vec::with_capacity(header.len());
        for (i, name) in header.iter().enumerate() {
            let col = FIXED
                .iter()
                .find(|(f, _)| *f == name)
                .map(|&(_, c)| c)
                .or_else(|| robot.joint_index(name).map(Col::Joint))
                .or_else(|| (temperature == Some(name)).then_some(Col::Temperature))
                .or_else(|| {
                    setup
                        .ignore_columns
                        .iter()
                        .any(|c| c == name)
                        .then_some(Col::Ignored)
                })
                .ok_or_else(|| {
                    cell_err(
                        ErrorKind::UnknownColumn,
                        1,
                        name,
                        format!(
                            "neither a fixed column nor a movable joint of the chain \
                             from '{}' to '{}' (joints: {}); to leave it out, add it to \
                             the setup's ignore_columns",
                            robot.base_link,
                            robot.tip_link,
                            robot.joint_names.join(", ")
                        ),
                    )
                })?;
            if header.iter().take(i).any(|n| n == name) {
                return Err(cell_err(
                    ErrorKind::DuplicateColumn,
                    1,
                    name,
                    "column appears twice".into(),
                ));
            }
            cols.push(col);
        }
        // `rep`, `marker` and `load_kg` may be left out where the setup makes
        // them unambiguous (data contract 7.2): one repetition, the one marker,
        // no load.
        let one_marker = setup.markers.len() == 1;
        let optional = |name: &str| match name {
            "rep" => true,
            "marker" => one_marker,
            "load_kg" => setup.load.is_none(),
            // A file of plane contacts or distances alone has no points.
            "x" | "y" | "z" => header.iter().any(|n| n == "plane" || n == "anchor"),
            _ => false,
        };
        let required = FIXED[..7]
            .iter()
            .map(|(n, _)| *n)
            .chain(robot.joint_names.iter().map(String::as_str));
        for name in required {
            if !header.iter().any(|n| n == name) && !optional(name) {
                let why = match name {
                    "marker" => "missing column (the setup declares more than one marker)",
                    "load_kg" => "missing column (the setup has a [load])",
                    _ => "missing column",
                };
                return Err(cell_err(ErrorKind::MissingColumn, 1, name, why.into()));
            }
        }
        let has_time = cols.contains(&Col::Time);
        // The record field of each joint.
        let joint_field: Vec<Option<usize>> = (0..robot.dof())
            .map(|j| cols.iter().position(|&c| c == Col::Joint(j)))
            .collect();
        // `x, y, z` come together (or none, in a file of plane contacts
        // and distances).
        let pos_cols = (0..3).filter(|&k| cols.contains(&Col::Pos(k))).count();
        if pos_cols != 0 && pos_cols != 3 {
            let missing =
                ["x", "y", "z"][(0..3).find(|&k| !cols.contains(&Col::Pos(k))).unwrap_or(0)];
            return Err(cell_err(
                ErrorKind::MissingColumn,
                1,
                missing,
                "a point comes as three columns x, y, z".into(),
            ));
        }
        // `sx, sy, sz` come together (data contract 7.2).
        let sigma_cols = (0..3).filter(|&k| cols.contains(&Col::Sigma(k))).count();
        if sigma_cols != 0 && sigma_cols != 3 {
            let missing = ["sx", "sy", "sz"][(0..3)
                .find(|&k| !cols.contains(&Col::Sigma(k)))
                .unwrap_or(0)];
            return Err(cell_err(
                ErrorKind::MissingColumn,
                1,
                missing,
                "the instrument's σ comes as three columns sx, sy, sz or none".into(),
            ));
        }

        // `rx, ry, rz` come together, and `srx, sry, srz` only with them.
        for (names, col, what) in [
            (
                ["rx", "ry", "rz"],
                Col::Rot as fn(usize) -> Col,
                "the orientation comes as three columns rx, ry, rz or none",
            ),
            (
                ["srx", "sry", "srz"],
                Col::SigmaRot,
                "the orientation's σ comes as three columns srx, sry, srz or none",
            ),
        ] {
            let n = (0..3).filter(|&k| cols.contains(&col(k))).count();
            if n != 0 && n != 3 {
                let missing = names[(0..3).find(|&k| !cols.contains(&col(k))).unwrap_or(0)];
                return Err(cell_err(ErrorKind::MissingColumn, 1, missing, what.into()));
            }
        }
        // `anchor` and `distance` come together; `sd` with one of them.
        for (have, need, what) in [
            (
                Col::Anchor,
                Col::Distance,
                "an anchor's rows measure a distance: distance is missing",
            ),
            (
                Col::Distance,
                Col::Anchor,
                "distance is from an anchor: anchor is missing",
            ),
        ] {
            if cols.contains(&have) && !cols.contains(&need) {
                let name = if need == Col::Distance {
                    "distance"
                } else {
                    "anchor"
                };
                return Err(cell_err(ErrorKind::MissingColumn, 1, name, what.into()));
            }
        }
        if cols.contains(&Col::SigmaScalar)
            && !cols.contains(&Col::Plane)
            && !cols.contains(&Col::Anchor)
        {
            return Err(cell_err(
                ErrorKind::MissingColumn,
                1,
                "plane",
                "sd is the σ of a plane contact or a distance: plane and anchor are missing".into(),
            ));
        }
        if cols.contains(&Col::SigmaRot(0)) && !cols.contains(&Col::Rot(0)) {
            return Err(cell_err(
                ErrorKind::MissingColumn,
                1,
                "rx",
                "srx, sry, srz are the σ of an orientation: rx, ry, rz are missing".into(),
            ));
        }

        Ok(Self {
            record: header,
            cols,
            joint_field,
            has_time,
            data_start: rdr.position().byte() as usize,
        })
    }

    /// The layout of the records under this header.
    pub(super) fn layout<'a>(
        &'a self,
        file: &'a Path,
        robot: &'a Robot,
        setup: &'a Setup,
    ) -> Layout<'a> {
        Layout {
            file,
            robot,
            setup,
            header: &self.record,
            cols: &self.cols,
            joint_field: &self.joint_field,
            markers: setup.markers.iter().map(|m| m.id).collect(),
        }
    }
}
