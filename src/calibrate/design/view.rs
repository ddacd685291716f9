//! The rows of a [`Design`] on some of its columns, optionally without one
//! configuration: the [`Reweightable`] source of the host's row-by-row fits
//! ([`crate::calibrate::fit::fit`]).
//!
//! Every sum is the core's ([`crate::estimate::Accumulator::update`] and
//! [`crate::estimate::leverage`]), bit for bit, in a layout the processor
//! streams faster (issue 16). A view of more than [`BLOCK_ROWS`] rows is
//! summed a block of [`BLOCK_ROWS`] rows at a time, each block as the core
//! sums its rows from zero, the blocks' sums merged in row order as the
//! core merges accumulators ([`crate::estimate::Accumulator::merge`]): the
//! blocks are independent, and worker threads take them in turn, each
//! reading only its blocks' rows.
//!
//! - the included rows are copied, each row's three axes as three
//!   contiguous runs of its columns, so that the rank-3 update of a column
//!   of `Λ` runs over contiguous values (vectorised across the elements of
//!   the column, each element's sum unchanged): once per view when it has
//!   at most [`BLOCK_ROWS`] rows, else a block at a time in each pass (a
//!   copy of a million rows' columns was 190 MB while a fit ran);
//! - two rows are added per pass over the triangle (each element gets the
//!   first row's three terms, then the second's: the order of the row by
//!   row stream);
//! - the sandwich's middle term `M` is summed alone (the core's pass with σ
//!   sums `Λ` again, which the fit does not use);
//! - the leverages of four rows are computed side by side.
//!
//! Where a weight, σ or sum is not finite (or a weight negative), the
//! core's [`crate::estimate::Accumulator::update`] is run instead, over all
//! the rows in order: it gives the errors it always gave. `tests` compare
//! both ways bit for bit (the core's per block, merged).

use std::sync::Mutex;

use nalgebra::{DMatrix, DVector, Dyn, OMatrix, Vector3, U3};

use crate::calibrate::design::Design;

mod blocks;
mod terms;
use crate::error::Error;
use crate::estimate::accumulator::symmetric;
use crate::estimate::{
    group_dof, group_sigma, robust_weights, Accumulator, Block, Fit, Noise, Reweightable,
    RobustWeight, Solution,
};
pub(in crate::calibrate) use terms::Term;
use terms::{add_terms, leverage3_rows, LANES};

/// The rows of a [`Design`] on some of its columns, optionally without one
/// group (leave-one-out).
pub(in crate::calibrate) struct View<'a> {
    d: &'a Design,
    cols: &'a [usize],
    /// A floor for the residual σ per group and axis \[m\]: the
    /// instrument's ([`crate::calibrate::fit::Weighting::Both`]).
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
    /// The residuals of every row from the last σ pass, with the estimate
    /// they are at, when asked for ([`View::capturing`]).
    captured: Option<Mutex<Option<Captured>>>,
}

/// Residuals of every row \[m, scaled\] and the estimate they are at.
type Captured = (Vec<f64>, Vec<Vector3<f64>>);

/// One block's sums: `Λ` (upper triangle), `η`, `Σ Δpᵀ W² Δp` and the
/// equations with a positive weight.
pub(in crate::calibrate) type Sums = (DMatrix<f64>, DVector<f64>, f64, usize);

/// The sums of a block of rows, each a [`Term`] (its three axes' columns,
/// `w²` per axis, `Δp`), in order, from zero: `Λ`'s columns `columns` (and
/// their `η`), and with `first` also `Σ Δpᵀ W² Δp` and the equations
/// ([`View::sums`]' block, and the relinearisation's
/// ([`crate::calibrate::design::Design::relinearised`])).
pub(in crate::calibrate) fn block_sums<'b>(
    n: usize,
    rows: impl Iterator<Item = Term<'b>>,
    columns: std::ops::Range<usize>,
    first: bool,
) -> Sums {
    let mut info = DMatrix::<f64>::zeros(n, n);
    let mut eta = DVector::<f64>::zeros(n);
    let (mut yy, mut equations) = (0.0, 0);
    let terms: Vec<Term<'b>> = rows
        .inspect(|t| {
            if first {
                let (f, y) = (t.k, t.y);
                yy = ((yy + f[0] * y[0] * y[0]) + f[1] * y[1] * y[1]) + f[2] * y[2] * y[2];
                equations += f.iter().filter(|f| **f > 0.0).count();
            }
        })
        .collect();
    add_terms(
        info.as_mut_slice(),
        Some(eta.as_mut_slice()),
        n,
        &terms,
        columns,
    );
    (info, eta, yy, equations)
}

/// The sums of blocks, in order, each from its shares of the triangle's
/// columns (the first share's `Δpᵀ W² Δp` and equations), merged as the
/// core merges accumulators ([`Accumulator::merge`]); `None` where a sum
/// is not finite (or there is no block).
pub(in crate::calibrate) fn merged(
    n: usize,
    blocks: Vec<Vec<(std::ops::Range<usize>, Sums)>>,
) -> Option<Accumulator<f64, Dyn>> {
    let mut all: Option<Accumulator<f64, Dyn>> = None;
    for mut parts in blocks {
        let (mut info, mut eta, mut yy, mut equations) = match &parts[..] {
            // One share: its sums are all.
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
        let block = Accumulator::from_sums(info, eta, yy, equations);
        match &mut all {
            None => all = Some(block),
            Some(all) => all.merge(&block).ok()?,
        }
    }
    let all = all?;
    let finite = all.weighted_yy().is_finite()
        && all
            .information()
            .iter()
            .chain(all.eta().iter())
            .all(|v| v.is_finite());
    finite.then_some(all)
}

/// Rows a view copies at a time ([`View`]).
pub(in crate::calibrate) const BLOCK_ROWS: usize = 4096;

/// Rows whose leverages and residuals are computed before they are summed
/// ([`Reweightable::residual_sigma_into`]; a multiple of [`LANES`]).
const LEVERAGE_CHUNK: usize = 1 << 15;

impl<'a> View<'a> {
    /// The rows of `d` on the columns `cols`, without the groups `skip`
    /// (a configuration left out: [`crate::calibrate::rows::Rows::fold`]).
    pub(in crate::calibrate) fn new(
        d: &'a Design,
        cols: &'a [usize],
        skip: &[usize],
        floor: Option<&'a [Vector3<f64>]>,
    ) -> Self {
        Self::blocked(d, cols, skip, floor, BLOCK_ROWS)
    }

    /// [`View::new`], copying `block` rows at a time (rounded up to even).
    fn blocked(
        d: &'a Design,
        cols: &'a [usize],
        skip: &[usize],
        floor: Option<&'a [Vector3<f64>]>,
        block: usize,
    ) -> Self {
        let rows: Vec<usize> = (0..d.rows())
            .filter(|&i| !skip.contains(&d.group[i]))
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
            captured: None,
        };
        if view.rows.len() <= block {
            view.b = view.copy(0, view.rows.len());
        }
        view
    }

    /// The view that keeps the residuals of its last σ pass
    /// ([`View::residuals_at`]) when it has every row (a pass fewer after
    /// the fit when the design does not hold its columns).
    pub(in crate::calibrate) fn capturing(mut self) -> Self {
        if self.rows.len() == self.d.rows() {
            self.captured = Some(Mutex::new(None));
        }
        self
    }

    /// The residuals of every row at `x` ([`crate::calibrate::design::Design::residual`],
    /// bit for bit), when the view's last σ pass was at `x`.
    pub(in crate::calibrate) fn residuals_at(&self, x: &[f64]) -> Option<Vec<Vector3<f64>>> {
        let mut slot = self.captured.as_ref()?.lock().ok()?;
        let (at, r) = slot.take()?;
        let same = at.len() == x.len() && at.iter().zip(x).all(|(a, b)| a.to_bits() == b.to_bits());
        same.then_some(r)
    }

    /// The view whose sums at unit weights ([`View::information`]) are
    /// `known`: an OLS fit on it makes no pass for them.
    pub(in crate::calibrate) fn knowing(mut self, known: Accumulator<f64, Dyn>) -> Self {
        self.known = Some(known);
        self
    }

    /// The weights of group `g` as they enter the sums: `weights[g]`, zero
    /// on the axes that are no equations ([`Design::live`]).
    fn w(&self, weights: &[Vector3<f64>], g: usize) -> Vector3<f64> {
        weights[g].component_mul(&self.d.live(g))
    }

    /// The σ of group `g` as they enter the middle term: `noise`'s, 1 on
    /// the axes that are no equations (their weight is 0 there: any
    /// positive σ gives the same sums, and the core takes none other).
    fn s(&self, noise: Noise<'_, f64>, weights: &[Vector3<f64>], g: usize) -> Vector3<f64> {
        let s = noise.sigma(g, &weights[g]);
        Vector3::from_fn(|a, _| if self.d.is_live(g, a) { s[a] } else { 1.0 })
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
        self.streamed_rows(&self.rows, weights, noise)
    }

    /// [`View::streamed`] of the design rows `rows`.
    fn streamed_rows(
        &self,
        rows: &[usize],
        weights: &[Vector3<f64>],
        noise: Option<Noise<'_, f64>>,
    ) -> Result<Accumulator<f64, Dyn>, Error> {
        let n = self.cols.len();
        let mut acc = Accumulator::zeros(Dyn(n));
        // One block, refilled for every row.
        let mut block = Block::new(OMatrix::<f64, U3, Dyn>::zeros(n), Vector3::zeros());
        let mut row = Vec::new();
        for &i in rows {
            let g = self.d.group[i];
            self.d.rows_into(&[i], self.cols, &mut row);
            for a in 0..3 {
                for k in 0..n {
                    block.b[(a, k)] = row[a * n + k];
                }
            }
            block.dp = Vector3::from(self.y(i));
            block.w = self.w(weights, g);
            block.sigma = noise.map(|n| self.s(n, weights, g));
            acc.update(&block)?;
        }
        Ok(acc)
    }

    /// `Λ` (upper triangle), `η`, `Σ Δpᵀ W² Δp` and the rows with a
    /// positive weight, as [`Accumulator::update`] sums them; `None` where
    /// a weight is negative or anything is not finite.
    fn sums(&self, weights: &[Vector3<f64>]) -> Option<Accumulator<f64, Dyn>> {
        if let Some(made) = self.made(weights) {
            return Some(made);
        }
        let n = self.cols.len();
        let ok = |w: &Vector3<f64>| w.iter().all(|w| *w >= 0.0 && w.is_finite());
        if !self.rows.iter().all(|&i| ok(&weights[self.d.group[i]])) {
            return None;
        }
        // Each block's sums, its columns shared between threads or all on
        // one ([`View::by_blocks`]); the first share of a block also sums
        // `Δpᵀ W² Δp` and counts the equations.
        let blocks = self.by_blocks(|t, rows, b, columns| {
            let terms = rows.iter().enumerate().map(|(k, &i)| {
                let w = self.w(weights, self.d.group[i]);
                Term {
                    b: self.row_of(b, k),
                    k: [w[0] * w[0], w[1] * w[1], w[2] * w[2]],
                    y: self.y(i),
                }
            });
            block_sums(n, terms, columns, t == 0)
        });
        merged(n, blocks)
    }

    /// `Λ = Σ Bᵀ B` of the included rows, unit weights (the independence
    /// test's information, [`crate::calibrate::design::Design::identifiability`]):
    /// [`Accumulator::update`]'s sums of blocks with unit weights, bit for
    /// bit; `None` where a sum is not finite.
    pub(in crate::calibrate) fn information(&self) -> Option<Accumulator<f64, Dyn>> {
        self.sums(&vec![Vector3::repeat(1.0); self.d.groups])
    }

    /// The design's own unit-weight sums ([`Design`]'s `unit_sums`, made
    /// in the pass that built it), when this view is every row on every
    /// column and `weights` are all one: what [`View::sums`] gives, bit
    /// for bit, without a pass.
    fn made(&self, weights: &[Vector3<f64>]) -> Option<Accumulator<f64, Dyn>> {
        let sums = self.d.unit_sums.as_ref()?;
        let every = self.rows.len() == self.d.rows()
            && self.cols.len() == self.d.params.len()
            && self.cols.iter().enumerate().all(|(k, &c)| k == c)
            && weights.iter().all(|w| *w == Vector3::repeat(1.0));
        every.then(|| sums.clone())
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
            let (w, s) = (weights[g], self.s(noise, weights, g));
            w.iter().all(|w| *w >= 0.0 && w.is_finite())
                && s.iter().all(|s| *s > 0.0 && s.is_finite())
        });
        if ok {
            let blocks = self.by_blocks(|_, rows, b, columns| {
                let mut m = DMatrix::<f64>::zeros(n, n);
                let mut terms = Vec::with_capacity(rows.len());
                for (r, &i) in rows.iter().enumerate() {
                    let g = self.d.group[i];
                    let (w, s) = (self.w(weights, g), self.s(noise, weights, g));
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
                m
            });
            // Each block's `M` from its shares, the blocks' added in order
            // (as [`Accumulator::merge`] adds the middle terms).
            for (k, parts) in blocks.into_iter().enumerate() {
                let mut block = DMatrix::<f64>::zeros(n, n);
                for (columns, part) in parts {
                    if columns == (0..n) {
                        // One share: its sum is all.
                        block = part;
                        continue;
                    }
                    for j in columns {
                        block.column_mut(j).copy_from(&part.column(j));
                    }
                }
                if k == 0 {
                    m = block;
                } else {
                    m += &block;
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
        crate::calibrate::design::pool(&self.d.pools, sigma, dof);
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
        let mut kept = self
            .captured
            .as_ref()
            .map(|_| Vec::with_capacity(self.rows.len()));
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
            let mut copy = Vec::new();
            let mut out = Vec::with_capacity(rows.len());
            for batch in rows.chunks(LANES) {
                b.fill(0.0);
                self.d.rows_into(batch, self.cols, &mut copy);
                for j in 0..batch.len() {
                    for a in 0..3 {
                        for k in 0..p {
                            b[(3 * k + a) * LANES + j] = copy[(3 * j + a) * p + k];
                        }
                    }
                }
                let q = leverage3_rows(inv, p, &b);
                for (j, &i) in batch.iter().enumerate() {
                    let q = [q[j], q[LANES + j], q[2 * LANES + j]];
                    out.push((
                        q,
                        self.d.residual_of(i, &copy[3 * j * p..3 * (j + 1) * p], x),
                    ));
                }
            }
            out
        };
        for chunk in self.rows.chunks(LEVERAGE_CHUNK) {
            let threads = crate::parallel::for_rows(chunk.len());
            let per = chunk.len().div_ceil(threads).next_multiple_of(LANES);
            let parts = crate::parallel::map(chunk.len().div_ceil(per), threads, |t| {
                batch_run(&chunk[t * per..((t + 1) * per).min(chunk.len())])
            });
            for (&i, (q, r)) in chunk.iter().zip(parts.into_iter().flatten()) {
                if let Some(kept) = &mut kept {
                    kept.push(r);
                }
                let g = self.d.group[i];
                ss[g] += r.component_mul(&r);
                let w = self.w(weights, g);
                for a in 0..3 {
                    h[g][a] += w[a] * w[a] * q[a];
                }
                n[g] += 1;
            }
        }
        for g in 0..groups {
            let (ss, h) = (sigma[g], dof[g]);
            // A scalar row's second and third axes are no equations.
            let n = |a: usize| {
                if self.d.is_live(g, a) {
                    n[g] as usize
                } else {
                    0
                }
            };
            sigma[g] = Vector3::from_fn(|a, _| group_sigma(ss[a], n(a), h[a]));
            if let Some(floor) = self.floor.and_then(|f| f.get(g)) {
                sigma[g] = sigma[g].sup(floor);
            }
            dof[g] = Vector3::from_fn(|a, _| group_dof(n(a), h[a]));
        }
        if let (Some(slot), Some(kept)) = (&self.captured, kept) {
            if let Ok(mut slot) = slot.lock() {
                *slot = Some((x.to_vec(), kept));
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

#[cfg(test)]
mod tests;
