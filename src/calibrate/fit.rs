//! The estimator on the host: the rows of a [`Design`] as a
//! [`Reweightable`] source of the core, at the exact number of parameters
//! (`Dyn`), and the fits and tests the engine asks for.

use nalgebra::{Dyn, OMatrix, Vector3, U3};

use super::design::Design;
use super::moments::DesignMoments;
pub use super::settings::Method;
use crate::estimate::{
    group_dof, group_sigma, nested_test, robust_weights, Accumulator, Block, Fit, IrlsSettings,
    NestedTest, Noise, Reweightable, RobustWeight, Solution,
};
pub use crate::io::Weighting;
use crate::Error;

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
    /// Residual σ per group and axis \[m\].
    pub sigma: Vec<Vector3<f64>>,
    /// Its degrees of freedom per group and axis (a pooled σ carries the
    /// pool's, [`crate::estimate::pool_small_groups`]).
    pub dof: Vec<Vector3<f64>>,
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

/// The rows of a [`Design`] on some of its columns, optionally without one
/// group (leave-one-out).
struct View<'a> {
    d: &'a Design,
    cols: &'a [usize],
    skip_group: Option<usize>,
    /// A floor for the residual σ per group and axis \[m\]: the
    /// instrument's ([`Weighting::Both`]).
    floor: Option<&'a [Vector3<f64>]>,
}

impl View<'_> {
    fn included(&self, i: usize) -> bool {
        Some(self.d.group[i]) != self.skip_group
    }
}

impl Reweightable<f64, Dyn> for View<'_> {
    fn group_count(&self) -> usize {
        self.d.groups
    }

    fn weighted(
        &self,
        weights: &[Vector3<f64>],
        noise: Option<Noise<'_, f64>>,
    ) -> Result<Accumulator<f64, Dyn>, Error> {
        if weights.len() != self.d.groups || noise.is_some_and(|n| !n.fits(self.d.groups)) {
            return Err(Error::Mismatch {
                what: "one weight per group",
            });
        }
        let n = self.cols.len();
        let mut acc = Accumulator::zeros(Dyn(n));
        // One block, refilled for every row.
        let mut block = Block::new(OMatrix::<f64, U3, Dyn>::zeros(n), Vector3::zeros());
        for i in (0..self.d.rows()).filter(|&i| self.included(i)) {
            let g = self.d.group[i];
            for (k, &c) in self.cols.iter().enumerate() {
                for a in 0..3 {
                    block.b[(a, k)] = self.d.b[(3 * i + a, c)];
                }
            }
            block.dp = Vector3::new(self.d.y[3 * i], self.d.y[3 * i + 1], self.d.y[3 * i + 2]);
            block.w = weights[g];
            block.sigma = noise.map(|n| n.sigma(g, &weights[g]));
            acc.update(&block)?;
        }
        Ok(acc)
    }

    fn residual_sigma_into(
        &self,
        fit: &Solution<f64, Dyn>,
        weights: &[Vector3<f64>],
        sigma: &mut [Vector3<f64>],
        dof: &mut [Vector3<f64>],
    ) -> Result<(), Error> {
        let groups = self.d.groups;
        if sigma.len() != groups || dof.len() != groups || weights.len() != groups {
            return Err(Error::Mismatch {
                what: "one sigma and one weight per group",
            });
        }
        let mut ss = vec![Vector3::<f64>::zeros(); self.d.groups];
        let mut h = vec![Vector3::<f64>::zeros(); self.d.groups];
        let mut n = vec![0usize; self.d.groups];
        // `LANES` rows at a time, their three axes side by side:
        // `b[(3k + a) LANES + j]` is column `k`, axis `a` of the batch's row
        // `j` (unused lanes zero).
        let p = self.cols.len();
        let inv = fit.lambda_inv.as_slice();
        let included: Vec<usize> = (0..self.d.rows()).filter(|&i| self.included(i)).collect();
        let mut b = vec![0.0; 3 * p * LANES];
        for batch in included.chunks(LANES) {
            b.fill(0.0);
            for (k, &c) in self.cols.iter().enumerate() {
                let column = self.d.b.column(c);
                for (j, &i) in batch.iter().enumerate() {
                    for a in 0..3 {
                        b[(3 * k + a) * LANES + j] = column[3 * i + a];
                    }
                }
            }
            let q = leverage3_rows(inv, p, &b);
            // The sums per group in row order, as row by row.
            for (j, &i) in batch.iter().enumerate() {
                let r = self.d.residual(self.cols, fit.x.as_slice(), i);
                let g = self.d.group[i];
                ss[g] += r.component_mul(&r);
                for a in 0..3 {
                    h[g][a] += weights[g][a] * weights[g][a] * q[a * LANES + j];
                }
                n[g] += 1;
            }
        }
        for g in 0..groups {
            sigma[g] = Vector3::from_fn(|a, _| group_sigma(ss[g][a], n[g], h[g][a]));
            if let Some(floor) = self.floor.and_then(|f| f.get(g)) {
                sigma[g] = sigma[g].sup(floor);
            }
            dof[g] = Vector3::from_fn(|a, _| group_dof(n[g], h[g][a]));
        }
        Ok(())
    }
}

/// Rows whose leverages [`leverage3_rows`] computes at once.
const LANES: usize = 4;

/// `bᵀ Λ⁻¹ b` of the three axes of `LANES` rows (`b[(3k + a) LANES + j]`:
/// column `k`, axis `a`, row `j`; `inv` column-major `p × p`), at
/// `q[a LANES + j]`: for each row and axis the arithmetic of
/// [`crate::estimate::leverage`] (`Σ_c (Σ_r Λ⁻¹_rc b_r) b_c`, both sums in
/// index order), bit for bit; the `3 LANES` sums are independent chains
/// side by side (the processor overlaps them, the compiler may vectorise
/// across them: neither changes any lane's arithmetic).
fn leverage3_rows(inv: &[f64], p: usize, b: &[f64]) -> [f64; 3 * LANES] {
    let mut q = [0.0; 3 * LANES];
    let bk = |k: usize| -> &[f64] { &b[3 * LANES * k..3 * LANES * (k + 1)] };
    for (c, col) in inv.chunks_exact(p.max(1)).enumerate().take(p) {
        let mut s = [0.0; 3 * LANES];
        for (r, &v) in col.iter().enumerate() {
            for (s, &x) in s.iter_mut().zip(bk(r)) {
                *s += v * x;
            }
        }
        for ((q, s), &x) in q.iter_mut().zip(&s).zip(bk(c)) {
            *q += s * x;
        }
    }
    q
}

/// Fits the columns `cols` of `d` (all rows, or all but group `skip_group`)
/// by the method of `s`.
///
/// # Errors
/// From the solve ([`Error::NotIdentifiable`], …).
pub fn fit(
    d: &Design,
    cols: &[usize],
    skip_group: Option<usize>,
    s: &FitSettings,
) -> Result<FitOut, Error> {
    let instrument = d.instrument_sigma.as_deref();
    let view = View {
        d,
        cols,
        skip_group,
        floor: instrument.filter(|_| s.weighting == Weighting::Both),
    };
    fit_source(&view, cols, instrument, s)
}

/// [`fit`] of all the columns of `m` (the moments of the columns `cols` of
/// `d`, [`DesignMoments::new`]) without the configuration `skip_group`: the
/// same fit from the moments per configuration and axis, equal to the
/// row-by-row one up to rounding ([`super::moments`]).
///
/// # Errors
/// As [`fit`].
pub fn fit_moments(
    m: &DesignMoments,
    d: &Design,
    cols: &[usize],
    skip_group: Option<usize>,
    s: &FitSettings,
) -> Result<FitOut, Error> {
    let instrument = d.instrument_sigma.as_deref();
    let source = m.without(
        skip_group,
        instrument.filter(|_| s.weighting == Weighting::Both),
    );
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
        dof,
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
    let view = View {
        d,
        cols: &cols,
        skip_group: None,
        floor: None,
    };
    let acc = view.weighted(weights, None)?;
    let m: Vec<bool> = (0..cols.len()).map(|i| i < model.len()).collect();
    let c: Vec<bool> = m.iter().map(|v| !v).collect();
    let sol = acc.solve_active(&m)?;
    nested_test(&acc, &m, &sol, &c)
}

#[cfg(test)]
mod tests {
    use super::{leverage3_rows, LANES};

    /// The leverage of one row and axis as [`crate::estimate::leverage`]
    /// sums it.
    fn one(inv: &[f64], p: usize, b: impl Fn(usize) -> f64) -> f64 {
        let mut q = 0.0;
        for c in 0..p {
            let mut s = 0.0;
            for r in 0..p {
                s += inv[c * p + r] * b(r);
            }
            q += s * b(c);
        }
        q
    }

    #[test]
    fn batched_leverages_are_the_row_by_row_ones_bit_for_bit() {
        let mut s = 7_u64;
        let mut next = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for p in [1, 2, 5, 43] {
            let inv: Vec<f64> = (0..p * p).map(|_| next() * 1e3).collect();
            let b: Vec<f64> = (0..3 * p * LANES).map(|_| next()).collect();
            let q = leverage3_rows(&inv, p, &b);
            for j in 0..LANES {
                for a in 0..3 {
                    let want = one(&inv, p, |k| b[(3 * k + a) * LANES + j]);
                    assert_eq!(q[a * LANES + j].to_bits(), want.to_bits());
                }
            }
        }
    }
}
