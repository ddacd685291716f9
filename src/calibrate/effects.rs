//! The effect library (data contract §6) on the host: for a model, every
//! effect it lacks, as the [`Param`]s to test and how the model changes
//! when the effect is added — the core's rule
//! ([`crate::model::effect::candidates`], shared with the device), owned
//! and named; and which estimates of an added effect are physical. The
//! declared model, the setup's `[model]` as parameters, is [`declared`].
//!
//! To add an effect: a [`Param`] with its column (`crate::model::columns`)
//! and unit (`crate::model::param`), a variant of [`Effect`] with its
//! contract name, its candidates in the core's rule
//! ([`crate::model::effect::candidates`]), its physical limit (if
//! any) in [`inadmissible`], and a test in `host-tests/tests/loop_effects.rs`
//! that simulates data with the effect and checks that the loop names it.

pub mod declared;

use core::convert::Infallible;

use crate::calibrate::params::names::Names;
use crate::calibrate::rows::{revolute, DataKinds};
use crate::calibrate::settings::Policy;
use crate::model::effect::{self, Unphysical};
use crate::model::Param;

pub use crate::model::effect::Effect;

/// One candidate extension of the model.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// The effect.
    pub effect: Effect,
    /// Joint index, for per-joint effects.
    pub joint: Option<usize>,
    /// Marker index, for [`Effect::Marker`].
    pub marker: Option<u8>,
    /// Parameters whose significance is tested (added to the model as it is).
    pub test: Vec<Param>,
    /// Parameters the model loses when the effect is accepted (a constant
    /// compliance replaced by its angle bins).
    pub remove: Vec<Param>,
    /// Parameters the model gains when the effect is accepted.
    pub add: Vec<Param>,
}

impl Candidate {
    /// `on <joint>` or `on marker <id>` (empty for a model-wide effect).
    pub fn about(&self, names: &Names) -> Option<String> {
        if let Some(j) = self.joint {
            return Some(names.joint(j as u8).to_string());
        }
        self.marker
            .map(|m| format!("marker {}", names.marker_id(m)))
    }
}

/// Every candidate effect `model` lacks, given the data's row kinds, the
/// angle bins of each joint and whether they make a compensator candidate:
/// the core's rule ([`effect::candidates`], which says which effects, on
/// which parameters, in which order), with the names' joints and markers.
pub fn candidates(
    names: &Names,
    model: &[Param],
    kinds: DataKinds,
    bins: &[Vec<i32>],
    compensator_ok: &[bool],
) -> Vec<Candidate> {
    let mut out = Vec::new();
    let compensator = |j: usize| {
        compensator_ok
            .get(j)
            .copied()
            .unwrap_or(false)
            .then(|| bins[j].as_slice())
    };
    let all = effect::candidates(
        model,
        names.joints.len(),
        |j| revolute(names, j),
        names.markers.len() as u8,
        kinds,
        compensator,
        |c| {
            out.push(Candidate {
                effect: c.effect,
                joint: c.joint.map(usize::from),
                marker: c.marker,
                test: c.test().collect(),
                remove: c.remove.into_iter().collect(),
                add: c.add.iter().collect(),
            });
            Ok::<(), Infallible>(())
        },
    );
    match all {
        Ok(()) => out,
        Err(never) => match never {},
    }
}

/// Why the estimate `x` of `params` is not physical for the effect
/// parameters `added`, if it is not: the core's rule
/// ([`effect::unphysical`]: a compliance or a backlash below zero, a drift
/// above [`Policy::max_drift_mm_per_h`]), a gear cyclic error above
/// [`Policy::max_cyclic_mrad`] (a gear's transmission error is a fraction
/// of a milliradian to a few) and a gravity compliance above
/// [`Policy::max_gravity_deflection_mrad`] (a joint's sag under the
/// robot's own weight), a link's mass below zero (`x` holds the mass
/// itself, not a Gauss–Newton step; effects only absolute data show), and
/// a thermal expansion above [`Policy::max_thermal_expansion_um_per_m_k`].
pub fn inadmissible(
    names: &Names,
    policy: &Policy,
    params: &[Param],
    x: &[f64],
    added: &[Param],
) -> Option<String> {
    let value = |p: &Param| params.iter().position(|u| u == p).map(|i| x[i]);
    for p in added {
        let bad = match effect::unphysical(p, value, policy.max_drift_mm_per_h) {
            Some(Unphysical::Negative(v)) => Some(format!(
                "{} = {v:.3} {} < 0",
                names.name(p),
                names.unit(p).name
            )),
            Some(Unphysical::Drift(norm)) => Some(format!(
                "drift {norm:.3} mm/h > {} mm/h",
                policy.max_drift_mm_per_h
            )),
            None => match (*p, value(p)) {
                (Param::GearCyclic { joint, cos: false }, Some(v)) => {
                    let c = value(&Param::GearCyclic { joint, cos: true }).unwrap_or(0.0);
                    let amp = v.hypot(c);
                    (amp > policy.max_cyclic_mrad).then(|| {
                        format!(
                            "gear_cyclic_{} amplitude {amp:.3} mrad > {} mrad",
                            names.joint(joint),
                            policy.max_cyclic_mrad
                        )
                    })
                }
                (Param::LinkMass { .. }, Some(v)) if v < 0.0 => {
                    Some(format!("{} = {v:.3} kg < 0", names.name(p)))
                }
                (Param::ThermalExpansion, Some(v))
                    if v.abs() > policy.max_thermal_expansion_um_per_m_k =>
                {
                    Some(format!(
                        "thermal_expansion |{v:.3}| um/(m*K) > {} um/(m*K)",
                        policy.max_thermal_expansion_um_per_m_k
                    ))
                }
                (Param::GravityCompliance { joint, b: false }, Some(v)) => {
                    let w = value(&Param::GravityCompliance { joint, b: true }).unwrap_or(0.0);
                    let amp = v.hypot(w);
                    (amp > policy.max_gravity_deflection_mrad).then(|| {
                        format!(
                            "gravity_compliance_{} |x| {amp:.3} mrad > {} mrad",
                            names.joint(joint),
                            policy.max_gravity_deflection_mrad
                        )
                    })
                }
                _ => None,
            },
        };
        if bad.is_some() {
            return bad;
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::settings::Policy;
    use crate::robot::JointKind;
    use nalgebra::Vector3;

    fn names() -> Names {
        Names {
            joints: vec!["a1".into(), "a2".into()],
            kinds: vec![JointKind::Revolute; 2],
            markers: vec![(1, Vector3::zeros())],
            bins: Default::default(),
        }
    }

    #[test]
    fn physical_limits_reject_impossible_estimates() {
        let (n, p) = (names(), Policy::default());
        let k = [Param::Compliance { joint: 1 }];
        assert!(inadmissible(&n, &p, &k, &[0.5], &k).is_none());
        assert!(inadmissible(&n, &p, &k, &[-0.5], &k)
            .unwrap()
            .contains("< 0"));
        let b = [Param::Backlash { joint: 0 }];
        assert!(inadmissible(&n, &p, &b, &[-1.0], &b).is_some());
        assert!(inadmissible(&n, &p, &b, &[1.0], &b).is_none());
        // A negative compliance already in the model is not the candidate's.
        let params = [Param::Compliance { joint: 0 }, Param::Backlash { joint: 1 }];
        assert!(inadmissible(
            &n,
            &p,
            &params,
            &[-1.0, 1.0],
            &[Param::Backlash { joint: 1 }]
        )
        .is_none());
        let cyc = [
            Param::GearCyclic {
                joint: 0,
                cos: false,
            },
            Param::GearCyclic {
                joint: 0,
                cos: true,
            },
        ];
        assert!(inadmissible(&n, &p, &cyc, &[6.0, 8.0], &cyc).is_none()); // 10 mrad
        assert!(inadmissible(&n, &p, &cyc, &[6.0, 8.1], &cyc).is_some());
        let grav = [false, true].map(|b| Param::GravityCompliance { joint: 1, b });
        assert!(inadmissible(&n, &p, &grav, &[30.0, -40.0], &grav).is_none()); // 50 mrad
        assert!(inadmissible(&n, &p, &grav, &[30.0, -40.1], &grav)
            .unwrap()
            .contains("gravity_compliance_a2"));
        let drift: Vec<Param> = (0..3).map(|axis| Param::Drift { axis }).collect();
        // 1 µm/s = 3.6 mm/h.
        assert!(inadmissible(&n, &p, &drift, &[1.0, 0.0, 0.0], &drift).is_none());
        assert!(inadmissible(&n, &p, &drift, &[1.0, 1.0, 0.0], &drift).is_some());
    }
}
