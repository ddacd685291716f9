//! The host problem: rows kept in memory, their columns for a list of
//! [`Term`]s, and the fits of [`crate::irls`] on them through
//! [`Reweightable`], dispatched to the smallest const-generic capacity
//! `N ∈ {16, 32, 64, 128}` that holds the columns (inactive ones masked).

use nalgebra::{DMatrix, SMatrix, SVector, Vector3};

use crate::accumulator::{Accumulator, Block};
use crate::diagnose::{nested_test, NestedTest};
use crate::irls::{robust_weights, Fit, IrlsSettings, Reweightable};
use crate::weights::RobustWeight;
use crate::Error;

use super::terms::{Context, Row, Term};

/// Largest number of columns a fit or a test can hold.
pub const MAX_COLUMNS: usize = 128;
/// Largest number of configurations (IRLS groups).
pub const MAX_GROUPS: usize = 512;

/// Estimation method (data contract §4).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Iteratively reweighted least squares (eq. 14, section 5).
    Irls,
    /// One reweighting step from OLS (eq. 10, 14).
    Wls,
    /// Ordinary least squares (eq. 6).
    Ols,
}

impl Method {
    /// Its name in the contract.
    pub fn name(self) -> &'static str {
        match self {
            Method::Irls => "irls",
            Method::Wls => "wls",
            Method::Ols => "ols",
        }
    }
}

/// The columns of some terms at every row: `b` is `3·rows × terms`, row
/// `3i + a` is axis `a` of row `i`.
#[derive(Debug, Clone)]
pub struct Design {
    /// The terms, in column order.
    pub terms: Vec<Term>,
    /// Columns in the reported units.
    pub b: DMatrix<f64>,
    /// Measured `Δp` \[m\], `3·rows`.
    pub y: Vec<f64>,
    /// Group (configuration index) of every row.
    pub group: Vec<usize>,
    /// Number of groups.
    pub groups: usize,
}

impl Design {
    /// Columns of `terms` at `rows`.
    pub fn new(ctx: &Context, rows: &[Row], terms: &[Term], groups: usize) -> Self {
        let mut b = DMatrix::zeros(3 * rows.len(), terms.len());
        let mut y = Vec::with_capacity(3 * rows.len());
        for (i, row) in rows.iter().enumerate() {
            for (c, t) in terms.iter().enumerate() {
                let col = ctx.column(t, row);
                for a in 0..3 {
                    b[(3 * i + a, c)] = col[a];
                }
            }
            y.extend_from_slice(row.y.as_slice());
        }
        Self {
            terms: terms.to_vec(),
            b,
            y,
            group: rows.iter().map(|r| r.group).collect(),
            groups,
        }
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.group.len()
    }

    /// Column index of a term.
    pub fn index(&self, t: &Term) -> Option<usize> {
        self.terms.iter().position(|u| u == t)
    }

    /// Residual `Δp − B x` \[m\] of row `i` for `x` on columns `cols`.
    pub fn residual(&self, cols: &[usize], x: &[f64], i: usize) -> Vector3<f64> {
        let mut r = Vector3::new(self.y[3 * i], self.y[3 * i + 1], self.y[3 * i + 2]);
        for (&c, &v) in cols.iter().zip(x) {
            for a in 0..3 {
                r[a] -= self.b[(3 * i + a, c)] * v;
            }
        }
        r
    }
}

/// A fit on some columns: the estimate and its noise model.
#[derive(Debug, Clone)]
pub struct FitOut {
    /// Column indices into the [`Design`].
    pub cols: Vec<usize>,
    /// Estimate, one per column, in the reported units.
    pub x: Vec<f64>,
    /// One standard deviation (sandwich covariance, eq. 8 / 11).
    pub std: Vec<f64>,
    /// Weights per group and axis the fit used.
    pub weights: Vec<Vector3<f64>>,
    /// Residual σ per group and axis \[m\].
    pub sigma: Vec<Vector3<f64>>,
    /// Reweighting iterations.
    pub iterations: usize,
    /// Whether IRLS converged.
    pub converged: bool,
}

/// The rows of a [`Design`] on some of its columns, optionally without one
/// group (leave-one-out), seen with capacity `N`.
struct View<'a, const N: usize> {
    d: &'a Design,
    cols: &'a [usize],
    skip_group: Option<usize>,
}

impl<const N: usize> View<'_, N> {
    fn block(&self, i: usize) -> SMatrix<f64, 3, N> {
        let mut b = SMatrix::<f64, 3, N>::zeros();
        for (k, &c) in self.cols.iter().enumerate() {
            for a in 0..3 {
                b[(a, k)] = self.d.b[(3 * i + a, c)];
            }
        }
        b
    }

    fn included(&self, i: usize) -> bool {
        Some(self.d.group[i]) != self.skip_group
    }
}

impl<const N: usize> Reweightable<f64, N> for View<'_, N> {
    fn group_count(&self) -> usize {
        self.d.groups
    }

    fn weighted(
        &self,
        weights: &[Vector3<f64>],
        sigma: Option<&[Vector3<f64>]>,
    ) -> Result<Accumulator<f64, N>, Error> {
        if weights.len() != self.d.groups || sigma.is_some_and(|s| s.len() != self.d.groups) {
            return Err(Error::Mismatch {
                what: "one weight per group",
            });
        }
        let mut acc = Accumulator::new();
        for i in 0..self.d.rows() {
            if !self.included(i) {
                continue;
            }
            let g = self.d.group[i];
            let dp = Vector3::new(self.d.y[3 * i], self.d.y[3 * i + 1], self.d.y[3 * i + 2]);
            let mut block = Block::new(self.block(i), dp).with_weights(weights[g]);
            if let Some(s) = sigma {
                block = block.with_sigma(s[g]);
            }
            acc.update(&block)?;
        }
        Ok(acc)
    }

    fn residual_sigma_into(
        &self,
        x: &SVector<f64, N>,
        parameters: usize,
        out: &mut [Vector3<f64>],
    ) -> Result<(), Error> {
        if out.len() != self.d.groups {
            return Err(Error::Mismatch {
                what: "one sigma per group",
            });
        }
        let mut ss = vec![Vector3::<f64>::zeros(); self.d.groups];
        let mut n = vec![0usize; self.d.groups];
        let mut m = 0usize;
        let xs: Vec<f64> = (0..self.cols.len()).map(|k| x[k]).collect();
        for i in 0..self.d.rows() {
            if !self.included(i) {
                continue;
            }
            let r = self.d.residual(self.cols, &xs, i);
            let g = self.d.group[i];
            ss[g] += r.component_mul(&r);
            n[g] += 1;
            m += 3;
        }
        let dof = m as f64 / (m.saturating_sub(parameters).max(1)) as f64;
        for g in 0..self.d.groups {
            out[g] = if n[g] == 0 {
                Vector3::zeros()
            } else {
                (ss[g] * (dof / n[g] as f64)).map(f64::sqrt)
            };
        }
        Ok(())
    }
}

/// Settings of a fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitSettings {
    /// OLS, one WLS step or IRLS.
    pub method: Method,
    /// σ0 \[m\] and λ of eq. 14.
    pub weight: RobustWeight<f64>,
    /// IRLS iterations at most.
    pub max_iterations: usize,
}

macro_rules! dispatch {
    ($n:expr, $f:ident ( $($arg:expr),* )) => {
        match $n {
            0..=16 => $f::<16>($($arg),*),
            17..=32 => $f::<32>($($arg),*),
            33..=64 => $f::<64>($($arg),*),
            65..=128 => $f::<128>($($arg),*),
            _ => Err(Error::CapacityExceeded { what: "columns", capacity: MAX_COLUMNS }),
        }
    };
}

fn active<const N: usize>(p: usize) -> [bool; N] {
    let mut a = [false; N];
    for v in a.iter_mut().take(p) {
        *v = true;
    }
    a
}

fn fit_n<const N: usize>(
    d: &Design,
    cols: &[usize],
    skip_group: Option<usize>,
    s: &FitSettings,
) -> Result<FitOut, Error> {
    let view = View::<N> {
        d,
        cols,
        skip_group,
    };
    let act = active::<N>(cols.len());
    let fit: Box<Fit<f64, N, MAX_GROUPS>> = Box::new(match s.method {
        Method::Ols => view.fit_ols(&act)?,
        Method::Wls => {
            let ols: Fit<f64, N, MAX_GROUPS> = view.fit_ols(&act)?;
            let w = robust_weights::<f64, MAX_GROUPS>(&ols.sigma, &s.weight)?;
            let mut f: Fit<f64, N, MAX_GROUPS> = view.fit_weighted(&w, &act)?;
            f.iterations = 1;
            f
        }
        Method::Irls => {
            let mut settings = IrlsSettings::new(s.weight);
            settings.max_iterations = s.max_iterations.max(1);
            let mut history = heapless::Vec::<_, 0>::new();
            view.fit_irls(&settings, &act, &mut history)?
        }
    });
    let std = fit.std();
    Ok(FitOut {
        cols: cols.to_vec(),
        x: (0..cols.len()).map(|k| fit.solution.x[k]).collect(),
        std: (0..cols.len()).map(|k| std[k]).collect(),
        weights: fit.weights.to_vec(),
        sigma: fit.sigma.to_vec(),
        iterations: fit.iterations,
        converged: fit.converged,
    })
}

/// Fits the columns `cols` of `d` (all rows, or all but group `skip_group`).
///
/// # Errors
/// From the solve ([`Error::NotIdentifiable`], …); more than
/// [`MAX_COLUMNS`] columns or [`MAX_GROUPS`] groups.
pub fn fit(
    d: &Design,
    cols: &[usize],
    skip_group: Option<usize>,
    s: &FitSettings,
) -> Result<FitOut, Error> {
    dispatch!(cols.len(), fit_n(d, cols, skip_group, s))
}

fn test_n<const N: usize>(
    d: &Design,
    model: &[usize],
    candidate: &[usize],
    weights: &[Vector3<f64>],
) -> Result<NestedTest, Error> {
    let mut cols = model.to_vec();
    cols.extend_from_slice(candidate);
    let view = View::<N> {
        d,
        cols: &cols,
        skip_group: None,
    };
    let acc = Box::new(view.weighted(weights, None)?);
    let m = active::<N>(model.len());
    let mut c = [false; N];
    for v in c.iter_mut().skip(model.len()).take(candidate.len()) {
        *v = true;
    }
    let sol = Box::new(acc.solve_active(&m)?);
    nested_test(&acc, &m, &sol, &c)
}

/// Nested F test (`crate::diagnose`) of adding `candidate` to `model`, with
/// the model's weights.
///
/// # Errors
/// As [`nested_test`].
pub fn test(
    d: &Design,
    model: &[usize],
    candidate: &[usize],
    weights: &[Vector3<f64>],
) -> Result<NestedTest, Error> {
    dispatch!(
        model.len() + candidate.len(),
        test_n(d, model, candidate, weights)
    )
}

/// A column is dependent when less than this share of its norm is left
/// after projecting out the columns before it. The solver refuses a pivot
/// of the column-scaled information matrix at or below √ε (a share of
/// 1.2e-4 in f64); the weights of a fit move the share, so the margin is
/// ten.
pub const INDEPENDENCE_SHARE: f64 = 1e-3;

/// Greedy independent subset: of `extra`, the columns that are not
/// (numerically, [`INDEPENDENCE_SHARE`]) combinations of `base` and the
/// extra columns kept before them, by modified Gram–Schmidt on the
/// unweighted columns.
pub fn independent(d: &Design, base: &[usize], extra: &[usize]) -> Vec<usize> {
    let mut basis: Vec<Vec<f64>> = Vec::new();
    let mut push = |c: usize| -> bool {
        let mut v: Vec<f64> = d.b.column(c).iter().copied().collect();
        let n0 = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if n0 == 0.0 {
            return false;
        }
        for _ in 0..2 {
            for u in &basis {
                let dot: f64 = u.iter().zip(&v).map(|(a, b)| a * b).sum();
                for (vi, ui) in v.iter_mut().zip(u) {
                    *vi -= dot * ui;
                }
            }
        }
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if n <= INDEPENDENCE_SHARE * n0 {
            return false;
        }
        v.iter_mut().for_each(|x| *x /= n);
        basis.push(v);
        true
    };
    for &c in base {
        push(c);
    }
    extra.iter().copied().filter(|&c| push(c)).collect()
}
