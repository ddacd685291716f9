//! The effect library (data contract §6): for a model, every effect it
//! lacks, as the [`Param`]s to test and how the model changes when the
//! effect is added; and which estimates of an added effect are physical.
//!
//! To add an effect: a [`Param`] with its column (`crate::model::columns`)
//! and unit (`crate::model::param`), a variant of [`Effect`] with its
//! contract name, its candidates in [`candidates`], its physical limit (if
//! any) in [`inadmissible`], and a test in `host-tests/tests/loop_effects.rs`
//! that simulates data with the effect and checks that the loop names it.

use super::names::Names;
use super::rows::{revolute, DataKinds};
use super::settings::Policy;
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
/// angle bins of each joint and whether they make a compensator candidate.
pub fn candidates(
    names: &Names,
    model: &[Param],
    kinds: DataKinds,
    bins: &[Vec<i32>],
    compensator_ok: &[bool],
) -> Vec<Candidate> {
    let has = |p: &Param| model.contains(p);
    let any = |f: &dyn Fn(&Param) -> bool| model.iter().any(f);
    let mut out = Vec::new();
    let cand = |effect, joint, test: Vec<Param>, remove: Vec<Param>, add: Vec<Param>| Candidate {
        effect,
        joint,
        marker: None,
        test,
        remove,
        add,
    };
    let any_compliance = any(&|p| p.is_compliance());
    for j in 0..names.joints.len() {
        let joint = j as u8;
        let k = Param::Compliance { joint };
        let binned = any(&|p| matches!(p, Param::ComplianceAt { joint: i, .. } if *i == joint));
        let compliant = has(&k) || binned;
        if kinds.deflections || kinds.absolute {
            if !binned && compensator_ok.get(j).copied().unwrap_or(false) {
                let per_bin: Vec<Param> = bins[j]
                    .iter()
                    .map(|&angle_urad| Param::ComplianceAt { joint, angle_urad })
                    .collect();
                // With a constant k in the model, the bins minus one are
                // tested (the constant stays); on acceptance k is replaced by
                // one compliance per bin.
                let (test, remove) = if has(&k) {
                    (per_bin[1..].to_vec(), vec![k])
                } else {
                    (per_bin.clone(), vec![])
                };
                out.push(cand(Effect::Compensator, Some(j), test, remove, per_bin));
            }
            if !compliant {
                out.push(cand(
                    Effect::JointCompliance,
                    Some(j),
                    vec![k],
                    vec![],
                    vec![k],
                ));
            }
            let p = Param::NonlinearStiffness { joint };
            if compliant && !has(&p) {
                out.push(cand(
                    Effect::NonlinearStiffness,
                    Some(j),
                    vec![p],
                    vec![],
                    vec![p],
                ));
            }
            let p = Param::Backlash { joint };
            if !has(&p) {
                out.push(cand(Effect::Backlash, Some(j), vec![p], vec![], vec![p]));
            }
        }
        let p = Param::LinkCompliance { joint };
        if kinds.deflections && revolute(names, j) && !has(&p) {
            out.push(cand(
                Effect::LinkCompliance,
                Some(j),
                vec![p],
                vec![],
                vec![p],
            ));
        }
        if kinds.absolute {
            let p = Param::JointOffset { joint };
            let frame = any(&|p| matches!(p, Param::JointFrame { joint: i, .. } if *i == joint));
            if !has(&p) && !frame {
                out.push(cand(Effect::JointOffset, Some(j), vec![p], vec![], vec![p]));
            }
            // The first joint's frame error is, to first order, a base pose
            // error (both are a rigid transform before the first motion):
            // that is `base_frame`.
            if !frame && j > 0 {
                let ps: Vec<Param> = (0..6)
                    .map(|axis| Param::JointFrame { joint, axis })
                    .collect();
                out.push(cand(Effect::Geometry, Some(j), ps.clone(), vec![], ps));
            }
            if revolute(names, j) && !has(&Param::GearCyclic { joint, cos: false }) {
                let ps = vec![
                    Param::GearCyclic { joint, cos: false },
                    Param::GearCyclic { joint, cos: true },
                ];
                out.push(cand(Effect::GearCyclic, Some(j), ps.clone(), vec![], ps));
            }
        }
    }
    if kinds.deflections && any_compliance && !any(&|p| matches!(p, Param::LoadCom { .. })) {
        let ps: Vec<Param> = (0..3).map(|axis| Param::LoadCom { axis }).collect();
        out.push(cand(Effect::LoadCom, None, ps.clone(), vec![], ps));
    }
    if kinds.time && !any(&|p| matches!(p, Param::Drift { .. })) {
        let ps: Vec<Param> = (0..3).map(|axis| Param::Drift { axis }).collect();
        out.push(cand(Effect::Drift, None, ps.clone(), vec![], ps));
    }
    if kinds.absolute {
        for m in 0..names.markers.len() as u8 {
            if !any(&|p| matches!(p, Param::Marker { marker, .. } if *marker == m)) {
                let ps: Vec<Param> = (0..3)
                    .map(|axis| Param::Marker { marker: m, axis })
                    .collect();
                let mut c = cand(Effect::Marker, None, ps.clone(), vec![], ps);
                c.marker = Some(m);
                out.push(c);
            }
        }
        if !any(&|p| matches!(p, Param::Base { .. })) {
            let ps: Vec<Param> = (0..6).map(|axis| Param::Base { axis }).collect();
            out.push(cand(Effect::BaseFrame, None, ps.clone(), vec![], ps));
        }
    }
    out
}

/// Why the estimate `x` of `params` is not physical for the effect
/// parameters `added`, if it is not. Physics, not tuning:
/// - a compliance (`k_<joint>`, `k_<joint>@<angle>`) is ≥ 0: a joint
///   yields in the direction of its torque;
/// - a backlash (`δq = b · sign τ`) is ≥ 0: the joint rests on the side of
///   its play that its torque pushes it to;
/// - a gear cyclic error is at most [`Policy::max_cyclic_mrad`];
/// - a drift is at most [`Policy::max_drift_mm_per_h`].
pub fn inadmissible(
    names: &Names,
    policy: &Policy,
    params: &[Param],
    x: &[f64],
    added: &[Param],
) -> Option<String> {
    let value = |p: &Param| params.iter().position(|u| u == p).map(|i| x[i]);
    for p in added {
        let Some(v) = value(p) else { continue };
        let bad = match *p {
            Param::Compliance { .. } | Param::ComplianceAt { .. } | Param::Backlash { .. } => {
                (v < 0.0).then(|| format!("{} = {v:.3} {} < 0", names.name(p), names.unit(p).name))
            }
            Param::GearCyclic { joint, cos: false } => {
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
            Param::Drift { axis: 0 } => {
                // µm/s → mm/h.
                let norm = (0..3)
                    .map(|axis| value(&Param::Drift { axis }).unwrap_or(0.0).powi(2))
                    .sum::<f64>()
                    .sqrt()
                    * 3.6;
                (norm > policy.max_drift_mm_per_h)
                    .then(|| format!("drift {norm:.3} mm/h > {} mm/h", policy.max_drift_mm_per_h))
            }
            _ => None,
        };
        if bad.is_some() {
            return bad;
        }
    }
    None
}
