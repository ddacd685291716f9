//! A fixed-capacity parameter layout for the device: which [`Param`] each
//! column of `B = [J  A]` (eq. 4) is, in which unit, and the rows of one
//! measurement.
//!
//! ```
//! use nalgebra::{Vector3, U2};
//! use robcal::model::{Layout, Marker, Param};
//! use robcal::robot::PointLoad;
//! use robcal::{Chain, Joint, JointKind};
//!
//! // Two links along x, both joints about y; a 100 kg load at the tip.
//! let mut chain = Chain::<f64, 2>::new();
//! let y = Vector3::y();
//! chain.push(Joint::from_urdf(Vector3::zeros(), Vector3::zeros(), y, JointKind::Revolute).unwrap()).unwrap();
//! chain.push(Joint::from_urdf(Vector3::x(), Vector3::zeros(), y, JointKind::Revolute).unwrap()).unwrap();
//! let mut layout = Layout::<2>::new();
//! layout.push(&chain, Param::Compliance { joint: 0 }).unwrap();
//! layout.push(&chain, Param::Compliance { joint: 1 }).unwrap();
//! assert_eq!(layout.columns()[0].unit.name, "urad/(N*m)");
//! let load = PointLoad { mass_kg: 100.0, com_m: Vector3::x(), gravity_mps2: Vector3::new(0.0, 0.0, -9.81) };
//! let marker = Marker { index: 0, xyz_m: Vector3::x() };
//! let b = layout.block::<f64, 2, U2>(&chain, &[0.0, 0.0], &marker, Some(&load)).unwrap();
//! // 1 µrad/(N·m) at joint 0 under 1962 N·m lowers the marker 2 m out by 3.9 mm.
//! assert!((b[(2, 0)] + 1962.0 * 2.0 * 1e-6).abs() < 1e-9);
//! ```

use nalgebra::allocator::Allocator;
use nalgebra::storage::StorageMut;
use nalgebra::{DefaultAllocator, Dim, DimName, Matrix, OMatrix, RealField, Vector3, U3};

use super::bins::{in_bin, in_some_bin};
use super::columns::turn;
use super::param::{Param, Unit};
use super::sample::Sample;
use crate::error::Error;
use crate::robot::{gravity_torques, joint_torques, Chain, Frames, JointKind, PointLoad};

/// One column of a layout: the parameter and its unit.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Column {
    /// What the parameter is.
    pub param: Param,
    /// The unit of its estimate.
    pub unit: Unit,
}

/// A marker: its index and nominal position in the tip frame.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Marker<T: RealField + Copy> {
    /// Index (matches [`Param::Marker`]).
    pub index: u8,
    /// Position \[m\] in the tip frame.
    pub xyz_m: Vector3<T>,
}

/// The parameter layout of `X`, at most `N` parameters. See the
/// [module docs](self).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Layout<const N: usize> {
    columns: heapless::Vec<Column, N>,
}

impl<const N: usize> Default for Layout<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Layout<N> {
    /// An empty layout.
    pub const fn new() -> Self {
        Self {
            columns: heapless::Vec::new(),
        }
    }

    /// Appends a parameter with its unit (which depends on its joint's
    /// kind, hence the chain). Returns its column index.
    ///
    /// # Errors
    /// [`Error::OutOfRange`] for a joint index `≥ dof` or an axis out of
    /// range; [`Error::Mismatch`] when the parameter is already in the
    /// layout; [`Error::CapacityExceeded`] when the layout holds `N` columns.
    /// The layout is unchanged on error.
    pub fn push<T: RealField + Copy, const J: usize>(
        &mut self,
        chain: &Chain<T, J>,
        param: Param,
    ) -> Result<usize, Error> {
        let column = column_of(
            param,
            |j| chain.joints().get(j).map(|jt| jt.kind),
            chain.dof(),
        )?;
        if self.columns.iter().any(|c| c.param == param) {
            return Err(Error::Mismatch {
                what: "parameter already in the layout",
            });
        }
        let index = self.columns.len();
        self.columns
            .push(column)
            .map_err(|_| Error::CapacityExceeded {
                what: "layout columns",
                capacity: N,
            })?;
        Ok(index)
    }

    /// The columns, in order.
    pub fn columns(&self) -> &[Column] {
        &self.columns
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.columns.len()
    }

    /// Whether the layout has no parameter.
    pub fn is_empty(&self) -> bool {
        self.columns.is_empty()
    }

    /// Column index of a parameter, if present.
    pub fn index_of(&self, param: &Param) -> Option<usize> {
        self.columns.iter().position(|c| c.param == *param)
    }

    /// Writes the three rows (x, y, z) of `B` (eq. 4) for one sample into `b`,
    /// one column per parameter of the layout, in its unit; columns of `b` past
    /// them are set to zero. `b` is left unchanged on error.
    ///
    /// # Errors
    /// [`Error::Mismatch`] when `b` has fewer columns than the layout, when a
    /// joint with angle bins ([`Param::ComplianceAt`]) is at an angle that
    /// matches none of them, or when the sample's torques are shorter than the
    /// chain; [`Error::OutOfRange`] when a column names a joint the sample does
    /// not have; [`Error::NonFinite`] when a column is not finite.
    pub fn fill<T, D, S, const J: usize>(
        &self,
        sample: &Sample<'_, T, J>,
        b: &mut Matrix<T, U3, D, S>,
    ) -> Result<(), Error>
    where
        T: RealField + Copy,
        D: Dim,
        S: StorageMut<T, U3, D>,
        DefaultAllocator: Allocator<U3, D>,
    {
        let columns = self.columns();
        if columns.len() > b.ncols() {
            return Err(Error::Mismatch {
                what: "layout has more parameters than B has columns",
            });
        }
        // Every column into a copy first: `b` changes only when all succeed.
        let mut out = OMatrix::<T, U3, D>::zeros_generic(U3, b.shape_generic().1);
        for (i, c) in columns.iter().enumerate() {
            let col = match c.param {
                // Not this bin: the sample must be in another one.
                Param::ComplianceAt { joint, angle_urad }
                    if !in_bin(angle_urad, sample.q(joint)?) =>
                {
                    if !in_some_bin(columns.iter().map(|c| &c.param), joint, sample.q(joint)?) {
                        return Err(Error::Mismatch {
                            what: "joint angle matches no compliance bin",
                        });
                    }
                    continue;
                }
                p => p.column_si(sample)?,
            };
            let si: T = nalgebra::convert(c.unit.si);
            out.set_column(i, &(col * si));
        }
        if !out.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite { what: "row" });
        }
        b.copy_from(&out);
        Ok(())
    }

    /// `B` (eq. 4) of one **deflection** of a marker at joint values `q`
    /// under an optional hanging load (the elastostatic experiment: the
    /// measured `Δp` is the loaded minus the unloaded position, so only the
    /// load's torques enter, and geometric parameters do not act: their
    /// columns are zero). Without a load, compliance columns are zero too.
    /// `D` must hold the layout (columns past it are zero). For an absolute
    /// position, [`Layout::absolute_block`].
    ///
    /// # Errors
    /// As [`crate::robot::Chain::frames`] and [`Layout::fill`].
    pub fn block<T: RealField + Copy, const J: usize, D: DimName>(
        &self,
        chain: &Chain<T, J>,
        q: &[T],
        marker: &Marker<T>,
        load: Option<&PointLoad<T>>,
    ) -> Result<OMatrix<T, U3, D>, Error>
    where
        DefaultAllocator: Allocator<U3, D>,
    {
        let frames = chain.frames(q)?;
        let mut tau = [T::zero(); J];
        let wrench = load.map(|l| l.wrench(&frames));
        if let Some(w) = &wrench {
            joint_torques(&frames, w, &mut tau)?;
        }
        let point = frames.point_m(&marker.xyz_m);
        let sample = Sample::deflection(&frames, point, marker.index, &tau[..frames.dof()], wrench);
        let mut b = OMatrix::<T, U3, D>::zeros();
        self.fill(&sample, &mut b)?;
        Ok(b)
    }

    /// `B` (eq. 4) of the **absolute position** of a marker at joint values
    /// `q` (geometric calibration, eq. 2): every parameter acts, and the
    /// robot's own weight under gravity `gravity_mps2` \[m/s², base frame\]
    /// loads the joints (the chain's link inertias; compliance columns are
    /// the deflection under it). The measured `Δp` is the position minus
    /// the forward kinematics of the current model.
    ///
    /// # Errors
    /// As [`crate::robot::Chain::frames`] and [`Layout::fill`].
    pub fn absolute_block<T: RealField + Copy, const J: usize, D: DimName>(
        &self,
        chain: &Chain<T, J>,
        q: &[T],
        marker: &Marker<T>,
        gravity_mps2: &Vector3<T>,
    ) -> Result<OMatrix<T, U3, D>, Error>
    where
        DefaultAllocator: Allocator<U3, D>,
    {
        let (frames, tau) = own_weight(chain, q, gravity_mps2)?;
        let point = frames.point_m(&marker.xyz_m);
        let sample = Sample::absolute(&frames, point, marker.index, &tau[..frames.dof()]);
        let mut b = OMatrix::<T, U3, D>::zeros();
        self.fill(&sample, &mut b)?;
        Ok(b)
    }

    /// `B` of the **orientation** of a 6-D pose (data contract extension
    /// `rx, ry, rz`): the turn `∂θ/∂x` of the marker's link frame per unit
    /// of each parameter \[rad per unit, measurement frame\], at joint
    /// values `q` under the robot's own weight as in
    /// [`Layout::absolute_block`]. A pose is the two blocks: this one's
    /// `Δθ = log(R_meas R_predᵀ)` \[rad\] (`R_pred` the tip frame's rotation
    /// turned by the tool's) beside `absolute_block`'s `Δp`, each a
    /// [`crate::Block`] of three rows with its own weights (its σ in rad),
    /// so that a device takes a pose as it takes a point: the layout and the
    /// accumulator are the same, and nothing is built for a device that
    /// measures points only.
    ///
    /// Every column is affine in the point it is taken at, `c(p) = v + W p`
    /// (`W = [ω]×` for a rigid motion of the frame: a joint's offset or
    /// yield, a frame error, the base, the tool; a marker's position moves
    /// no frame), so `ω` is read from the columns at the marker's point and
    /// 1 m beside it along x and y ([`turn`], the host's rule for its
    /// orientation rows).
    ///
    /// # Errors
    /// As [`Layout::absolute_block`].
    pub fn orientation_block<T: RealField + Copy, const J: usize, D: DimName>(
        &self,
        chain: &Chain<T, J>,
        q: &[T],
        marker: &Marker<T>,
        gravity_mps2: &Vector3<T>,
    ) -> Result<OMatrix<T, U3, D>, Error>
    where
        DefaultAllocator: Allocator<U3, D>,
    {
        let (frames, tau) = own_weight(chain, q, gravity_mps2)?;
        let point = frames.point_m(&marker.xyz_m);
        let tau = &tau[..frames.dof()];
        let at = |p: Vector3<T>| {
            let sample = Sample::absolute(&frames, p, marker.index, tau);
            let mut b = OMatrix::<T, U3, D>::zeros();
            self.fill(&sample, &mut b).map(|()| b)
        };
        let (c, cx, cy) = (
            at(point)?,
            at(point + Vector3::x())?,
            at(point + Vector3::y())?,
        );
        let mut out = OMatrix::<T, U3, D>::zeros();
        for j in 0..out.ncols() {
            let w = turn(
                &c.column(j).into(),
                &cx.column(j).into(),
                &cy.column(j).into(),
            );
            out.set_column(j, &w);
        }
        Ok(out)
    }
}

/// The frames at `q` and the joint torques of the robot's own weight under
/// `gravity_mps2` there: what an absolute measurement's columns are taken at.
fn own_weight<T: RealField + Copy, const J: usize>(
    chain: &Chain<T, J>,
    q: &[T],
    gravity_mps2: &Vector3<T>,
) -> Result<(Frames<T, J>, [T; J]), Error> {
    let frames = chain.frames(q)?;
    let mut tau = [T::zero(); J];
    gravity_torques(chain, &frames, gravity_mps2, &mut tau)?;
    Ok((frames, tau))
}

/// A [`Column`] for `param`, checking its joint (`kind(j)`, `None` past the
/// chain's `dof` joints) and axis.
///
/// # Errors
/// [`Error::OutOfRange`] for a joint or axis out of range.
pub fn column_of(
    param: Param,
    kind: impl Fn(usize) -> Option<JointKind>,
    dof: usize,
) -> Result<Column, Error> {
    let joint_kind = match param.joint() {
        Some(j) => kind(usize::from(j)).ok_or(Error::OutOfRange {
            what: "joint",
            index: usize::from(j),
            len: dof,
        })?,
        None => JointKind::Revolute,
    };
    let (axis, len) = match param {
        Param::JointFrame { axis, .. } | Param::Base { axis } | Param::Tool { axis } => (axis, 6),
        Param::Marker { axis, .. } | Param::LoadCom { axis } | Param::Drift { axis } => (axis, 3),
        _ => (0, 1),
    };
    if usize::from(axis) >= len {
        return Err(Error::OutOfRange {
            what: "axis",
            index: usize::from(axis),
            len,
        });
    }
    Ok(Column {
        param,
        unit: param.unit(joint_kind),
    })
}
