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
//! so the result equals the row-by-row fit of [`crate::calibrate::fit::fit`] up to
//! rounding (`tests` compare them to 1e-10 relative), not bit for bit; the
//! engine uses this for the held-out folds only, so every reported estimate
//! is still the row-by-row one.

use nalgebra::{DMatrix, DVector, Dyn, Vector3};

use crate::calibrate::design::Design;
use crate::error::Error;
use crate::estimate::accumulator::symmetric;
use crate::estimate::{
    group_dof, group_sigma, robust_weights, Accumulator, Fit, Noise, Reweightable, RobustWeight,
    Solution,
};

mod kernels;
use kernels::{axpy, axpy_cells, dot, dot2x3};

/// The moments of some columns of a design, per configuration and axis,
/// each `S` as its packed upper triangle (column by column, `S[r, c]` for
/// `r ≤ c`): `S`, `u`, `yy` and `n` of cell `(g, a)` at index `3g + a`.
#[derive(Debug, Clone)]
pub struct DesignMoments {
    /// Columns.
    n: usize,
    /// Configurations.
    groups: usize,
    /// Packed upper triangles, `n(n+1)/2` per cell.
    s: Vec<f64>,
    /// `u = Σ b y`, `n` per cell.
    u: Vec<f64>,
    /// `Σ y²` per cell.
    yy: Vec<f64>,
    /// Rows per cell.
    rows: Vec<usize>,
    /// The design's runs of groups whose σ pool together
    /// ([`Design::pools`]).
    pools: Vec<std::ops::Range<usize>>,
}

/// `n(n+1)/2`.
fn packed(n: usize) -> usize {
    n * (n + 1) / 2
}

impl DesignMoments {
    /// The moments of the columns `cols` of `d`: one pass over its rows.
    pub fn new(d: &Design, cols: &[usize]) -> Self {
        let (n, p, cells) = (cols.len(), packed(cols.len()), 3 * d.groups);
        let mut m = Self {
            n,
            groups: d.groups,
            s: vec![0.0; cells * p],
            u: vec![0.0; cells * n],
            yy: vec![0.0; cells],
            rows: vec![0; cells],
            pools: d.pools.clone(),
        };
        let mut row = Vec::new();
        for (i, &g) in d.group.iter().enumerate() {
            if g >= d.groups {
                continue;
            }
            d.rows_into(&[i], cols, &mut row);
            // (A scalar row's other axes are no equations: `Design::live`.)
            for a in (0..3).filter(|&a| d.is_live(g, a)) {
                let (r, cell) = (3 * i + a, 3 * g + a);
                let b = &row[a * n..(a + 1) * n];
                let y = d.y[r];
                let s = &mut m.s[cell * p..(cell + 1) * p];
                let u = &mut m.u[cell * n..(cell + 1) * n];
                let mut k = 0;
                for (j, &bj) in b.iter().enumerate() {
                    for (sij, &bi) in s[k..=k + j].iter_mut().zip(b) {
                        *sij += bi * bj;
                    }
                    k += j + 1;
                    u[j] += bj * y;
                }
                m.yy[cell] += y * y;
                m.rows[cell] += 1;
            }
        }
        m
    }

    /// The number of configurations.
    pub fn groups(&self) -> usize {
        self.groups
    }

    /// These moments without the groups `skip` (all of them with none), σ
    /// floored at `floor` per configuration and axis (the
    /// instrument's, [`crate::calibrate::fit::Weighting::Both`]).
    pub fn without<'a>(
        &'a self,
        skip: &'a [usize],
        floor: Option<&'a [Vector3<f64>]>,
    ) -> Folded<'a> {
        Folded {
            m: self,
            skip,
            floor,
        }
    }

    /// `S` of cell `c`, packed.
    fn s(&self, c: usize) -> &[f64] {
        let p = packed(self.n);
        &self.s[c * p..(c + 1) * p]
    }

    /// `u` of cell `c`.
    fn u(&self, c: usize) -> &[f64] {
        &self.u[c * self.n..(c + 1) * self.n]
    }
}

/// A fold by downdate keeps at least this share of every parameter's
/// information (`Λⱼⱼ` of the other configurations over all of them); a
/// configuration that holds more is refitted from the others' rows
/// ([`FixedFolds::estimate`]): the subtraction then loses at most a bit
/// of each diagonal, where a configuration holding all but 10⁻⁶ of it lost
/// twenty (a helper's skewed design: 12 % off the refit).
const DOWNDATE_SHARE: f64 = 0.5;

/// The folds of a fit whose weights do not depend on its residuals (the
/// instrument's σ through eq. 14, [`crate::calibrate::fit::Weighting::Instrument`]):
/// `Λ = Σ w² S` and `η = Σ w² u` over every configuration, summed once, and
/// each fold's estimate the same sums with one configuration's cells taken
/// off, `(Λ − Λ_g)⁻¹ (η − η_g)` — a downdate of `O(N²)` and a solve of
/// `O(N³)` per configuration, where a fit from the moments is `O(G N²)`
/// (the held-out error of such a fit was quadratic in the configurations).
#[derive(Debug, Clone)]
pub struct FixedFolds<'a> {
    m: &'a DesignMoments,
    weights: &'a [Vector3<f64>],
    /// `Λ` over every configuration, packed.
    upper: Vec<f64>,
    /// `η` over every configuration.
    eta: Vec<f64>,
    /// Rows of positive weight over every configuration.
    equations: usize,
}

impl DesignMoments {
    /// The sums of every configuration at the fixed `weights` (one per
    /// configuration and axis), for [`FixedFolds::estimate`].
    ///
    /// # Errors
    /// [`Error::Mismatch`] for other than one weight per configuration;
    /// [`Error::NonFinite`] or [`Error::NotPositive`] for a weight, or a
    /// sum that overflows.
    pub fn fixed_folds<'a>(&'a self, weights: &'a [Vector3<f64>]) -> Result<FixedFolds<'a>, Error> {
        if weights.len() != self.groups {
            return Err(Error::Mismatch {
                what: "one weight per group",
            });
        }
        let n = self.n;
        let mut upper = vec![0.0; packed(n)];
        let mut eta = vec![0.0; n];
        let mut equations = 0;
        let mut terms = Vec::with_capacity(3 * self.groups);
        for (g, w) in weights.iter().enumerate() {
            for (a, &w) in w.iter().enumerate() {
                let c = 3 * g + a;
                let Some(w2) = moment_weight(w, None, self.rows[c])? else {
                    continue;
                };
                terms.push((self.s(c), w2));
                axpy(&mut eta, self.u(c), w2);
                equations += self.rows[c];
            }
        }
        axpy_cells(&mut upper, &terms);
        if !upper.iter().chain(&eta).all(|v| v.is_finite()) {
            return Err(Error::NonFinite { what: "overflow" });
        }
        Ok(FixedFolds {
            m: self,
            weights,
            upper,
            eta,
            equations,
        })
    }
}

impl FixedFolds<'_> {
    /// The estimate of the fit without the groups `skip` (a configuration
    /// left out: [`crate::calibrate::rows::Rows::fold`]).
    ///
    /// # Errors
    /// [`Error::OutOfRange`] for a group that is not one;
    /// [`Error::TooFewEquations`] when the others have fewer rows than
    /// parameters; [`crate::estimate::Factor::new`]'s errors (a parameter
    /// the others cannot identify: the caller refits, leaving it out).
    pub fn estimate(&self, skip: &[usize]) -> Result<DVector<f64>, Error> {
        let (n, m) = (self.m.n, self.m);
        if let Some(&g) = skip.iter().find(|&&g| g >= m.groups) {
            return Err(Error::OutOfRange {
                what: "configuration",
                index: g,
                len: m.groups,
            });
        }
        let mut upper = self.upper.clone();
        let mut eta = self.eta.clone();
        let mut equations = self.equations;
        for &g in skip {
            for (a, &w) in self.weights[g].iter().enumerate() {
                let c = 3 * g + a;
                if let Some(w2) = moment_weight(w, None, m.rows[c])? {
                    axpy(&mut upper, m.s(c), -w2);
                    axpy(&mut eta, m.u(c), -w2);
                    equations -= m.rows[c];
                }
            }
        }
        if equations < n {
            return Err(Error::TooFewEquations {
                equations,
                parameters: n,
            });
        }
        // A configuration that holds most of a parameter's information
        // leaves the others' sum as the difference of two near numbers:
        // refused here (the caller refits it from the other configurations'
        // rows), so that no fold carries the cancellation.
        let mut k = 0;
        for c in 0..n {
            k += c;
            let (total, left) = (self.upper[k], upper[k]);
            if left <= DOWNDATE_SHARE * total || !left.is_finite() {
                return Err(Error::NotIdentifiable {
                    column: c,
                    rcond: 0.0,
                });
            }
            k += 1;
        }
        let f = crate::estimate::Factor::new(&unpack(&upper, n), &vec![true; n])?;
        let x = f.solve(&DVector::from_vec(eta));
        if !x.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite { what: "estimate" });
        }
        Ok(x)
    }
}

/// [`DesignMoments`] with at most one configuration left out: a
/// [`Reweightable`] source for the fits of [`crate::calibrate::fit`].
#[derive(Debug, Clone, Copy)]
pub struct Folded<'a> {
    m: &'a DesignMoments,
    skip: &'a [usize],
    floor: Option<&'a [Vector3<f64>]>,
}

impl<'a> Folded<'a> {
    /// The configurations that enter the fit.
    fn groups(&self) -> impl Iterator<Item = usize> + 'a {
        let skip = self.skip;
        (0..self.m.groups).filter(move |g| !skip.contains(g))
    }

    /// The fit with `weights` (as [`Reweightable::fit_weighted`]; `estimated`:
    /// the weights are eq. 14 of these data's σ): `Λ` and `η` from the
    /// cells' packed triangles, the solve, σ per cell, the middle term.
    fn fit(
        &self,
        weights: &[Vector3<f64>],
        active: &[bool],
        sigma: &mut [Vector3<f64>],
        dof: &mut [Vector3<f64>],
        estimated: bool,
    ) -> Result<Fit<f64, Dyn>, Error> {
        let (n, m) = (self.m.n, self.m);
        if weights.len() != m.groups {
            return Err(Error::Mismatch {
                what: "one weight per group",
            });
        }
        let mut upper = vec![0.0; packed(n)];
        let mut eta = DVector::<f64>::zeros(n);
        let (mut yy, mut equations) = (0.0, 0);
        let mut terms = Vec::with_capacity(3 * m.groups);
        for g in self.groups() {
            for (a, &w) in weights[g].iter().enumerate() {
                let c = 3 * g + a;
                let Some(w2) = moment_weight(w, None, m.rows[c])? else {
                    continue;
                };
                terms.push((m.s(c), w2));
                axpy(eta.as_mut_slice(), m.u(c), w2);
                yy += w2 * m.yy[c];
                equations += m.rows[c];
            }
        }
        axpy_cells(&mut upper, &terms);
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
        let solution = Solution::new(&unpack(&upper, n), &eta, yy, equations, active)?;
        self.residual_sigma_into(&solution, weights, sigma, dof)?;
        crate::calibrate::design::pool(&m.pools, sigma, dof);
        let noise = Noise {
            sigma,
            estimated_from: estimated.then_some(&*dof),
        };
        let mut middle = vec![0.0; packed(n)];
        terms.clear();
        for g in self.groups() {
            let s = noise.sigma(g, &weights[g]);
            for (a, (&w, &s)) in weights[g].iter().zip(s.iter()).enumerate() {
                let c = 3 * g + a;
                let Some(w2) = moment_weight(w, Some(s), m.rows[c])? else {
                    continue;
                };
                terms.push((m.s(c), w2 * w2 * s * s));
            }
        }
        axpy_cells(&mut middle, &terms);
        if !middle.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite { what: "overflow" });
        }
        // `Λ⁻¹ M Λ⁻¹` (eq. 11) by nalgebra's blocked product, symmetrised
        // as `Solution::cov_sandwich` does.
        let inv = &solution.lambda_inv;
        let c = inv * unpack(&middle, n) * inv;
        let covariance = (&c + c.transpose()) * 0.5;
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
        self.m.groups
    }

    fn weighted(
        &self,
        weights: &[Vector3<f64>],
        noise: Option<Noise<'_, f64>>,
    ) -> Result<Accumulator<f64, Dyn>, Error> {
        let (n, groups) = (self.m.n, self.m.groups);
        if weights.len() != groups || noise.is_some_and(|n| !n.fits(groups)) {
            return Err(Error::Mismatch {
                what: "one weight per group",
            });
        }
        let mut acc = Accumulator::zeros(Dyn(n));
        for g in self.groups() {
            let s = noise.map(|n| n.sigma(g, &weights[g]));
            for a in 0..3 {
                let c = 3 * g + a;
                // `add_moments` takes `S` as an upper-triangular matrix.
                let s_upper = unpack_upper(self.m.s(c), n);
                let u = DVector::from_column_slice(self.m.u(c));
                acc.add_moments(
                    &s_upper,
                    &u,
                    self.m.yy[c],
                    self.m.rows[c],
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
        let (n, m) = (self.m.n, self.m);
        if sigma.len() != m.groups || dof.len() != m.groups || weights.len() != m.groups {
            return Err(Error::Mismatch {
                what: "one sigma and one weight per group",
            });
        }
        // With `S` packed, `tr(Λ⁻¹ S)` and `xᵀ S x` are dot products with
        // `Λ⁻¹` and `x xᵀ` packed, their off-diagonal elements doubled.
        let (inv, x) = (&fit.lambda_inv, &fit.x);
        let mut inv2 = Vec::with_capacity(packed(n));
        let mut xx2 = Vec::with_capacity(packed(n));
        for c in 0..n {
            for r in 0..=c {
                let k = if r == c { 1.0 } else { 2.0 };
                inv2.push(k * 0.5 * (inv[(r, c)] + inv[(c, r)]));
                xx2.push(k * x[r] * x[c]);
            }
        }
        for g in 0..m.groups {
            if self.skip.contains(&g) {
                // No rows: as the row-by-row source, σ = 0 and ν = 0.
                sigma[g] = Vector3::repeat(group_sigma(0.0, 0, 0.0));
                dof[g] = Vector3::repeat(group_dof(0, 0.0));
            } else {
                let sums = dot2x3(&inv2, &xx2, [m.s(3 * g), m.s(3 * g + 1), m.s(3 * g + 2)]);
                for (a, (tr, xsx)) in sums.into_iter().enumerate() {
                    let c = 3 * g + a;
                    let h = weights[g][a] * weights[g][a] * tr;
                    let rss = (m.yy[c] - 2.0 * dot(x.as_slice(), m.u(c)) + xsx).max(0.0);
                    sigma[g][a] = group_sigma(rss, m.rows[c], h);
                    dof[g][a] = group_dof(m.rows[c], h);
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

/// The `n × n` upper-triangular matrix of a packed triangle.
fn unpack_upper(packed: &[f64], n: usize) -> DMatrix<f64> {
    let mut m = DMatrix::zeros(n, n);
    let mut k = 0;
    for c in 0..n {
        for r in 0..=c {
            m[(r, c)] = packed[k];
            k += 1;
        }
    }
    m
}

/// The symmetric `n × n` matrix of a packed upper triangle.
fn unpack(packed: &[f64], n: usize) -> DMatrix<f64> {
    let m = unpack_upper(packed, n);
    symmetric(&m)
}

#[cfg(test)]
mod tests {
    use crate::calibrate::fit::moments::*;
    use crate::calibrate::fit::{fit, fit_moments, FitSettings, Method, Weighting};
    use crate::estimate::RobustWeight;

    /// `groups` groups of `per` rows on `n` columns, pseudo-random, the
    /// noise of each group scaled differently (so the weights differ).
    fn design(groups: usize, per: usize, n: usize, seed: u64, sigma: bool) -> Design {
        design_with(groups, per, n, seed, sigma, None)
    }

    /// [`design`], with column `c` of group `g`'s rows times `k` when
    /// `scale` is `Some((g, c, k))`.
    fn design_with(
        groups: usize,
        per: usize,
        n: usize,
        seed: u64,
        sigma: bool,
        scale: Option<(usize, usize, f64)>,
    ) -> Design {
        let mut s = seed;
        let mut next = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let rows = groups * per;
        let mut b = DMatrix::from_fn(3 * rows, n, |_, _| next());
        if let Some((g, c, k)) = scale {
            for r in 3 * g * per..3 * (g + 1) * per {
                b[(r, c)] *= k;
            }
        }
        let x: Vec<f64> = (0..n).map(|_| next()).collect();
        let y = (0..3 * rows)
            .map(|r| {
                let g = r / 3 / per;
                let noise = 1e-5 * (1.0 + (g % 5) as f64) * next();
                (0..n).map(|c| b[(r, c)] * x[c]).sum::<f64>() * 1e-3 + noise
            })
            .collect();
        let instrument_sigma = sigma.then(|| {
            (0..groups)
                .map(|g| Vector3::repeat(2e-6 * (1 + g % 3) as f64))
                .collect()
        });
        let group = (0..rows).map(|i| i / per).collect();
        Design::from_columns(Vec::new(), b, y, group, groups, instrument_sigma)
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

    /// With the instrument's σ (weights fixed in advance) each fold by
    /// downdate is the fold fitted from the moments, to rounding.
    #[test]
    fn fixed_weight_folds_are_the_refits() {
        let d = design(12, 4, 5, 7, true);
        let cols: Vec<usize> = (0..5).collect();
        let m = DesignMoments::new(&d, &cols);
        let s = settings(Method::Irls, Weighting::Instrument);
        let mut w = vec![Vector3::zeros(); d.groups];
        robust_weights(d.instrument_sigma.as_deref().unwrap(), &s.weight, &mut w).unwrap();
        let folds = m.fixed_folds(&w).unwrap();
        for g in 0..d.groups {
            let refit = fit_moments(&m, &d, &cols, &[g], &s).unwrap();
            let x = folds.estimate(&[g]).unwrap();
            let scale = refit.x.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
            close(x.as_slice(), &refit.x, 10.0 * scale);
        }
    }

    /// A configuration that holds most of a parameter's information is not
    /// downdated (the caller refits it).
    #[test]
    fn a_fold_that_would_cancel_is_refused() {
        let d = design(12, 4, 5, 7, true);
        let cols: Vec<usize> = (0..5).collect();
        let m0 = DesignMoments::new(&d, &cols);
        let s = settings(Method::Irls, Weighting::Instrument);
        let mut w = vec![Vector3::zeros(); d.groups];
        robust_weights(d.instrument_sigma.as_deref().unwrap(), &s.weight, &mut w).unwrap();
        assert!(m0.fixed_folds(&w).unwrap().estimate(&[0]).is_ok());
        // Column 3 a hundred times larger in group 0's rows alone.
        let d = design_with(12, 4, 5, 7, true, Some((0, 3, 100.0)));
        let m = DesignMoments::new(&d, &cols);
        let folds = m.fixed_folds(&w).unwrap();
        assert!(matches!(
            folds.estimate(&[0]),
            Err(Error::NotIdentifiable { column: 3, .. })
        ));
        assert!(folds.estimate(&[1]).is_ok());
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
            for skip in [&[][..], &[0], &[7], &[0, 7]] {
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

    /// The one-cell sums the passes of several cells replace.
    fn dot2(a: &[f64], b: &[f64], s: &[f64]) -> (f64, f64) {
        let (mut p, mut q) = ([0.0; 4], [0.0; 4]);
        let (ac, bc, sc) = (a.chunks_exact(4), b.chunks_exact(4), s.chunks_exact(4));
        let (ar, br, sr) = (ac.remainder(), bc.remainder(), sc.remainder());
        for ((a, b), s) in ac.zip(bc).zip(sc) {
            for k in 0..4 {
                p[k] += a[k] * s[k];
                q[k] += b[k] * s[k];
            }
        }
        let (mut p0, mut q0) = ((p[0] + p[1]) + (p[2] + p[3]), (q[0] + q[1]) + (q[2] + q[3]));
        for ((a, b), s) in ar.iter().zip(br).zip(sr) {
            p0 += a * s;
            q0 += b * s;
        }
        (p0, q0)
    }

    #[test]
    fn several_cells_per_pass_sum_as_one_at_a_time() {
        let d = design(1, 60, 1, 4, false);
        let v: Vec<f64> = d.y.iter().map(|y| y * 1e3).collect();
        for len in [1, 4, 7, 10, 21] {
            let (a, b) = (&v[..len], &v[len..2 * len]);
            let s = [
                &v[2 * len..3 * len],
                &v[3 * len..4 * len],
                &v[4 * len..5 * len],
            ];
            let got = dot2x3(a, b, s);
            for c in 0..3 {
                let want = dot2(a, b, s[c]);
                assert_eq!(got[c].0.to_bits(), want.0.to_bits());
                assert_eq!(got[c].1.to_bits(), want.1.to_bits());
            }
            for cells in 0..=6 {
                let terms: Vec<(&[f64], f64)> = (0..cells)
                    .map(|c| (&v[c * len..(c + 1) * len], v[100 + c]))
                    .collect();
                let mut got = v[6 * len..7 * len].to_vec();
                let mut want = got.clone();
                axpy_cells(&mut got, &terms);
                for (x, k) in &terms {
                    axpy(&mut want, x, *k);
                }
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&got), bits(&want));
            }
        }
    }

    #[test]
    fn a_fold_without_enough_equations_errs_as_the_rows() {
        let d = design(2, 1, 4, 3, false);
        let cols: Vec<usize> = (0..4).collect();
        let m = DesignMoments::new(&d, &cols);
        let s = settings(Method::Irls, Weighting::Estimated);
        let rows = fit(&d, &cols, &[0], &s).map(|_| ());
        let mom = fit_moments(&m, &d, &cols, &[0], &s).map(|_| ());
        assert_eq!(rows, mom);
    }
}
