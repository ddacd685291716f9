//! What one measurement carries, evaluated at the current model: everything
//! a column ([`super::columns`]) is computed from.

use nalgebra::{RealField, Vector3};

use crate::error::Error;
use crate::robot::{Frames, Wrench};

/// One measured point at the current model: the pose, where the marker is,
/// the torques behind it, the load, the time.
///
/// Two kinds of measurement (data contract §3):
/// - an **absolute** position (`absolute = true`, geometric calibration,
///   eq. 2): the robot's own weight loads the joints (`tau` = gravity
///   torques), every parameter acts;
/// - a **deflection** (`absolute = false`, elastostatic calibration,
///   eq. 3): loaded minus unloaded position at the same pose; only the
///   load's torques enter (`tau` = the load's), geometric parameters do
///   not act.
#[derive(Debug, Clone, Copy)]
pub struct Sample<'a, T: RealField + Copy, const J: usize> {
    /// The chain's frames at the pose the point is at — the measured joint
    /// values, or the deflected pose of the exact model
    /// ([`crate::robot::equilibrium()`]) — in the frame the point is given in.
    pub frames: &'a Frames<T, J>,
    /// The measured (commanded) joint values \[rad or m\]: what angle bins
    /// and the gear's cyclic error are functions of.
    pub q: &'a [T],
    /// The column of a change of each joint's value that the joint law adds
    /// ([`crate::robot::Equilibrium::twist_column`]); empty: each joint's own
    /// `zⱼ × (p − oⱼ)` at `frames` (the first-order model, eq. 2 and 3).
    pub twists: &'a [Vector3<T>],
    /// The marker's predicted position \[m\], in the same frame.
    pub point_m: Vector3<T>,
    /// Marker index (for [`super::Param::Marker`]).
    pub marker: u8,
    /// Joint torques behind the measurement \[N·m or N\], one per joint.
    pub tau: &'a [T],
    /// The load's wrench (deflections; `None` without a load).
    pub load: Option<Wrench<T>>,
    /// Absolute position (`true`) or deflection (`false`).
    pub absolute: bool,
    /// Time \[s\] for the drift, from any fixed origin.
    pub dt_s: T,
    /// Effective compliance \[rad/(N·m) or m/N\] of each joint at this
    /// sample, about which the linearised `load_com` column is taken; may be
    /// empty (then that column is zero).
    pub compliance: &'a [T],
    /// The unit direction of gravity `ĝ` in the frame of `frames` (absolute
    /// rows; zero: none, and the `gravity_compliance` columns are zero).
    /// Host only (`std`), as [`super::Param`]'s gravity compliance.
    #[cfg(feature = "std")]
    pub gravity: Vector3<T>,
    /// Per joint, the components of `ĝ` on the joint's basis `(aⱼ, bⱼ)` at
    /// the commanded pose `q` ([`super::gravity_components`]), when
    /// `frames` are elsewhere (the exact deflection model's equilibrium);
    /// empty: computed at `frames`. Host only (`std`).
    #[cfg(feature = "std")]
    pub gravity_q: &'a [[T; 2]],
    /// Per joint, the moment \[N·m, the frame of `frames`\] about its origin
    /// of the robot's own weight it carries ([`crate::robot::gravity_moments`]):
    /// an absolute row's, what bends its links
    /// ([`super::Param::LinkCompliance`]); empty: none (no mass model, or a
    /// deflection, whose own weight cancels). Host only (`std`).
    #[cfg(feature = "std")]
    pub weight_moments_nm: &'a [Vector3<T>],
    /// Temperature \[K\] over the data's mean (absolute rows) or between
    /// the loaded and the unloaded measurement (deflections): what the
    /// links' thermal expansion ([`super::Param::ThermalExpansion`]) is
    /// proportional to; zero without a temperature. Host only (`std`).
    #[cfg(feature = "std")]
    pub dtemp_k: T,
}

impl<'a, T: RealField + Copy, const J: usize> Sample<'a, T, J> {
    /// A deflection sample under `load` with its torques `tau`: no time,
    /// no compliance estimate.
    pub fn deflection(
        frames: &'a Frames<T, J>,
        point_m: Vector3<T>,
        marker: u8,
        tau: &'a [T],
        load: Option<Wrench<T>>,
    ) -> Self {
        Self {
            frames,
            q: frames.q(),
            twists: &[],
            point_m,
            marker,
            tau,
            load,
            absolute: false,
            dt_s: T::zero(),
            compliance: &[],
            #[cfg(feature = "std")]
            gravity: Vector3::zeros(),
            #[cfg(feature = "std")]
            gravity_q: &[],
            #[cfg(feature = "std")]
            weight_moments_nm: &[],
            #[cfg(feature = "std")]
            dtemp_k: T::zero(),
        }
    }

    /// An absolute-position sample with the torques `tau` of the robot's
    /// own weight: no load, no time, no compliance estimate.
    pub fn absolute(
        frames: &'a Frames<T, J>,
        point_m: Vector3<T>,
        marker: u8,
        tau: &'a [T],
    ) -> Self {
        Self {
            absolute: true,
            ..Self::deflection(frames, point_m, marker, tau, None)
        }
    }

    /// Joint `j`'s measured value \[rad or m\].
    ///
    /// # Errors
    /// [`Error::OutOfRange`] when the sample has no joint `j`.
    pub fn q(&self, j: u8) -> Result<T, Error> {
        self.q
            .get(usize::from(j))
            .copied()
            .ok_or(Error::OutOfRange {
                what: "joint",
                index: usize::from(j),
                len: self.q.len(),
            })
    }

    /// The column of a change of joint `j`'s value at the sample's point:
    /// [`Sample::twists`] when given, else `zⱼ × (p − oⱼ)` (revolute) or
    /// `zⱼ` (prismatic) at [`Sample::frames`].
    ///
    /// # Errors
    /// [`Error::OutOfRange`] when the frames have no joint `j`.
    pub fn twist(&self, j: u8) -> Result<Vector3<T>, Error> {
        let jf = self.frames.joint(usize::from(j))?;
        Ok(match self.twists.get(usize::from(j)) {
            Some(t) => *t,
            None => jf.twist_column(&self.point_m),
        })
    }
}
