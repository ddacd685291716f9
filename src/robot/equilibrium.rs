//! Static equilibrium of a chain whose joints yield under their torques:
//! the virtual-joint model of eq. 3 (rigid links, a spring in every joint),
//! solved exactly instead of to first order.
//!
//! A robot commanded to joint values `q` and loaded (a hanging mass, its own
//! weight) settles at the pose `θ` where every joint's deflection is the
//! one its torque *at that pose* produces:
//!
//! ```text
//!   θ = q + δ(τ(θ)),      δⱼ = the joint law of joint j (e.g. kⱼ τⱼ)
//! ```
//!
//! The paper's eq. 3 is the first-order form: torques at `q`, and
//! `Δp = Σⱼ δⱼ zⱼ × (p − oⱼ)` at `q`. For the KR-270's 2–11 mm deflections
//! the first-order form misses up to ~26 µm, systematic within a
//! configuration — the order of the tracker's noise.
//!
//! [`equilibrium`] solves it by Newton's method (for an industrial robot
//! `‖D T‖` is about 1e-3 and two or three steps reach rounding) and
//! returns the deflected frames, the torques there, and the **sensitivity**
//! `M = (I − D T)⁻¹`, `D = diag(∂δⱼ/∂τⱼ)`, `T = ∂τ/∂θ`
//! ([`Loading::torque_jacobian`]): a change `ε` of the joint values the
//! law adds (a compliance, an offset) moves the equilibrium by `M ε`, so the
//! exact column of anything that acts through a joint value is
//! [`Equilibrium::twist_column`], `Σᵢ (zᵢ × (p − oᵢ)) Mᵢⱼ`, instead of
//! `zⱼ × (p − oⱼ)`.

use nalgebra::{Point3, RealField, SMatrix, Vector3};

use super::chain::{Chain, JointKind};
use super::kinematics::{Frames, JointFrame};
use super::load::{check_len, gravity_moments, gravity_torques, joint_torques, PointLoad, Wrench};
use crate::error::Error;

/// What loads the joints at the deflected pose.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Loading<T: RealField + Copy> {
    /// A mass hanging from the tip (the calibration tool).
    pub load: Option<PointLoad<T>>,
    /// Gravity \[m/s², in the chain's base frame\] acting on the chain's own
    /// link masses ([`crate::robot::LinkInertia`]); `None`: the robot's own weight
    /// is not modelled.
    pub own_weight_mps2: Option<Vector3<T>>,
}

impl<T: RealField + Copy> Loading<T> {
    /// Joint torques `τ` \[N·m or N\] at `frames`, written to `tau[..dof]`.
    ///
    /// # Errors
    /// As [`joint_torques`] and [`gravity_torques`].
    pub fn torques<const J: usize>(
        &self,
        chain: &Chain<T, J>,
        frames: &Frames<T, J>,
        tau: &mut [T],
    ) -> Result<(), Error> {
        check_len(frames, tau.len())?;
        let dof = frames.dof();
        for t in tau.iter_mut().take(dof) {
            *t = T::zero();
        }
        if let Some(g) = self.own_weight_mps2 {
            gravity_torques(chain, frames, &g, tau)?;
        }
        if let Some(load) = self.load {
            let mut extra = [T::zero(); J];
            joint_torques(frames, &load.wrench(frames), &mut extra)?;
            for (t, e) in tau.iter_mut().zip(&extra).take(dof) {
                *t += *e;
            }
        }
        Ok(())
    }

    /// Moments `mⱼ` \[N·m, base frame\] about each joint's origin of
    /// everything the joint carries at `frames`, written to `out[..dof]`:
    /// the own weight's ([`gravity_moments`]) and the load's
    /// `(c − oⱼ) × F` (joints that carry the tip). Their parts along the
    /// axes are [`Loading::torques`]; across them, what bends the links.
    ///
    /// # Errors
    /// As [`Loading::torques`].
    pub fn moments<const J: usize>(
        &self,
        chain: &Chain<T, J>,
        frames: &Frames<T, J>,
        out: &mut [Vector3<T>],
    ) -> Result<(), Error> {
        check_len(frames, out.len())?;
        let dof = frames.dof();
        for m in out.iter_mut().take(dof) {
            *m = Vector3::zeros();
        }
        if let Some(g) = self.own_weight_mps2 {
            gravity_moments(chain, frames, &g, out)?;
        }
        if let Some(load) = self.load {
            let w = load.wrench(frames);
            for (m, jf) in out.iter_mut().zip(frames.joints()).take(dof) {
                if cfg!(not(feature = "tree")) || jf.carries {
                    *m += (w.point_m - jf.origin_m()).cross(&w.force_n) + w.moment_nm;
                }
            }
        }
        Ok(())
    }

    /// `T = ∂τ/∂θ` at `frames` (row `j`: joint `j`'s torque; column `i`:
    /// joint `i`'s value), the loads held constant in the base frame (their
    /// points move with the links). Entries past the chain's dof are zero.
    ///
    /// # Errors
    /// [`Error::Mismatch`] when `frames` was not computed for `chain`.
    pub fn torque_jacobian<const J: usize>(
        &self,
        chain: &Chain<T, J>,
        frames: &Frames<T, J>,
    ) -> Result<SMatrix<T, J, J>, Error> {
        if chain.dof() != frames.dof() {
            return Err(Error::Mismatch {
                what: "frames computed for another chain",
            });
        }
        let mut t = SMatrix::<T, J, J>::zeros();
        let dof = frames.dof();
        if let Some(g) = self.own_weight_mps2 {
            for (l, (joint, lf)) in chain.joints().iter().zip(frames.joints()).enumerate() {
                let Some(link) = joint.link else { continue };
                let w = Wrench::force(
                    g * link.mass_kg,
                    lf.frame.transform_point(&Point3::from(link.com_m)).coords,
                );
                add_wrench_jacobian(chain, frames.joints(), &w, Some(l), &mut t);
            }
        }
        if let Some(load) = self.load {
            if dof > 0 {
                let w = load.wrench(frames);
                add_wrench_jacobian(chain, frames.joints(), &w, chain.tip_joint(), &mut t);
            }
        }
        Ok(t)
    }
}

/// Adds `∂τⱼ/∂θᵢ` of wrench `w`, carried by joint `last` and the joints it
/// hangs from (`0..=last` in a serial chain; it acts on link `last` or
/// beyond; `None`: on the base, nothing), to `t`. A joint `i` moves the
/// wrench's point (`dc = zᵢ × (c − oᵢ)` revolute, `zᵢ` prismatic) and, when
/// it lies before joint `j` (on one path: `i < j`), joint `j`'s axis and
/// origin with it.
fn add_wrench_jacobian<T: RealField + Copy, const J: usize>(
    chain: &Chain<T, J>,
    js: &[JointFrame<T>],
    w: &Wrench<T>,
    last: Option<usize>,
    t: &mut SMatrix<T, J, J>,
) {
    let (f, c, m) = (w.force_n, w.point_m, w.moment_nm);
    let Some(last) = last else { return };
    // A tree's joints off the path to `last` do not carry the wrench.
    #[cfg(feature = "tree")]
    let on = {
        let mut on = [false; J];
        for j in chain.path(Some(last)) {
            if let Some(o) = on.get_mut(j) {
                *o = true;
            }
        }
        on
    };
    #[cfg(not(feature = "tree"))]
    let _ = chain;
    for (j, jj) in js.iter().enumerate().take(last + 1) {
        #[cfg(feature = "tree")]
        if !on[j] {
            continue;
        }
        let zj = jj.axis.into_inner();
        let cj = c - jj.origin_m();
        for (i, ji) in js.iter().enumerate().take(last + 1) {
            #[cfg(feature = "tree")]
            if !on[i] {
                continue;
            }
            let zi = ji.axis.into_inner();
            let d = match (ji.kind, jj.kind, i < j) {
                // Joint i turns joint j's axis and origin and the point.
                (JointKind::Revolute, JointKind::Revolute, true) => {
                    zi.cross(&zj).dot(&(cj.cross(&f) + m)) + zj.dot(&zi.cross(&cj).cross(&f))
                }
                (JointKind::Revolute, JointKind::Prismatic, true) => zi.cross(&zj).dot(&f),
                // A prismatic joint before j moves j and the point together.
                (JointKind::Prismatic, _, true) => T::zero(),
                // Joint i at or after j moves the point only.
                (JointKind::Revolute, JointKind::Revolute, false) => {
                    zj.dot(&zi.cross(&(c - ji.origin_m())).cross(&f))
                }
                (JointKind::Prismatic, JointKind::Revolute, false) => zj.dot(&zi.cross(&f)),
                (_, JointKind::Prismatic, false) => T::zero(),
            };
            t[(j, i)] += d;
        }
    }
}

/// How each joint yields under its torque: the joint law of the model
/// (compliance, its angle bins, nonlinear stiffness, backlash, …).
pub trait JointLaw<T> {
    /// Joint `j`'s deflection `δⱼ` \[rad or m\] under torque `tau` \[N·m or
    /// N\], and its derivative `∂δⱼ/∂τⱼ`.
    fn deflection(&self, j: usize, tau: T) -> (T, T);
}

/// When [`equilibrium`] stops.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EquilibriumSettings<T> {
    /// Stop when the next Newton step would move no joint value by more
    /// than this \[rad or m\].
    pub tolerance: T,
    /// At most this many Newton steps.
    pub max_iterations: usize,
}

/// The settled pose of a loaded chain (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Equilibrium<T: RealField + Copy, const J: usize> {
    /// Frames at the deflected pose `θ` (`frames.q()` is `θ`).
    pub frames: Frames<T, J>,
    /// Joint torques at `θ` \[N·m or N\] (first `dof` entries).
    pub tau: [T; J],
    /// `θ − q` \[rad or m\] (first `dof` entries).
    pub deflection: [T; J],
    /// `M = (I − D T)⁻¹`: `∂θ/∂ε` for a change `ε` of the joint values the
    /// law adds.
    pub sensitivity: SMatrix<T, J, J>,
    /// Newton steps taken.
    pub iterations: usize,
}

impl<T: RealField + Copy, const J: usize> Equilibrium<T, J> {
    /// `∂p/∂εⱼ` \[m/rad or m/m\] of a point `p_m` \[m\] carried by the chain,
    /// for a change `εⱼ` of joint `j`'s value that the law adds (an offset, a
    /// compliance times its torque): `Σᵢ (zᵢ × (p − oᵢ)) Mᵢⱼ` at `θ`. With
    /// `M = I` it is [`JointFrame::twist_column`].
    ///
    /// # Errors
    /// [`Error::OutOfRange`] when `j ≥ dof`.
    pub fn twist_column(&self, j: usize, p_m: &Vector3<T>) -> Result<Vector3<T>, Error> {
        self.frames.joint(j)?;
        Ok(self
            .frames
            .joints()
            .iter()
            .enumerate()
            .fold(Vector3::zeros(), |s, (i, jf)| {
                s + jf.twist_column(p_m) * self.sensitivity[(i, j)]
            }))
    }
}

/// The equilibrium `θ = q + δ(τ(θ))` of `chain` commanded to `q` under
/// `loading`, each joint yielding by `law` (see the [module docs](self)),
/// by Newton's method on `r(θ) = θ − q − δ(τ(θ))`: `θ ← θ − M r(θ)`,
/// `M = (I − D T)⁻¹`, from `θ = guess` (`q`, or a previous equilibrium). (Successive substitution would need
/// `‖D T‖ < 1`; a soft joint under a large torque breaks that while the
/// equilibrium still exists.)
///
/// # Errors
/// As [`Chain::frames`]; [`Error::NotConverged`] when Newton does not
/// settle (a law so soft that the loaded robot has no nearby equilibrium);
/// [`Error::NotIdentifiable`] when `I − D T` is singular there;
/// [`Error::NonFinite`] when the iteration leaves the finite numbers.
pub fn equilibrium<T: RealField + Copy, const J: usize, L: JointLaw<T>>(
    chain: &Chain<T, J>,
    q: &[T],
    guess: &[T],
    loading: &Loading<T>,
    law: &L,
    settings: &EquilibriumSettings<T>,
) -> Result<Equilibrium<T, J>, Error> {
    let dof = chain.dof();
    if guess.len() != dof {
        return Err(Error::Mismatch {
            what: "equilibrium guess length differs from the chain's dof",
        });
    }
    let mut theta = [T::zero(); J];
    theta[..dof].copy_from_slice(guess);
    let mut iterations = 0;
    loop {
        let frames = chain.frames(&theta[..dof])?;
        let mut tau = [T::zero(); J];
        loading.torques(chain, &frames, &mut tau)?;
        let sensitivity = sensitivity(chain, &frames, loading, law, &tau)?;
        let mut r = nalgebra::SVector::<T, J>::zeros();
        for j in 0..dof {
            r[j] = theta[j] - q[j] - law.deflection(j, tau[j]).0;
        }
        let step = sensitivity * r;
        let largest = step.iter().fold(T::zero(), |m, v| m.max(v.abs()));
        if !largest.is_finite() {
            return Err(Error::NonFinite {
                what: "equilibrium",
            });
        }
        if largest <= settings.tolerance {
            let mut deflection = [T::zero(); J];
            for j in 0..dof {
                deflection[j] = theta[j] - q[j];
            }
            return Ok(Equilibrium {
                frames,
                tau,
                deflection,
                sensitivity,
                iterations,
            });
        }
        if iterations >= settings.max_iterations {
            return Err(Error::NotConverged { iterations });
        }
        for j in 0..dof {
            theta[j] -= step[j];
        }
        iterations += 1;
    }
}

/// `M = (I − D T)⁻¹` at `frames` with torques `tau`.
fn sensitivity<T: RealField + Copy, const J: usize, L: JointLaw<T>>(
    chain: &Chain<T, J>,
    frames: &Frames<T, J>,
    loading: &Loading<T>,
    law: &L,
    tau: &[T; J],
) -> Result<SMatrix<T, J, J>, Error> {
    let t = loading.torque_jacobian(chain, frames)?;
    let mut a = SMatrix::<T, J, J>::identity();
    for j in 0..frames.dof() {
        let d = law.deflection(j, tau[j]).1;
        for i in 0..frames.dof() {
            a[(j, i)] -= d * t[(j, i)];
        }
    }
    invert_leading(&mut a, frames.dof())?;
    Ok(a)
}

/// Inverts the leading `n × n` block of `a` in place (Gauss–Jordan with
/// partial pivoting), the rest being the identity: the chain's dof, not the
/// capacity `J`.
fn invert_leading<T: RealField + Copy, const J: usize>(
    a: &mut SMatrix<T, J, J>,
    n: usize,
) -> Result<(), Error> {
    let mut inv = SMatrix::<T, J, J>::identity();
    for c in 0..n {
        let p = (c..n)
            .max_by(|&i, &k| {
                a[(i, c)]
                    .abs()
                    .partial_cmp(&a[(k, c)].abs())
                    .unwrap_or(core::cmp::Ordering::Equal)
            })
            .unwrap_or(c);
        let pivot = a[(p, c)];
        if pivot.abs() <= T::zero() || !pivot.is_finite() {
            return Err(Error::NotIdentifiable {
                column: c,
                rcond: 0.0,
            });
        }
        a.swap_rows(c, p);
        inv.swap_rows(c, p);
        let scale = T::one() / pivot;
        for k in 0..n {
            a[(c, k)] *= scale;
            inv[(c, k)] *= scale;
        }
        for i in (0..n).filter(|&i| i != c) {
            let f = a[(i, c)];
            if f != T::zero() {
                for k in 0..n {
                    let (ack, ick) = (a[(c, k)], inv[(c, k)]);
                    a[(i, k)] -= f * ack;
                    inv[(i, k)] -= f * ick;
                }
            }
        }
    }
    *a = inv;
    Ok(())
}
