//! Loads on the chain: a wrench at or beyond the tip, a hanging mass (the
//! paper's calibration tool, section 5), and the robot's own weight — and
//! the joint torques `τ` they cause.
//!
//! A wrench (force `F` \[N\] acting at point `c` \[m\], plus a moment `M`
//! \[N·m\], all in the base frame) loads joint `j` with
//!
//! - `τⱼ = zⱼᵀ((c − oⱼ) × F + M)` \[N·m\] (revolute),
//! - `τⱼ = zⱼᵀ F` \[N\] (prismatic).
//!
//! A wrench acting at or beyond the tip loads every joint that carries the
//! tip ([`joint_torques`]; all of a serial chain's); the weight of link `l`
//! (carried by joint `l`) loads joint `l` and the joints it hangs from only
//! (`0..=l` in a serial chain; [`gravity_torques`]). How a joint yields under its
//! torque is the model's business ([`crate::model`]: compliance, eq. 3).
//!
//! ```
//! use nalgebra::Vector3;
//! use robcal::robot::{joint_torques, Wrench};
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
//! ```

use nalgebra::{Point3, RealField, Vector3};

use super::chain::{Chain, JointKind};
use super::kinematics::{Frames, JointFrame};
use crate::error::Error;

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
/// joint that carries the tip, [`crate::robot::JointFrame::carries`]; the
/// others get 0), written to `tau[..dof]`.
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
        *t = if cfg!(not(feature = "tree")) || jf.carries {
            wrench.torque_on(jf)
        } else {
            T::zero()
        };
    }
    Ok(())
}

/// Joint torques `τⱼ` from the chain's own link masses under gravity `g`
/// \[m/s², base frame\], written to `tau[..dof]`: the weight `m_l g` of link
/// `l` acts at its centre of mass `T_l · com_l` and loads joint `l` and the
/// joints it hangs from (`0..=l` in a serial chain).
/// Links without [`crate::robot::LinkInertia`] weigh nothing.
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
    carried_weights(chain, frames, gravity_mps2, |j, jf, w| {
        if let Some(t) = tau.get_mut(j) {
            *t += w.torque_on(jf);
        }
    })
}

/// Moments `mⱼ` \[N·m, base frame\] about each joint's origin `oⱼ` of the
/// chain's own link masses under gravity `g` \[m/s², base frame\], added to
/// `out[..dof]`: `mⱼ = Σₗ (cₗ − oⱼ) × mₗ g` over the links `l` joint `j`
/// carries (`l ≥ j` in a serial chain), the whole vector — its part along
/// `zⱼ` is [`gravity_torques`]'s `τⱼ`, the part across it what bends link
/// `j` ([`crate::model::Param::LinkCompliance`]). Links without
/// [`crate::robot::LinkInertia`] weigh nothing.
///
/// # Errors
/// As [`gravity_torques`].
pub fn gravity_moments<T: RealField + Copy, const J: usize>(
    chain: &Chain<T, J>,
    frames: &Frames<T, J>,
    gravity_mps2: &Vector3<T>,
    out: &mut [Vector3<T>],
) -> Result<(), Error> {
    check_len(frames, out.len())?;
    carried_weights(chain, frames, gravity_mps2, |j, jf, w| {
        if let Some(m) = out.get_mut(j) {
            *m += (w.point_m - jf.origin_m()).cross(&w.force_n);
        }
    })
}

/// Each link's weight `m_l g` at its centre of mass `T_l · com_l` (a
/// [`Wrench::force`], base frame) with each joint that carries it (`0..=l`
/// in a serial chain): `f(j, joint j's frame, weight)`. Links without
/// [`crate::robot::LinkInertia`] weigh nothing.
///
/// # Errors
/// [`Error::Mismatch`] when `frames` was not computed for `chain`.
fn carried_weights<T: RealField + Copy, const J: usize>(
    chain: &Chain<T, J>,
    frames: &Frames<T, J>,
    gravity_mps2: &Vector3<T>,
    mut f: impl FnMut(usize, &JointFrame<T>, &Wrench<T>),
) -> Result<(), Error> {
    if chain.dof() != frames.dof() {
        return Err(Error::Mismatch {
            what: "frames computed for another chain",
        });
    }
    for (l, (joint, lf)) in chain.joints().iter().zip(frames.joints()).enumerate() {
        let Some(link) = joint.link else { continue };
        let w = Wrench::force(
            gravity_mps2 * link.mass_kg,
            lf.frame.transform_point(&Point3::from(link.com_m)).coords,
        );
        #[cfg(feature = "tree")]
        for j in chain.path(Some(l)) {
            if let Some(jf) = frames.joints().get(j) {
                f(j, jf, &w);
            }
        }
        #[cfg(not(feature = "tree"))]
        for (j, jf) in frames.joints().iter().enumerate().take(l + 1) {
            f(j, jf, &w);
        }
    }
    Ok(())
}

pub(crate) fn check_len<T: RealField + Copy, const J: usize>(
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
