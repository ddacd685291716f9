//! The rows of a [`Design`] on some of its columns, optionally without one
//! configuration: the [`Reweightable`] source of the host's row-by-row fits
//! ([`super::fit::fit`]).
//!
//! Every sum is the core's ([`crate::estimate::Accumulator::update`] and
//! [`crate::estimate::leverage`]), bit for bit, in a layout the processor
//! streams faster (issue 16):
//!
//! - the included rows are copied, each row's three axes as three
//!   contiguous runs of its columns, so that the rank-3 update of a column
//!   of `Λ` runs over contiguous values (vectorised across the elements of
//!   the column, each element's sum unchanged): once per view when it has
//!   at most [`BLOCK_ROWS`] rows, else [`BLOCK_ROWS`] at a time in each
//!   pass (a copy of a million rows' columns was 190 MB while a fit ran);
//! - two rows are added per pass over the triangle (each element gets the
//!   first row's three terms, then the second's: the order of the row by
//!   row stream);
//! - the sandwich's middle term `M` is summed alone (the core's pass with σ
//!   sums `Λ` again, which the fit does not use);
//! - the leverages of four rows are computed side by side.
//!
//! Where a weight, σ or sum is not finite (or a weight negative), the
//! core's [`crate::estimate::Accumulator::update`] is run instead: it gives
//! the errors it always gave. `tests` compare both ways bit for bit.

use nalgebra::{DMatrix, DVector, Dyn, OMatrix, Vector3, U3};

use super::design::Design;

mod blocks;
mod terms;
use crate::estimate::accumulator::symmetric;
use crate::estimate::{
    group_dof, group_sigma, pool_small_groups, robust_weights, Accumulator, Block, Fit, Noise,
    Reweightable, RobustWeight, Solution,
};
use crate::Error;
use terms::{add_terms, leverage3_rows, Term, LANES};

/// The rows of a [`Design`] on some of its columns, optionally without one
/// group (leave-one-out).
pub(super) struct View<'a> {
    d: &'a Design,
    cols: &'a [usize],
    /// A floor for the residual σ per group and axis \[m\]: the
    /// instrument's ([`super::fit::Weighting::Both`]).
    floor: Option<&'a [Vector3<f64>]>,
    /// The included rows, in order.
    rows: Vec<usize>,
    /// Rows copied at a time (even: the pairs of [`add_terms`] never
    /// straddle two copies).
    block: usize,
    /// Their columns when there are at most `block` rows (else empty):
    /// row `k`'s axis `a` at `b[(3k + a) n..(3k + a + 1) n]`.
    b: Vec<f64>,
    /// The sums at unit weights when already made ([`View::knowing`]).
    known: Option<Accumulator<f64, Dyn>>,
}

/// Rows a view copies at a time ([`View`]).
pub(super) const BLOCK_ROWS: usize = 4096;

/// Rows whose leverages and residuals are computed before they are summed
/// ([`Reweightable::residual_sigma_into`]; a multiple of [`LANES`]).
const LEVERAGE_CHUNK: usize = 1 << 15;

impl<'a> View<'a> {
    /// The rows of `d` on the columns `cols`, without group `skip_group`.
    pub(super) fn new(
        d: &'a Design,
        cols: &'a [usize],
        skip_group: Option<usize>,
        floor: Option<&'a [Vector3<f64>]>,
    ) -> Self {
        Self::blocked(d, cols, skip_group, floor, BLOCK_ROWS)
    }

    /// [`View::new`], copying `block` rows at a time (rounded up to even).
    fn blocked(
        d: &'a Design,
        cols: &'a [usize],
        skip_group: Option<usize>,
        floor: Option<&'a [Vector3<f64>]>,
        block: usize,
    ) -> Self {
        let rows: Vec<usize> = (0..d.rows())
            .filter(|&i| Some(d.group[i]) != skip_group)
            .collect();
        let block = block.max(2).next_multiple_of(2);
        let mut view = Self {
            d,
            cols,
            floor,
            rows,
            block,
            b: Vec::new(),
            known: None,
        };
        if view.rows.len() <= block {
            view.b = view.copy(0, view.rows.len());
        }
        view
    }

    /// The view whose sums at unit weights ([`View::information`]) are
    /// `known`: an OLS fit on it makes no pass for them.
    pub(super) fn knowing(mut self, known: Accumulator<f64, Dyn>) -> Self {
        self.known = Some(known);
        self
    }

    /// Column `k` of axis `a` of design row `i`.
    fn at(&self, i: usize, a: usize, k: usize) -> f64 {
        self.d.b[(3 * i + a, self.cols[k])]
    }

    /// `Δp` of design row `i`.
    fn y(&self, i: usize) -> [f64; 3] {
        [self.d.y[3 * i], self.d.y[3 * i + 1], self.d.y[3 * i + 2]]
    }

    /// The core's accumulator, one [`Accumulator::update`] per row.
    fn streamed(
        &self,
        weights: &[Vector3<f64>],
        noise: Option<Noise<'_, f64>>,
    ) -> Result<Accumulator<f64, Dyn>, Error> {
        let n = self.cols.len();
        let mut acc = Accumulator::zeros(Dyn(n));
        // One block, refilled for every row.
        let mut block = Block::new(OMatrix::<f64, U3, Dyn>::zeros(n), Vector3::zeros());
        for &i in &self.rows {
            let g = self.d.group[i];
            for a in 0..3 {
                for k in 0..n {
                    block.b[(a, k)] = self.at(i, a, k);
                }
            }
            block.dp = Vector3::from(self.y(i));
            block.w = weights[g];
            block.sigma = noise.map(|n| n.sigma(g, &weights[g]));
            acc.update(&block)?;
        }
        Ok(acc)
    }

    /// `Λ` (upper triangle), `η`, `Σ Δpᵀ W² Δp` and the rows with a
    /// positive weight, as [`Accumulator::update`] sums them; `None` where
    /// a weight is negative or anything is not finite.
    fn sums(&self, weights: &[Vector3<f64>]) -> Option<Accumulator<f64, Dyn>> {
        let n = self.cols.len();
        let ok = |w: &Vector3<f64>| w.iter().all(|w| *w >= 0.0 && w.is_finite());
        if !self.rows.iter().all(|&i| ok(&weights[self.d.group[i]])) {
            return None;
        }
        // Each share of the triangle's columns over every row ([`by_columns`]);
        // the first also sums `Δpᵀ W² Δp` and counts the equations.
        let parts = self.by_columns(|t, columns| {
            let mut info = DMatrix::<f64>::zeros(n, n);
            let mut eta = DVector::<f64>::zeros(n);
            let (mut yy, mut equations) = (0.0, 0);
            self.each_block(columns.end, |rows, b| {
                let mut terms = Vec::with_capacity(rows.len());
                for (k, &i) in rows.iter().enumerate() {
                    let w = weights[self.d.group[i]];
                    let (f, y) = ([w[0] * w[0], w[1] * w[1], w[2] * w[2]], self.y(i));
                    if t == 0 {
                        yy = ((yy + f[0] * y[0] * y[0]) + f[1] * y[1] * y[1]) + f[2] * y[2] * y[2];
                        equations += f.iter().filter(|f| **f > 0.0).count();
                    }
                    terms.push(Term {
                        b: self.row_of(b, k),
                        k: f,
                        y,
                    });
                }
                let (m, e) = (info.as_mut_slice(), Some(eta.as_mut_slice()));
                add_terms(m, e, n, &terms, columns.clone());
            });
            (info, eta, yy, equations)
        });
        let mut parts = parts;
        let (mut info, mut eta, mut yy, mut equations) = match &parts[..] {
            // One share (a small view, or one thread): its sums are all.
            [(columns, _)] if *columns == (0..n) => parts.pop()?.1,
            _ => (DMatrix::zeros(n, n), DVector::zeros(n), 0.0, 0),
        };
        for (t, (columns, (part, part_eta, part_yy, part_equations))) in
            parts.into_iter().enumerate()
        {
            for j in columns {
                info.column_mut(j).copy_from(&part.column(j));
                eta[j] = part_eta[j];
            }
            if t == 0 {
                (yy, equations) = (part_yy, part_equations);
            }
        }
        let finite = yy.is_finite() && info.iter().chain(eta.iter()).all(|v| v.is_finite());
        finite.then(|| Accumulator::from_sums(info, eta, yy, equations))
    }

    /// `Λ = Σ Bᵀ B` of the included rows, unit weights (the independence
    /// test's information, [`super::design::Design::identifiability`]):
    /// [`Accumulator::update`]'s sums of blocks with unit weights, bit for
    /// bit; `None` where a sum is not finite.
    pub(super) fn information(&self) -> Option<Accumulator<f64, Dyn>> {
        self.sums(&vec![Vector3::repeat(1.0); self.d.groups])
    }

    /// The sandwich's middle term `M = Σ Bᵀ W² Σ² W² B` with σ of `noise`
    /// (the full symmetric matrix, as [`Accumulator::middle`]).
    fn middle(
        &self,
        weights: &[Vector3<f64>],
        noise: Noise<'_, f64>,
    ) -> Result<OMatrix<f64, Dyn, Dyn>, Error> {
        let n = self.cols.len();
        let mut m = DMatrix::<f64>::zeros(n, n);
        let ok = self.rows.iter().all(|&i| {
            let g = self.d.group[i];
            let (w, s) = (weights[g], noise.sigma(g, &weights[g]));
            w.iter().all(|w| *w >= 0.0 && w.is_finite())
                && s.iter().all(|s| *s > 0.0 && s.is_finite())
        });
        if ok {
            let parts = self.by_columns(|_, columns| {
                let mut m = DMatrix::<f64>::zeros(n, n);
                self.each_block(columns.end, |rows, b| {
                    let mut terms = Vec::with_capacity(rows.len());
                    for (r, &i) in rows.iter().enumerate() {
                        let g = self.d.group[i];
                        let (w, s) = (weights[g], noise.sigma(g, &weights[g]));
                        let k = |a: usize| {
                            let w2 = w[a] * w[a];
                            w2 * w2 * s[a] * s[a]
                        };
                        terms.push(Term {
                            b: self.row_of(b, r),
                            k: [k(0), k(1), k(2)],
                            y: [0.0; 3],
                        });
                    }
                    add_terms(m.as_mut_slice(), None, n, &terms, columns.clone());
                });
                m
            });
            for (columns, part) in parts {
                if columns == (0..n) {
                    // One share: its sum is all.
                    m = part;
                    continue;
                }
                for j in columns {
                    m.column_mut(j).copy_from(&part.column(j));
                }
            }
            if m.iter().all(|v| v.is_finite()) {
                return Ok(symmetric(&m));
            }
        }
        Ok(self.streamed(weights, Some(noise))?.middle())
    }

    /// [`crate::estimate::Reweightable::fit_weighted`]'s fit (`estimated`:
    /// [`crate::estimate::Reweightable::fit_reweighted`]'s), step by step as
    /// the core's, `M` summed alone.
    fn fit(
        &self,
        weights: &[Vector3<f64>],
        active: &[bool],
        sigma: &mut [Vector3<f64>],
        dof: &mut [Vector3<f64>],
        estimated: bool,
    ) -> Result<Fit<f64, Dyn>, Error> {
        let solution = self.weighted(weights, None)?.solve_active(active)?;
        self.residual_sigma_into(&solution, weights, sigma, dof)?;
        pool_small_groups(sigma, dof);
        let noise = Noise {
            sigma,
            estimated_from: estimated.then_some(&*dof),
        };
        let middle = self.middle(weights, noise)?;
        let covariance = solution.cov_sandwich(&middle);
        Ok(Fit {
            solution,
            covariance,
            iterations: 0,
            converged: false,
        })
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
        match (noise, &self.known) {
            (None, Some(known)) if weights.iter().all(|w| *w == Vector3::repeat(1.0)) => {
                Ok(known.clone())
            }
            (None, _) => match self.sums(weights) {
                Some(acc) => Ok(acc),
                None => self.streamed(weights, None),
            },
            (Some(noise), _) => self.streamed(weights, Some(noise)),
        }
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
        // Each group's sums in its own `sigma` (`Σ r²`) and `dof` (`Σ w² h`)
        // until the end (two vectors per group fewer: 48 MB at 10⁶
        // configurations), and its rows' count.
        sigma.fill(Vector3::zeros());
        dof.fill(Vector3::zeros());
        let (ss, h) = (&mut *sigma, &mut *dof);
        let mut n = vec![0_u32; groups];
        // `LANES` rows at a time, their three axes side by side:
        // `b[(3k + a) LANES + j]` is column `k`, axis `a` of the batch's row
        // `j` (unused lanes zero). Each row's leverages and residual on
        // worker threads, a chunk of rows at a time (each thread a run of
        // whole batches: the batches, and so each lane's arithmetic, are
        // those of one thread); then the sums per group in row order, as
        // row by row. (One thread: 0.3 s a pass at 10⁶ rows.)
        let p = self.cols.len();
        let inv = fit.lambda_inv.as_slice();
        let x = fit.x.as_slice();
        let batch_run = |rows: &[usize]| {
            let mut b = vec![0.0; 3 * p * LANES];
            let mut out = Vec::with_capacity(rows.len());
            for batch in rows.chunks(LANES) {
                b.fill(0.0);
                for (j, &i) in batch.iter().enumerate() {
                    for a in 0..3 {
                        for k in 0..p {
                            b[(3 * k + a) * LANES + j] = self.at(i, a, k);
                        }
                    }
                }
                let q = leverage3_rows(inv, p, &b);
                for (j, &i) in batch.iter().enumerate() {
                    let q = [q[j], q[LANES + j], q[2 * LANES + j]];
                    out.push((q, self.d.residual(self.cols, x, i)));
                }
            }
            out
        };
        for chunk in self.rows.chunks(LEVERAGE_CHUNK) {
            let threads = super::parallel::for_rows(chunk.len());
            let per = chunk.len().div_ceil(threads).next_multiple_of(LANES);
            let parts = super::parallel::map(chunk.len().div_ceil(per), threads, |t| {
                batch_run(&chunk[t * per..((t + 1) * per).min(chunk.len())])
            });
            for (&i, (q, r)) in chunk.iter().zip(parts.into_iter().flatten()) {
                let g = self.d.group[i];
                ss[g] += r.component_mul(&r);
                for a in 0..3 {
                    h[g][a] += weights[g][a] * weights[g][a] * q[a];
                }
                n[g] += 1;
            }
        }
        for g in 0..groups {
            let (ss, h, n) = (sigma[g], dof[g], n[g] as usize);
            sigma[g] = Vector3::from_fn(|a, _| group_sigma(ss[a], n, h[a]));
            if let Some(floor) = self.floor.and_then(|f| f.get(g)) {
                sigma[g] = sigma[g].sup(floor);
            }
            dof[g] = Vector3::from_fn(|a, _| group_dof(n, h[a]));
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::design::testing::{design, rng};

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
        let mut next = rng(7);
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

    fn same(a: &[f64], b: &[f64]) {
        assert_eq!(a.len(), b.len());
        for (a, b) in a.iter().zip(b) {
            assert_eq!(a.to_bits(), b.to_bits(), "{a} vs {b}");
        }
    }

    /// The leverage pass on worker threads (a chunk of rows at a time) is
    /// the pass on one thread (inside a worker, [`super::super::parallel`]
    /// gives one), bit for bit: more rows than a chunk, groups across the
    /// threads' runs and the chunks' ends.
    #[test]
    fn residual_sigma_on_threads_is_the_serial_one() {
        let d = design(5000, 7, 9, 11);
        let cols: Vec<usize> = (0..9).collect();
        let v = View::new(&d, &cols, None, None);
        let weights: Vec<Vector3<f64>> = (0..d.groups)
            .map(|g| Vector3::new(1.0, 0.5 + (g % 3) as f64, 2.0))
            .collect();
        let fit = v
            .weighted(&weights, None)
            .expect("sums")
            .solve_active(&[true; 9])
            .expect("solution");
        let run = || {
            let mut sigma = vec![Vector3::zeros(); d.groups];
            let mut dof = vec![Vector3::zeros(); d.groups];
            v.residual_sigma_into(&fit, &weights, &mut sigma, &mut dof)
                .expect("sigma");
            let flat =
                |v: Vec<Vector3<f64>>| v.iter().flat_map(|v| v.iter().copied()).collect::<Vec<_>>();
            (flat(sigma), flat(dof))
        };
        let threads = run();
        let serial = super::super::parallel::map(2, 2, |k| (k == 0).then(run))
            .into_iter()
            .flatten()
            .next()
            .expect("serial");
        same(&threads.0, &serial.0);
        same(&threads.1, &serial.1);
    }

    #[test]
    fn the_sums_are_the_cores_bit_for_bit() {
        // Odd and even row counts (the pairs and the last row alone), some
        // zero weights, every column or some.
        for (groups, per, n, seed) in [(5, 3, 7, 1), (4, 4, 43, 2), (1, 1, 3, 3)] {
            let d = design(groups, per, n, seed);
            let mut next = rng(seed + 10);
            let weights: Vec<Vector3<f64>> = (0..groups)
                .map(|g| {
                    let w = Vector3::from_fn(|_, _| next() + 0.6);
                    if g == 1 {
                        Vector3::new(0.0, w.y, w.z)
                    } else {
                        w
                    }
                })
                .collect();
            let sigma: Vec<Vector3<f64>> = (0..groups)
                .map(|_| Vector3::from_fn(|_, _| (next() + 0.6) * 1e-5))
                .collect();
            let all: Vec<usize> = (0..n).collect();
            let some: Vec<usize> = (0..n).step_by(2).collect();
            for cols in [&all, &some] {
                for (skip, block) in [
                    (None, BLOCK_ROWS),
                    (Some(0), BLOCK_ROWS),
                    (None, 2),
                    (Some(1), 4),
                ] {
                    let v = View::blocked(&d, cols, skip, None, block);
                    let fast = v.weighted(&weights, None).expect("sums");
                    let core = v.streamed(&weights, None).expect("stream");
                    assert_eq!(fast.equations(), core.equations());
                    assert_eq!(fast.weighted_yy().to_bits(), core.weighted_yy().to_bits());
                    same(fast.eta().as_slice(), core.eta().as_slice());
                    same(fast.information().as_slice(), core.information().as_slice());
                    let noise = Noise::known(&sigma);
                    let m = v.middle(&weights, noise).expect("middle");
                    let core = v.streamed(&weights, Some(noise)).expect("stream");
                    same(m.as_slice(), core.middle().as_slice());
                }
            }
        }
    }

    #[test]
    fn the_information_is_the_unit_weight_blocks_bit_for_bit() {
        // What `Design::identifiability` streamed before: blocks of the
        // columns with unit weights and Δp = 0, one `update` per row.
        for (groups, per, n, seed) in [(5, 3, 7, 4), (4, 4, 43, 5), (1, 1, 3, 6)] {
            let d = design(groups, per, n, seed);
            let cols: Vec<usize> = (0..n).rev().step_by(2).collect();
            let fast = View::new(&d, &cols, None, None)
                .information()
                .expect("finite");
            let mut core = Accumulator::<f64, Dyn>::zeros(Dyn(cols.len()));
            for i in 0..d.rows() {
                let b =
                    OMatrix::<f64, U3, Dyn>::from_fn(cols.len(), |a, k| d.b[(3 * i + a, cols[k])]);
                core.update(&Block::new(b, Vector3::zeros()))
                    .expect("finite");
            }
            same(fast.information().as_slice(), core.information().as_slice());
        }
    }

    #[test]
    fn bad_weights_give_the_cores_errors() {
        let d = design(3, 2, 4, 5);
        let cols: Vec<usize> = (0..4).collect();
        let v = View::new(&d, &cols, None, None);
        for bad in [-1.0, f64::NAN, f64::INFINITY] {
            let mut w = vec![Vector3::repeat(1.0); 3];
            w[1].y = bad;
            assert_eq!(
                v.weighted(&w, None).map(|_| ()),
                v.streamed(&w, None).map(|_| ())
            );
            let sigma = vec![Vector3::repeat(1e-5); 3];
            assert_eq!(
                v.middle(&w, Noise::known(&sigma)).map(|_| ()),
                v.streamed(&w, Some(Noise::known(&sigma))).map(|_| ())
            );
        }
    }
}
