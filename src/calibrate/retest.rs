//! The declared parameters left out at the nominal robot, tested again at
//! the fitted one.
//!
//! Which declared parameters the data identify is decided at the nominal
//! robot ([`super::engine::Engine::left_out`]): its dependences are mostly
//! structural (a1's offset is the base's turn about z) and hold at every
//! geometry. Some hold only at the nominal one: a marker exactly on a
//! joint's axis there makes that joint's turn and a tilt of the base move
//! it alike, while the real marker, a little off the axis, tells them
//! apart. Left out, such a parameter leaves its whole effect in the
//! residuals (a property test found 365 µm of RMS against 33 µm of noise,
//! with no warning). So each parameter left out at the nominal robot is
//! carried, unfitted, in the declared fit's designs
//! ([`Engine::fit_carrying`]), and at the fitted geometry:
//!
//! 1. those the one independence test ([`crate::estimate::rank`]) finds
//!    independent of the fitted ones there are the candidates;
//! 2. they are re-added, together, when the nested F test of adding them
//!    ([`crate::estimate::nested_test`], with the fit's weights) is
//!    significant at [`super::Policy::alpha`]; the fit is then made again
//!    with them, and the report's notes say so;
//! 3. otherwise they stay left out, as reported.
//!
//! The test keeps a dependence that the fitted geometry breaks only by
//! rounding (DLR Justin's `left_0.tx` and `left_0.ty`: independent at the
//! fitted geometry, F = 0.28, p = 0.75) from fitting noise. One round: a
//! parameter that becomes independent only after the re-added ones moved
//! the geometry again stays left out.

use super::diagnosis::first_fit;
use super::engine::{Engine, Fitted};
use super::fit;
use super::report::LeftOut;
use super::settings::CalibrationError;
use crate::estimate::{Accumulator, NestedTest};
use crate::model::Param;
use crate::Error;

/// `first`, the declared fit that carried `carried`
/// ([`Engine::fit_carrying`]; `info` its unit-weight sums with OLS), or the
/// fit with those of `carried` that the rule of the module re-adds (taken
/// off `left_out`, with a note in `notes`).
///
/// # Errors
/// As [`Engine::fit`] and [`fit::test`].
pub fn revive(
    e: &mut Engine<'_>,
    first: Fitted,
    info: Option<Accumulator<f64, nalgebra::Dyn>>,
    carried: &[Param],
    left_out: &mut Vec<LeftOut>,
    notes: &mut Vec<String>,
) -> Result<Fitted, CalibrationError> {
    if carried.is_empty() {
        return Ok(first);
    }
    let n = first.params.len();
    let all: Vec<Param> = first.params.iter().chain(carried).copied().collect();
    let test = test(e, &first, &all, info.as_ref())?;
    let Some((cols, t)) = test.filter(|(_, t)| t.p_value < e.policy.alpha) else {
        e.drop_carried(&first.params);
        return Ok(first);
    };
    let revived: Vec<Param> = cols.iter().map(|&c| all[c]).collect();
    let names: Vec<String> = revived.iter().map(|p| e.names.name(p)).collect();
    let note = format!(
        "{} re-added: dependent on the others at the nominal robot, not at the fitted \
         one, where adding {} is significant (F = {:.1} on ({}, {}) degrees of freedom, \
         p = {:.1e} < {})",
        names.join(", "),
        if names.len() == 1 { "it" } else { "them" },
        t.f,
        t.dof_num,
        t.dof_den,
        t.p_value,
        e.policy.alpha
    );
    (e.progress)(&note);
    notes.push(note);
    left_out.retain(|l| !names.contains(&l.name));
    let mut params = first.params;
    params.extend_from_slice(&revived);
    debug_assert!(params.len() > n);
    first_fit(e, params, left_out, &[]).map(|(f, _)| f)
}

/// The carried columns (after the first `first.params.len()` of `all`)
/// independent of the fitted ones at `first`'s geometry, and the nested
/// test of adding them; `None` when none is, or the test cannot be made.
fn test(
    e: &Engine<'_>,
    first: &Fitted,
    all: &[Param],
    info: Option<&Accumulator<f64, nalgebra::Dyn>>,
) -> Result<Option<(Vec<usize>, NestedTest)>, CalibrationError> {
    let n = first.params.len();
    // The fit's last design: its parameters, then the carried ones.
    let d = e.design(all)?;
    let model: Vec<usize> = (0..n).collect();
    let extra: Vec<usize> = (n..all.len()).collect();
    let cols = match info {
        // The same test on the same sums (`Design::independent`'s are the
        // unit-weight sums of these columns in this order).
        Some(acc) => match acc.identifiable() {
            Ok(rank) => extra.iter().copied().filter(|&c| rank.kept[c]).collect(),
            Err(_) => Vec::new(),
        },
        None => d.independent(&model, &extra),
    };
    if cols.is_empty() {
        return Ok(None);
    }
    let t = match info {
        // OLS: the fit's weights are one, and these are its sums.
        Some(acc) if cols == extra => fit::test_sums(acc, n),
        _ => fit::test(&d, &model, &cols, &first.fit.weights),
    };
    match t {
        Ok(t) => Ok(Some((cols, t))),
        Err(Error::NotIdentifiable { .. } | Error::TooFewEquations { .. }) => Ok(None),
        Err(err) => Err(CalibrationError::Core("left-out test", err)),
    }
}
