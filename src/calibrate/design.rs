//! The design: the columns of a list of parameters at every row (`B` of
//! eq. 4, stacked), and which of them the data can tell apart.
//!
//! Its parts: how the columns are computed at a row (`columns`), built
//! (`build`) into storage held or computed again where read (`source`,
//! `Policy::max_held_design_rows`), their unit-weight sums made in the same
//! pass (`unit_sums`), the rows of each configuration (`group_rows`), the
//! independence test on the columns themselves (`kept`), and the rows as
//! the core's source of sums, bit for bit, in a faster layout (`view`,
//! with the widest instruction set found at run time, `widest`).

use nalgebra::{Dyn, OMatrix, Vector3, U3};

use crate::calibrate::design::view::View;
use crate::calibrate::rows::Rows;
use crate::estimate::{
    identifiability_excluding, independence_tolerance, Accumulator, Block, Identifiability,
    IdentifiabilitySettings,
};
use crate::model::Param;

mod build;
mod columns;
mod group_rows;
mod kept;
mod source;
mod unit_sums;
pub(crate) mod view;
pub(crate) mod widest;
pub use build::Storage;
pub use group_rows::{GroupOf, GroupRows};

/// The columns of some parameters at every row (`3·rows × params`, row
/// `3i + a` axis `a` of row `i`, each column in its parameter's reported
/// unit): held, or computed from the rows where read (`source`; read
/// through [`Design::rows_into`], [`Design::columns_into`] and
/// [`Design::held`]).
#[derive(Debug, Clone)]
pub struct Design {
    /// The parameters, in column order.
    pub params: Vec<Param>,
    /// The columns.
    source: source::Source,
    /// Measured `Δp` \[m\], `3·rows`.
    pub y: Vec<f64>,
    /// Group (configuration index) of every row.
    pub group: Vec<usize>,
    /// Number of groups.
    pub groups: usize,
    /// The instrument's σ per group and axis \[m\] (the root mean square of
    /// its rows'), when every row has one (data contract 7.2).
    pub instrument_sigma: Option<Vec<Vector3<f64>>>,
    /// The unit-weight sums `Σ BᵀB`, `Σ Bᵀ Δp` of all the columns and rows,
    /// when the pass that built the design made them
    /// ([`Design::relinearised`]; the passes over the design then use them,
    /// bit for bit the sums they would make). `None` for a design built
    /// otherwise, and to be set to `None` by whoever changes `b` or `y`.
    pub unit_sums: Option<Accumulator<f64, Dyn>>,
    /// The groups whose rows are one equation each, on axis 0 (a distance
    /// or a plane contact: [`crate::calibrate::rows::Scalar`]); their
    /// other two axes are zero and not equations: weight 0 in every sum,
    /// no rows in their cells of eq. 14's σ. Empty: none.
    pub scalar_groups: std::ops::Range<usize>,
    /// The runs of groups whose small groups' σ pool together (eq. 14's
    /// [`crate::estimate::pool_small_groups`]): the points', the plane
    /// contacts' and distances', the orientations' — each a quantity of
    /// its own (µm of a point, of a distance, µrad). Empty: every group.
    pub pools: Vec<std::ops::Range<usize>>,
}

/// [`crate::estimate::pool_small_groups`] within each of `pools`
/// ([`Design::pools`]; empty: over every group).
pub(crate) fn pool(
    pools: &[std::ops::Range<usize>],
    sigma: &mut [Vector3<f64>],
    dof: &mut [Vector3<f64>],
) {
    if pools.is_empty() {
        crate::estimate::pool_small_groups(sigma, dof);
    }
    for r in pools {
        if let (Some(s), Some(d)) = (sigma.get_mut(r.clone()), dof.get_mut(r.clone())) {
            crate::estimate::pool_small_groups(s, d);
        }
    }
}

impl Design {
    /// The rows of each group, in row order ([`GroupRows`]); `None` when a
    /// row's group is not below [`Design::groups`].
    pub fn group_rows(&self) -> Option<GroupRows> {
        GroupRows::new(&self.group, self.groups)
    }

    /// Which axes of group `g`'s rows are equations: `1` or `0` per axis
    /// (`0` for the second and third axis of [`Design::scalar_groups`]).
    pub fn live(&self, g: usize) -> Vector3<f64> {
        if self.scalar_groups.contains(&g) {
            Vector3::from(crate::calibrate::rows::scalar::LIVE)
        } else {
            Vector3::repeat(1.0)
        }
    }

    /// Whether axis `a` of group `g`'s rows is an equation
    /// ([`Design::live`]).
    pub fn is_live(&self, g: usize, a: usize) -> bool {
        self.live(g)[a] > 0.0
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.group.len()
    }

    /// Column index of a parameter.
    pub fn index(&self, p: &Param) -> Option<usize> {
        self.params.iter().position(|u| u == p)
    }

    /// Residual `Δp − B x` \[m\] of row `i` (scaled: [`Rows::noise_scale`]).
    pub fn residual(&self, cols: &[usize], x: &[f64], i: usize) -> Vector3<f64> {
        let mut row = Vec::new();
        self.rows_into(&[i], cols, &mut row);
        self.residual_of(i, &row, x)
    }

    /// [`Design::residual`] of row `i` from its columns `row`
    /// ([`Design::rows_into`] of it alone: axis `a` at
    /// `[a·n..(a + 1)·n]`).
    pub fn residual_of(&self, i: usize, row: &[f64], x: &[f64]) -> Vector3<f64> {
        let n = x.len();
        let mut r = Vector3::new(self.y[3 * i], self.y[3 * i + 1], self.y[3 * i + 2]);
        for (k, &v) in x.iter().enumerate() {
            for a in 0..3 {
                r[a] -= row[a * n + k] * v;
            }
        }
        r
    }

    /// [`Design::residual`] of every row, in metres again
    /// ([`Rows::unscaled`]), by runs of rows on worker threads.
    pub fn residuals(&self, all: &Rows, cols: &[usize], x: &[f64]) -> Vec<Vector3<f64>> {
        let threads = crate::parallel::for_rows(self.rows());
        self.residuals_on(cols, x, threads, |i, r| all.unscaled(i, r))
    }

    /// [`Design::residual`] of every row, scaled as the fit sees them, by
    /// runs of rows on worker threads.
    pub fn scaled_residuals(&self, cols: &[usize], x: &[f64]) -> Vec<Vector3<f64>> {
        let threads = crate::parallel::for_rows(self.rows());
        self.residuals_on(cols, x, threads, |_, r| r)
    }

    /// `unscaled(i, `[`Design::residual`]`(cols, x, i))` of every row `i`,
    /// on `threads` threads.
    fn residuals_on(
        &self,
        cols: &[usize],
        x: &[f64],
        threads: usize,
        unscaled: impl Fn(usize, Vector3<f64>) -> Vector3<f64> + Sync,
    ) -> Vec<Vector3<f64>> {
        let mut out = vec![Vector3::zeros(); self.rows()];
        let done = crate::parallel::for_runs_mut(&mut out, threads, |first, run| {
            let mut row = Vec::new();
            for (i, r) in (first..).zip(run) {
                self.rows_into(&[i], cols, &mut row);
                *r = unscaled(i, self.residual_of(i, &row, x));
            }
            Ok::<(), std::convert::Infallible>(())
        });
        let Ok(()) = done;
        out
    }

    /// Of the columns `extra`, those that are not (numerically) combinations
    /// of the columns `base` and of the extra columns kept before them: the
    /// one column-independence test of robcal
    /// ([`crate::estimate::rank`]), on the unweighted columns, in order.
    pub fn independent(&self, base: &[usize], extra: &[usize]) -> Vec<usize> {
        let Some(rank) = self.identifiability(base, extra) else {
            return Vec::new();
        };
        extra
            .iter()
            .enumerate()
            .filter(|(k, _)| rank.kept[base.len() + k])
            .map(|(_, &c)| c)
            .collect()
    }

    /// The one column-independence test ([`crate::estimate::rank`]) of the
    /// columns `base` then `extra`, in that order (index `k` of the result is
    /// the `k`-th of them): what is kept, what absorbs what is left out,
    /// each kept parameter's variance inflation. `None` when there is no
    /// column (or the columns are not finite).
    pub fn identifiability(
        &self,
        base: &[usize],
        extra: &[usize],
    ) -> Option<Identifiability<f64, Dyn>> {
        let cols: Vec<usize> = base.iter().chain(extra).copied().collect();
        let n = cols.len();
        if n == 0 {
            return None;
        }
        // Λ in the view's layout (the same sums as the blocks below), its
        // columns shared between threads with many rows; the blocks where a
        // sum is not finite (the core's checks decide). (With the view's
        // former column-by-column copy the blocks were faster past one copy
        // of rows; 10⁶ rows: the blocks 0.17 s on one thread.)
        if let Some(acc) = View::new(self, &cols, &[], None).information() {
            return self.identifiability_of(&cols, &acc);
        }
        let mut acc = Accumulator::<f64, Dyn>::zeros(Dyn(n));
        let mut block = Block::new(OMatrix::<f64, U3, Dyn>::zeros(n), Vector3::zeros());
        let b = self.held();
        for i in 0..self.rows() {
            for (k, &c) in cols.iter().enumerate() {
                for a in 0..3 {
                    block.b[(a, k)] = b[(3 * i + a, c)];
                }
            }
            // Finite by construction (the columns were checked when built).
            let _ = acc.update(&block);
        }
        self.identifiability_of(&cols, &acc)
    }

    /// The independence test of the columns `cols` from their unit-weight
    /// sums `acc` (made before, e.g. by an OLS fit): the core's on `Λ`
    /// ([`Accumulator::identifiable`]), and when `Λ` is ill-conditioned
    /// (the ratio of its smallest kept pivot to its largest below
    /// [`CHECK_RCOND`]) checked on the columns themselves
    /// ([`Design::kept_by_columns`]): a column they find dependent is left
    /// out, whatever its pivot in `Λ`.
    pub fn identifiability_of(
        &self,
        cols: &[usize],
        acc: &Accumulator<f64, Dyn>,
    ) -> Option<Identifiability<f64, Dyn>> {
        let rank = acc.identifiable().ok()?;
        if rank.rcond >= CHECK_RCOND {
            return Some(rank);
        }
        let kept = self.kept_by_columns(cols, independence_tolerance());
        let excluded: Vec<bool> = kept.iter().map(|k| !k).collect();
        if !excluded.iter().zip(rank.kept.iter()).any(|(&x, &k)| x && k) {
            return Some(rank);
        }
        let all = vec![true; cols.len()];
        identifiability_excluding(
            &acc.information(),
            &all,
            &excluded,
            &IdentifiabilitySettings::default(),
        )
        .ok()
    }
}

/// Below this ratio of the smallest kept pivot of `Λ` to the largest, the
/// independence test is checked on the columns themselves
/// ([`Design::identifiability_of`]). 1e-3: above it a pivot's rounding,
/// about `ε·√rows / rcond` (at worst `ε·rows / rcond`), is 4e-10 at 3·10⁶
/// equations (at worst 7e-7), below the tolerance (1e-6); well-conditioned
/// models pay nothing.
pub const CHECK_RCOND: f64 = 1e-3;

/// Pseudo-random designs for the unit tests of what reads a design.
#[cfg(test)]
pub(crate) mod testing;
#[cfg(test)]
mod threads;

#[cfg(test)]
mod tests {
    use crate::calibrate::design::testing::design;

    #[test]
    fn residuals_on_threads_are_the_rows_residuals() {
        let d = design(3001, 3, 5, 7);
        let (cols, x) = ([4, 0, 2], [0.3, -1.5, 2.0e-3]);
        let serial: Vec<_> = (0..d.rows())
            .map(|i| d.residual(&cols, &x, i) * (i + 1) as f64)
            .collect();
        for threads in 1..=3 {
            let r = d.residuals_on(&cols, &x, threads, |i, r| r * (i + 1) as f64);
            assert_eq!(r, serial, "{threads} threads");
        }
    }
}
