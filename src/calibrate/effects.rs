//! The effect library (data contract §6): for a model, every effect it
//! lacks, as the [`Term`]s to test and how the model changes when the
//! effect is added.

use super::terms::{Context, Term};

/// Effect names of the data contract, §6.
pub const EFFECTS: [&str; 12] = [
    "compensator",
    "joint_compliance",
    "nonlinear_stiffness",
    "backlash",
    "link_compliance",
    "load_com",
    "drift",
    "joint_offset",
    "geometry",
    "gear_cyclic",
    "marker",
    "base_frame",
];

/// One candidate extension of the model.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// Contract name (§6).
    pub effect: &'static str,
    /// Joint index, for per-joint effects.
    pub joint: Option<usize>,
    /// Marker index (into [`Context::markers`]), for `marker`.
    pub marker: Option<usize>,
    /// Columns whose significance is tested (added to the model as it is).
    pub test: Vec<Term>,
    /// Terms the model loses when the effect is accepted (a constant
    /// compliance replaced by its angle bins).
    pub remove: Vec<Term>,
    /// Terms the model gains when the effect is accepted.
    pub add: Vec<Term>,
}

/// What the data can show: which kinds of rows there are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DataKinds {
    /// Deflection rows (a load).
    pub deflections: bool,
    /// Absolute rows (geometric calibration).
    pub absolute: bool,
    /// A time column.
    pub time: bool,
}

/// Joint angle bins that make a compensator candidate: 2 to 8 distinct
/// angles, each seen in at least two configurations.
pub fn compensator_eligible(bin_configs: &[usize]) -> bool {
    (2..=8).contains(&bin_configs.len()) && bin_configs.iter().all(|&n| n >= 2)
}

/// Every candidate effect `model` lacks. `compensator_ok[j]` says whether
/// joint `j`'s angle bins make a compensator candidate.
pub fn candidates(
    ctx: &Context,
    model: &[Term],
    kinds: DataKinds,
    compensator_ok: &[bool],
) -> Vec<Candidate> {
    let has = |t: &Term| model.contains(t);
    let any = |f: &dyn Fn(&Term) -> bool| model.iter().any(f);
    let mut out = Vec::new();
    let dof = ctx.joint_names.len();
    let revolute = |j: usize| ctx.joint_kinds[j] == crate::chain::JointKind::Revolute;
    let cand = |effect, joint, test: Vec<Term>, remove: Vec<Term>, add: Vec<Term>| Candidate {
        effect,
        joint,
        marker: None,
        test,
        remove,
        add,
    };
    let any_compliance = any(&|t| matches!(t, Term::Compliance(_) | Term::ComplianceAt(..)));
    for j in 0..dof {
        let k = Term::Compliance(j);
        let binned = any(&|t| matches!(t, Term::ComplianceAt(i, _) if *i == j));
        let compliant = has(&k) || binned;
        if kinds.deflections || kinds.absolute {
            if !binned && compensator_ok.get(j).copied().unwrap_or(false) {
                let bins: Vec<Term> = (0..ctx.bins[j].len())
                    .map(|b| Term::ComplianceAt(j, b))
                    .collect();
                let (test, remove) = if has(&k) {
                    (bins[1..].to_vec(), vec![k])
                } else {
                    (bins.clone(), vec![])
                };
                out.push(cand("compensator", Some(j), test, remove, bins));
            }
            if !compliant {
                out.push(cand("joint_compliance", Some(j), vec![k], vec![], vec![k]));
            }
            let t = Term::NonlinearStiffness(j);
            if compliant && !has(&t) {
                out.push(cand(
                    "nonlinear_stiffness",
                    Some(j),
                    vec![t],
                    vec![],
                    vec![t],
                ));
            }
            let t = Term::Backlash(j);
            if !has(&t) {
                out.push(cand("backlash", Some(j), vec![t], vec![], vec![t]));
            }
        }
        let t = Term::LinkCompliance(j);
        if kinds.deflections && revolute(j) && !has(&t) {
            out.push(cand("link_compliance", Some(j), vec![t], vec![], vec![t]));
        }
        if kinds.absolute {
            let t = Term::JointOffset(j);
            let frame = any(&|t| matches!(t, Term::JointFrame(i, _) if *i == j));
            if !has(&t) && !frame {
                out.push(cand("joint_offset", Some(j), vec![t], vec![], vec![t]));
            }
            // The first joint's frame error is, to first order, a base pose
            // error (both are a rigid transform before the first motion):
            // that is `base_frame`.
            if !frame && j > 0 {
                let terms: Vec<Term> = (0..6).map(|a| Term::JointFrame(j, a)).collect();
                out.push(cand("geometry", Some(j), terms.clone(), vec![], terms));
            }
            if revolute(j) && !has(&Term::GearCyclic(j, false)) {
                let terms = vec![Term::GearCyclic(j, false), Term::GearCyclic(j, true)];
                out.push(cand("gear_cyclic", Some(j), terms.clone(), vec![], terms));
            }
        }
    }
    if kinds.deflections && any_compliance && !any(&|t| matches!(t, Term::LoadCom(_))) {
        let terms: Vec<Term> = (0..3).map(Term::LoadCom).collect();
        out.push(cand("load_com", None, terms.clone(), vec![], terms));
    }
    if kinds.time && !any(&|t| matches!(t, Term::Drift(_))) {
        let terms: Vec<Term> = (0..3).map(Term::Drift).collect();
        out.push(cand("drift", None, terms.clone(), vec![], terms));
    }
    if kinds.absolute {
        for m in 0..ctx.markers.len() {
            if !any(&|t| matches!(t, Term::Marker(i, _) if *i == m)) {
                let terms: Vec<Term> = (0..3).map(|a| Term::Marker(m, a)).collect();
                let mut c = cand("marker", None, terms.clone(), vec![], terms);
                c.marker = Some(m);
                out.push(c);
            }
        }
        if !any(&|t| matches!(t, Term::Base(_))) {
            let terms: Vec<Term> = (0..6).map(Term::Base).collect();
            out.push(cand("base_frame", None, terms.clone(), vec![], terms));
        }
    }
    out
}
