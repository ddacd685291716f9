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
//! Both are warnings; negative compliances and backlash have their own
//! rule ([`super::check_result`]) and are not named twice.

use std::collections::BTreeSet;

use super::super::report::Report;
use super::super::settings::Policy;
use crate::model::Param;

/// Whether `p` is a joint-law term that follows the torque.
fn follows_torque(p: &Param) -> bool {
    matches!(
        p,
        Param::Compliance { .. }
            | Param::ComplianceAt { .. }
            | Param::NonlinearStiffness { .. }
            | Param::Backlash { .. }
            | Param::LinkCompliance { .. }
    )
}

/// The warnings of the [module docs](self).
pub(super) fn undetermined(report: &Report, policy: &Policy) -> Vec<String> {
    let n = policy.determined_sigmas;
    let within = |value: f64, std: f64| value.abs() < n * std;
    let mut warnings = Vec::new();
    // Parameters the loop added, by the effect that added them.
    let mut added: BTreeSet<&str> = BTreeSet::new();
    for (k, step) in report.effects.iter().enumerate() {
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
        let finals: Vec<_> = report
            .parameters
            .iter()
            .filter(|p| new.contains(&p.name.as_str()))
            .collect();
        if !finals.is_empty() && finals.iter().all(|p| within(p.value, p.std)) {
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
    for (p, par) in report.model.params.iter().zip(&report.parameters) {
        if follows_torque(p)
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
        }
    }
    warnings
}
