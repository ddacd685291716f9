//! Elastostatic identification columns (eq. 3, `Δpᵉ = A⁽ᵖ⁾ k`), virtual-joint
//! model: rigid links, one linear spring per joint.
//!
//! A wrench (force `F` \[N\] acting at point `c` \[m\], plus a moment `M`
//! \[N·m\], all in the base frame) loads joint `j` with
//!
//! - `τⱼ = zⱼᵀ((c − oⱼ) × F + M)` \[N·m\] (revolute),
//! - `τⱼ = zⱼᵀ F` \[N\] (prismatic),
//!
//! and the joint yields by `δqⱼ = kⱼ τⱼ` (`kⱼ` in rad/(N·m), or m/N for a
//! prismatic joint). To first order a marker at `p` moves by
//!
//! `Δp = Σⱼ kⱼ τⱼ (zⱼ × (p − oⱼ))` (prismatic: `kⱼ τⱼ zⱼ`),
//!
//! which is linear in `k`: the column of `kⱼ` is `τⱼ (zⱼ × (p − oⱼ))`
//! [m per rad/(N·m)]. A wrench acting at or beyond the tip loads every joint;
//! the weight of link `l` (carried by joint `l`) loads joints `0..=l` only
//! ([`gravity_torques`]).
//!
//! ```
//! use nalgebra::Vector3;
//! use robcal::elastostatic::{compliance_columns, joint_torques, Wrench};
//! use robcal::{Chain, Joint, JointKind};
//!
//! // One horizontal 1 m link about y, 100 N down at its end: τ = 100 N·m.
//! let mut chain = Chain::<f64, 1>::new();
//! chain.push(Joint::from_urdf(Vector3::zeros(), Vector3::zeros(), Vector3::y(), JointKind::Revolute).unwrap()).unwrap();
//! let frames = chain.frames(&[0.0]).unwrap();
//! let w = Wrench::force(Vector3::new(0.0, 0.0, -100.0), Vector3::x());
//! let mut tau = [0.0];
//! joint_torques(&frames, &w, &mut tau).unwrap();
//! assert!((tau[0] - 100.0).abs() < 1e-12);
//! let mut col = [Vector3::zeros()];
//! compliance_columns(&frames, &Vector3::x(), &tau, &mut col).unwrap();
//! // k = 1e-6 rad/(N·m) lowers the end by 100 µm.
//! assert!((col[0] * 1e-6 - Vector3::new(0.0, 0.0, -1e-4)).norm() < 1e-15);
//! ```

use nalgebra::{Point3, RealField, Vector3};

use crate::chain::{Chain, JointKind};
use crate::kinematics::{Frames, JointFrame};
use crate::Error;

/// A force and a moment, in the base frame.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Wrench<T: RealField + Copy> {
    /// Force `F` \[N\].
    pub force_n: Vector3<T>,
    /// Point of application `c` \[m\].
    pub point_m: Vector3<T>,
    /// Pure moment `M` \[N·m\].
    pub moment_nm: Vector3<T>,
}

impl<T: RealField + Copy> Wrench<T> {
    /// A force `F` \[N\] at point `c` \[m\], no moment.
    pub fn force(force_n: Vector3<T>, point_m: Vector3<T>) -> Self {
        Self {
            force_n,
            point_m,
            moment_nm: Vector3::zeros(),
        }
    }

    /// `τⱼ` this wrench puts on one joint (N·m revolute, N prismatic).
    pub fn torque_on(&self, joint: &JointFrame<T>) -> T {
        match joint.kind {
            JointKind::Revolute => joint
                .axis
                .dot(&((self.point_m - joint.origin_m()).cross(&self.force_n) + self.moment_nm)),
            JointKind::Prismatic => joint.axis.dot(&self.force_n),
        }
    }
}

/// A mass hanging from the tip (the paper's calibration tool, section 5):
/// weight `m g` acting at a centre of mass given in the tip frame.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PointLoad<T: RealField + Copy> {
    /// Mass \[kg\].
    pub mass_kg: T,
    /// Centre of mass \[m\] in the tip frame.
    pub com_m: Vector3<T>,
    /// Gravity `g` \[m/s²\] in the base frame (e.g. `(0, 0, −9.80665)`).
    pub gravity_mps2: Vector3<T>,
}

impl<T: RealField + Copy> PointLoad<T> {
    /// The load's wrench in the base frame at the pose `frames`:
    /// `F = m g` at `c = T_tip · com`.
    pub fn wrench<const J: usize>(&self, frames: &Frames<T, J>) -> Wrench<T> {
        Wrench::force(
            self.gravity_mps2 * self.mass_kg,
            frames.point_m(&self.com_m),
        )
    }
}

/// Joint torques `τⱼ` of a wrench acting at or beyond the tip (it loads every
/// joint), written to `tau[..dof]`.
///
/// # Errors
/// [`Error::Mismatch`] when `tau` is shorter than the number of joints.
pub fn joint_torques<T: RealField + Copy, const J: usize>(
    frames: &Frames<T, J>,
    wrench: &Wrench<T>,
    tau: &mut [T],
) -> Result<(), Error> {
    check_len(frames, tau.len())?;
    for (t, jf) in tau.iter_mut().zip(frames.joints()) {
        *t = wrench.torque_on(jf);
    }
    Ok(())
}

/// Joint torques `τⱼ` from the chain's own link masses under gravity `g`
/// \[m/s², base frame\], written to `tau[..dof]`: the weight `m_l g` of link
/// `l` acts at its centre of mass `T_l · com_l` and loads joints `0..=l`.
/// Links without [`crate::LinkInertia`] weigh nothing.
///
/// # Errors
/// [`Error::Mismatch`] when `tau` is shorter than the number of joints or
/// `frames` was not computed for `chain` (different dof).
pub fn gravity_torques<T: RealField + Copy, const J: usize>(
    chain: &Chain<T, J>,
    frames: &Frames<T, J>,
    gravity_mps2: &Vector3<T>,
    tau: &mut [T],
) -> Result<(), Error> {
    check_len(frames, tau.len())?;
    if chain.dof() != frames.dof() {
        return Err(Error::Mismatch {
            what: "frames computed for another chain",
        });
    }
    for t in tau.iter_mut().take(frames.dof()) {
        *t = T::zero();
    }
    for (l, (joint, lf)) in chain.joints().iter().zip(frames.joints()).enumerate() {
        let Some(link) = joint.link else { continue };
        let w = Wrench::force(
            gravity_mps2 * link.mass_kg,
            lf.frame.transform_point(&Point3::from(link.com_m)).coords,
        );
        for (t, jf) in tau.iter_mut().zip(frames.joints()).take(l + 1) {
            *t += w.torque_on(jf);
        }
    }
    Ok(())
}

/// Compliance columns at a marker `p_m` \[m, base frame\] for joint torques
/// `tau` (from [`joint_torques`], [`gravity_torques`] or their sum), written
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

fn check_len<T: RealField + Copy, const J: usize>(
    frames: &Frames<T, J>,
    len: usize,
) -> Result<(), Error> {
    if len < frames.dof() {
        return Err(Error::Mismatch {
            what: "slice shorter than the chain's dof",
        });
    }
    Ok(())
}
