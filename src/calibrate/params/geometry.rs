//! The robot's geometry at the current linearisation: Gauss–Newton for the
//! geometric parameters of absolute rows.
//!
//! The geometric columns (eq. 2, [`crate::model::columns`]) are derivatives at a
//! model, exact only for small errors. A laser tracker's or a mocap system's
//! frame is anywhere, and real joint-frame errors reach tens of mrad, so a
//! single linearisation about the nominal model leaves a second-order error
//! of `½ θ² L` (0.4 mm for 50 mrad on a 0.3 m lever). So, as FIGAROH (its
//! Levenberg–Marquardt) and ROS `robot_calibration` (Ceres) do, the fit is
//! iterated: each estimate of the geometric terms is applied to this model,
//! the absolute rows (`Δp`, columns, gravity torques) are recomputed at it,
//! and the fit is repeated until the geometric step is below
//! [`crate::calibrate::settings::Policy::step_tolerance`]. With the base frame declared, the first model places
//! the base by a rigid registration (Kabsch) of the nominal marker positions
//! onto the measured ones.
//!
//! How a step `x` (reported units) is applied, as the columns define it:
//! - base: `base ← E(x) · base`, `E = Trans(δt)·Rot(δr)` in the measurement
//!   frame;
//! - joint offset: `originⱼ ← originⱼ · motionⱼ(δqⱼ)` ([`crate::robot::Joint::motion`],
//!   the same as adding `δqⱼ` to the joint value);
//! - joint-frame error: `originⱼ ← originⱼ · E(x)`;
//! - marker: `markerₘ ← markerₘ + δ` (tip frame);
//! - tool frame: every marker (and its nominal position) `r ← E(x) · r`
//!   in the tip frame;
//! - a link's mass ([`Param::LinkMass`]): `mⱼ ← mⱼ + x` \[kg\] at its
//!   centre of mass (the rows' own-weight torques follow it).
//!
//! Deflection rows move with the model too: their `Δp` is measured in the
//! measurement frame, so their columns (and the load's torques, gravity
//! being given in the robot's base frame) are computed in it once the base
//! is placed.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};

use crate::model::Param;
use crate::robot::{Chain, End};

/// Joint capacity of the host chain ([`crate::io::urdf::MAX_JOINTS`]).
pub(crate) const J: usize = crate::io::urdf::MAX_JOINTS;

/// Measured points within this of one another \[m\] are one place, a
/// pivot: [`Geometry::register`] moves the base without turning it, and
/// the rows are a pivot's ([`crate::calibrate::rows::Rows::pivot`]).
pub const PIVOT_M: f64 = 1e-9;

/// The current model: chain, base pose, markers, and what has been applied.
#[derive(Debug, Clone, PartialEq)]
pub struct Geometry {
    /// The chain with the applied joint offsets and joint-frame errors (the
    /// base pose is kept apart, in `base`).
    pub chain: Chain<f64, J>,
    /// The robot base in the measurement frame.
    pub base: Isometry3<f64>,
    /// Marker positions \[m, in the frame of their end\], by marker index.
    pub markers: Vec<Vector3<f64>>,
    /// Where the chain ends (data contract 7.1; `ends[0]`: the chain's own
    /// tip): one per link markers are fixed to.
    pub ends: Vec<End<f64>>,
    /// Each marker's end (index into `ends`), by marker index.
    pub marker_ends: Vec<usize>,
    /// Nominal marker positions \[m, tip frame\].
    nominal_markers: Vec<Vector3<f64>>,
    /// The tool frame's identified rotation (its steps composed, in the
    /// tip frame): what turns a measured pose's orientation with the
    /// markers it moves (`rows::orientation`); identity without one.
    pub tool_rotation: UnitQuaternion<f64>,
    /// Sum of the applied steps of each joint-offset and joint-frame
    /// parameter (reported units; first order for the frame errors, whose
    /// steps compose on the chain).
    applied: BTreeMap<Param, f64>,
}

fn small_pose(t: Vector3<f64>, r: Vector3<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::from(t), UnitQuaternion::from_scaled_axis(r))
}

impl Geometry {
    /// The nominal model (base at the measurement frame's origin).
    pub fn nominal(chain: &Chain<f64, J>, markers: &[Vector3<f64>]) -> Self {
        Self {
            chain: chain.clone(),
            base: Isometry3::identity(),
            markers: markers.to_vec(),
            nominal_markers: markers.to_vec(),
            tool_rotation: UnitQuaternion::identity(),
            ends: vec![chain.tip_end()],
            marker_ends: vec![0; markers.len()],
            applied: BTreeMap::new(),
        }
    }

    /// The nominal model of a robot whose markers sit on several links
    /// (a tree, data contract 7.1): `ends` where the chain ends,
    /// `marker_ends` each marker's end.
    pub fn nominal_tree(
        chain: &Chain<f64, J>,
        ends: &[End<f64>],
        markers: &[Vector3<f64>],
        marker_ends: &[usize],
    ) -> Self {
        Self {
            ends: ends.to_vec(),
            marker_ends: marker_ends.to_vec(),
            ..Self::nominal(chain, markers)
        }
    }

    /// The chain with the base folded into its root joints' origins: frames
    /// of this chain are in the measurement frame.
    pub fn placed_chain(&self) -> Chain<f64, J> {
        self.chain.placed(&self.base)
    }

    /// [`Geometry::placed_chain`] ending at each of [`Geometry::ends`]: the
    /// chain of the markers of each end.
    pub fn placed_chains(&self) -> Vec<Chain<f64, J>> {
        self.ends
            .iter()
            .map(|e| {
                // Ends come from the robot's own chain: they fit.
                self.chain
                    .with_tip(e)
                    .unwrap_or_else(|_| self.chain.clone())
                    .placed(&self.base)
            })
            .collect()
    }

    /// Marker `m`'s end (index into [`Geometry::ends`]; 0 for an unknown
    /// marker).
    pub fn end_of(&self, m: u8) -> usize {
        self.marker_ends.get(usize::from(m)).copied().unwrap_or(0)
    }

    /// Places the base by the rigid transform (Kabsch) that best maps the
    /// `predicted` marker positions \[m, robot base frame\] onto the
    /// `measured` ones \[m, measurement frame\]. Fewer than three pairs, or
    /// non-finite ones, leave the base as it is.
    pub fn register(&mut self, predicted: &[Vector3<f64>], measured: &[Vector3<f64>]) {
        let n = predicted.len().min(measured.len());
        if n < 3 {
            return;
        }
        let ca = predicted[..n].iter().sum::<Vector3<f64>>() / n as f64;
        let cb = measured[..n].iter().sum::<Vector3<f64>>() / n as f64;
        // Measured at one place (a pivot): no turn to fit; the base is
        // moved, not turned.
        let spread = measured[..n]
            .iter()
            .map(|b| (b - cb).norm())
            .fold(0.0, f64::max);
        if spread < PIVOT_M {
            let rot = self.base.rotation;
            self.base = Isometry3::from_parts(Translation3::from(cb - rot * ca), rot);
            return;
        }
        let mut h = Matrix3::zeros();
        for (a, b) in predicted.iter().zip(measured) {
            h += (a - ca) * (b - cb).transpose();
        }
        if !h.iter().all(|v| v.is_finite()) {
            return;
        }
        let svd = h.svd(true, true);
        let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
            return;
        };
        let mut d = Matrix3::identity();
        if (vt.transpose() * u.transpose()).determinant() < 0.0 {
            d[(2, 2)] = -1.0;
        }
        let r = vt.transpose() * d * u.transpose();
        let rot = UnitQuaternion::from_matrix(&r);
        self.base = Isometry3::from_parts(Translation3::from(cb - rot * ca), rot);
    }

    /// Applies the stepped part ([`Param::is_stepped`]) of the estimate `x`
    /// of `params` (reported units: mm, mrad, kg) to the model; returns the
    /// largest step applied.
    pub fn apply(&mut self, params: &[Param], x: &[f64]) -> f64 {
        let dof = self.chain.dof();
        let mut base = [Vector3::zeros(); 2];
        let mut tool = [Vector3::zeros(); 2];
        let mut frame = vec![[Vector3::zeros(); 2]; dof];
        let mut largest: f64 = 0.0;
        for (p, &v) in params.iter().zip(x) {
            if !p.is_stepped() || v == 0.0 {
                continue;
            }
            largest = largest.max(v.abs());
            let si = v * 1e-3;
            match *p {
                Param::LinkMass { joint } => {
                    let jt = &mut self.chain.joints_mut()[usize::from(joint)];
                    let link = jt.link.get_or_insert(crate::robot::LinkInertia {
                        mass_kg: 0.0,
                        com_m: Vector3::zeros(),
                    });
                    link.mass_kg += v;
                    *self.applied.entry(*p).or_insert(0.0) += v;
                }
                Param::Base { axis } => base[usize::from(axis / 3)][usize::from(axis % 3)] = si,
                Param::Marker { marker, axis } => {
                    self.markers[usize::from(marker)][usize::from(axis)] += si;
                }
                Param::Tool { axis } => {
                    tool[usize::from(axis / 3)][usize::from(axis % 3)] = si;
                    *self.applied.entry(*p).or_insert(0.0) += v;
                }
                Param::JointOffset { joint } => {
                    let jt = &mut self.chain.joints_mut()[usize::from(joint)];
                    jt.origin *= jt.motion(si);
                    *self.applied.entry(*p).or_insert(0.0) += v;
                }
                Param::JointFrame { joint, axis } => {
                    frame[usize::from(joint)][usize::from(axis / 3)][usize::from(axis % 3)] = si;
                    *self.applied.entry(*p).or_insert(0.0) += v;
                }
                _ => {}
            }
        }
        for (jt, f) in self.chain.joints_mut().iter_mut().zip(&frame) {
            if f[0] != Vector3::zeros() || f[1] != Vector3::zeros() {
                jt.origin *= small_pose(f[0], f[1]);
            }
        }
        if tool[0] != Vector3::zeros() || tool[1] != Vector3::zeros() {
            // Everything on the tip link moves together, the nominal
            // positions too: a marker's own displacement (its value) stays
            // its own.
            let e = small_pose(tool[0], tool[1]);
            for m in self.markers.iter_mut().chain(&mut self.nominal_markers) {
                *m = (e * nalgebra::Point3::from(*m)).coords;
            }
            self.tool_rotation = e.rotation * self.tool_rotation;
        }
        if base[0] != Vector3::zeros() || base[1] != Vector3::zeros() {
            self.base = small_pose(base[0], base[1]) * self.base;
        }
        largest
    }

    /// The covariance of the reported values of `params` from `cov`, that
    /// of their steps (the fit's, reported units): the base's steps act in
    /// the measurement frame (`base ← E(x) · base`), so its translation `t`
    /// moves by `δt + δr × t` and its rotation vector `r` by `J_l⁻¹(r) δr`
    /// (the inverse left Jacobian of SO(3)); `G cov Gᵀ`, with `G` those
    /// derivatives on the base's rows and the identity elsewhere. `cov`
    /// itself (the same bits) without a base parameter. (The σ of a base
    /// far from the measurement frame's origin was the step's, `δt`'s,
    /// 2–4 times that of `t`: a helper's Monte Carlo.)
    pub fn reported_covariance(
        &self,
        params: &[Param],
        cov: &nalgebra::DMatrix<f64>,
    ) -> nalgebra::DMatrix<f64> {
        let base = |i: usize| match params.get(i) {
            Some(Param::Base { axis }) => Some(usize::from(*axis)),
            _ => None,
        };
        let n = params.len();
        if (0..n).all(|i| base(i).is_none()) || cov.shape() != (n, n) {
            return cov.clone();
        }
        let t = self.base.translation.vector;
        let r = self.base.rotation.scaled_axis();
        // ∂t/∂δr = −[t]× (mm per mrad: t in metres); ∂r/∂δr = J_l⁻¹(r).
        let lever = -t.cross_matrix();
        let theta = r.norm();
        let c = if theta < 1e-6 {
            1.0 / 12.0
        } else {
            1.0 / (theta * theta) - (1.0 + theta.cos()) / (2.0 * theta * theta.sin())
        };
        let rx = r.cross_matrix();
        let jinv = Matrix3::identity() - rx * 0.5 + rx * rx * c;
        let mut g = nalgebra::DMatrix::<f64>::identity(n, n);
        for i in 0..n {
            let Some(a) = base(i) else { continue };
            for k in 0..n {
                let Some(b) = base(k).filter(|&b| b >= 3) else {
                    continue;
                };
                g[(i, k)] = if a < 3 {
                    lever[(a, b - 3)]
                } else {
                    jinv[(a - 3, b - 3)]
                };
            }
        }
        &g * cov * g.transpose()
    }

    /// The σ of the reported values of `params` ([`Geometry::reported_covariance`]):
    /// `std` (the fit's) but for the base's parameters.
    pub fn reported_std(
        &self,
        params: &[Param],
        cov: &nalgebra::DMatrix<f64>,
        std: &[f64],
    ) -> Vec<f64> {
        let cov = self.reported_covariance(params, cov);
        (params.iter().zip(std).enumerate())
            .map(|(i, (p, &s))| match p {
                Param::Base { .. } => cov[(i, i)].max(0.0).sqrt(),
                _ => s,
            })
            .collect()
    }

    /// The mass of every moving body but joint `joint`'s, together \[kg\],
    /// as the model has them now (the mass model with the identified
    /// masses' steps).
    pub fn others_mass_kg(&self, joint: u8) -> f64 {
        (self.chain.joints().iter().enumerate())
            .filter(|(j, _)| *j != usize::from(joint))
            .filter_map(|(_, jt)| jt.link.map(|l| l.mass_kg))
            .sum()
    }

    /// The sum of the steps applied to stepped parameter `p`
    /// ([`Param::is_stepped`]; the base and the markers, which are moved
    /// in place, excepted): a link mass's change from its nominal value.
    pub fn applied(&self, p: &Param) -> f64 {
        self.applied.get(p).copied().unwrap_or(0.0)
    }

    /// The value of geometric parameter `p` in the model, plus a last step
    /// `dx` not applied (reported units): the base as its translation \[mm\]
    /// and rotation vector (axis × angle) \[mrad\] in the measurement frame;
    /// offsets and frame errors as the sum of their steps; a marker as its
    /// displacement from the nominal position \[mm\].
    pub fn value(&self, p: &Param, dx: f64) -> f64 {
        match *p {
            Param::Base { axis } if axis < 3 => {
                self.base.translation.vector[usize::from(axis)] * 1e3 + dx
            }
            Param::Base { axis } => {
                self.base.rotation.scaled_axis()[usize::from(axis - 3)] * 1e3 + dx
            }
            Param::Marker { marker, axis } => {
                let (m, a) = (usize::from(marker), usize::from(axis));
                (self.markers[m][a] - self.nominal_markers[m][a]) * 1e3 + dx
            }
            // A revolute joint's offset as the angle it is, in (−π, π]:
            // steps that went round (a fit along a direction the data
            // barely see) do not report 50 rad.
            Param::JointOffset { joint }
                if self.chain.joints().get(usize::from(joint)).map(|j| j.kind)
                    == Some(crate::robot::JointKind::Revolute) =>
            {
                wrap_mrad(self.applied.get(p).copied().unwrap_or(0.0) + dx)
            }
            // A link's mass as the mass it is (nominal plus its steps).
            Param::LinkMass { joint } => {
                let link = self
                    .chain
                    .joints()
                    .get(usize::from(joint))
                    .and_then(|j| j.link);
                link.map_or(0.0, |l| l.mass_kg) + dx
            }
            _ => self.applied.get(p).copied().unwrap_or(0.0) + dx,
        }
    }
}

/// An angle \[mrad\] in (−π, π] (itself when it is already there, bit for
/// bit).
fn wrap_mrad(v: f64) -> f64 {
    let half = core::f64::consts::PI * 1e3;
    if v > -half && v <= half {
        return v;
    }
    let turn = 2.0 * half;
    let w = v - turn * (v / turn).round();
    if w <= -half {
        w + turn
    } else {
        w
    }
}
