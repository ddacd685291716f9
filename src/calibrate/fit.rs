//! The estimator on the host: the fits and tests the engine asks for, on
//! the rows of a [`Design`] (`view`, a [`Reweightable`] source of
//! the core at the exact number of parameters, `Dyn`) or on its moments
//! per configuration and axis ([`crate::calibrate::fit::moments`]).
//!
//! Also here: the held-out predictions of an OLS fit in closed form
//! ([`heldout`]) and of weighted fits from the moments ([`moments`]), and
//! what the residuals say: RMS, lack of fit, the variable they follow
//! ([`residuals`]).

pub mod heldout;
pub mod moments;
pub mod residuals;

use nalgebra::{DMatrix, Dyn, OMatrix, Vector3};

use crate::calibrate::design::view::View;
use crate::calibrate::design::Design;
use crate::calibrate::fit::moments::DesignMoments;
pub use crate::calibrate::settings::Method;
use crate::error::Error;
use crate::estimate::{
    nested_test, robust_weights, Accumulator, Fit, IrlsSettings, NestedTest, Reweightable,
    RobustWeight,
};
pub use crate::io::setup::Weighting;

/// How one fit is made.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitSettings {
    /// OLS, one WLS step or IRLS.
    pub method: Method,
    /// σ0 \[m\] and λ of eq. 14.
    pub weight: RobustWeight<f64>,
    /// IRLS iterations at most.
    pub max_iterations: usize,
    /// IRLS stops when no parameter moves by more than this many of its σ.
    pub tolerance: f64,
    /// Which σ enters eq. 14 (WLS and IRLS); `instrument` and `both` use
    /// the design's [`Design::instrument_sigma`] (estimated without it).
    pub weighting: Weighting,
}

/// A fit on some columns of a design: the estimate and its noise model.
#[derive(Debug, Clone)]
pub struct FitOut {
    /// Column indices into the [`Design`].
    pub cols: Vec<usize>,
    /// Estimate, one per column, in the reported units.
    pub x: Vec<f64>,
    /// One standard deviation (sandwich covariance, eq. 8 / 11).
    pub std: Vec<f64>,
    /// The covariance (sandwich, eq. 8 / 11), in the reported units.
    pub covariance: OMatrix<f64, Dyn, Dyn>,
    /// Weights per group and axis the fit used.
    pub weights: Vec<Vector3<f64>>,
    /// Residual σ per group and axis \[m\] (its degrees of freedom, which
    /// only the fit reads, are not kept: 24 MB at 10⁶ configurations).
    pub sigma: Vec<Vector3<f64>>,
    /// Reweighting iterations.
    pub iterations: usize,
    /// Whether the fit settled: IRLS within its iterations (OLS and one WLS
    /// step are direct: always).
    pub converged: bool,
    /// The OLS start and every reweighting step after it: estimate,
    /// standard deviations, and the largest move in σ (the paper's
    /// Figure 3).
    pub history: Vec<Step>,
}

/// One step of a reweighted fit (an [`crate::estimate::Iteration`] at the
/// host's size).
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Estimate, reported units.
    pub x: Vec<f64>,
    /// Its standard deviations.
    pub std: Vec<f64>,
    /// `max_i |Δx_i| / σ_i` from the step before (0 for the OLS start).
    pub change: f64,
}

/// Fits the columns `cols` of `d` (all rows, or all but the groups `skip`:
/// a configuration left out, [`crate::calibrate::rows::Rows::fold`]) by the
/// method of `s`.
///
/// # Errors
/// From the solve ([`Error::NotIdentifiable`], …).
pub fn fit(d: &Design, cols: &[usize], skip: &[usize], s: &FitSettings) -> Result<FitOut, Error> {
    let instrument = d.instrument_sigma.as_deref();
    let floor = instrument.filter(|_| s.weighting == Weighting::Both);
    let view = View::new(d, cols, skip, floor);
    fit_source(&view, cols, instrument, s)
}

/// [`fit`] of `cols` without a configuration left out, where `known` are
/// the sums of those columns at unit weights ([`information`], made
/// before): an OLS fit makes no pass for them (the same fit, bit for bit).
///
/// # Errors
/// As [`fit`].
pub fn fit_known(
    d: &Design,
    cols: &[usize],
    known: Accumulator<f64, Dyn>,
    s: &FitSettings,
) -> Result<FitOut, Error> {
    fit_with_residuals(d, cols, Some(known), s).map(|(out, _)| out)
}

/// The residuals of every row \[m, scaled: [`Design::residual`]\].
pub type Residuals = Vec<Vector3<f64>>;

/// [`fit`] of `cols` on every row (the sums at unit weights `known` when
/// made before: [`fit_known`]), with the rows' residuals \[m, scaled:
/// [`Design::residual`]\] at the estimate when its last σ pass computed
/// them there (the same bits; `None` else).
///
/// # Errors
/// As [`fit`].
pub fn fit_with_residuals(
    d: &Design,
    cols: &[usize],
    known: Option<Accumulator<f64, Dyn>>,
    s: &FitSettings,
) -> Result<(FitOut, Option<Residuals>), Error> {
    let instrument = d.instrument_sigma.as_deref();
    let floor = instrument.filter(|_| s.weighting == Weighting::Both);
    let view = View::new(d, cols, &[], floor).capturing();
    let view = match known {
        Some(known) => view.knowing(known),
        None => view,
    };
    let out = fit_source(&view, cols, instrument, s)?;
    let residuals = view.residuals_at(&out.x);
    Ok((out, residuals))
}

/// `Λ = Σ BᵀB` and `η = Σ BᵀΔp` of the columns `cols` of `d` at unit
/// weights: the sums the OLS [`fit`] solves, bit for bit (and the
/// information of the independence test, [`Design::identifiability`]).
///
/// # Errors
/// As [`fit`] (a sum that is not finite).
pub fn information(d: &Design, cols: &[usize]) -> Result<Accumulator<f64, Dyn>, Error> {
    View::new(d, cols, &[], None).weighted(&vec![Vector3::repeat(1.0); d.groups], None)
}

/// The sums of the leading `n` columns of `acc` (`Λ`'s leading block, `η`'s
/// leading part; `Σ Δpᵀ W² Δp` and the equations as they are): what the
/// same rows streamed on those columns alone give, bit for bit (each sum of
/// the view is one element's, in row order).
pub fn leading(acc: &Accumulator<f64, Dyn>, n: usize) -> Accumulator<f64, Dyn> {
    let cols: Vec<usize> = (0..n).collect();
    columns_of(acc, &cols)
}

/// The sums of the columns `cols` of `acc`, in that order ([`leading`];
/// with unit weights, those of the same rows streamed on those columns
/// alone in any order, bit for bit: `bᵢ bⱼ = bⱼ bᵢ`).
pub fn columns_of(acc: &Accumulator<f64, Dyn>, cols: &[usize]) -> Accumulator<f64, Dyn> {
    let all = acc.information();
    // The sums hold the upper triangle, the rest zero.
    let info = DMatrix::from_fn(cols.len(), cols.len(), |i, j| {
        if i <= j {
            all[(cols[i], cols[j])]
        } else {
            0.0
        }
    });
    let eta = nalgebra::DVector::from_fn(cols.len(), |i, _| acc.eta()[cols[i]]);
    Accumulator::from_sums(info, eta, acc.weighted_yy(), acc.equations())
}

/// [`fit`] of all the columns of `m` (the moments of the columns `cols` of
/// `d`, [`DesignMoments::new`]) without the groups `skip` (as [`fit`]): the
/// same fit from the moments per configuration and axis, equal to the
/// row-by-row one up to rounding ([`crate::calibrate::fit::moments`]).
///
/// # Errors
/// As [`fit`].
pub fn fit_moments(
    m: &DesignMoments,
    d: &Design,
    cols: &[usize],
    skip: &[usize],
    s: &FitSettings,
) -> Result<FitOut, Error> {
    let instrument = d.instrument_sigma.as_deref();
    let source = m.without(skip, instrument.filter(|_| s.weighting == Weighting::Both));
    fit_source(&source, cols, instrument, s)
}

/// The fit of `s.method` on `view` (`cols`: the columns it holds).
fn fit_source<R: Reweightable<f64, Dyn>>(
    view: &R,
    cols: &[usize],
    instrument: Option<&[Vector3<f64>]>,
    s: &FitSettings,
) -> Result<FitOut, Error> {
    let groups = view.group_count();
    let active = vec![true; cols.len()];
    let mut weights = vec![Vector3::zeros(); groups];
    let mut sigma = vec![Vector3::zeros(); groups];
    let mut dof = vec![Vector3::zeros(); groups];
    let mut history = Vec::new();
    let step = |f: &Fit<f64, Dyn>, change| Step {
        x: f.solution.x.as_slice().to_vec(),
        std: f.std().as_slice().to_vec(),
        change,
    };
    let fit: Fit<f64, Dyn> = match s.method {
        Method::Ols => {
            let f = view.fit_ols(&active, &mut weights, &mut sigma, &mut dof)?;
            history.push(step(&f, 0.0));
            f
        }
        Method::Wls | Method::Irls
            if s.weighting == Weighting::Instrument && instrument.is_some() =>
        {
            // Weights known in advance: one weighted fit (eq. 10) with
            // eq. 14 at the instrument's σ; the sandwich with σ from its
            // residuals.
            let ols = view.fit_ols(&active, &mut weights, &mut sigma, &mut dof)?;
            history.push(step(&ols, 0.0));
            robust_weights(instrument.unwrap_or_default(), &s.weight, &mut weights)?;
            let mut f = view.fit_weighted(&weights, &active, &mut sigma, &mut dof)?;
            f.iterations = 1;
            let std = f.std();
            let change = (0..cols.len())
                .filter(|&i| std[i] > 0.0)
                .map(|i| (f.solution.x[i] - ols.solution.x[i]).abs() / std[i])
                .fold(0.0, f64::max);
            history.push(step(&f, change));
            f
        }
        Method::Wls => {
            let ols = view.fit_ols(&active, &mut weights, &mut sigma, &mut dof)?;
            history.push(step(&ols, 0.0));
            let mut f =
                view.fit_reweighted(&s.weight, &active, &mut weights, &mut sigma, &mut dof)?;
            f.iterations = 1;
            let std = f.std();
            let change = (0..cols.len())
                .filter(|&i| std[i] > 0.0)
                .map(|i| (f.solution.x[i] - ols.solution.x[i]).abs() / std[i])
                .fold(0.0, f64::max);
            history.push(step(&f, change));
            f
        }
        Method::Irls => {
            let settings = IrlsSettings {
                weight: s.weight,
                tolerance: s.tolerance,
                max_iterations: s.max_iterations.max(1),
            };
            view.fit_irls(
                &settings,
                &active,
                &mut weights,
                &mut sigma,
                &mut dof,
                |it| {
                    history.push(Step {
                        x: it.x.as_slice().to_vec(),
                        std: it.std.as_slice().to_vec(),
                        change: it.change,
                    });
                },
            )?
        }
    };
    let std = fit.std();
    Ok(FitOut {
        cols: cols.to_vec(),
        x: fit.solution.x.as_slice().to_vec(),
        std: std.as_slice().to_vec(),
        covariance: fit.covariance,
        weights,
        sigma,
        iterations: fit.iterations,
        converged: s.method != Method::Irls
            || fit.converged
            || (s.weighting == Weighting::Instrument && instrument.is_some()),
        history,
    })
}

/// Nested F test ([`nested_test`]) of adding the columns `candidate` to the
/// columns `model`, with the model's weights per group and axis.
///
/// # Errors
/// As [`nested_test`].
pub fn test(
    d: &Design,
    model: &[usize],
    candidate: &[usize],
    weights: &[Vector3<f64>],
) -> Result<NestedTest, Error> {
    let mut cols = model.to_vec();
    cols.extend_from_slice(candidate);
    let view = View::new(d, &cols, &[], None);
    test_sums(&view.weighted(weights, None)?, model.len())
}

/// [`test()`] from the sums `acc` of the model's columns (its first `model`)
/// then the candidate's.
///
/// # Errors
/// As [`nested_test`].
pub fn test_sums(acc: &Accumulator<f64, Dyn>, model: usize) -> Result<NestedTest, Error> {
    let m: Vec<bool> = (0..acc.parameters()).map(|i| i < model).collect();
    let c: Vec<bool> = m.iter().map(|v| !v).collect();
    let sol = acc.solve_active(&m)?;
    nested_test(acc, &m, &sol, &c)
}

#[cfg(test)]
mod tests {
    use crate::calibrate::design::testing;
    use crate::calibrate::fit::*;
    use crate::estimate::RobustWeight;

    /// `rows` rows, each its own configuration, on `n` pseudo-random columns.
    fn design(rows: usize, n: usize, seed: u64) -> Design {
        testing::design(rows, 1, n, seed)
    }

    /// An OLS fit given its sums is the fit that makes them, bit for bit;
    /// and it does use them (other sums, another fit).
    #[test]
    fn an_ols_fit_given_its_sums_is_the_fit_that_makes_them() {
        let d = design(9000, 13, 7);
        let cols: Vec<usize> = (0..13).collect();
        let s = FitSettings {
            method: Method::Ols,
            weight: RobustWeight::new(1e-5, 0.0).expect("valid weight"),
            max_iterations: 1,
            tolerance: 0.1,
            weighting: Weighting::Estimated,
        };
        let bits = |f: &FitOut| {
            let mut v: Vec<u64> = f.x.iter().chain(&f.std).map(|v| v.to_bits()).collect();
            v.extend(f.covariance.iter().map(|v| v.to_bits()));
            v
        };
        let made = fit(&d, &cols, &[], &s).expect("fit");
        let known = information(&d, &cols).expect("sums");
        let given = fit_known(&d, &cols, known, &s).expect("fit");
        assert_eq!(bits(&given), bits(&made));
        let other = information(&design(9000, 13, 8), &cols).expect("sums");
        assert_ne!(
            bits(&fit_known(&d, &cols, other, &s).expect("fit")),
            bits(&made)
        );
    }

    /// The sums of the leading columns of a view are those of a view of
    /// those columns alone, bit for bit (what [`leading`] promises the fit
    /// that carries columns): more rows than a block, both threads.
    #[test]
    fn leading_sums_are_the_sums_of_those_columns_alone() {
        let (rows, n, extra) = (9000, 13, 2);
        let d = design(rows, n + extra, 0x9e37_79b9_7f4a_7c15);
        let every: Vec<usize> = (0..n + extra).collect();
        let all = information(&d, &every).expect("sums");
        let alone = information(&d, &every[..n]).expect("sums");
        let lead = leading(&all, n);
        let bits = |m: &OMatrix<f64, Dyn, Dyn>| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&lead.information()), bits(&alone.information()));
        assert_eq!(
            lead.eta().iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            alone.eta().iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(lead.weighted_yy().to_bits(), alone.weighted_yy().to_bits());
        assert_eq!(lead.equations(), alone.equations());
        // Any columns in any order, with unit weights.
        let some = [3, 0, 14, 7];
        let picked = columns_of(&all, &some);
        let streamed = information(&d, &some).expect("sums");
        assert_eq!(bits(&picked.information()), bits(&streamed.information()));
        assert_eq!(
            picked.eta().iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            streamed
                .eta()
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>()
        );
        // And differ from the leading block of another column order.
        let swapped: Vec<usize> = (1..n + extra).chain([0]).collect();
        let other = leading(&information(&d, &swapped).expect("sums"), n);
        assert_ne!(bits(&other.information()), bits(&alone.information()));
    }
}
