//! The one parameter vocabulary of robcal: every column of `B = [J  A]`
//! (eq. 4) and of the effect library, its unit and the SI value of that
//! unit. The firmware's [`super::Layout`] and the host calibration name
//! their parameters with the same [`Param`].
//!
//! Parameters are estimated **in the reported unit**: column `i` of `B` is
//! `∂p [m] / ∂xᵢ [unit]`, so an estimate is directly in `mm`, `mrad`,
//! `urad/(N*m)`, … and its scale is moderate (a compliance of
//! 0.3 µrad/(N·m) is 0.3, not 3e-7); `x_SI = si · x` ([`Unit::si`]).
//!
//! | parameter | unit (revolute / prismatic joint) | `si` | eq. |
//! |---|---|---|---|
//! | [`Param::JointOffset`], [`Param::Backlash`], [`Param::GearCyclic`], `Param::GravityCompliance` (`std`) | `mrad` / `mm` | 1e-3 | 2 |
//! | [`Param::JointFrame`], [`Param::Base`], [`Param::Tool`]: translation / rotation | `mm` / `mrad` | 1e-3 | 2 |
//! | [`Param::Marker`], [`Param::LoadCom`] | `mm` | 1e-3 | 2 |
//! | [`Param::Compliance`], [`Param::ComplianceAt`] | `urad/(N*m)` / `um/N` | 1e-6 | 3 |
//! | [`Param::LinkCompliance`] | `urad/(N*m)` | 1e-6 | |
//! | [`Param::NonlinearStiffness`] | `urad/(kN*m)^2` / `um/kN^2` | 1e-12 | |
//! | [`Param::Drift`] | `um/s` | 1e-6 | |
//! | `Param::LinkMass` (`std`) | `kg` | 1 | |
//! | `Param::ThermalExpansion` (`std`) | `um/(m*K)` | 1e-6 | |
//!
//! Joint indices count the chain's movable joints from the base, from 0;
//! marker indices count the markers of the job (or of the layout), from 0.

use core::fmt;

use crate::robot::JointKind;

/// Half-width \[rad\] of an angle bin of [`Param::ComplianceAt`]: a sample
/// is in the bin when its joint value is within this of the bin's angle
/// (1e-3 rad ≈ 0.06°, far below the spacing of a compensator's angles and
/// far above a controller's rounding of a commanded angle).
pub const BIN_TOLERANCE_RAD: f64 = 1e-3;

/// Names of the six components of a frame error: translation x, y, z,
/// then small rotation about x, y, z.
pub const POSE_COMPONENTS: [&str; 6] = ["tx", "ty", "tz", "rx", "ry", "rz"];
/// Names of the three components of a vector.
pub const XYZ: [&str; 3] = ["x", "y", "z"];

/// What one parameter is. See the [module docs](self) for units.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Param {
    /// Zero offset `δqⱼ` added to joint `j`'s value (eq. 2).
    JointOffset {
        /// Joint index.
        joint: u8,
    },
    /// One of the six components of a joint-frame error, in the joint's own
    /// frame at zero joint value ([`super::columns`]).
    JointFrame {
        /// Joint index.
        joint: u8,
        /// 0..6: tx, ty, tz, rx, ry, rz.
        axis: u8,
    },
    /// One of the six components of the base pose in the measurement frame.
    Base {
        /// 0..6: tx, ty, tz, rx, ry, rz.
        axis: u8,
    },
    /// One of the six components of the tool frame's error: a small rigid
    /// motion `E` of everything fixed to the tip link, in the tip frame
    /// (every marker `r ← E r`). It carries points never measured in a
    /// calibration pose (a test point, a tool centre point) with the ones
    /// that were, which per-marker positions ([`Param::Marker`]) cannot.
    Tool {
        /// 0..6: tx, ty, tz, rx, ry, rz.
        axis: u8,
    },
    /// One coordinate of a marker's position in the tip frame.
    Marker {
        /// Marker index.
        marker: u8,
        /// 0..3: x, y, z.
        axis: u8,
    },
    /// Compliance `kⱼ` of a joint (eq. 3): `δqⱼ = kⱼ τⱼ`.
    Compliance {
        /// Joint index.
        joint: u8,
    },
    /// Compliance of a joint that holds only while that joint is at one
    /// angle (the gravity compensator of the KR-270's A2: `k21…k25`,
    /// section 5): non-zero only for samples within [`BIN_TOLERANCE_RAD`]
    /// of the angle.
    ComplianceAt {
        /// Joint index.
        joint: u8,
        /// The bin's joint angle \[µrad\] ([`angle_urad`]).
        angle_urad: i32,
    },
    /// A joint's deflection not linear in its torque: `δqⱼ += k2ⱼ τⱼ|τⱼ|`.
    NonlinearStiffness {
        /// Joint index.
        joint: u8,
    },
    /// Free play: `δqⱼ += bⱼ sign(τⱼ)`, the joint resting on the side its
    /// torque pushes it to.
    Backlash {
        /// Joint index.
        joint: u8,
    },
    /// The link after joint `j` bends about the axes normal to the joint's
    /// in proportion to the moment there of what it carries: the load's
    /// (a deflection) or the robot's own weight (an absolute position;
    /// host only, `std`).
    LinkCompliance {
        /// Joint index.
        joint: u8,
    },
    /// Shift of the load's centre of mass along a tip-frame axis,
    /// linearised about the current compliances.
    LoadCom {
        /// 0..3: x, y, z of the tip frame.
        axis: u8,
    },
    /// Linear drift of the measurement along a measurement-frame axis.
    Drift {
        /// 0..3: x, y, z.
        axis: u8,
    },
    /// First-harmonic cyclic error of a joint: `δqⱼ = s sin qⱼ + c cos qⱼ`.
    GearCyclic {
        /// Joint index.
        joint: u8,
        /// `false`: the sine's amplitude `s`; `true`: the cosine's `c`.
        cos: bool,
    },
    /// A joint bending under the robot's own weight, the masses unknown
    /// (lumped gravity compliance): everything outboard of joint `j` as one
    /// rigid body (mass `m`, centre of mass `u` fixed in joint `j`'s moved
    /// frame), `τⱼ = m u · Rⱼᵀ(g × ẑⱼ)`, so `δqⱼ = kⱼ τⱼ` is linear in the
    /// two components of `Rⱼᵀ ĝ` perpendicular to the joint's axis:
    /// `δqⱼ = x_a (Rⱼᵀĝ · aⱼ) + x_b (Rⱼᵀĝ · bⱼ)` with `ĝ` the unit gravity
    /// direction, `Rⱼ` joint `j`'s frame at the commanded pose (its own
    /// rotation included) and `(aⱼ, bⱼ, ẑⱼ)` a right-handed basis of that
    /// frame ([`super::gravity_basis`]). `x_a` is the deflection when
    /// gravity points along `aⱼ`; `|x| = kⱼ m |g| |u⊥|` the largest the
    /// weight can make (reported in mrad). Host only (`std`): it needs
    /// absolute rows and the host's Gauss–Newton, and a controller's image
    /// has no room for it.
    #[cfg(feature = "std")]
    GravityCompliance {
        /// Joint index.
        joint: u8,
        /// `false`: the coefficient `x_a` of `aⱼ`; `true`: `x_b` of `bⱼ`.
        b: bool,
    },
    /// The mass of joint `j`'s moving body (the link after it and what is
    /// fixed to it) \[kg\], at its centre of mass (the URDF's, or the joint
    /// frame's origin for an assumed mass): the robot's own weight loads
    /// the joints that carry it, so it acts through their compliances and
    /// their links' bending, bilinear in them. Estimated by the host's
    /// Gauss–Newton as the geometry is (steps applied to the model), its
    /// column at the current compliances. Host only (`std`).
    #[cfg(feature = "std")]
    LinkMass {
        /// Joint index.
        joint: u8,
    },
    /// The links' thermal expansion: every length from the first joint's
    /// origin out (the joints' offsets, the tool, the markers) grows by
    /// `α ΔT`, `ΔT` the point's temperature over the data's mean (the
    /// setup's temperature column), so the marker moves by
    /// `α ΔT (p − o₁)`, `o₁` the first joint's origin. One coefficient `α`
    /// \[1/K\] for the arm (steel 12, aluminium 23 µm/(m·K)). Host only
    /// (`std`).
    #[cfg(feature = "std")]
    ThermalExpansion,
}

/// The unit a parameter is estimated and reported in, and its SI value.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Unit {
    /// Its name (`"mm"`, `"mrad"`, `"urad/(N*m)"`, …).
    pub name: &'static str,
    /// SI value of one unit: `x_SI = si · x` (m, rad, rad/(N·m), m/N, …).
    pub si: f64,
}

const MM: Unit = Unit {
    name: "mm",
    si: 1e-3,
};
const MRAD: Unit = Unit {
    name: "mrad",
    si: 1e-3,
};

impl Param {
    /// The joint the parameter belongs to, if any.
    pub fn joint(&self) -> Option<u8> {
        match *self {
            Param::JointOffset { joint }
            | Param::JointFrame { joint, .. }
            | Param::Compliance { joint }
            | Param::ComplianceAt { joint, .. }
            | Param::NonlinearStiffness { joint }
            | Param::Backlash { joint }
            | Param::LinkCompliance { joint }
            | Param::GearCyclic { joint, .. } => Some(joint),
            #[cfg(feature = "std")]
            Param::GravityCompliance { joint, .. } | Param::LinkMass { joint } => Some(joint),
            Param::Base { .. }
            | Param::Tool { .. }
            | Param::Marker { .. }
            | Param::LoadCom { .. }
            | Param::Drift { .. } => None,
            #[cfg(feature = "std")]
            Param::ThermalExpansion => None,
        }
    }

    /// Whether the parameter is geometric (eq. 2): it changes the model's
    /// frames, and a fit applies it to the model (Gauss–Newton) rather than
    /// keeping it as a column value.
    pub fn is_geometric(&self) -> bool {
        matches!(
            self,
            Param::JointOffset { .. }
                | Param::JointFrame { .. }
                | Param::Base { .. }
                | Param::Tool { .. }
                | Param::Marker { .. }
        )
    }

    /// Whether the host's Gauss–Newton applies the parameter's estimate
    /// to the model as a step and evaluates the rows again there (its
    /// estimate then the step's size): the geometric parameters and
    /// (`std`) a link's mass.
    pub fn is_stepped(&self) -> bool {
        #[cfg(feature = "std")]
        if matches!(self, Param::LinkMass { .. }) {
            return true;
        }
        self.is_geometric()
    }

    /// Whether the parameter is a compliance of the declared kind (`k_<joint>`
    /// or `k_<joint>@<angle>`).
    pub fn is_compliance(&self) -> bool {
        matches!(self, Param::Compliance { .. } | Param::ComplianceAt { .. })
    }

    /// Its unit, given the kind of its joint (ignored for parameters
    /// without a joint). See the [module docs](self).
    pub fn unit(&self, joint_kind: JointKind) -> Unit {
        let prismatic = joint_kind == JointKind::Prismatic && self.joint().is_some();
        match *self {
            Param::JointOffset { .. } | Param::Backlash { .. } | Param::GearCyclic { .. } => {
                if prismatic {
                    MM
                } else {
                    MRAD
                }
            }
            #[cfg(feature = "std")]
            Param::GravityCompliance { .. } => {
                if prismatic {
                    MM
                } else {
                    MRAD
                }
            }
            Param::JointFrame { axis, .. } | Param::Base { axis } | Param::Tool { axis } => {
                if axis < 3 {
                    MM
                } else {
                    MRAD
                }
            }
            Param::Marker { .. } | Param::LoadCom { .. } => MM,
            Param::Compliance { .. } | Param::ComplianceAt { .. } => Unit {
                name: if prismatic { "um/N" } else { "urad/(N*m)" },
                si: 1e-6,
            },
            Param::LinkCompliance { .. } => Unit {
                name: "urad/(N*m)",
                si: 1e-6,
            },
            Param::NonlinearStiffness { .. } => Unit {
                name: if prismatic {
                    "um/kN^2"
                } else {
                    "urad/(kN*m)^2"
                },
                si: 1e-12,
            },
            Param::Drift { .. } => Unit {
                name: "um/s",
                si: 1e-6,
            },
            #[cfg(feature = "std")]
            Param::LinkMass { .. } => Unit {
                name: "kg",
                si: 1.0,
            },
            #[cfg(feature = "std")]
            Param::ThermalExpansion => Unit {
                name: "um/(m*K)",
                si: 1e-6,
            },
        }
    }

    /// The component's name, the part of a parameter's name after its
    /// joint, marker or effect: `offset`, `tx`…`rz`, `x`…`z`, `sin`, `cos`,
    /// `a`, `b`;
    /// empty for a one-parameter effect.
    pub fn component(&self) -> &'static str {
        let six = |a: u8| POSE_COMPONENTS.get(usize::from(a)).copied().unwrap_or("?");
        let xyz = |a: u8| XYZ.get(usize::from(a)).copied().unwrap_or("?");
        match *self {
            Param::JointOffset { .. } => "offset",
            Param::JointFrame { axis, .. } | Param::Base { axis } | Param::Tool { axis } => {
                six(axis)
            }
            Param::Marker { axis, .. } | Param::LoadCom { axis } | Param::Drift { axis } => {
                xyz(axis)
            }
            Param::GearCyclic { cos, .. } => {
                if cos {
                    "cos"
                } else {
                    "sin"
                }
            }
            #[cfg(feature = "std")]
            Param::GravityCompliance { b, .. } => {
                if b {
                    "b"
                } else {
                    "a"
                }
            }
            Param::Compliance { .. }
            | Param::ComplianceAt { .. }
            | Param::NonlinearStiffness { .. }
            | Param::Backlash { .. }
            | Param::LinkCompliance { .. } => "",
            #[cfg(feature = "std")]
            Param::LinkMass { .. } | Param::ThermalExpansion => "",
        }
    }

    /// The bin angle \[rad\] of a [`Param::ComplianceAt`].
    pub fn bin_angle_rad(&self) -> Option<f64> {
        match *self {
            Param::ComplianceAt { angle_urad, .. } => Some(f64::from(angle_urad) * 1e-6),
            _ => None,
        }
    }
}

/// Generic names with joint and marker indices (`j2.offset`, `k_j1`,
/// `k_j1@-25.24deg`, `marker0.x`, `backlash_j4`); the host names them after
/// the URDF's joints and the setup's markers instead.
impl fmt::Display for Param {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = self.component();
        match *self {
            Param::JointOffset { joint } | Param::JointFrame { joint, .. } => {
                write!(f, "j{joint}.{c}")
            }
            Param::Base { .. } => write!(f, "base.{c}"),
            Param::Tool { .. } => write!(f, "tool.{c}"),
            Param::Marker { marker, .. } => write!(f, "marker{marker}.{c}"),
            Param::Compliance { joint } => write!(f, "k_j{joint}"),
            Param::ComplianceAt { joint, angle_urad } => write!(
                f,
                "k_j{joint}@{:.2}deg",
                f64::from(angle_urad) * 1e-6 * 180.0 / core::f64::consts::PI
            ),
            Param::NonlinearStiffness { joint } => write!(f, "nonlinear_stiffness_j{joint}"),
            Param::Backlash { joint } => write!(f, "backlash_j{joint}"),
            Param::LinkCompliance { joint } => write!(f, "link_compliance_j{joint}"),
            Param::LoadCom { .. } => write!(f, "load_com_{c}"),
            Param::Drift { .. } => write!(f, "drift_{c}"),
            Param::GearCyclic { joint, .. } => write!(f, "gear_cyclic_j{joint}.{c}"),
            #[cfg(feature = "std")]
            Param::GravityCompliance { joint, .. } => {
                write!(f, "gravity_compliance_j{joint}.{c}")
            }
            #[cfg(feature = "std")]
            Param::LinkMass { joint } => write!(f, "link_mass_j{joint}"),
            #[cfg(feature = "std")]
            Param::ThermalExpansion => write!(f, "thermal_expansion"),
        }
    }
}

/// Angle \[rad\] → the `angle_urad` of a [`Param::ComplianceAt`] (rounded to
/// the nearest µrad; saturates outside ±2147 rad).
pub fn angle_urad(angle_rad: f64) -> i32 {
    let v = libm::round(angle_rad * 1e6);
    if v >= f64::from(i32::MAX) {
        i32::MAX
    } else if v <= f64::from(i32::MIN) {
        i32::MIN
    } else {
        v as i32
    }
}
