//! The identification columns `∂p/∂x` of every [`Param`] (eq. 2, 3 and the
//! effect library), at one [`Sample`].
//!
//! A *column* is the derivative of one marker's position `p` \[m, base or
//! measurement frame\] with respect to one parameter; the free functions
//! give it in SI units (m/m, m/rad, m per rad/(N·m)), [`Param::column`] in
//! the parameter's reported unit ([`super::param`]).
//!
//! **Geometric parameters** (eq. 2, `Δpᵍ = J⁽ᵖ⁾ ΔΠ`), with the error
//! transforms that define them (first order, `Rot(δr) ≈ I + [δr]×`):
//!
//! - **joint offset** `δqⱼ`: added to joint `j`'s value. Column
//!   `zⱼ × (p − oⱼ)` (revolute, m/rad) or `zⱼ` (prismatic, m/m).
//! - **joint-frame error** `(δx, δy, δz, δrx, δry, δrz)` of joint `j`: a small
//!   transform `E = Trans(δt) · Rot(δr)` *right*-multiplying the joint's
//!   origin, `origin_j → origin_j · E`, i.e. expressed in joint `j`'s own
//!   frame at zero joint value `Z_j = T_{j-1} · origin_j` (axes `Rᶻ eₖ`,
//!   origin `aⱼ`), before the joint's motion. Columns: translation `Rᶻ eₖ`,
//!   rotation `(Rᶻ eₖ) × (p − aⱼ)`. The URDF `xyz` of joint `j` is the same
//!   translation expressed in the parent frame: `∂p/∂xyz = Rᶻ R_originᵀ`
//!   times the translation columns.
//! - **base frame** `(δx, δy, δz, δrx, δry, δrz)`: the robot base placed in
//!   the measurement frame by `E = Trans(δt) · Rot(δr)`, `p_meas = E · p`;
//!   rotation about the measurement frame's axes through its origin. Columns
//!   `eₖ` and `eₖ × p`.
//! - **marker position** `(δx, δy, δz)` in the tip frame. Columns
//!   `R_tip eₖ`.
//!
//! These act on absolute positions only: a deflection (loaded minus
//! unloaded position at the same pose) does not see them.
//!
//! **Elastostatic parameters** (eq. 3, `Δpᵉ = A⁽ᵖ⁾ k`, the virtual-joint
//! model: rigid links, one linear spring per joint). A joint under torque
//! `τⱼ` ([`crate::robot::load`]) yields by `δqⱼ = kⱼ τⱼ`; to first order a
//! marker at `p` moves by `Δp = Σⱼ kⱼ τⱼ (zⱼ × (p − oⱼ))` (prismatic:
//! `kⱼ τⱼ zⱼ`), which is linear in `k`: the column of `kⱼ` is
//! `τⱼ (zⱼ × (p − oⱼ))`.
//!
//! **Effects** of the library (data contract §6) follow the same pattern: a
//! joint-value change `δqⱼ = x · f(sample)` has the column
//! `f · (zⱼ × (p − oⱼ))` — `f = τ|τ|` (nonlinear stiffness), `sign τ`
//! (backlash), `sin qⱼ`, `cos qⱼ` (gear cyclic error), `Rⱼᵀĝ · aⱼ`,
//! `Rⱼᵀĝ · bⱼ` (gravity compliance: [`gravity_basis`],
//! [`gravity_components`]).
//!
//! **Link compliance** (lateral elasticity of link `j`): the moment `mⱼ`
//! about `oⱼ` of what joint `j` carries bends it about the moment's part
//! across its axis, `m⊥ = mⱼ − zⱼ(zⱼ · mⱼ)`, by `x m⊥`; the column is
//! `m⊥ × (p − oⱼ)`. A deflection's `mⱼ` is the load's `(c − oⱼ) × F`; an
//! absolute position's (host only, `std`) is the robot's own weight's,
//! [`crate::robot::gravity_moments`] ([`Sample::weight_moments_nm`]).
//!
//! **Thermal expansion** (host only, `std`): every length from the first
//! joint's origin `o₁` out grows by `α ΔT`, so the column of `α` is
//! `ΔT (p − o₁)` ([`Sample::dtemp_k`]).
//!
//! ```
//! use nalgebra::Vector3;
//! use robcal::model::compliance_columns;
//! use robcal::robot::{joint_torques, Wrench};
//! use robcal::{Chain, Joint, JointKind};
//!
//! // One horizontal 1 m link about y, 100 N down at its end: τ = 100 N·m.
//! let mut chain = Chain::<f64, 1>::new();
//! chain.push(Joint::from_urdf(Vector3::zeros(), Vector3::zeros(), Vector3::y(), JointKind::Revolute).unwrap()).unwrap();
//! let frames = chain.frames(&[0.0]).unwrap();
//! let mut tau = [0.0];
//! joint_torques(&frames, &Wrench::force(Vector3::new(0.0, 0.0, -100.0), Vector3::x()), &mut tau).unwrap();
//! let mut col = [Vector3::zeros()];
//! compliance_columns(&frames, &Vector3::x(), &tau, &mut col).unwrap();
//! // k = 1e-6 rad/(N·m) lowers the end by 100 µm.
//! assert!((col[0] * 1e-6 - Vector3::new(0.0, 0.0, -1e-4)).norm() < 1e-15);
//! ```

use nalgebra::{RealField, Vector3};

use super::bins::in_bin;
use super::param::Param;
use super::sample::Sample;
use crate::error::Error;
use crate::robot::load::check_len;
use crate::robot::{Frames, JointFrame, JointKind};

/// The turn `ω` of an affine column `c(p) = v + W p`, `W` a rotation's
/// `[ω]×` plus a stretch `s I`, from its values at `p` (`c0`), `p + eₓ`
/// (`cx`) and `p + e_y` (`cy`): `W eₓ = (s, ω_z, −ω_y)`,
/// `W e_y = (−ω_z, s, ω_x)`. What a parameter does to a 6-D pose's
/// orientation ([`crate::model::Layout::orientation_block`], and the host's
/// orientation rows): a rigid motion turns the frame by `ω`, a stretch and
/// a marker's position turn nothing.
pub fn turn<T: RealField + Copy>(c0: &Vector3<T>, cx: &Vector3<T>, cy: &Vector3<T>) -> Vector3<T> {
    let a = cx - c0;
    let b = cy - c0;
    let half: T = nalgebra::convert(0.5);
    Vector3::new(b.z, -a.z, (a.y - b.x) * half)
}

impl Param {
    /// The column `∂p/∂x` \[m per reported unit\] of this parameter at
    /// `sample` (see the [module docs](self)); zero where the parameter
    /// does not act on the sample (a geometric parameter on a deflection,
    /// another marker's position, a bin the joint is not in, …).
    ///
    /// # Errors
    /// [`Error::OutOfRange`] for a joint the sample's frames do not have or
    /// an axis out of range; [`Error::Mismatch`] when the sample's torques
    /// are shorter than the chain.
    pub fn column<T: RealField + Copy, const J: usize>(
        &self,
        sample: &Sample<'_, T, J>,
    ) -> Result<Vector3<T>, Error> {
        let kind = match self.joint() {
            Some(j) => sample.frames.joint(usize::from(j))?.kind,
            None => JointKind::Revolute,
        };
        let si: T = nalgebra::convert(self.unit(kind).si);
        Ok(self.column_si(sample)? * si)
    }

    /// [`Param::column`] in SI units.
    ///
    /// # Errors
    /// As [`Param::column`].
    pub fn column_si<T: RealField + Copy, const J: usize>(
        &self,
        s: &Sample<'_, T, J>,
    ) -> Result<Vector3<T>, Error> {
        let zero = Vector3::zeros();
        let p = &s.point_m;
        let twist = |j: u8| s.twist(j);
        let tau = |j: u8| -> Result<T, Error> {
            s.tau.get(usize::from(j)).copied().ok_or(Error::Mismatch {
                what: "joint torques shorter than the chain's dof",
            })
        };
        let axis = |a: u8, len: usize| -> Result<usize, Error> {
            let a = usize::from(a);
            if a < len {
                Ok(a)
            } else {
                Err(Error::OutOfRange {
                    what: "axis",
                    index: a,
                    len,
                })
            }
        };
        Ok(match *self {
            Param::Compliance { joint } => twist(joint)? * tau(joint)?,
            Param::ComplianceAt { joint, angle_urad } => {
                if in_bin(angle_urad, s.q(joint)?) {
                    twist(joint)? * tau(joint)?
                } else {
                    zero
                }
            }
            Param::NonlinearStiffness { joint } => {
                let t = tau(joint)?;
                twist(joint)? * (t * t.abs())
            }
            Param::Backlash { joint } => {
                let t = tau(joint)?;
                if t.abs() < nalgebra::convert(1e-9) {
                    zero
                } else {
                    twist(joint)? * t.signum()
                }
            }
            Param::LinkCompliance { joint } => {
                let jf = s.frames.joint(usize::from(joint))?;
                let o = jf.origin_m();
                let m = match (&s.load, s.absolute) {
                    _ if cfg!(feature = "tree") && !jf.carries => None,
                    (Some(w), false) => Some((w.point_m - o).cross(&w.force_n)),
                    #[cfg(feature = "std")]
                    (_, true) => s.weight_moments_nm.get(usize::from(joint)).copied(),
                    _ => None,
                };
                match m {
                    Some(m) => {
                        let z = jf.axis.into_inner();
                        (m - z * z.dot(&m)).cross(&(p - o))
                    }
                    None => zero,
                }
            }
            Param::LoadCom { axis: a } => match (&s.load, s.absolute) {
                (Some(w), false) => {
                    let dir = s.frames.tip().rotation * Vector3::ith(axis(a, 3)?, T::one());
                    let mut col = zero;
                    for (j, (jf, &k)) in s.frames.joints().iter().zip(s.compliance).enumerate() {
                        if k == T::zero() || jf.kind != JointKind::Revolute {
                            continue;
                        }
                        let dtau = jf.axis.dot(&dir.cross(&w.force_n));
                        col += s.twist(j as u8)? * (k * dtau);
                    }
                    col
                }
                _ => zero,
            },
            Param::Drift { axis: a } => Vector3::ith(axis(a, 3)?, s.dt_s),
            // Every length from the first joint's origin out grows by
            // `α ΔT`: the marker moves by `ΔT (p − o₁)` per unit of `α`.
            #[cfg(feature = "std")]
            Param::ThermalExpansion => (p - s.frames.joint(0)?.origin_m()) * s.dtemp_k,
            _ if !s.absolute => zero,
            // Rigid at the (equilibrium) frames, like the frame errors and
            // the base: a joint offset and the next joint's frame error move
            // the robot, its weight and its deflection identically, so their
            // columns must stay exactly dependent; the load's coupling
            // (`M − I ≈ D T`, a few per cent) is left to the Gauss–Newton
            // iteration, whose rows are exact.
            Param::JointOffset { joint } => s.frames.joint(usize::from(joint))?.twist_column(p),
            Param::JointFrame { joint, axis: a } => {
                joint_frame_columns(s.frames, usize::from(joint), p)?[axis(a, 6)?]
            }
            Param::Base { axis: a } => base_columns(p)[axis(a, 6)?],
            Param::Tool { axis: a } => tool_columns(s.frames, p)[axis(a, 6)?],
            Param::Marker { marker, axis: a } => {
                if marker == s.marker {
                    marker_columns(s.frames)[axis(a, 3)?]
                } else {
                    zero
                }
            }
            Param::GearCyclic { joint, cos } => {
                let qj = s.q(joint)?;
                twist(joint)? * if cos { qj.cos() } else { qj.sin() }
            }
            // A mass acts through the joints that carry it, the chain's
            // structure and the compliances at the row: the host's design
            // computes its column (`calibrate::params::masses`); a sample
            // alone has none.
            #[cfg(feature = "std")]
            Param::LinkMass { .. } => zero,
            #[cfg(feature = "std")]
            Param::GravityCompliance { joint, b } => {
                let g = match s.gravity_q.get(usize::from(joint)) {
                    Some(g) => *g,
                    None => gravity_components(s.frames.joint(usize::from(joint))?, &s.gravity),
                };
                twist(joint)? * g[usize::from(b)]
            }
        })
    }
}

/// The basis `(aⱼ, bⱼ)` perpendicular to a joint's unit axis `ẑ` \[its own
/// frame\] of `Param::GravityCompliance` (`std`): `aⱼ` the joint frame's x axis
/// made perpendicular to `ẑ` (its y axis when `|ẑ · x| ≥ 0.9`), `bⱼ = ẑ × aⱼ`
/// — for the usual axis `ẑ = z`, the frame's own x and y.
pub fn gravity_basis<T: RealField + Copy>(z: &Vector3<T>) -> [Vector3<T>; 2] {
    let seed = if z.x.abs() < nalgebra::convert(0.9) {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let a = (seed - z * z.dot(&seed)).normalize();
    [a, z.cross(&a)]
}

/// The components `(Rⱼᵀĝ · aⱼ, Rⱼᵀĝ · bⱼ)` of the gravity direction `ĝ`
/// (unit, in the frame `jf` is in) on joint `j`'s basis ([`gravity_basis`])
/// in its moved frame `Rⱼ` (its own rotation included): what joint `j`'s
/// `Param::GravityCompliance` deflection is linear in. Zero for a zero
/// `ĝ`.
pub fn gravity_components<T: RealField + Copy>(jf: &JointFrame<T>, g: &Vector3<T>) -> [T; 2] {
    let r = jf.frame.rotation;
    let local = r.inverse_transform_vector(g);
    let [a, b] = gravity_basis(&r.inverse_transform_vector(&jf.axis));
    [local.dot(&a), local.dot(&b)]
}

/// Joint-offset column of joint `j` at a point `p_m` [m, base frame]:
/// `zⱼ × (p − oⱼ)` [m/rad] (revolute) or `zⱼ` [m/m] (prismatic).
///
/// # Errors
/// [`Error::OutOfRange`] when `j ≥ dof`.
pub fn joint_offset_column<T: RealField + Copy, const J: usize>(
    frames: &Frames<T, J>,
    j: usize,
    p_m: &Vector3<T>,
) -> Result<Vector3<T>, Error> {
    Ok(frames.joint(j)?.twist_column(p_m))
}

/// Joint-offset columns of every joint, written to `out[..dof]`.
///
/// # Errors
/// [`Error::Mismatch`] when `out` is shorter than the number of joints.
pub fn joint_offset_columns<T: RealField + Copy, const J: usize>(
    frames: &Frames<T, J>,
    p_m: &Vector3<T>,
    out: &mut [Vector3<T>],
) -> Result<(), Error> {
    if out.len() < frames.dof() {
        return Err(Error::Mismatch {
            what: "column slice shorter than the chain's dof",
        });
    }
    for (o, jf) in out.iter_mut().zip(frames.joints()) {
        *o = jf.twist_column(p_m);
    }
    Ok(())
}

/// The six joint-frame error columns of joint `j` (see the
/// [module docs](self)): `[δx, δy, δz]` in m/m, then `[δrx, δry, δrz]` in
/// m/rad, all along the axes of `Z_j`; zero when joint `j` does not carry
/// the tip ([`crate::robot::JointFrame::carries`]).
///
/// # Errors
/// [`Error::OutOfRange`] when `j ≥ dof`.
pub fn joint_frame_columns<T: RealField + Copy, const J: usize>(
    frames: &Frames<T, J>,
    j: usize,
    p_m: &Vector3<T>,
) -> Result<[Vector3<T>; 6], Error> {
    let jf = frames.joint(j)?;
    if cfg!(feature = "tree") && !jf.carries {
        return Ok([Vector3::zeros(); 6]);
    }
    let z = jf.zero;
    let r = z.rotation.to_rotation_matrix();
    let arm = p_m - z.translation.vector;
    let e = |k: usize| r.matrix().column(k).into_owned();
    Ok([
        e(0),
        e(1),
        e(2),
        e(0).cross(&arm),
        e(1).cross(&arm),
        e(2).cross(&arm),
    ])
}

/// The six base-frame columns at a point `p_m` [m, robot base frame]:
/// `[eₓ, e_y, e_z]` (m/m), then `[eₓ × p, e_y × p, e_z × p]` (m/rad).
pub fn base_columns<T: RealField + Copy>(p_m: &Vector3<T>) -> [Vector3<T>; 6] {
    let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
    [x, y, z, x.cross(p_m), y.cross(p_m), z.cross(p_m)]
}

/// The six tool-frame columns at a point `p_m` [m, base frame] fixed to the
/// tip link: the tip frame's axes `R_tip eₖ` (m/m), then
/// `R_tip eₖ × (p − o_tip)` (m/rad) — a small rigid motion of the tip link's
/// contents in the tip frame ([`Param::Tool`]).
pub fn tool_columns<T: RealField + Copy, const J: usize>(
    frames: &Frames<T, J>,
    p_m: &Vector3<T>,
) -> [Vector3<T>; 6] {
    let tip = frames.tip();
    let r = tip.rotation.to_rotation_matrix();
    let arm = p_m - tip.translation.vector;
    let e = |k: usize| r.matrix().column(k).into_owned();
    [
        e(0),
        e(1),
        e(2),
        e(0).cross(&arm),
        e(1).cross(&arm),
        e(2).cross(&arm),
    ]
}

/// The three marker-position columns (m/m): the tip frame's axes in the base
/// frame, `R_tip eₖ`.
pub fn marker_columns<T: RealField + Copy, const J: usize>(
    frames: &Frames<T, J>,
) -> [Vector3<T>; 3] {
    let r = frames.tip().rotation.to_rotation_matrix();
    let e = |k: usize| r.matrix().column(k).into_owned();
    [e(0), e(1), e(2)]
}

/// Compliance columns at a marker `p_m` \[m, base frame\] for joint torques
/// `tau` (from [`crate::robot::joint_torques`], [`crate::robot::gravity_torques`]
/// or their sum), written
/// to `out[..dof]`: `τⱼ (zⱼ × (p − oⱼ))` [m per rad/(N·m)] (revolute) or
/// `τⱼ zⱼ` \[m per m/N\] (prismatic).
///
/// # Errors
/// [`Error::Mismatch`] when `tau` or `out` is shorter than the number of
/// joints.
pub fn compliance_columns<T: RealField + Copy, const J: usize>(
    frames: &Frames<T, J>,
    p_m: &Vector3<T>,
    tau: &[T],
    out: &mut [Vector3<T>],
) -> Result<(), Error> {
    check_len(frames, tau.len())?;
    check_len(frames, out.len())?;
    for ((o, jf), &t) in out.iter_mut().zip(frames.joints()).zip(tau) {
        *o = jf.twist_column(p_m) * t;
    }
    Ok(())
}

/// First-order deflection `Δp = Σⱼ kⱼ τⱼ (zⱼ × (p − oⱼ))` \[m\] of a marker at
/// `p_m` under joint torques `tau`, with compliances `k` \[rad/(N·m) or m/N\].
///
/// # Errors
/// [`Error::Mismatch`] when `tau` or `k` is shorter than the number of
/// joints.
pub fn deflection_m<T: RealField + Copy, const J: usize>(
    frames: &Frames<T, J>,
    p_m: &Vector3<T>,
    tau: &[T],
    k: &[T],
) -> Result<Vector3<T>, Error> {
    check_len(frames, tau.len())?;
    check_len(frames, k.len())?;
    let mut dp = Vector3::zeros();
    for ((jf, &t), &kj) in frames.joints().iter().zip(tau).zip(k) {
        dp += jf.twist_column(p_m) * (t * kj);
    }
    Ok(dp)
}
