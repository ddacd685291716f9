//! The host's decision rule, shared with the device's in-stream diagnosis
//! ([`super::screen`]): the lack of fit against the repetitions
//! ([`PureError`], [`LackOfFit`]), the multiple-testing rule ([`Rule`]:
//! Bonferroni over the candidates tried, and the share of the lack of fit a
//! candidate must explain) and the order of the tests ([`rank_tests`]).

use nalgebra::{RealField, Vector3};

use super::distributions;
use super::nested::NestedTest;
use crate::error::Error;

/// The lack-of-fit test against the repetitions: rows of one cell
/// (configuration, marker, kind) share their regressors, so the scatter
/// within a cell is pure error and the cell means carry the lack of fit.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LackOfFit {
    /// `F = (SS_lof / df_lof) / (SS_pe / df_pe)`.
    pub f: f64,
    /// Its p-value.
    pub p_value: f64,
    /// Between-cell weighted sum of squares.
    pub ss_lof: f64,
    /// Its degrees of freedom (cells · 3 − parameters).
    pub df_lof: usize,
    /// Within-cell weighted sum of squares.
    pub ss_pe: f64,
    /// Its degrees of freedom.
    pub df_pe: usize,
}

impl LackOfFit {
    /// The test from its sums of squares; `None` without degrees of
    /// freedom on either side or without pure error.
    pub fn new(ss_lof: f64, df_lof: usize, ss_pe: f64, df_pe: usize) -> Option<Self> {
        if df_lof == 0 || df_pe == 0 || ss_pe <= 0.0 {
            return None;
        }
        let f = (ss_lof / df_lof as f64) / (ss_pe / df_pe as f64);
        Some(Self {
            f,
            p_value: distributions::f_sf(f, df_lof, df_pe),
            ss_lof,
            df_lof,
            ss_pe,
            df_pe,
        })
    }

    /// `SS_lof` above its expectation under noise alone.
    pub fn excess(&self) -> f64 {
        (self.ss_lof - self.df_lof as f64 * self.ss_pe / self.df_pe.max(1) as f64).max(0.0)
    }
}

/// One cell's running moments of `Δp` (Welford).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Cell<T> {
    group: u16,
    key: u16,
    n: u32,
    mean: [T; 3],
    m2: [T; 3],
}

/// The pure error of the repetitions, per cell, in one stream: `C` cells
/// at most (the device's configurations × markers).
#[derive(Debug, Clone, PartialEq)]
pub struct PureError<T: RealField + Copy, const C: usize> {
    cells: heapless::Vec<Cell<T>, C>,
}

impl<T: RealField + Copy, const C: usize> Default for PureError<T, C> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: RealField + Copy, const C: usize> PureError<T, C> {
    /// No cell yet.
    pub const fn new() -> Self {
        Self {
            cells: heapless::Vec::new(),
        }
    }

    /// Adds one measurement `Δp` of cell `key` (e.g. the marker) of
    /// configuration `group` (the group of the weights). Unchanged on error.
    ///
    /// # Errors
    /// [`Error::NonFinite`]; [`Error::CapacityExceeded`] past `C` cells.
    pub fn update(&mut self, group: u16, key: u16, dp: &Vector3<T>) -> Result<(), Error> {
        if !dp.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite { what: "row" });
        }
        let i = match self
            .cells
            .iter()
            .position(|c| c.group == group && c.key == key)
        {
            Some(i) => i,
            None => {
                let cell = Cell {
                    group,
                    key,
                    n: 0,
                    mean: [T::zero(); 3],
                    m2: [T::zero(); 3],
                };
                self.cells.push(cell).map_err(|_| Error::CapacityExceeded {
                    what: "pure-error cells",
                    capacity: C,
                })?;
                self.cells.len() - 1
            }
        };
        let c = &mut self.cells[i];
        c.n += 1;
        let n: T = nalgebra::convert(f64::from(c.n));
        for a in 0..3 {
            let d = dp[a] - c.mean[a];
            c.mean[a] += d / n;
            c.m2[a] += d * (dp[a] - c.mean[a]);
        }
        Ok(())
    }

    /// Number of cells.
    pub fn cells(&self) -> usize {
        self.cells.len()
    }

    /// The lack-of-fit test of a fit of `params` parameters with weighted
    /// RSS `wrss` at the weights `weights` (one per group and axis, eq. 14):
    /// `SS_pe = Σ w² · scatter`, `SS_lof = RSS_w − SS_pe`. `None` as
    /// [`LackOfFit::new`], or for a group without a weight.
    pub fn lack_of_fit(
        &self,
        wrss: f64,
        weights: &[Vector3<T>],
        params: usize,
    ) -> Option<LackOfFit> {
        let to = |v: T| nalgebra::try_convert::<T, f64>(v).unwrap_or(f64::NAN);
        let (mut ss_pe, mut df_pe) = (0.0, 0usize);
        for c in &self.cells {
            let w = weights.get(usize::from(c.group))?;
            for a in 0..3 {
                ss_pe += to(w[a] * w[a]) * to(c.m2[a]);
            }
            df_pe += 3 * (c.n as usize).saturating_sub(1);
        }
        let df_lof = (3 * self.cells.len()).checked_sub(params)?;
        LackOfFit::new((wrss - ss_pe).max(0.0), df_lof, ss_pe, df_pe)
    }
}

/// The host's decision constants for adding an effect
/// (`calibrate::Policy`'s `alpha` and `min_share`).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Rule {
    /// Significance level (Bonferroni: `p · tried < α`). 0.01.
    pub alpha: f64,
    /// Share of the excess lack of fit an effect must explain when the lack
    /// of fit is significant. 0.1.
    pub min_share: f64,
}

impl Default for Rule {
    fn default() -> Self {
        Self {
            alpha: 0.01,
            min_share: 0.1,
        }
    }
}

impl Rule {
    /// Whether a test passes among `tried` tests, given the model's lack of
    /// fit (the host's rule, `calibrate::diagnosis::run`).
    pub fn eligible(&self, t: &NestedTest, tried: usize, lof: Option<&LackOfFit>) -> bool {
        let significant = t.p_value * (tried.max(1) as f64) < self.alpha;
        let share_ok = match lof {
            Some(l) if l.p_value < self.alpha && l.excess() > 0.0 => {
                t.delta_rss >= self.min_share * l.excess()
            }
            _ => true,
        };
        significant && share_ok
    }
}

/// Orders tests as the host does: by p-value, then by F (largest first);
/// stable (insertion sort: a device tests a few dozen candidates).
pub fn rank_tests<I: Copy>(tests: &mut [(I, NestedTest)]) {
    for i in 1..tests.len() {
        let mut j = i;
        while j > 0 && before(&tests[j].1, &tests[j - 1].1) {
            tests.swap(j, j - 1);
            j -= 1;
        }
    }
}

fn before(a: &NestedTest, b: &NestedTest) -> bool {
    match a.p_value.total_cmp(&b.p_value) {
        core::cmp::Ordering::Less => true,
        core::cmp::Ordering::Equal => b.f.total_cmp(&a.f) == core::cmp::Ordering::Less,
        core::cmp::Ordering::Greater => false,
    }
}
