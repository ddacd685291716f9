//! What follows from a row's frames ([`Rows::frames`], recomputed where
//! read): its predicted point ([`Rows::point_m`]) and its left-hand side
//! ([`Rows::y`]), which the rows do not keep.

use nalgebra::{Rotation3, Vector3};

use crate::calibrate::params::geometry::{Geometry, J};
use crate::calibrate::rows::{Row, RowKind, Rows};
use crate::error::Error;
use crate::robot::Frames;

impl Rows {
    /// The frames of `row` (one of these rows) at the last
    /// [`Rows::relinearise`]: the forward kinematics of its chain at its
    /// pose, as they were computed there.
    ///
    /// # Errors
    /// [`Error`] from the forward kinematics (a row not relinearised).
    pub fn frames(&self, row: &Row) -> Result<Frames<f64, J>, Error> {
        let mut out = Frames::empty();
        self.frames_into(row, &mut out)?;
        Ok(out)
    }

    /// [`Rows::frames`] into `out` ([`crate::robot::Chain::frames_into`]).
    ///
    /// # Errors
    /// As [`Rows::frames`].
    pub fn frames_into(&self, row: &Row, out: &mut Frames<f64, J>) -> Result<(), Error> {
        let chain = usize::try_from(row.chain).ok();
        let chain = chain
            .and_then(|c| self.chains.get(c))
            .ok_or(Error::Mismatch {
                what: "rows not evaluated at a geometry",
            })?;
        if row.theta().is_empty() {
            chain.frames_into(&row.q, out)
        } else {
            chain.frames_into(row.theta(), out)
        }
    }

    /// The predicted position of `row`'s marker \[m, measurement frame\]
    /// at its `frames` ([`Rows::frames`]): the current model's, as
    /// [`Rows::relinearise`] computed it (bit for bit).
    pub fn point_m(&self, row: &Row, frames: &Frames<f64, J>) -> Vector3<f64> {
        frames.point_m(&marker_m(&self.markers, row))
    }

    /// The left-hand side of `row` \[m\] at its `frames` ([`Rows::frames`]),
    /// linearised at the current model ([`crate::calibrate::params::linearisation`]):
    /// measured minus predicted plus the linearised joint-law part,
    /// `measured − f(x₀) + B(x₀) x₀`. With the first-order model the
    /// measured deflection, or the measured position minus the rigid
    /// forward kinematics ([`Rows::point_m`]); with the exact model, as
    /// [`Rows::relinearise`] kept it ([`crate::calibrate::rows::RowExtra::y`]). Not kept per row
    /// otherwise (24 MB at 10⁶ rows).
    pub fn y(&self, row: &Row, frames: &Frames<f64, J>) -> Vector3<f64> {
        lhs(&self.markers, &self.tool_rotation, row, frames)
    }

    /// [`Rows::y`] of every row, in order (their frames recomputed: on
    /// worker threads with many rows).
    ///
    /// # Errors
    /// As [`Rows::frames`].
    pub fn lhs(&self) -> Result<Vec<Vector3<f64>>, Error> {
        per_row(&self.rows, |row, frames| {
            if needs_frames(row) {
                self.frames_into(row, frames)?;
            }
            Ok(self.y(row, frames))
        })
    }

    /// [`Rows::lhs`] of every row as [`Rows::relinearise`] at `geometry`
    /// without a joint law (the nominal robot's: first order, no row's
    /// [`crate::calibrate::rows::RowExtra::y`]) gives it, without relinearising: the frames at each
    /// row's `q` on `geometry`'s chains.
    ///
    /// # Errors
    /// As [`Rows::frames`].
    pub fn rigid_lhs_at(&self, geometry: &Geometry) -> Result<Vec<Vector3<f64>>, Error> {
        let chains = geometry.placed_chains();
        per_row(&self.rows, |row, frames| {
            if row.kind == RowKind::Deflection {
                return Ok(row.measured);
            }
            let end = geometry.end_of(row.marker);
            let chain =
                chains
                    .get(end.min(chains.len().saturating_sub(1)))
                    .ok_or(Error::Mismatch {
                        what: "a geometry without a chain",
                    })?;
            chain.frames_into(&row.q, frames)?;
            let tool = geometry.tool_rotation.to_rotation_matrix();
            Ok(rigid_y(&geometry.markers, &tool, row, frames))
        })
    }

    /// [`Rows::point_m`] of each of `rows` (some of these rows), at their
    /// frames (recomputed: on worker threads with many rows).
    ///
    /// # Errors
    /// As [`Rows::frames`].
    pub fn points_m(&self, rows: &[&Row]) -> Result<Vec<Vector3<f64>>, Error> {
        per_row(rows, |row, frames| {
            self.frames_into(row, frames)?;
            Ok(self.point_m(row, frames))
        })
    }
}

/// `f(row, frames)` of each of `rows`, in order, with one [`Frames`] to
/// fill per run of rows: runs on worker threads with many rows; the first
/// error in row order.
fn per_row<R: std::borrow::Borrow<Row> + Sync>(
    rows: &[R],
    f: impl Fn(&Row, &mut Frames<f64, J>) -> Result<Vector3<f64>, Error> + Sync,
) -> Result<Vec<Vector3<f64>>, Error> {
    let threads = crate::parallel::for_rows(rows.len());
    let per = rows.len().div_ceil(threads).max(1);
    let runs = crate::parallel::map(rows.len().div_ceil(per), threads, |t| {
        let mut frames = Frames::empty();
        rows[t * per..((t + 1) * per).min(rows.len())]
            .iter()
            .map(|row| f(row.borrow(), &mut frames))
            .collect::<Result<Vec<_>, Error>>()
    });
    let mut out = Vec::with_capacity(rows.len());
    for run in runs {
        out.extend(run?);
    }
    Ok(out)
}

/// Whether [`lhs`] of `row` reads its frames (a first-order absolute
/// row's).
fn needs_frames(row: &Row) -> bool {
    row.kind == RowKind::Absolute && row.extra.as_ref().is_none_or(|e| e.y.is_none())
}

/// [`Rows::y`] with the markers `markers` (frames not read where
/// [`needs_frames`] is false).
pub(crate) fn lhs(
    markers: &[Vector3<f64>],
    tool: &Rotation3<f64>,
    row: &Row,
    frames: &Frames<f64, J>,
) -> Vector3<f64> {
    match row.extra.as_ref().and_then(|e| e.y) {
        Some(y) => y,
        None if row.kind == RowKind::Absolute => rigid_y(markers, tool, row, frames),
        None => row.measured,
    }
}

/// An absolute row's left-hand side at `frames`, no joint law: the
/// measured point minus the predicted, a pose's orientation left
/// ([`super::orientation::residual`], \[rad\]), or a plane contact's or a
/// distance's number left ([`super::scalar`], on axis 0).
fn rigid_y(
    markers: &[Vector3<f64>],
    tool: &Rotation3<f64>,
    row: &Row,
    frames: &Frames<f64, J>,
) -> Vector3<f64> {
    if row.orientation {
        let predicted = frames.tip().rotation.to_rotation_matrix() * tool;
        super::orientation::residual(&row.measured, &predicted)
    } else if let Some(s) = row.scalar() {
        s.lhs(&frames.point_m(&marker_m(markers, row)), &Vector3::zeros())
    } else {
        row.measured - frames.point_m(&marker_m(markers, row))
    }
}

/// `row`'s marker's position on its link \[m\] among `markers` (zero
/// for one not there).
pub(crate) fn marker_m(markers: &[Vector3<f64>], row: &Row) -> Vector3<f64> {
    markers
        .get(usize::from(row.marker))
        .copied()
        .unwrap_or_default()
}
