//! Kinematic chain: fixed origin transforms and joint axes (URDF
//! convention), revolute or prismatic joints, optional link inertia — a
//! serial chain, or a tree (data contract 7.1: markers on several links).
//!
//! A chain has at most `J` movable joints (a fixed capacity, as in
//! `heapless::Vec<_, J>`). Fixed joints of a URDF are folded into the origin
//! of the next movable joint; the fixed transforms after the last movable
//! joint form `tip` (the transform from the last joint frame to `tip_link`).
//!
//! Frames: joint `j`'s frame at joint value `q_j` is
//! `T_j = T_{p(j)} · origin_j · motion_j(q_j)`, with `p(j)` its parent joint
//! (`j − 1` in a serial chain; the base frame, identity, for a root joint)
//! and `motion_j` a rotation of `q_j` \[rad\] about `axis_j` (revolute) or a
//! translation of `q_j` \[m\] along it (prismatic). `T_tip = T_t · tip` with
//! `t` the joint the tip is fixed to (the last one pushed with
//! [`Chain::push`]). All lengths in metres.
//!
//! **Trees.** [`Chain::push_child`] hangs a joint from any earlier joint, so
//! joints are in topological order (a parent before its children). Only the
//! joints on the path from the base to the tip move the tip: their
//! [`crate::robot::JointFrame::carries`] is set, and every other joint's
//! columns are zero for a point on the tip. A tree with markers on several
//! links is one chain per marker link, all sharing the joints
//! (`Chain::with_tip`, `tree` feature): the parameters of a shared joint are one column.

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

/// Where a tip is fixed: a movable joint's frame (or the base frame) and the
/// fixed transform from it (see `Chain::with_tip`, `tree` feature).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct End<T: RealField + Copy> {
    /// The movable joint whose frame the tip is fixed to; `None`: the base.
    pub joint: Option<usize>,
    /// The transform from that frame to the tip frame (translation in m).
    pub origin: Isometry3<T>,
}

/// A chain of at most `J` movable joints from the base frame to the tip
/// frame (`tip_link`): serial, or a tree (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Chain<T: RealField + Copy, const J: usize> {
    joints: heapless::Vec<Joint<T>, J>,
    /// Each joint's parent joint plus one (0: the base frame).
    #[cfg(feature = "tree")]
    parents: heapless::Vec<u8, J>,
    /// The joint the tip is fixed to, plus one (0: the base frame).
    #[cfg(feature = "tree")]
    tip_parent: u8,
    tip: Isometry3<T>,
}

impl<T: RealField + Copy, const J: usize> Chain<T, J> {
    /// An empty chain whose tip frame is the base frame.
    pub fn new() -> Self {
        Self {
            joints: heapless::Vec::new(),
            #[cfg(feature = "tree")]
            parents: heapless::Vec::new(),
            #[cfg(feature = "tree")]
            tip_parent: 0,
            tip: Isometry3::identity(),
        }
    }

    /// Appends a movable joint after the tip's joint (serial: after the last
    /// one), and moves the tip onto it.
    ///
    /// # Errors
    /// [`crate::error::Error::CapacityExceeded`] when the chain already holds `J`
    /// joints (or 255); [`crate::error::Error::NonFinite`] when the joint holds a
    /// non-finite number. The chain is unchanged on error.
    pub fn push(&mut self, joint: Joint<T>) -> Result<(), crate::error::Error> {
        let parent = self.tip_joint();
        let _index = self.push_child(joint, parent)?;
        // `index + 1 ≤ 255`: `push_child` refuses more joints.
        #[cfg(feature = "tree")]
        {
            self.tip_parent = (_index + 1) as u8;
        }
        Ok(())
    }

    /// Appends a movable joint whose frame hangs from joint `parent`'s frame
    /// (`None`: from the base frame), leaving the tip where it is: a branch
    /// of a tree. Returns the new joint's index. Without the `tree` feature
    /// (a controller's build), only the serial `parent` (the last joint) is
    /// taken, and the tip follows it.
    ///
    /// # Errors
    /// As [`Chain::push`]; [`crate::error::Error::OutOfRange`] when `parent` is not
    /// a joint of the chain (without `tree`: not the last one). The chain is
    /// unchanged on error.
    pub fn push_child(
        &mut self,
        joint: Joint<T>,
        parent: Option<usize>,
    ) -> Result<usize, crate::error::Error> {
        let index = self.joints.len();
        if let Some(p) = parent {
            if p >= index || (cfg!(not(feature = "tree")) && p + 1 != index) {
                return Err(crate::error::Error::OutOfRange {
                    what: "parent joint",
                    index: p,
                    len: index,
                });
            }
        }
        if index >= J.min(255) {
            return Err(crate::error::Error::CapacityExceeded {
                what: "chain joints",
                capacity: J.min(255),
            });
        }
        let finite = joint
            .origin
            .translation
            .vector
            .iter()
            .all(|v| v.is_finite())
            && joint.origin.rotation.coords.iter().all(|v| v.is_finite())
            && joint.axis.iter().all(|v| v.is_finite())
            && joint
                .link
                .is_none_or(|l| l.mass_kg.is_finite() && l.com_m.iter().all(|v| v.is_finite()));
        if !finite {
            return Err(crate::error::Error::NonFinite { what: "joint" });
        }
        #[cfg(feature = "tree")]
        {
            let full = |_| crate::error::Error::CapacityExceeded {
                what: "chain joints",
                capacity: J,
            };
            // Both have room: `index < J`.
            self.parents
                .push(parent.map_or(0, |p| (p + 1) as u8))
                .map_err(full)?;
        }
        #[cfg(not(feature = "tree"))]
        if parent.is_none() && index > 0 {
            return Err(crate::error::Error::OutOfRange {
                what: "parent joint",
                index: 0,
                len: index,
            });
        }
        self.joints
            .push(joint)
            .map_err(|_| crate::error::Error::CapacityExceeded {
                what: "chain joints",
                capacity: J,
            })?;
        Ok(index)
    }

    /// Sets the fixed transform from the tip's joint frame to the tip frame.
    pub fn set_tip(&mut self, tip: Isometry3<T>) {
        self.tip = tip;
    }

    /// The same chain with its tip at `end`: the chain of one marker link of
    /// a tree (see the [module docs](self); the `tree` feature).
    ///
    /// # Errors
    /// [`crate::error::Error::OutOfRange`] when `end.joint` is not a joint of the
    /// chain; [`crate::error::Error::NonFinite`] for a non-finite transform.
    #[cfg(feature = "tree")]
    pub fn with_tip(&self, end: &End<T>) -> Result<Self, crate::error::Error> {
        if let Some(j) = end.joint {
            if j >= self.dof() {
                return Err(crate::error::Error::OutOfRange {
                    what: "tip joint",
                    index: j,
                    len: self.dof(),
                });
            }
        }
        let o = &end.origin;
        if !(o.translation.vector.iter().all(|v| v.is_finite())
            && o.rotation.coords.iter().all(|v| v.is_finite()))
        {
            return Err(crate::error::Error::NonFinite { what: "tip" });
        }
        let mut c = self.clone();
        // `j < dof ≤ 255`.
        c.tip_parent = end.joint.map_or(0, |j| (j + 1) as u8);
        c.tip = end.origin;
        Ok(c)
    }

    /// Where the tip is fixed.
    pub fn tip_end(&self) -> End<T> {
        End {
            joint: self.tip_joint(),
            origin: self.tip,
        }
    }

    /// The joint the tip is fixed to (`None`: the base frame).
    pub fn tip_joint(&self) -> Option<usize> {
        #[cfg(feature = "tree")]
        return usize::from(self.tip_parent).checked_sub(1);
        #[cfg(not(feature = "tree"))]
        return self.joints.len().checked_sub(1);
    }

    /// Joint `j`'s parent joint (`None`: the base frame, or no joint `j`).
    pub fn parent(&self, j: usize) -> Option<usize> {
        #[cfg(feature = "tree")]
        return self
            .parents
            .get(j)
            .and_then(|&p| usize::from(p).checked_sub(1));
        #[cfg(not(feature = "tree"))]
        return j.checked_sub(1).filter(|_| j < self.joints.len());
    }

    /// Whether every joint hangs from the one before it (a serial chain).
    pub fn is_serial(&self) -> bool {
        #[cfg(feature = "tree")]
        return self
            .parents
            .iter()
            .enumerate()
            .all(|(j, &p)| usize::from(p) == j);
        #[cfg(not(feature = "tree"))]
        return true;
    }

    /// Joint `j` and the joints it hangs from, up to the base (`j` first):
    /// the joints that move a point fixed to joint `j`'s frame.
    pub fn path(&self, j: Option<usize>) -> Path<'_> {
        Path {
            #[cfg(feature = "tree")]
            parents: &self.parents,
            next: j.filter(|&j| j < self.joints.len()),
            #[cfg(not(feature = "tree"))]
            _chain: core::marker::PhantomData,
        }
    }

    /// The chain with its base placed by `base`: every root joint's origin
    /// (and a tip fixed to the base) premultiplied by it, so that frames of
    /// the result are in the frame `base` is given in.
    pub fn placed(&self, base: &Isometry3<T>) -> Self {
        let mut c = self.clone();
        for (j, joint) in c.joints.iter_mut().enumerate() {
            if self.parent(j).is_none() {
                joint.origin = base * joint.origin;
            }
        }
        if self.tip_joint().is_none() {
            c.tip = base * c.tip;
        }
        c
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

/// The joints from one joint up to the base ([`Chain::path`]).
#[derive(Debug, Clone)]
pub struct Path<'a> {
    #[cfg(feature = "tree")]
    parents: &'a [u8],
    next: Option<usize>,
    #[cfg(not(feature = "tree"))]
    _chain: core::marker::PhantomData<&'a ()>,
}

impl Iterator for Path<'_> {
    type Item = usize;

    fn next(&mut self) -> Option<usize> {
        let j = self.next?;
        // Parents come before their children (`Chain::push_child` checks
        // it), so this ends.
        #[cfg(feature = "tree")]
        {
            self.next = usize::from(*self.parents.get(j)?).checked_sub(1);
        }
        #[cfg(not(feature = "tree"))]
        {
            self.next = j.checked_sub(1);
        }
        Some(j)
    }
}

impl<T: RealField + Copy, const J: usize> Default for Chain<T, J> {
    fn default() -> Self {
        Self::new()
    }
}
