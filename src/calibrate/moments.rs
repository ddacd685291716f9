//! The moments of a [`Design`] per configuration and axis, built once, and
//! fits from them with one configuration left out (issue 16).
//!
//! Every reweighting of eq. 14 gives one weight per configuration and axis,
//! so the unweighted moments of each configuration `g` and axis `a`,
//! `S = Σ b bᵀ`, `u = Σ b y`, `yy = Σ y²` and the rows `n`, are all a fit
//! needs ([`crate::estimate::grouped`]): `Λ = Σ w² S`, `η = Σ w² u`, the
//! residual sum `yy − 2xᵀu + xᵀSx`, the leverage `w² tr(Λ⁻¹ S)` and the
//! sandwich's middle term `Σ w⁴ σ² S`. A fit from them costs `O(G N²)` per
//! reweighting instead of `O(M N²)` over the rows, and the fit without one
//! configuration (the held-out error of a weighted fit, whose weights are
//! re-estimated without it) is the same sums with that configuration's
//! cells skipped: no row is streamed again.
//!
//! The sums are the rows' sums in another order (per cell, then weighted),
//! so the result equals the row-by-row fit of [`super::fit::fit`] up to
//! rounding (`tests` compare them to 1e-10 relative), not bit for bit; the
//! engine uses this for the held-out folds only, so every reported estimate
//! is still the row-by-row one.

use nalgebra::{DMatrix, DVector, Dyn, OMatrix, Vector3};

use super::design::Design;
use crate::estimate::accumulator::symmetric;
use crate::estimate::{
    group_dof, group_sigma, pool_small_groups, robust_weights, Accumulator, AxisMoments, Fit,
    Noise, Reweightable, RobustWeight, Solution,
};
use crate::Error;

/// The moments of some columns of a design, per configuration and axis.
#[derive(Debug, Clone)]
pub struct DesignMoments {
    /// Columns.
    n: usize,
    /// Per configuration, per axis x, y, z.
    cells: Vec<[AxisMoments<f64, Dyn>; 3]>,
}

impl DesignMoments {
    /// The moments of the columns `cols` of `d`: one pass over its rows.
    pub fn new(d: &Design, cols: &[usize]) -> Self {
        let n = cols.len();
        let zero = || AxisMoments {
            s_upper: DMatrix::zeros(n, n),
            u: DVector::zeros(n),
            yy: 0.0,
            n: 0,
        };
        let mut cells: Vec<[AxisMoments<f64, Dyn>; 3]> =
            (0..d.groups).map(|_| [zero(), zero(), zero()]).collect();
        let mut b = vec![0.0; n];
        for (i, &g) in d.group.iter().enumerate() {
            let Some(cell) = cells.get_mut(g) else {
                continue;
            };
            for (a, ax) in cell.iter_mut().enumerate() {
                let r = 3 * i + a;
                for (v, &c) in b.iter_mut().zip(cols) {
                    *v = d.b[(r, c)];
                }
                let y = d.y[r];
                let s = ax.s_upper.as_mut_slice();
                for (j, &bj) in b.iter().enumerate() {
                    for (sij, &bi) in s[j * n..=j * n + j].iter_mut().zip(&b) {
                        *sij += bi * bj;
                    }
                    ax.u[j] += bj * y;
                }
                ax.yy += y * y;
                ax.n += 1;
            }
        }
        Self { n, cells }
    }

    /// The number of configurations.
    pub fn groups(&self) -> usize {
        self.cells.len()
    }

    /// These moments without configuration `skip` (all of them with
    /// `None`), σ floored at `floor` per configuration and axis (the
    /// instrument's, [`super::fit::Weighting::Both`]).
    pub fn without<'a>(
        &'a self,
        skip: Option<usize>,
        floor: Option<&'a [Vector3<f64>]>,
    ) -> Folded<'a> {
        Folded {
            m: self,
            skip,
            floor,
        }
    }
}

/// [`DesignMoments`] with at most one configuration left out: a
/// [`Reweightable`] source for the fits of [`super::fit`].
#[derive(Debug, Clone, Copy)]
pub struct Folded<'a> {
    m: &'a DesignMoments,
    skip: Option<usize>,
    floor: Option<&'a [Vector3<f64>]>,
}

impl Folded<'_> {
    /// The cells that enter the fit, with their configuration index.
    fn cells(&self) -> impl Iterator<Item = (usize, &[AxisMoments<f64, Dyn>; 3])> {
        let skip = self.skip;
        self.m
            .cells
            .iter()
            .enumerate()
            .filter(move |(g, _)| Some(*g) != skip)
    }

    /// The fit with `weights` (as [`Reweightable::fit_weighted`]; `estimated`:
    /// the weights are eq. 14 of these data's σ): `Λ` and `η` from the
    /// cells' upper triangles, the solve, σ per cell, the middle term.
    fn fit(
        &self,
        weights: &[Vector3<f64>],
        active: &[bool],
        sigma: &mut [Vector3<f64>],
        dof: &mut [Vector3<f64>],
        estimated: bool,
    ) -> Result<Fit<f64, Dyn>, Error> {
        let n = self.m.n;
        if weights.len() != self.m.groups() {
            return Err(Error::Mismatch {
                what: "one weight per group",
            });
        }
        let mut upper = DMatrix::<f64>::zeros(n, n);
        let mut eta = DVector::<f64>::zeros(n);
        let (mut yy, mut equations) = (0.0, 0);
        for (g, cell) in self.cells() {
            for (ax, &w) in cell.iter().zip(weights[g].iter()) {
                let Some(w2) = moment_weight(w, None, ax.n)? else {
                    continue;
                };
                add_upper(&mut upper, &ax.s_upper, w2);
                eta.zip_apply(&ax.u, |e, v| *e += v * w2);
                yy += w2 * ax.yy;
                equations += ax.n;
            }
        }
        if !yy.is_finite() || !upper.iter().chain(eta.iter()).all(|v| v.is_finite()) {
            return Err(Error::NonFinite { what: "overflow" });
        }
        let parameters = active.iter().filter(|a| **a).count();
        if active.len() == n && equations < parameters {
            return Err(Error::TooFewEquations {
                equations,
                parameters,
            });
        }
        let solution = Solution::new(&symmetric(&upper), &eta, yy, equations, active)?;
        self.residual_sigma_into(&solution, weights, sigma, dof)?;
        pool_small_groups(sigma, dof);
        let noise = Noise {
            sigma,
            estimated_from: estimated.then_some(&*dof),
        };
        let mut middle = DMatrix::<f64>::zeros(n, n);
        for (g, cell) in self.cells() {
            let s = noise.sigma(g, &weights[g]);
            for ((ax, &w), &s) in cell.iter().zip(weights[g].iter()).zip(s.iter()) {
                let Some(w2) = moment_weight(w, Some(s), ax.n)? else {
                    continue;
                };
                add_upper(&mut middle, &ax.s_upper, w2 * w2 * s * s);
            }
        }
        if !middle.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite { what: "overflow" });
        }
        let covariance = solution.cov_sandwich(&symmetric(&middle));
        Ok(Fit {
            solution,
            covariance,
            iterations: 0,
            converged: false,
        })
    }
}

impl Reweightable<f64, Dyn> for Folded<'_> {
    fn group_count(&self) -> usize {
        self.m.groups()
    }

    fn weighted(
        &self,
        weights: &[Vector3<f64>],
        noise: Option<Noise<'_, f64>>,
    ) -> Result<Accumulator<f64, Dyn>, Error> {
        let groups = self.m.groups();
        if weights.len() != groups || noise.is_some_and(|n| !n.fits(groups)) {
            return Err(Error::Mismatch {
                what: "one weight per group",
            });
        }
        let mut acc = Accumulator::zeros(Dyn(self.m.n));
        for (g, cell) in self.cells() {
            let s = noise.map(|n| n.sigma(g, &weights[g]));
            for (a, ax) in cell.iter().enumerate() {
                acc.add_moments(
                    &ax.s_upper,
                    &ax.u,
                    ax.yy,
                    ax.n,
                    weights[g][a],
                    s.map(|s| s[a]),
                )?;
            }
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
        let groups = self.m.groups();
        if sigma.len() != groups || dof.len() != groups || weights.len() != groups {
            return Err(Error::Mismatch {
                what: "one sigma and one weight per group",
            });
        }
        let n = self.m.n;
        let inv = fit.lambda_inv.as_slice();
        for (g, cell) in self.m.cells.iter().enumerate() {
            if Some(g) == self.skip {
                // No rows: as the row-by-row source, σ = 0 and ν = 0.
                sigma[g] = Vector3::repeat(group_sigma(0.0, 0, 0.0));
                dof[g] = Vector3::repeat(group_dof(0, 0.0));
            } else {
                for (a, ax) in cell.iter().enumerate() {
                    // h = w² tr(Λ⁻¹ S), S from its upper triangle.
                    let s = ax.s_upper.as_slice();
                    let mut tr = 0.0;
                    for c in 0..n {
                        tr += inv[c * n + c] * s[c * n + c];
                        for r in 0..c {
                            tr += (inv[c * n + r] + inv[r * n + c]) * s[c * n + r];
                        }
                    }
                    let h = weights[g][a] * weights[g][a] * tr;
                    sigma[g][a] = group_sigma(ax.rss(&fit.x), ax.n, h);
                    dof[g][a] = group_dof(ax.n, h);
                }
            }
            if let Some(floor) = self.floor.and_then(|f| f.get(g)) {
                sigma[g] = sigma[g].sup(floor);
            }
        }
        Ok(())
    }

    fn fit_weighted(
        &self,
        weights: &[Vector3<f64>],
        active: &[bool],
        sigma: &mut [Vector3<f64>],
        dof: &mut [Vector3<f64>],
    ) -> Result<Fit<f64, Dyn>, Error> {
        self.fit(weights, active, sigma, dof, false)
    }

    fn fit_reweighted(
        &self,
        weight: &RobustWeight<f64>,
        active: &[bool],
        weights: &mut [Vector3<f64>],
        sigma: &mut [Vector3<f64>],
        dof: &mut [Vector3<f64>],
    ) -> Result<Fit<f64, Dyn>, Error> {
        robust_weights(sigma, weight, weights)?;
        self.fit(weights, active, sigma, dof, true)
    }
}

/// The checks of a weight (and σ) of `Accumulator::add_moments`:
/// `Some(w²)` when the cell's `n` rows enter the sums, `None` when they do
/// not (no rows, or weight 0).
fn moment_weight(w: f64, sigma: Option<f64>, n: usize) -> Result<Option<f64>, Error> {
    if !w.is_finite() || sigma.is_some_and(|s| !s.is_finite()) {
        return Err(Error::NonFinite { what: "weight" });
    }
    if w < 0.0 {
        return Err(Error::NotPositive { what: "weight" });
    }
    let w2 = w * w;
    Ok((n > 0 && w2 != 0.0).then_some(w2))
}

/// `m += s k` on the upper triangle.
fn add_upper(m: &mut OMatrix<f64, Dyn, Dyn>, s: &OMatrix<f64, Dyn, Dyn>, k: f64) {
    let n = m.nrows().max(1);
    let cols = m
        .as_mut_slice()
        .chunks_exact_mut(n)
        .zip(s.as_slice().chunks_exact(n));
    for (j, (mc, sc)) in cols.enumerate() {
        for (a, &v) in mc[..=j].iter_mut().zip(&sc[..=j]) {
            *a += v * k;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::fit::{fit, fit_moments, FitSettings, Method, Weighting};
    use crate::estimate::RobustWeight;

    /// `groups` groups of `per` rows on `n` columns, pseudo-random, the
    /// noise of each group scaled differently (so the weights differ).
    fn design(groups: usize, per: usize, n: usize, seed: u64, sigma: bool) -> Design {
        let mut s = seed;
        let mut next = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let rows = groups * per;
        let b = DMatrix::from_fn(3 * rows, n, |_, _| next());
        let x: Vec<f64> = (0..n).map(|_| next()).collect();
        let y = (0..3 * rows)
            .map(|r| {
                let g = r / 3 / per;
                let noise = 1e-5 * (1.0 + (g % 5) as f64) * next();
                (0..n).map(|c| b[(r, c)] * x[c]).sum::<f64>() * 1e-3 + noise
            })
            .collect();
        Design {
            params: Vec::new(),
            b,
            y,
            group: (0..rows).map(|i| i / per).collect(),
            groups,
            instrument_sigma: sigma.then(|| {
                (0..groups)
                    .map(|g| Vector3::repeat(2e-6 * (1 + g % 3) as f64))
                    .collect()
            }),
        }
    }

    fn settings(method: Method, weighting: Weighting) -> FitSettings {
        FitSettings {
            method,
            weight: RobustWeight::new(1e-5, 1.0).expect("valid weight"),
            max_iterations: 100,
            tolerance: 1e-3,
            weighting,
        }
    }

    fn close(a: &[f64], b: &[f64], scale: f64) {
        for (a, b) in a.iter().zip(b) {
            assert!((a - b).abs() <= 1e-10 * scale, "{a} vs {b}");
        }
    }

    #[test]
    fn folds_match_the_row_by_row_refit() {
        let cases = [
            (Method::Irls, Weighting::Estimated, false),
            (Method::Wls, Weighting::Estimated, false),
            (Method::Ols, Weighting::Estimated, false),
            (Method::Irls, Weighting::Both, true),
            (Method::Irls, Weighting::Instrument, true),
        ];
        for (k, (method, weighting, sigma)) in cases.into_iter().enumerate() {
            let d = design(12, 4, 6, 10 + k as u64, sigma);
            let cols: Vec<usize> = (0..6).collect();
            let m = DesignMoments::new(&d, &cols);
            let s = settings(method, weighting);
            for skip in [None, Some(0), Some(7)] {
                let rows = fit(&d, &cols, skip, &s).expect("row fit");
                let mom = fit_moments(&m, &d, &cols, skip, &s).expect("moment fit");
                let scale = rows.x.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
                close(&mom.x, &rows.x, scale);
                let scale = rows.std.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
                close(&mom.std, &rows.std, scale);
                assert_eq!(mom.iterations, rows.iterations);
            }
        }
    }

    #[test]
    fn a_fold_without_enough_equations_errs_as_the_rows() {
        let d = design(2, 1, 4, 3, false);
        let cols: Vec<usize> = (0..4).collect();
        let m = DesignMoments::new(&d, &cols);
        let s = settings(Method::Irls, Weighting::Estimated);
        let rows = fit(&d, &cols, Some(0), &s).map(|_| ());
        let mom = fit_moments(&m, &d, &cols, Some(0), &s).map(|_| ());
        assert_eq!(rows, mom);
    }
}
