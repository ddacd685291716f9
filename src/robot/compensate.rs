//! Compensation: the joint command whose loaded, deflected robot reaches a
//! desired point (the compliance-error compensation of Klimchik et al.
//! 2013, the paper's reference, on the exact model).
//!
//! A controller that sends the nominal inverse kinematics `q₀` of a target
//! `p*` misses it twice: by the geometric errors the calibration found and
//! by the deflection of the joints under the payload and the robot's own
//! weight. With the calibrated chain (its joint origins already corrected)
//! and its joint law, the commanded `q` settles at the equilibrium
//! `θ(q) = q + δ(τ(θ))` ([`super::equilibrium()`]) and the tool point is at
//! `p(θ(q))`. [`compensate`] solves
//!
//! ```text
//!   p(θ(q)) = p*
//! ```
//!
//! by Newton's method from `q₀`: `∂p/∂q = Σᵢ (zᵢ × (p − oᵢ)) Mᵢⱼ` with the
//! equilibrium's sensitivity `M = (I − D T)⁻¹`
//! ([`super::Equilibrium::twist_column`]), and of the joint changes that
//! move the point by the error `e = p* − p` it takes the smallest,
//! `Δq = Jᵀ (J Jᵀ + μ²I)⁻¹ e` (a point fixes three of the robot's joint
//! values; the others stay where `q₀` put them, to first order), with a
//! damping `μ² = 1000 ε · trace(J Jᵀ)` (`ε` the type's machine epsilon) that
//! changes nothing away from a singular pose and keeps the step finite at
//! one: a direction the joints cannot move the point in is not moved in,
//! and a target off that direction ends in [`Error::NotConverged`]. Each step is
//! limited to [`CompensateSettings::max_step`] per joint; the iteration
//! stops when `‖e‖ ≤ tolerance_m`, and is an error after `max_iterations`.
//! Typical: 2–3 steps (the corrections are millimetres on metres).
//!
//! [`compensate_pose`] does the same for a pose (the tool point and the tip
//! frame's orientation, six equations), where the markers determine the
//! orientation.
//!
//! Everything is on the stack (`J` is the chain's capacity), nothing
//! allocates, and an error leaves nothing behind: the function is pure.

use nalgebra::{RealField, SMatrix, SVector, UnitQuaternion, Vector3};

use super::chain::{Chain, JointKind};
use super::equilibrium::{equilibrium, Equilibrium, EquilibriumSettings, JointLaw, Loading};
use crate::error::Error;

/// When [`compensate`] stops, and how far one step may go.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CompensateSettings<T> {
    /// Stop when the tool point is within this distance of the target \[m\].
    pub tolerance_m: T,
    /// At most this many Newton steps; more is [`Error::NotConverged`].
    pub max_iterations: usize,
    /// The largest change of any joint value in one step \[rad or m\]; a
    /// longer step is scaled down (a target far from `q₀` is approached
    /// gradually instead of overshooting).
    pub max_step: T,
    /// The equilibrium solve at each step.
    pub equilibrium: EquilibriumSettings<T>,
}

impl<T: RealField + Copy> CompensateSettings<T> {
    /// 0.1 µm, 20 steps of at most 0.1 rad, equilibrium to 1e-12 rad in at
    /// most 20 Newton steps (f64). For f32 use a tolerance above its
    /// rounding (~1 µm on a 2 m robot).
    pub fn new() -> Self {
        Self {
            tolerance_m: nalgebra::convert(1e-7),
            max_iterations: 20,
            max_step: nalgebra::convert(0.1),
            equilibrium: EquilibriumSettings {
                tolerance: nalgebra::convert(1e-12),
                max_iterations: 20,
            },
        }
    }
}

impl<T: RealField + Copy> Default for CompensateSettings<T> {
    fn default() -> Self {
        Self::new()
    }
}

/// The compensated command (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Compensation<T: RealField + Copy, const J: usize> {
    /// The joint command `q` \[rad or m\] (first `dof` entries).
    pub q: [T; J],
    /// Where the tool point settles under the command \[m\], by the model.
    pub reached_m: Vector3<T>,
    /// `‖p* − reached‖` \[m\].
    pub error_m: T,
    /// The orientation error \[rad\] of [`compensate_pose`] (0 for a point).
    pub error_rad: T,
    /// Newton steps taken.
    pub iterations: usize,
    /// The loaded robot at the command (its frames, torques, deflections).
    pub equilibrium: Equilibrium<T, J>,
}

/// The joint command whose loaded, deflected robot puts the point `tool_m`
/// \[m, tip frame\] at `target_m` \[m, the chain's base frame\], starting from
/// `q_start` (typically the nominal inverse kinematics of the target).
/// `law(q)` is the joint law at command `q` (a compensator table depends on
/// the angle; a plain compliance does not).
///
/// # Errors
/// [`Error::Mismatch`] when `q_start` does not have one value per joint;
/// [`Error::NonFinite`] for a non-finite input (`"target"`, `"tool"`,
/// `"q_start"`); the errors of [`equilibrium`] at a step;
/// [`Error::NotIdentifiable`] when no joint moves the point at all;
/// [`Error::NotConverged`] after `max_iterations` steps (an unreachable
/// target).
pub fn compensate<T, const J: usize, L, F>(
    chain: &Chain<T, J>,
    tool_m: &Vector3<T>,
    target_m: &Vector3<T>,
    q_start: &[T],
    loading: &Loading<T>,
    law: F,
    settings: &CompensateSettings<T>,
) -> Result<Compensation<T, J>, Error>
where
    T: RealField + Copy,
    L: JointLaw<T>,
    F: FnMut(&[T]) -> L,
{
    check_inputs(tool_m, target_m, None, q_start, chain.dof())?;
    newton::<T, J, 3, L, F>(
        chain,
        q_start,
        loading,
        law,
        settings,
        |eq| {
            let p = eq.frames.point_m(tool_m);
            let e = target_m - p;
            (e, p, e.norm(), T::zero())
        },
        |eq, p| {
            let mut jac = SMatrix::<T, 3, J>::zeros();
            for j in 0..eq.frames.dof() {
                jac.set_column(j, &eq.twist_column(j, p)?);
            }
            Ok(jac)
        },
    )
}

/// As [`compensate`], for a **pose**: the tool frame (the tip frame moved
/// to `tool_m`) at `target_m` with the tip frame's orientation
/// `target_rotation` (both in the chain's base frame) — for a robot whose
/// markers determine its orientation. Six equations: the position error
/// and the rotation error `log(R* Rᵀ)` (rotation vector, base frame), an
/// angle `θ` weighing as `θ · 1 m` in the step and the stopping rule
/// ([`Compensation::error_rad`] ≤ `tolerance_m / 1 m`). A robot with fewer
/// than six joints reaches the pose only where it can; a redundant one
/// takes the smallest step.
///
/// # Errors
/// As [`compensate`]; [`Error::NonFinite`] `"target rotation"`.
#[allow(clippy::too_many_arguments)]
pub fn compensate_pose<T, const J: usize, L, F>(
    chain: &Chain<T, J>,
    tool_m: &Vector3<T>,
    target_m: &Vector3<T>,
    target_rotation: &UnitQuaternion<T>,
    q_start: &[T],
    loading: &Loading<T>,
    law: F,
    settings: &CompensateSettings<T>,
) -> Result<Compensation<T, J>, Error>
where
    T: RealField + Copy,
    L: JointLaw<T>,
    F: FnMut(&[T]) -> L,
{
    check_inputs(
        tool_m,
        target_m,
        Some(target_rotation),
        q_start,
        chain.dof(),
    )?;
    newton::<T, J, 6, L, F>(
        chain,
        q_start,
        loading,
        law,
        settings,
        |eq| {
            let p = eq.frames.point_m(tool_m);
            let ep = target_m - p;
            let er = (target_rotation * eq.frames.tip().rotation.inverse()).scaled_axis();
            let e = SVector::<T, 6>::from_fn(|i, _| if i < 3 { ep[i] } else { er[i - 3] });
            (e, p, ep.norm(), er.norm())
        },
        |eq, p| {
            let mut jac = SMatrix::<T, 6, J>::zeros();
            let m = &eq.sensitivity;
            for j in 0..eq.frames.dof() {
                let lin = eq.twist_column(j, p)?;
                // ω per unit εⱼ: Σᵢ zᵢ Mᵢⱼ over the revolute joints.
                let ang = eq
                    .frames
                    .joints()
                    .iter()
                    .enumerate()
                    .filter(|(_, f)| f.kind == JointKind::Revolute)
                    .fold(Vector3::zeros(), |s, (i, f)| {
                        s + f.axis.into_inner() * m[(i, j)]
                    });
                for r in 0..3 {
                    jac[(r, j)] = lin[r];
                    jac[(r + 3, j)] = ang[r];
                }
            }
            Ok(jac)
        },
    )
}

fn check_inputs<T: RealField + Copy>(
    tool_m: &Vector3<T>,
    target_m: &Vector3<T>,
    target_rotation: Option<&UnitQuaternion<T>>,
    q_start: &[T],
    dof: usize,
) -> Result<(), Error> {
    if q_start.len() != dof {
        return Err(Error::Mismatch {
            what: "compensation start length differs from the chain's dof",
        });
    }
    let finite = |v: &[T]| v.iter().all(|x| x.is_finite());
    if !finite(target_m.as_slice()) {
        return Err(Error::NonFinite { what: "target" });
    }
    if target_rotation.is_some_and(|r| !finite(r.coords.as_slice())) {
        return Err(Error::NonFinite {
            what: "target rotation",
        });
    }
    if !finite(tool_m.as_slice()) {
        return Err(Error::NonFinite { what: "tool" });
    }
    if !finite(q_start) {
        return Err(Error::NonFinite { what: "q_start" });
    }
    Ok(())
}

/// The Newton iteration of [`compensate`] and [`compensate_pose`] on `R`
/// equations: `error(eq)` gives the error vector, the point reached and
/// the position and angle errors; `jacobian(eq, p)` its derivative by the
/// commanded joint values.
#[allow(clippy::too_many_arguments)]
fn newton<T, const J: usize, const R: usize, L, F>(
    chain: &Chain<T, J>,
    q_start: &[T],
    loading: &Loading<T>,
    mut law: F,
    settings: &CompensateSettings<T>,
    error: impl Fn(&Equilibrium<T, J>) -> (SVector<T, R>, Vector3<T>, T, T),
    jacobian: impl Fn(&Equilibrium<T, J>, &Vector3<T>) -> Result<SMatrix<T, R, J>, Error>,
) -> Result<Compensation<T, J>, Error>
where
    T: RealField + Copy,
    L: JointLaw<T>,
    F: FnMut(&[T]) -> L,
{
    let dof = chain.dof();
    let mut q = [T::zero(); J];
    q[..dof].copy_from_slice(q_start);
    let mut guess = q;
    let mut iterations = 0;
    loop {
        let eq = equilibrium(
            chain,
            &q[..dof],
            &guess[..dof],
            loading,
            &law(&q[..dof]),
            &settings.equilibrium,
        )?;
        let (e, p, error_m, error_rad) = error(&eq);
        if !(error_m.is_finite() && error_rad.is_finite()) {
            return Err(Error::NonFinite {
                what: "compensation",
            });
        }
        // An angle weighs as its arc on a 1 m lever.
        if error_m <= settings.tolerance_m && error_rad <= settings.tolerance_m {
            return Ok(Compensation {
                q,
                reached_m: p,
                error_m,
                error_rad,
                iterations,
                equilibrium: eq,
            });
        }
        if iterations >= settings.max_iterations {
            return Err(Error::NotConverged { iterations });
        }
        // The minimum-norm step Jᵀ (J Jᵀ + μ²I)⁻¹ e.
        let jac = jacobian(&eq, &p)?;
        let mut jjt: SMatrix<T, R, R> = jac * jac.transpose();
        let mu2 = T::default_epsilon() * nalgebra::convert(1000.0) * jjt.trace();
        for i in 0..R {
            jjt[(i, i)] += mu2;
        }
        let Some(chol) = jjt.cholesky() else {
            return Err(Error::NotIdentifiable {
                column: 0,
                rcond: 0.0,
            });
        };
        let step = jac.transpose() * chol.solve(&e);
        let largest = step.iter().fold(T::zero(), |m, v| m.max(v.abs()));
        if !largest.is_finite() {
            return Err(Error::NonFinite {
                what: "compensation",
            });
        }
        let scale = if largest > settings.max_step {
            settings.max_step / largest
        } else {
            T::one()
        };
        for j in 0..dof {
            let s = step[j] * scale;
            q[j] += s;
            // The settled pose moves with the command: start there.
            guess[j] = eq.frames.q()[j] + s;
        }
        iterations += 1;
    }
}

/// A joint law of constant compliances: `δⱼ = kⱼ τⱼ` (the paper's eq. 3
/// virtual springs), for a device that holds the calibrated compliances in
/// an array.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Compliances<T, const J: usize> {
    /// `kⱼ` \[rad/(N·m) or m/N\] per joint.
    pub k: [T; J],
}

impl<T: RealField + Copy, const J: usize> JointLaw<T> for Compliances<T, J> {
    fn deflection(&self, j: usize, tau: T) -> (T, T) {
        let k = self.k.get(j).copied().unwrap_or_else(T::zero);
        (k * tau, k)
    }
}
