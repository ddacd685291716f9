//! Serial kinematic chain: fixed origin transforms and joint axes (URDF
//! convention), revolute or prismatic joints, optional link inertia.
//!
//! A chain has at most `J` movable joints (a fixed capacity, as in
//! `heapless::Vec<_, J>`). Fixed joints of a URDF are folded into the origin
//! of the next movable joint; the fixed transforms after the last movable
//! joint form `tip` (the transform from the last joint frame to `tip_link`).
//!
//! Frames: joint `j`'s frame at joint value `q_j` is
//! `T_j = T_{j-1} · origin_j · motion_j(q_j)`, with `motion_j` a rotation of
//! `q_j` \[rad\] about `axis_j` (revolute) or a translation of `q_j` \[m\] along
//! it (prismatic). `T_tip = T_last · tip`. All lengths in metres.

use nalgebra::{Isometry3, RealField, Translation3, Unit, UnitQuaternion, Vector3};

/// How a joint moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum JointKind {
    /// Rotation about the axis; joint value in rad.
    Revolute,
    /// Translation along the axis; joint value in m.
    Prismatic,
}

/// Mass properties of the link a joint carries (its child link, with every
/// link fixed to it folded in).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LinkInertia<T: RealField + Copy> {
    /// Mass \[kg\].
    pub mass_kg: T,
    /// Centre of mass \[m\], in the joint's (child) frame.
    pub com_m: Vector3<T>,
}

/// One movable joint.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Joint<T: RealField + Copy> {
    /// Transform from the previous joint frame (or the base) to this joint's
    /// frame at zero joint value (URDF `<origin xyz rpy>`, fixed joints before
    /// it folded in). Translation in m.
    pub origin: Isometry3<T>,
    /// Unit axis in this joint's frame (URDF `<axis>`).
    pub axis: Unit<Vector3<T>>,
    /// Revolute or prismatic.
    pub kind: JointKind,
    /// Mass properties of the child link, if known.
    pub link: Option<LinkInertia<T>>,
}

impl<T: RealField + Copy> Joint<T> {
    /// A joint from URDF-style data: origin `xyz` \[m\] and `rpy` \[rad\] (fixed
    /// X-Y-Z angles, `R = Rz(y)·Ry(p)·Rx(r)`), an axis (normalised here).
    /// Returns `None` when the axis is zero or not finite.
    pub fn from_urdf(
        xyz_m: Vector3<T>,
        rpy_rad: Vector3<T>,
        axis: Vector3<T>,
        kind: JointKind,
    ) -> Option<Self> {
        let axis = Unit::try_new(axis, T::default_epsilon())?;
        let rotation = nalgebra::UnitQuaternion::from_euler_angles(rpy_rad.x, rpy_rad.y, rpy_rad.z);
        Some(Self {
            origin: Isometry3::from_parts(xyz_m.into(), rotation),
            axis,
            kind,
            link: None,
        })
    }

    /// `motion_j(q)`: the joint's own motion at value `q` — a rotation of
    /// `q` \[rad\] about the axis (revolute) or a translation of `q` \[m\]
    /// along it (prismatic). The joint frame is `T_j = T_{j-1} · origin_j ·
    /// motion_j(q_j)`; a joint offset `δq` is the same motion applied to the
    /// origin, `origin_j · motion_j(δq)`.
    pub fn motion(&self, q: T) -> Isometry3<T> {
        match self.kind {
            JointKind::Revolute => Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_axis_angle(&self.axis, q),
            ),
            JointKind::Prismatic => Isometry3::from_parts(
                Translation3::from(self.axis.into_inner() * q),
                UnitQuaternion::identity(),
            ),
        }
    }
}

/// A serial chain of at most `J` movable joints from the base frame to the
/// tip frame (`tip_link`).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Chain<T: RealField + Copy, const J: usize> {
    joints: heapless::Vec<Joint<T>, J>,
    tip: Isometry3<T>,
}

impl<T: RealField + Copy, const J: usize> Chain<T, J> {
    /// An empty chain whose tip frame is the base frame.
    pub fn new() -> Self {
        Self {
            joints: heapless::Vec::new(),
            tip: Isometry3::identity(),
        }
    }

    /// Appends a movable joint.
    ///
    /// # Errors
    /// [`crate::Error::CapacityExceeded`] when the chain already holds `J` joints;
    /// [`crate::Error::NonFinite`] when the joint holds a non-finite number. The
    /// chain is unchanged on error.
    pub fn push(&mut self, joint: Joint<T>) -> Result<(), crate::Error> {
        let finite = joint
            .origin
            .translation
            .vector
            .iter()
            .all(|v| v.is_finite())
            && joint.origin.rotation.coords.iter().all(|v| v.is_finite())
            && joint.axis.iter().all(|v| v.is_finite())
            && joint.link.map_or(true, |l| {
                l.mass_kg.is_finite() && l.com_m.iter().all(|v| v.is_finite())
            });
        if !finite {
            return Err(crate::Error::NonFinite { what: "joint" });
        }
        self.joints
            .push(joint)
            .map_err(|_| crate::Error::CapacityExceeded {
                what: "chain joints",
                capacity: J,
            })
    }

    /// Sets the fixed transform from the last joint frame to the tip frame.
    pub fn set_tip(&mut self, tip: Isometry3<T>) {
        self.tip = tip;
    }

    /// The movable joints, base to tip.
    pub fn joints(&self) -> &[Joint<T>] {
        &self.joints
    }

    /// Mutable access to the joints (e.g. to attach link inertia).
    pub fn joints_mut(&mut self) -> &mut [Joint<T>] {
        &mut self.joints
    }

    /// The fixed transform from the last joint frame to the tip frame.
    pub fn tip(&self) -> &Isometry3<T> {
        &self.tip
    }

    /// Number of movable joints.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }
}

impl<T: RealField + Copy, const J: usize> Default for Chain<T, J> {
    fn default() -> Self {
        Self::new()
    }
}
