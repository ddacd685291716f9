//! How the columns of some parameters are computed at a row (`B` of
//! eq. 4, in the reported units): the one function a held design writes
//! (`build`) and a design not held computes again where read (`source`).

use std::borrow::Cow;

use nalgebra::Vector3;

use crate::calibrate::params::geometry::J;
use crate::calibrate::params::linearisation::Linearisation;
use crate::calibrate::params::masses;
use crate::calibrate::rows::{orientation, Row, Rows};
use crate::error::Error;
use crate::model::Param;
use crate::robot::Chain;

/// How the columns of some parameters are computed at a row.
pub(super) struct Columns<'a> {
    pub(super) params: &'a [Param],
    /// Each parameter's reported unit in SI.
    pub(super) si: Cow<'a, [f64]>,
    /// Whether a column needs the joints' compliances (the load's centre of
    /// mass).
    pub(super) linearised: bool,
    pub(super) lin: &'a Linearisation,
    /// Whether the rows mix both kinds ([`crate::calibrate::rows::noise_scale`]).
    pub(super) mixed: bool,
    /// The markers' positions on their links \[m\] (a row's predicted
    /// point is its frames' at its marker: [`Rows::point_m`]).
    pub(super) markers: &'a [Vector3<f64>],
    /// With a link mass among the parameters, the chains of the rows'
    /// markers (by [`Row::chain_index`]: their structure and the bodies'
    /// centres of mass) and gravity \[m/s², robot base frame\]; empty
    /// otherwise.
    pub(super) masses: Option<Masses<'a>>,
}

/// The chains of the rows' markers and gravity \[m/s², robot base frame\]
/// ([`Columns::masses`]).
pub(super) type Masses<'a> = (Cow<'a, [Chain<f64, J>]>, Vector3<f64>);

impl<'a> Columns<'a> {
    pub(super) fn new(
        params: &'a [Param],
        lin: &'a Linearisation,
        names: &crate::calibrate::params::names::Names,
        all: &Rows,
        markers: &'a [Vector3<f64>],
        chains: Cow<'a, [Chain<f64, J>]>,
    ) -> Self {
        Self {
            params,
            si: params.iter().map(|p| names.unit(p).si).collect(),
            linearised: params.iter().any(|p| matches!(p, Param::LoadCom { .. })),
            lin,
            mixed: all.mixed(),
            markers,
            masses: masses(params, chains, all.gravity),
        }
    }

    /// The row's columns at its `frames` into row `k` of a run's `piece`
    /// of every column.
    pub(super) fn write(
        &self,
        row: &Row,
        frames: &crate::robot::Frames<f64, { crate::calibrate::params::geometry::J }>,
        gravity_unit: Vector3<f64>,
        piece: &mut [&mut [f64]],
        k: usize,
    ) -> Result<(), Error> {
        self.each(row, frames, gravity_unit, |c, col| {
            if let Some(column) = piece.get_mut(c) {
                column[3 * k..3 * k + 3].copy_from_slice(col.as_slice());
            }
        })
    }

    /// `f(c, column)` for each parameter's column `c` of the row at its
    /// `frames`, in order (what [`Columns::write`] writes, and what a
    /// design not held computes where read: `source`).
    pub(super) fn each(
        &self,
        row: &Row,
        frames: &crate::robot::Frames<f64, { crate::calibrate::params::geometry::J }>,
        gravity_unit: Vector3<f64>,
        mut f: impl FnMut(usize, Vector3<f64>),
    ) -> Result<(), Error> {
        let compliance = if self.linearised {
            self.lin.compliance_at(&row.q)
        } else {
            Vec::new()
        };
        let point = frames.point_m(&crate::calibrate::rows::marker_m(self.markers, row));
        let sample = row.sample(frames, point, &compliance, gravity_unit);
        let scale = crate::calibrate::rows::row_scale(self.mixed, row);
        // A mass's column: the row's chain, gravity in the frames' frame
        // (the measurement frame: `gravity_unit` is turned there) and the
        // joint law at the row.
        let weight = self.masses.as_ref().map(|(chains, g)| {
            let chain = chains.get(row.chain_index()).or(chains.first());
            let law = self.lin.joint_law(&row.q, true, &[]);
            (chain, gravity_unit * g.norm(), law)
        });
        let column = |p: &Param, sample: &crate::model::Sample<'_, f64, J>| match (p, &weight) {
            (Param::LinkMass { joint }, Some((Some(chain), g, law))) => {
                masses::column(chain, sample, usize::from(*joint), g, law, |i| {
                    self.lin.bending(i)
                })
            }
            _ => p.column_si(sample),
        };
        // A pose's orientation: each column's turn, from the columns at
        // the point and at its probes (`rows::orientation`).
        let probes = row.orientation.then(|| {
            let [a, b] = orientation::PROBES;
            (
                row.sample_probe(frames, point + a, 1, &compliance, gravity_unit),
                row.sample_probe(frames, point + b, 2, &compliance, gravity_unit),
            )
        });
        for (c, (p, &si)) in self.params.iter().zip(self.si.iter()).enumerate() {
            let at = column(p, &sample)?;
            let mut col = match (&probes, row.scalar()) {
                (Some((sx, sy)), _) => crate::model::turn(&at, &column(p, sx)?, &column(p, sy)?),
                // A plane contact or a distance: the point's column
                // projected on the number's gradient (`rows::scalar`).
                (None, Some(s)) => s.column(&point, &at),
                (None, None) => at,
            } * si;
            if scale != 1.0 {
                col *= scale;
            }
            f(c, col);
        }
        Ok(())
    }
}

/// [`Columns::masses`] of `params`: `chains` and gravity when a link mass
/// is among them.
pub(super) fn masses<'a>(
    params: &[Param],
    chains: Cow<'a, [Chain<f64, J>]>,
    gravity_mps2: Vector3<f64>,
) -> Option<Masses<'a>> {
    params
        .iter()
        .any(|p| matches!(p, Param::LinkMass { .. }))
        .then_some((chains, gravity_mps2))
}
