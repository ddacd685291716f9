//! Forward kinematics of a [`Chain`]: joint frames, joint origins `oⱼ` and
//! axes `zⱼ` in the base frame, the tip pose and marker positions.
//!
//! Convention (see [`super::chain`]): `T_j = T_{p(j)} · origin_j · motion_j(q_j)`
//! (`p(j) = j − 1` in a serial chain), `T_tip = T_t · tip` (`t` the tip's
//! joint). For every joint [`Frames`] keeps both the frame at zero joint
//! value, `Z_j = T_{p(j)} · origin_j` (where the joint-frame errors
//! of [`crate::model::columns`] act), and the moved frame `T_j`. All lengths in m,
//! revolute joint values in rad, prismatic ones in m.
//!
//! ```
//! use nalgebra::Vector3;
//! use robcal::{Chain, Joint, JointKind};
//!
//! // A planar two-link arm, 1 m links, both joints about z.
//! let mut chain = Chain::<f64, 2>::new();
//! let z = Vector3::z();
//! chain.push(Joint::from_urdf(Vector3::zeros(), Vector3::zeros(), z, JointKind::Revolute).unwrap()).unwrap();
//! chain.push(Joint::from_urdf(Vector3::x(), Vector3::zeros(), z, JointKind::Revolute).unwrap()).unwrap();
//! let frames = chain.frames(&[core::f64::consts::FRAC_PI_2, 0.0]).unwrap();
//! let p = frames.point_m(&Vector3::x()); // a marker 1 m along x of the last frame
//! assert!((p - Vector3::new(0.0, 2.0, 0.0)).norm() < 1e-12);
//! ```

use nalgebra::{Isometry3, Point3, RealField, Unit, Vector3};

use super::chain::{Chain, JointKind};
use crate::error::Error;

/// One joint of a posed chain, in the base frame.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct JointFrame<T: RealField + Copy> {
    /// `Z_j = T_{j-1} · origin_j`: the joint's frame at zero joint value
    /// (translation in m). Joint-frame errors act on this frame.
    pub zero: Isometry3<T>,
    /// `T_j = Z_j · motion_j(q_j)`: the moved joint frame. Its origin is
    /// `oⱼ` \[m\] (for a revolute joint the same point as `Z_j`'s origin).
    pub frame: Isometry3<T>,
    /// `zⱼ`: the unit joint axis in the base frame.
    pub axis: Unit<Vector3<T>>,
    /// Revolute or prismatic.
    pub kind: JointKind,
    /// Whether the joint moves the tip (it is on the path from the base to
    /// the tip; every joint of a serial chain). A joint that does not — on
    /// another branch of a tree — has zero columns for a point on the tip.
    pub carries: bool,
}

impl<T: RealField + Copy> JointFrame<T> {
    /// `oⱼ` \[m\]: origin of the moved joint frame, in the base frame.
    pub fn origin_m(&self) -> Vector3<T> {
        self.frame.translation.vector
    }

    /// `∂p/∂qⱼ` \[m/rad or m/m\] of a point `p_m` \[m, base frame\] on the
    /// tip: `zⱼ × (p − oⱼ)` for a revolute joint, `zⱼ` for a prismatic one,
    /// zero for a joint that does not carry the tip ([`JointFrame::carries`]).
    /// This is the joint-offset column of eq. 2 and, times `τⱼ`, the
    /// compliance column of eq. 3.
    pub fn twist_column(&self, p_m: &Vector3<T>) -> Vector3<T> {
        if cfg!(feature = "tree") && !self.carries {
            return Vector3::zeros();
        }
        match self.kind {
            JointKind::Revolute => self.axis.cross(&(p_m - self.origin_m())),
            JointKind::Prismatic => self.axis.into_inner(),
        }
    }
}

/// The frames of a chain at one joint vector `q` (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Frames<T: RealField + Copy, const J: usize> {
    joints: heapless::Vec<JointFrame<T>, J>,
    q: heapless::Vec<T, J>,
    tip: Isometry3<T>,
}

impl<T: RealField + Copy, const J: usize> Frames<T, J> {
    /// No joint, the tip at the base: what [`Chain::frames_into`] fills.
    pub fn empty() -> Self {
        Self {
            joints: heapless::Vec::new(),
            q: heapless::Vec::new(),
            tip: Isometry3::identity(),
        }
    }

    /// The joint frames, base to tip.
    pub fn joints(&self) -> &[JointFrame<T>] {
        &self.joints
    }

    /// Joint `j`'s frame.
    ///
    /// # Errors
    /// [`Error::OutOfRange`] when `j ≥ dof`.
    pub fn joint(&self, j: usize) -> Result<&JointFrame<T>, Error> {
        self.joints.get(j).ok_or(Error::OutOfRange {
            what: "joint",
            index: j,
            len: self.joints.len(),
        })
    }

    /// The joint values the frames were computed at.
    pub fn q(&self) -> &[T] {
        &self.q
    }

    /// `T_tip`: the tip frame in the base frame (translation in m).
    pub fn tip(&self) -> &Isometry3<T> {
        &self.tip
    }

    /// Position \[m, base frame\] of a marker given at `marker_m` \[m\] in the
    /// tip frame: `p = T_tip · m`.
    pub fn point_m(&self, marker_m: &Vector3<T>) -> Vector3<T> {
        self.tip.transform_point(&Point3::from(*marker_m)).coords
    }

    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }
}

impl<T: RealField + Copy, const J: usize> Chain<T, J> {
    /// Forward kinematics: every joint frame and the tip frame at joint
    /// values `q` (rad for revolute, m for prismatic joints).
    ///
    /// # Errors
    /// [`Error::Mismatch`] when `q.len() != dof`; [`Error::NonFinite`] when
    /// `q` holds NaN or ±∞.
    pub fn frames(&self, q: &[T]) -> Result<Frames<T, J>, Error> {
        let mut out = Frames::empty();
        self.frames_into(q, &mut out)?;
        Ok(out)
    }

    /// [`Chain::frames`] into `out` (its joints replaced): the same frames,
    /// without moving a [`Frames`] (room for `J` joints) on return, for a
    /// caller that evaluates many poses.
    ///
    /// # Errors
    /// As [`Chain::frames`]; `out` is unchanged on error.
    pub fn frames_into(&self, q: &[T], out: &mut Frames<T, J>) -> Result<(), Error> {
        if q.len() != self.dof() {
            return Err(Error::Mismatch {
                what: "joint vector length differs from the chain's dof",
            });
        }
        if !q.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite { what: "q" });
        }
        // The chain holds at most `J` joints and `q` is its length: the
        // pushes below cannot fail (mapped anyway), `out` is whole on return.
        let joints = &mut out.joints;
        joints.clear();
        for (j, (joint, &qj)) in self.joints().iter().zip(q).enumerate() {
            // Parents come before their children (`Chain::push_child`).
            let zero = match self.parent(j).and_then(|p| joints.get(p)) {
                Some(f) => f.frame * joint.origin,
                None => joint.origin,
            };
            let moved = zero * joint.motion(qj);
            let axis = Unit::new_normalize(zero.rotation * joint.axis.into_inner());
            // Capacity equals the chain's, so this cannot fail; map it anyway.
            joints
                .push(JointFrame {
                    zero,
                    frame: moved,
                    axis,
                    kind: joint.kind,
                    // Serial: every joint carries the tip.
                    carries: cfg!(not(feature = "tree")),
                })
                .map_err(|_| Error::CapacityExceeded {
                    what: "frames",
                    capacity: J,
                })?;
        }
        // The tip's path, walked up from its joint: one pass from the last
        // joint down, since a parent has the lower index.
        let tip_joint = self.tip_joint();
        let t = tip_joint
            .and_then(|j| joints.get(j))
            .map_or_else(Isometry3::identity, |f| f.frame);
        #[cfg(feature = "tree")]
        {
            let mut next = tip_joint;
            for (j, jf) in joints.iter_mut().enumerate().rev() {
                if next == Some(j) {
                    jf.carries = true;
                    next = self.parent(j);
                }
            }
        }
        out.q.clear();
        out.q
            .extend_from_slice(q)
            .map_err(|_| Error::CapacityExceeded {
                what: "frames",
                capacity: J,
            })?;
        out.tip = t * *self.tip();
        Ok(())
    }

    /// `T_tip` at joint values `q`.
    ///
    /// # Errors
    /// As [`Chain::frames`].
    pub fn tip_pose(&self, q: &[T]) -> Result<Isometry3<T>, Error> {
        Ok(*self.frames(q)?.tip())
    }

    /// Position \[m, base frame\] of a marker at `marker_m` \[m\] in the tip
    /// frame, at joint values `q`.
    ///
    /// # Errors
    /// As [`Chain::frames`].
    pub fn marker_m(&self, q: &[T], marker_m: &Vector3<T>) -> Result<Vector3<T>, Error> {
        Ok(self.frames(q)?.point_m(marker_m))
    }
}
