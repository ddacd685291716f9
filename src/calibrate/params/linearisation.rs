//! Where the rows are evaluated: the current value of every parameter that
//! acts through a joint value (compliances, their angle bins, nonlinear
//! stiffness, backlash, the gear's cyclic error, the lumped gravity
//! compliance), and which deflection model the rows use.
//!
//! The gravity compliance ([`Param::GravityCompliance`]) is a deflection
//! `δqⱼ = x_a gₐ + x_b g_b` independent of the torque, like the gear's
//! cyclic error, with `(gₐ, g_b)` the components of the unit gravity
//! direction on joint `j`'s basis in its frame at the **commanded** pose
//! ([`crate::model::gravity_components`]): the lumped body's torque is
//! taken at the commanded pose, not at the deflected one (the difference
//! is the product of two deflections, µrad for mrad). The caller computes
//! them from the chain's frames at `q` ([`Linearisation::gravity_at`]).
//!
//! **Exact** (the default): each row is the robot at its equilibrium
//! ([`crate::robot::equilibrium()`]) — a deflection is the marker at the
//! loaded equilibrium (the load acting on the deflected robot) minus the
//! marker at the commanded pose; an absolute position is the marker at the
//! equilibrium under the robot's own weight. The model is not linear in
//! its parameters, so the engine solves it by Gauss–Newton: rows and
//! columns at the current estimate `x₀`, the fit of the linearised rows
//! (`y = measured − f(x₀) + B(x₀) x₀`, so that the fit returns the
//! parameters themselves, not a step), repeated until no parameter moves by
//! more than [`crate::calibrate::settings::Policy::gauss_newton_sigma`] of its σ.
//!
//! **Linear**: eq. 3 as the paper wrote it — torques and columns at the
//! commanded pose, the model linear in the compliances, one fit.

use std::collections::BTreeMap;

use nalgebra::Vector3;

use crate::calibrate::params::geometry::J;
use crate::calibrate::params::names::Names;
use crate::model::{gravity_components, in_bin, Param};
use crate::robot::{Frames, JointLaw};

/// The deflection model of the rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeflectionModel {
    /// The equilibrium of the deflected robot, by Gauss–Newton.
    Exact,
    /// Eq. 3: first order at the commanded pose.
    Linear,
}

impl DeflectionModel {
    /// Its name in the report and the JSON (`deflection_model`).
    pub fn name(self) -> &'static str {
        match self {
            DeflectionModel::Exact => "exact",
            DeflectionModel::Linear => "linear",
        }
    }
}

/// The point the rows are evaluated at (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct Linearisation {
    /// The deflection model.
    pub model: DeflectionModel,
    /// SI value of every parameter that acts through a joint value
    /// (compliances in rad/(N·m) or m/N, backlash, cyclic error and gravity
    /// compliance in rad or m, nonlinear stiffness in rad/(N·m)²).
    values: BTreeMap<Param, f64>,
    /// SI value \[rad/(N·m)\] of each link's bending
    /// ([`Param::LinkCompliance`], by joint), with a link mass among the
    /// parameters (empty otherwise): not a term of the joint law, but what
    /// a link mass's column goes through besides it
    /// ([`crate::calibrate::params::masses`]).
    bending: BTreeMap<u8, f64>,
}

/// Whether `p` acts through a joint value and enters the joint law.
pub(crate) fn acts_on_joint(p: &Param) -> bool {
    matches!(
        p,
        Param::Compliance { .. }
            | Param::ComplianceAt { .. }
            | Param::NonlinearStiffness { .. }
            | Param::Backlash { .. }
            | Param::GearCyclic { .. }
            | Param::GravityCompliance { .. }
    )
}

impl Linearisation {
    /// Whether the linearisation holds the value of `p` (the Gauss–Newton
    /// iteration follows it until it settles): a parameter acting through
    /// a joint value. A `load_com` estimate is not one: it is the
    /// correction itself, its column only depends on the compliances.
    pub fn tracks(p: &Param) -> bool {
        acts_on_joint(p)
    }

    /// The rigid nominal robot: every value zero.
    pub fn nominal(model: DeflectionModel) -> Self {
        Self {
            model,
            values: BTreeMap::new(),
            bending: BTreeMap::new(),
        }
    }

    /// The joint law of the given SI values (every key a parameter that
    /// acts through a joint value; others are ignored): a model file's.
    pub fn from_values(model: DeflectionModel, values: BTreeMap<Param, f64>) -> Self {
        Self {
            model,
            values: values
                .into_iter()
                .filter(|(p, _)| acts_on_joint(p))
                .collect(),
            bending: BTreeMap::new(),
        }
    }

    /// The SI value of every parameter of the joint law.
    pub fn values(&self) -> &BTreeMap<Param, f64> {
        &self.values
    }

    /// The values of a fit of `params` with estimate `x` (reported units).
    pub fn of(model: DeflectionModel, params: &[Param], x: &[f64], names: &Names) -> Self {
        Self {
            model,
            values: params
                .iter()
                .zip(x)
                .filter(|(p, _)| acts_on_joint(p))
                .map(|(p, v)| (*p, v * names.unit(p).si))
                .collect(),
            // Held only for a mass's column: otherwise a change of a
            // bending alone would make the rows look evaluated elsewhere.
            bending: if params.iter().any(|p| matches!(p, Param::LinkMass { .. })) {
                params
                    .iter()
                    .zip(x)
                    .filter_map(|(p, v)| match *p {
                        Param::LinkCompliance { joint } => Some((joint, v * names.unit(p).si)),
                        _ => None,
                    })
                    .collect()
            } else {
                BTreeMap::new()
            },
        }
    }

    /// The SI value \[rad/(N·m)\] of joint `j`'s link bending (0 without
    /// one).
    pub fn bending(&self, j: usize) -> f64 {
        u8::try_from(j)
            .ok()
            .and_then(|j| self.bending.get(&j))
            .copied()
            .unwrap_or(0.0)
    }

    /// Whether the rows depend on the values: the exact model with a
    /// parameter acting through a joint value, or a `load_com` or
    /// `link_mass` column (first order about the compliances, in either
    /// model).
    pub fn iterates(&self, params: &[Param]) -> bool {
        params.iter().any(|p| match p {
            Param::LoadCom { .. } | Param::LinkMass { .. } => true,
            p => self.model == DeflectionModel::Exact && acts_on_joint(p),
        })
    }

    /// The point a fraction `t` of the way from `self` to `to` (a damped
    /// Gauss–Newton step); `to`'s deflection model.
    pub fn towards(&self, to: &Self, t: f64) -> Self {
        let mut values = self.values.clone();
        for v in values.values_mut() {
            *v *= 1.0 - t;
        }
        for (p, v) in &to.values {
            *values.entry(*p).or_insert(0.0) += t * v;
        }
        let mut bending = self.bending.clone();
        for v in bending.values_mut() {
            *v *= 1.0 - t;
        }
        for (j, v) in &to.bending {
            *bending.entry(*j).or_insert(0.0) += t * v;
        }
        Self {
            model: to.model,
            values,
            bending,
        }
    }

    /// Value of `p` in its reported unit (0 when absent).
    pub fn value(&self, p: &Param, names: &Names) -> f64 {
        self.values.get(p).map_or(0.0, |v| v / names.unit(p).si)
    }

    /// The effective compliance \[rad/(N·m) or m/N\] of every joint at the
    /// joint values `q`: its constant compliance plus that of its
    /// compensator table (angle bins, [`Param::ComplianceAt`]) at `qⱼ`.
    ///
    /// The table answers for any angle: within
    /// [`crate::model::param::BIN_TOLERANCE_RAD`] of a calibrated angle it is
    /// that bin's value (as the fit used it); between two calibrated angles
    /// it is linear in the angle between the two bins' values; beyond the
    /// first or last calibrated angle it is the nearest bin's value (no
    /// extrapolation). [`Self::interpolated`] says whether a joint needed it.
    pub fn compliance_at(&self, q: &[f64]) -> Vec<f64> {
        let mut k = vec![0.0; q.len()];
        for (p, &v) in &self.values {
            if let Param::Compliance { joint } = *p {
                k[usize::from(joint)] += v;
            }
        }
        for (j, kj) in k.iter_mut().enumerate() {
            *kj += self.table(j, q[j]).0;
        }
        k
    }

    /// Joint `j`'s compensator-table compliance at `qj` \[rad\] and whether
    /// it was interpolated (no bin within the tolerance): see
    /// [`Self::compliance_at`]. 0 without a table.
    fn table(&self, j: usize, qj: f64) -> (f64, bool) {
        let bins = self.values.iter().filter_map(|(p, &v)| match *p {
            Param::ComplianceAt { joint, angle_urad } if usize::from(joint) == j => {
                Some((angle_urad, v))
            }
            _ => None,
        });
        // The nearest calibrated angle below and above `qj`: (angle, value).
        let mut below = (f64::NEG_INFINITY, None);
        let mut above = (f64::INFINITY, None);
        for (angle_urad, v) in bins {
            if in_bin(angle_urad, qj) {
                return (v, false);
            }
            let a = f64::from(angle_urad) * 1e-6;
            if a < qj && a > below.0 {
                below = (a, Some(v));
            }
            if a > qj && a < above.0 {
                above = (a, Some(v));
            }
        }
        let (below, above) = (below.1.map(|v| (below.0, v)), above.1.map(|v| (above.0, v)));
        match (below, above) {
            (Some((a0, v0)), Some((a1, v1))) => (v0 + (v1 - v0) * (qj - a0) / (a1 - a0), true),
            (Some((_, v)), None) | (None, Some((_, v))) => (v, true),
            (None, None) => (0.0, false),
        }
    }

    /// The joints whose compensator table is interpolated (or held at its
    /// end) at `q`: no calibrated angle within the bin tolerance.
    pub fn interpolated(&self, q: &[f64]) -> Vec<usize> {
        (0..q.len()).filter(|&j| self.table(j, q[j]).1).collect()
    }

    /// Whether the law has a gravity compliance: its deflection needs the
    /// gravity's components at the pose ([`Self::gravity_at`]).
    pub fn needs_gravity(&self) -> bool {
        self.values
            .keys()
            .any(|p| matches!(p, Param::GravityCompliance { .. }))
    }

    /// The components of the gravity direction (`gravity` \[any length,
    /// the frame of `frames`\], normalised here; zero: none) on every
    /// joint's basis at `frames` ([`gravity_components`]), the commanded
    /// pose's: what [`Self::joint_law`] takes. Empty when the law has no
    /// gravity compliance ([`Self::needs_gravity`]).
    pub fn gravity_at(&self, frames: &Frames<f64, J>, gravity: &Vector3<f64>) -> Vec<[f64; 2]> {
        if !self.needs_gravity() {
            return Vec::new();
        }
        let g = gravity.try_normalize(0.0).unwrap_or_else(Vector3::zeros);
        frames
            .joints()
            .iter()
            .map(|jf| gravity_components(jf, &g))
            .collect()
    }

    /// The joint law at measured joint values `q`, for an absolute
    /// position (the gear's cyclic error and the gravity compliance act)
    /// or a deflection (they do not: they are the same loaded and
    /// unloaded). `gravity`: [`Self::gravity_at`] the frames at `q`. `None`
    /// when every joint is rigid (the rows are the first-order ones) or the
    /// model is linear.
    pub fn law(&self, q: &[f64], absolute: bool, gravity: &[[f64; 2]]) -> Option<Law> {
        // No value: every term is zero, the robot rigid (without the four
        // vectors per row and relinearisation that say so).
        if self.model == DeflectionModel::Linear || self.values.is_empty() {
            return None;
        }
        let law = self.joint_law(q, absolute, gravity);
        let rigid = [&law.compliance, &law.quadratic, &law.backlash, &law.fixed]
            .iter()
            .all(|v| v.iter().all(|&x| x == 0.0));
        (!rigid).then_some(law)
    }

    /// The joint law at joint values `q` in either deflection model (a
    /// prediction or a compensation solves the exact equilibrium with the
    /// calibrated values whichever model fitted them); `absolute` and
    /// `gravity` as [`Self::law`] (a gravity compliance with no components
    /// for its joint is NaN: the equilibrium fails rather than leave it
    /// out).
    pub fn joint_law(&self, q: &[f64], absolute: bool, gravity: &[[f64; 2]]) -> Law {
        let n = q.len();
        let mut law = Law {
            compliance: self.compliance_at(q),
            quadratic: vec![0.0; n],
            backlash: vec![0.0; n],
            fixed: vec![0.0; n],
        };
        for (p, &v) in &self.values {
            match *p {
                Param::NonlinearStiffness { joint } => law.quadratic[usize::from(joint)] += v,
                Param::Backlash { joint } => law.backlash[usize::from(joint)] += v,
                Param::GearCyclic { joint, cos } if absolute => {
                    let qj = q[usize::from(joint)];
                    law.fixed[usize::from(joint)] += v * if cos { qj.cos() } else { qj.sin() };
                }
                Param::GravityCompliance { joint, b } if absolute => {
                    let g = gravity
                        .get(usize::from(joint))
                        .map_or(f64::NAN, |g| g[usize::from(b)]);
                    law.fixed[usize::from(joint)] += v * g;
                }
                _ => {}
            }
        }
        law
    }
}

/// The joint law of one row: `δⱼ = kⱼ τⱼ + cⱼ τⱼ|τⱼ| + bⱼ sign τⱼ + eⱼ`.
#[derive(Debug, Clone, PartialEq)]
pub struct Law {
    /// `kⱼ` \[rad/(N·m) or m/N\]: compliance (constant plus angle bin).
    pub compliance: Vec<f64>,
    /// `cⱼ` \[rad/(N·m)²\]: nonlinear stiffness.
    pub quadratic: Vec<f64>,
    /// `bⱼ` \[rad or m\]: backlash, in the direction of the torque.
    pub backlash: Vec<f64>,
    /// `eⱼ` \[rad or m\]: independent of the torque (gear cyclic error,
    /// gravity compliance).
    pub fixed: Vec<f64>,
}

/// Below this torque \[N·m or N\] a joint's backlash side is undecided and
/// counts as zero (the `backlash` column uses the same threshold).
const BACKLASH_DEADBAND: f64 = 1e-9;

impl JointLaw<f64> for Law {
    fn deflection(&self, j: usize, tau: f64) -> (f64, f64) {
        let side = if tau.abs() < BACKLASH_DEADBAND {
            0.0
        } else {
            tau.signum()
        };
        (
            self.compliance[j] * tau
                + self.quadratic[j] * tau * tau.abs()
                + self.backlash[j] * side
                + self.fixed[j],
            self.compliance[j] + 2.0 * self.quadratic[j] * tau.abs(),
        )
    }
}
