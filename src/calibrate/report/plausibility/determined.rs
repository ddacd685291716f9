//! Final estimates the data do not determine (within
//! [`Policy::determined_sigmas`] σ of zero), where that matters:
//!
//! - a **declared** term of the joint law that follows the torque (a
//!   compliance, a compensator's bin, nonlinear stiffness, backlash, a
//!   link's bending): `predict` and `compensate` apply it as estimated
//!   under any load. A helper's independent generator: a compliance of
//!   5 µrad/(N·m) on a wrist the calibration load barely turned (0.04 N·m
//!   at most) came out 769 ± 817, and predictions under a 10 N·m payload
//!   torque were 448 µm RMS off, 8 µm without the term;
//! - an **effect the loop added** whose every parameter ended there: the
//!   effects added after it took over what it explained (the same
//!   generator: a link's bending added first on data with joint
//!   compliances only, −0.16 ± 0.70 at the end).
//!
//! - **any other estimate** within those σ of 0 (a joint's offset or
//!   frame, a marker, a declared effect; not the base frame, whose value
//!   is a pose): the data do not tell it from the nominal robot's value,
//!   and it reads as 0 ± 2σ (the report's table flags it too,
//!   [`crate::calibrate::report::Parameter::determined`]). One warning
//!   names them all.
//!
//! All are warnings; negative compliances and backlash have their own
//! rule ([`crate::calibrate::report::plausibility::check_result`]) and no
//! parameter is named twice.

use std::collections::BTreeSet;

use crate::calibrate::report::{EffectStep, Parameter, Report};
use crate::calibrate::settings::Policy;
use crate::model::Param;

/// The warnings of the [module docs](self).
pub(super) fn undetermined(report: &Report, policy: &Policy) -> Vec<String> {
    findings(
        &report.effects,
        &report.model.params,
        &report.parameters,
        policy.determined_sigmas,
    )
}

/// The last warning of the [module docs](self): the estimates of
/// `parameters` that are not [`Parameter::determined`], but those named
/// in `named`.
fn the_others(parameters: &[Parameter], named: &BTreeSet<&str>, n: f64) -> Option<String> {
    let rest: Vec<String> = parameters
        .iter()
        .filter(|p| !p.determined && !named.contains(p.name.as_str()))
        .map(|p| format!("{} = {:.4} ± {:.4} {}", p.name, p.value, p.std, p.unit))
        .collect();
    (!rest.is_empty()).then(|| {
        format!(
            "{} estimate{} within {n} sigma of 0, which the data do not tell from the nominal \
             robot's value (read {} as 0 ± {n} sigma): {}",
            rest.len(),
            if rest.len() == 1 { " is" } else { "s are" },
            if rest.len() == 1 { "it" } else { "them" },
            rest.join(", ")
        )
    })
}

/// [`undetermined`] of the loop's steps `effects` and the final model's
/// `params` with their estimates `parameters` (the same order), at `n` σ.
fn findings<'p>(
    effects: &[EffectStep],
    params: &[Param],
    parameters: &'p [Parameter],
    n: f64,
) -> Vec<String> {
    let within = |value: f64, std: f64| value.abs() < n * std;
    let mut warnings = Vec::new();
    // Named by the negative rule already.
    let negative: BTreeSet<&'p str> = params
        .iter()
        .zip(parameters)
        .filter(|(p, par)| crate::calibrate::report::plausibility::sign_bound(p) && par.value < 0.0)
        .map(|(_, par)| par.name.as_str())
        .collect();
    // Named by a warning (here or the negative rule's).
    let mut named = negative.clone();
    // Parameters the loop added, by the effect that added them.
    let mut added: BTreeSet<&str> = BTreeSet::new();
    for (k, step) in effects.iter().enumerate() {
        let before: BTreeSet<&str> = step
            .parameters_before
            .iter()
            .map(|p| p.name.as_str())
            .collect();
        let new: Vec<&str> = step
            .parameters_after
            .iter()
            .map(|p| p.name.as_str())
            .filter(|n| !before.contains(n))
            .collect();
        added.extend(&new);
        let finals: Vec<_> = parameters
            .iter()
            .filter(|p| new.contains(&p.name.as_str()))
            .collect();
        if !finals.is_empty()
            && finals.iter().all(|p| within(p.value, p.std))
            && !finals.iter().any(|p| negative.contains(p.name.as_str()))
        {
            named.extend(finals.iter().map(|p| p.name.as_str()));
            let values: Vec<String> = finals
                .iter()
                .map(|p| format!("{} = {:.4} ± {:.4} {}", p.name, p.value, p.std, p.unit))
                .collect();
            let on = step
                .joint
                .as_deref()
                .map_or(String::new(), |j| format!(" on {j}"));
            warnings.push(format!(
                "{}{on}, added at step {}, is within {n} sigma of 0 in the final model ({}): \
                 the effects added after it took over what it explained; do not read it as \
                 found",
                step.effect,
                k + 1,
                values.join(", ")
            ));
        }
    }
    for (p, par) in params.iter().zip(parameters) {
        if crate::calibrate::report::plausibility::follows_torque(p)
            && !added.contains(par.name.as_str())
            && par.value >= 0.0
            && within(par.value, par.std)
        {
            warnings.push(format!(
                "{} = {:.4} ± {:.4} {} is within {n} sigma of 0: the data do not determine it \
                 (too little torque on its joint?), yet a prediction applies it as estimated \
                 under any load; load the joint more, or leave it out of [model]",
                par.name, par.value, par.std, par.unit
            ));
            named.insert(par.name.as_str());
        }
    }
    warnings.extend(the_others(parameters, &named, n));
    warnings
}

#[cfg(test)]
mod tests {
    use crate::calibrate::effects::Effect;
    use crate::calibrate::report::plausibility::determined::*;

    fn par(name: &str, value: f64, std: f64) -> Parameter {
        Parameter {
            name: name.into(),
            value,
            std,
            unit: "urad/(N*m)".into(),
            determined: value.abs() >= 2.0 * std,
        }
    }

    fn step(effect: Effect, joint: &str, before: &[Parameter], after: &[Parameter]) -> EffectStep {
        EffectStep {
            effect,
            joint: Some(joint.into()),
            marker: None,
            p_value: 1e-9,
            f: 40.0,
            tried: 10,
            rms_um_before: 60.0,
            rms_um_after: 55.0,
            heldout_rms_um_before: None,
            heldout_rms_um_after: None,
            parameters_before: before.to_vec(),
            parameters_after: after.to_vec(),
        }
    }

    /// The helper's wrist: 769 ± 817 on a declared compliance is named;
    /// 5.0 ± 0.1 is not; a geometric parameter within 2 σ of 0 is named by
    /// the last warning, the compliance not again.
    #[test]
    fn a_declared_compliance_the_data_do_not_determine_is_named() {
        let params = [
            Param::Compliance { joint: 2 },
            Param::Compliance { joint: 5 },
            Param::JointOffset { joint: 1 },
        ];
        let pars = [
            par("k_j3", 5.0, 0.1),
            par("k_j6", 769.131, 816.844),
            par("j2.offset", 0.1, 1.0),
        ];
        let w = findings(&[], &params, &pars, 2.0);
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(
            w[0].starts_with("k_j6 = 769.1310 ± 816.8440 urad/(N*m) is within 2 sigma of 0"),
            "{w:?}"
        );
        assert!(
            w[1].starts_with("1 estimate is within 2 sigma of 0")
                && w[1].ends_with(": j2.offset = 0.1000 ± 1.0000 urad/(N*m)"),
            "{w:?}"
        );
        // A negative one is the negative rule's, not named twice.
        let pars = [
            par("k_j3", 5.0, 0.1),
            par("k_j6", -769.1, 816.8),
            par("j2.offset", 3.0, 1.0),
        ];
        assert!(findings(&[], &params, &pars, 2.0).is_empty());
    }

    /// Every estimate within 2 σ of 0 is named once, in one warning, but
    /// the base frame's pose; one at 2.0 σ is determined.
    #[test]
    fn every_other_estimate_within_two_sigma_is_named_once() {
        let params = [
            Param::Base { axis: 0 },
            Param::JointFrame { joint: 3, axis: 2 },
            Param::Marker { marker: 0, axis: 1 },
            Param::JointOffset { joint: 0 },
        ];
        let mut base = par("base.tx", 0.1, 1.0);
        base.determined = true;
        let pars = [
            base,
            par("j4.tz", -1.5, 0.9),
            par("marker1.y", 0.3, 0.2),
            par("j1.offset", 2.0, 1.0),
        ];
        let w = findings(&[], &params, &pars, 2.0);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].starts_with("2 estimates are within 2 sigma of 0")
                && w[0].contains("j4.tz = -1.5000 ± 0.9000")
                && w[0].contains("marker1.y = 0.3000 ± 0.2000")
                && !w[0].contains("base.tx")
                && !w[0].contains("j1.offset"),
            "{w:?}"
        );
    }

    /// The helper's Panda: a link bending added first, taken over by the
    /// joint compliances added after it, is named once, as an effect.
    #[test]
    fn an_effect_later_steps_took_over_is_named_once() {
        let params = [
            Param::LinkCompliance { joint: 2 },
            Param::Compliance { joint: 1 },
        ];
        let bend = par("link_compliance_pj3", -0.16, 0.70);
        let k = par("k_pj2", 3.0, 0.2);
        let steps = [
            step(
                Effect::LinkCompliance,
                "pj3",
                &[],
                &[par("link_compliance_pj3", 4.0, 0.5)],
            ),
            step(
                Effect::JointCompliance,
                "pj2",
                std::slice::from_ref(&bend),
                &[bend.clone(), k.clone()],
            ),
        ];
        let w = findings(&steps, &params, &[bend.clone(), k.clone()], 2.0);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].starts_with("link_compliance on pj3, added at step 1, is within 2 sigma of 0"),
            "{w:?}"
        );
        // Still significant at the end: nothing to say.
        let firm = par("link_compliance_pj3", 4.0, 0.5);
        assert!(findings(&steps, &params, &[firm, k.clone()], 2.0).is_empty());
        // A compliance that ends negative is the negative rule's (TIAGo
        // select's arm_6 under IRLS, -3 352 ± 8 512): not named again.
        let params = [
            Param::Compliance { joint: 5 },
            Param::Compliance { joint: 1 },
        ];
        let neg = par("k_pj6", -3352.4, 8512.0);
        let steps = [step(
            Effect::JointCompliance,
            "pj6",
            &[],
            &[par("k_pj6", 80.0, 9.0)],
        )];
        assert!(findings(&steps, &params, &[neg, k], 2.0).is_empty());
    }
}
