//! The robot (`no_std`): a serial chain of revolute and prismatic joints
//! (URDF convention), its forward kinematics, and the loads on it.
//!
//! | module | what |
//! |---|---|
//! | [`chain`] | [`Chain`], [`Joint`] (with the one [`Joint::motion`]), [`LinkInertia`] |
//! | [`kinematics`] | [`Frames`]: joint frames, axes and origins, marker positions |
//! | [`load`] | [`Wrench`], [`PointLoad`], the joint torques of a load and of the robot's own weight |
//! | [`equilibrium`](mod@equilibrium) | the deflected pose of a loaded chain whose joints yield (eq. 3 solved exactly) and its sensitivity |
//! | [`compensate`](mod@compensate) | the joint command whose loaded, deflected robot reaches a desired point (Newton on the exact model) |
//!
//! All lengths in metres, revolute joint values in radians, prismatic ones
//! in metres, torques in N·m (N for a prismatic joint).

pub mod chain;
pub mod compensate;
pub mod equilibrium;
pub mod kinematics;
pub mod load;

pub use chain::{Chain, End, Joint, JointKind, LinkInertia, Path};
pub use compensate::{compensate, compensate_pose, CompensateSettings, Compensation, Compliances};
pub use equilibrium::{equilibrium, Equilibrium, EquilibriumSettings, JointLaw, Loading};
pub use kinematics::{Frames, JointFrame};
pub use load::{gravity_moments, gravity_torques, joint_torques, PointLoad, Wrench};
