//! The columns a host calibration can estimate: the declared model's
//! parameters and every effect of the library, each a [`Term`] whose
//! regressor is computed from what one row carries (pose, load, marker,
//! time).
//!
//! Columns are in the reported unit, as in [`crate::layout`]: column `i` is
//! `∂p [m] / ∂xᵢ [unit]`, `x_SI = si_per_unit · x`.

use nalgebra::Vector3;

use crate::chain::JointKind;
use crate::geometric;
use crate::kinematics::Frames;

/// Joint capacity of the host chain ([`crate::io::MAX_JOINTS`]).
pub(crate) const J: usize = crate::io::MAX_JOINTS;

/// What one row of the problem is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowKind {
    /// Loaded minus unloaded position of one marker (elastostatic, eq. 3):
    /// only the load's torques enter.
    Deflection,
    /// Unloaded position minus its nominal forward kinematics (geometric,
    /// eq. 2); the robot's own weight loads the joints.
    Absolute,
}

/// One row (three equations) of the identification problem.
#[derive(Debug, Clone)]
pub struct Row {
    /// Deflection or absolute position.
    pub kind: RowKind,
    /// Index of the configuration (IRLS group).
    pub group: usize,
    /// `config` as in the CSV.
    pub config: i64,
    /// Marker id.
    pub marker: u32,
    /// Load \[kg\] (0 for absolute rows).
    pub load_kg: f64,
    /// Joint values \[rad or m\].
    pub q: Vec<f64>,
    /// Frames at `q` in the current model ([`super::Geometry`]).
    pub frames: Frames<f64, J>,
    /// Predicted marker position \[m, measurement frame\] at `q`.
    pub p: Vector3<f64>,
    /// Joint torques behind the row: the load's (deflection rows) or the
    /// links' own weight (absolute rows) \[N·m or N\].
    pub tau: Vec<f64>,
    /// The load's weight `m g` \[N\] and where it acts \[m\] (deflection rows).
    pub load_force: Option<(Vector3<f64>, Vector3<f64>)>,
    /// Time \[s\] relative to the data's mean time (absolute rows) or between
    /// the unloaded and the loaded measurement (deflection rows).
    pub dt: Option<f64>,
    /// `Δp` \[m\]: measured minus predicted at the current model (absolute
    /// rows), or the measured deflection.
    pub y: Vector3<f64>,
    /// What was measured \[m\]: the position (absolute rows, measurement
    /// frame) or the deflection.
    pub measured: Vector3<f64>,
    /// CSV line (of the loaded row for deflections).
    pub line: usize,
}

/// One distinct angle of a joint (a compensator bin).
#[derive(Debug, Clone, PartialEq)]
pub struct Bin {
    /// Centre \[rad\].
    pub angle: f64,
    /// As written in the CSV (for the parameter's name).
    pub written: String,
}

/// One estimable column.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Term {
    /// Compliance `kⱼ` (`k_<joint>`).
    Compliance(usize),
    /// Compliance of joint `j` while it is in angle bin `b` (`k_<joint>@<angle>`).
    ComplianceAt(usize, usize),
    /// `δqⱼ += k2ⱼ τⱼ|τⱼ|` (`nonlinear_stiffness_<joint>`).
    NonlinearStiffness(usize),
    /// `δqⱼ += bⱼ sign(τⱼ)` (`backlash_<joint>`).
    Backlash(usize),
    /// The link after joint `j` bends (rotates about the axes normal to the
    /// joint's) in proportion to the load's moment there (`link_compliance_<joint>`).
    LinkCompliance(usize),
    /// Shift of the load's centre of mass along tip axis `a` (`load_com_<x|y|z>`),
    /// linearised about the current compliances.
    LoadCom(usize),
    /// Linear drift of the measurement along base axis `a` (`drift_<x|y|z>`).
    Drift(usize),
    /// Zero offset of joint `j` (`<joint>.offset`).
    JointOffset(usize),
    /// Joint-frame error component `a` (tx..rz) of joint `j` (`<joint>.<tx..rz>`).
    JointFrame(usize, usize),
    /// Base pose component `a` (`base.<tx..rz>`).
    Base(usize),
    /// Marker position component `a` (`marker<id>.<x|y|z>`), marker index `m`.
    Marker(usize, usize),
    /// First-harmonic cyclic error of joint `j`: `δqⱼ = s sin qⱼ + c cos qⱼ`
    /// (`gear_cyclic_<joint>.sin` / `.cos`); `true` for the cosine.
    GearCyclic(usize, bool),
}

const SIX: [&str; 6] = ["tx", "ty", "tz", "rx", "ry", "rz"];
const XYZ: [&str; 3] = ["x", "y", "z"];

/// What the columns need besides a row: names, bins and the current
/// compliances (for the linearised `load_com`).
#[derive(Debug, Clone)]
pub struct Context {
    /// Movable joint names.
    pub joint_names: Vec<String>,
    /// Joint kinds.
    pub joint_kinds: Vec<JointKind>,
    /// Marker ids and nominal positions \[m, tip frame\].
    pub markers: Vec<(u32, Vector3<f64>)>,
    /// Distinct angles per joint (empty when the joint takes too many).
    pub bins: Vec<Vec<Bin>>,
    /// Half-width of a bin \[rad\].
    pub bin_tolerance: f64,
    /// Current compliance estimate \[rad/(N·m)\] per joint (constant part).
    pub k: Vec<f64>,
    /// Current compliance estimate \[rad/(N·m)\] per joint and bin.
    pub k_bins: Vec<Vec<f64>>,
}

impl Context {
    /// Bin of joint `j` at value `qj`, if any.
    pub fn bin_of(&self, j: usize, qj: f64) -> Option<usize> {
        self.bins
            .get(j)?
            .iter()
            .position(|b| (b.angle - qj).abs() <= self.bin_tolerance)
    }

    /// The parameter's name (data contract §5).
    pub fn name(&self, t: &Term) -> String {
        let jn = |j: usize| self.joint_names[j].as_str();
        match *t {
            Term::Compliance(j) => format!("k_{}", jn(j)),
            Term::ComplianceAt(j, b) => format!("k_{}@{}", jn(j), self.bins[j][b].written),
            Term::NonlinearStiffness(j) => format!("nonlinear_stiffness_{}", jn(j)),
            Term::Backlash(j) => format!("backlash_{}", jn(j)),
            Term::LinkCompliance(j) => format!("link_compliance_{}", jn(j)),
            Term::LoadCom(a) => format!("load_com_{}", XYZ[a]),
            Term::Drift(a) => format!("drift_{}", XYZ[a]),
            Term::JointOffset(j) => format!("{}.offset", jn(j)),
            Term::JointFrame(j, a) => format!("{}.{}", jn(j), SIX[a]),
            Term::Base(a) => format!("base.{}", SIX[a]),
            Term::Marker(m, a) => format!("marker{}.{}", self.markers[m].0, XYZ[a]),
            Term::GearCyclic(j, c) => {
                format!("gear_cyclic_{}.{}", jn(j), if c { "cos" } else { "sin" })
            }
        }
    }

    /// Unit of the estimate and its SI value.
    pub fn unit(&self, t: &Term) -> (&'static str, f64) {
        let prismatic = |j: usize| self.joint_kinds[j] == JointKind::Prismatic;
        match *t {
            Term::Compliance(j) | Term::ComplianceAt(j, _) | Term::LinkCompliance(j) => {
                if prismatic(j) && !matches!(t, Term::LinkCompliance(_)) {
                    ("um/N", 1e-6)
                } else {
                    ("urad/(N*m)", 1e-6)
                }
            }
            Term::NonlinearStiffness(j) => {
                if prismatic(j) {
                    ("um/kN^2", 1e-12)
                } else {
                    ("urad/(kN*m)^2", 1e-12)
                }
            }
            Term::Backlash(j) | Term::JointOffset(j) | Term::GearCyclic(j, _) => {
                if prismatic(j) {
                    ("mm", 1e-3)
                } else {
                    ("mrad", 1e-3)
                }
            }
            Term::LoadCom(_) | Term::Marker(..) => ("mm", 1e-3),
            Term::Drift(_) => ("um/s", 1e-6),
            Term::JointFrame(_, a) | Term::Base(a) => {
                if a < 3 {
                    ("mm", 1e-3)
                } else {
                    ("mrad", 1e-3)
                }
            }
        }
    }

    /// Column of `t` at `row`, in the reported unit (`∂p [m] / ∂x [unit]`).
    pub fn column(&self, t: &Term, row: &Row) -> Vector3<f64> {
        let (_, si) = self.unit(t);
        self.column_si(t, row) * si
    }

    fn twist(&self, row: &Row, j: usize) -> Vector3<f64> {
        row.frames.joints()[j].twist_column(&row.p)
    }

    fn column_si(&self, t: &Term, row: &Row) -> Vector3<f64> {
        let deflection = row.kind == RowKind::Deflection;
        let zero = Vector3::zeros();
        match *t {
            Term::Compliance(j) => self.twist(row, j) * row.tau[j],
            Term::ComplianceAt(j, b) => {
                if self.bin_of(j, row.q[j]) == Some(b) {
                    self.twist(row, j) * row.tau[j]
                } else {
                    zero
                }
            }
            Term::NonlinearStiffness(j) => {
                let tau = row.tau[j];
                self.twist(row, j) * (tau * tau.abs())
            }
            Term::Backlash(j) => {
                let tau = row.tau[j];
                if tau.abs() < 1e-9 {
                    zero
                } else {
                    self.twist(row, j) * tau.signum()
                }
            }
            Term::LinkCompliance(j) => match row.load_force {
                Some((point, force)) if deflection => {
                    let jf = &row.frames.joints()[j];
                    let m = (point - jf.origin_m()).cross(&force);
                    let z = jf.axis.into_inner();
                    let m_perp = m - z * z.dot(&m);
                    m_perp.cross(&(row.p - jf.origin_m()))
                }
                _ => zero,
            },
            Term::LoadCom(a) => match row.load_force {
                Some((_, force)) if deflection => {
                    let dir = row.frames.tip().rotation * Vector3::ith(a, 1.0);
                    let mut col = zero;
                    for (j, jf) in row.frames.joints().iter().enumerate() {
                        let k = match self.bin_of(j, row.q[j]) {
                            Some(b) if self.k_bins[j].len() > b => self.k_bins[j][b] + self.k[j],
                            _ => self.k[j],
                        };
                        if k == 0.0 {
                            continue;
                        }
                        let dtau = match jf.kind {
                            JointKind::Revolute => jf.axis.dot(&dir.cross(&force)),
                            JointKind::Prismatic => 0.0,
                        };
                        col += jf.twist_column(&row.p) * (k * dtau);
                    }
                    col
                }
                _ => zero,
            },
            Term::Drift(a) => Vector3::ith(a, row.dt.unwrap_or(0.0)),
            Term::JointOffset(j) if !deflection => self.twist(row, j),
            Term::JointFrame(j, a) if !deflection => {
                geometric::joint_frame_columns(&row.frames, j, &row.p)
                    .map(|c| c[a])
                    .unwrap_or(zero)
            }
            Term::Base(a) if !deflection => geometric::base_columns(&row.p)[a],
            Term::Marker(m, a) if !deflection => {
                if self.markers[m].0 == row.marker {
                    geometric::marker_columns(&row.frames)[a]
                } else {
                    zero
                }
            }
            Term::GearCyclic(j, cos) if !deflection => {
                let qj = row.q[j];
                self.twist(row, j) * if cos { qj.cos() } else { qj.sin() }
            }
            _ => zero,
        }
    }
}
