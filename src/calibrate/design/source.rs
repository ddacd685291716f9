//! Where a [`Design`]'s columns are: held (`3·rows × params`, column-major:
//! 384 B a row at 16 parameters, 384 MB at 10⁶ rows), or computed again
//! from the rows where a pass reads them, a block of rows at a time
//! ([`crate::calibrate::settings::Policy::max_held_design_rows`]).
//!
//! A column computed again is the held one bit for bit: the same function
//! ([`crate::calibrate::design::Columns`]) of the same row at the same frames (the rows the
//! design was built from, shared: [`crate::calibrate::engine::Engine::rows`],
//! which a relinearisation changes only once the design is let go).

use std::borrow::Cow;
use std::sync::Arc;

use nalgebra::{DMatrix, Vector3};

use crate::calibrate::design::columns::Columns;
use crate::calibrate::design::Design;
use crate::calibrate::params::linearisation::Linearisation;
use crate::calibrate::rows::Rows;

/// The columns of a design ([`Design`]'s).
#[derive(Debug, Clone)]
pub(super) enum Source {
    /// Held: `3·rows × params`, row `3i + a` axis `a` of row `i`.
    Held(DMatrix<f64>),
    /// Computed where read, from the rows by [`Recipe`].
    Rows(Recipe),
}

/// What the columns of a design not held are computed from.
#[derive(Debug, Clone)]
pub(super) struct Recipe {
    /// The rows the design was built from (`None` until
    /// [`Design::reading`] gives them: a design built while they were
    /// being relinearised).
    pub(super) rows: Option<Arc<Rows>>,
    /// The joint law of the build (the compliances of `load_com`).
    pub(super) lin: Linearisation,
    /// Each parameter's reported unit in SI.
    pub(super) si: Vec<f64>,
    /// Whether a column needs the joints' compliances.
    pub(super) linearised: bool,
    /// Whether the rows mix both kinds.
    pub(super) mixed: bool,
}

impl Recipe {
    /// How `columns` are computed again where read.
    pub(super) fn of(columns: &Columns<'_>) -> Self {
        Self {
            rows: None,
            lin: columns.lin.clone(),
            si: columns.si.to_vec(),
            linearised: columns.linearised,
            mixed: columns.mixed,
        }
    }
}

impl Design {
    /// Whether the columns are held (else computed where read).
    pub fn is_held(&self) -> bool {
        matches!(self.source, Source::Held(_))
    }

    /// The design, its columns computed from `rows` when they are not held
    /// (the rows it was built from; nothing changes when held).
    #[must_use]
    pub fn reading(mut self, rows: &Arc<Rows>) -> Self {
        if let Source::Rows(r) = &mut self.source {
            r.rows = Some(Arc::clone(rows));
        }
        self
    }

    /// All the columns, `3·rows × params`: the held ones, else computed
    /// (for the passes that read them whole and seldom run: an
    /// ill-conditioned independence test, a weighted held-out error).
    pub fn held(&self) -> Cow<'_, DMatrix<f64>> {
        match &self.source {
            Source::Held(b) => Cow::Borrowed(b),
            Source::Rows(_) => {
                let (m, n) = (self.rows(), self.params.len());
                let cols: Vec<usize> = (0..n).collect();
                let mut b = Vec::new();
                self.columns_into(0, m, &cols, &mut b);
                Cow::Owned(DMatrix::from_vec(3 * m, n, b))
            }
        }
    }

    /// The design of `params` whose columns are `b` (`3·rows × params`,
    /// held), its left-hand sides `y` (`3·rows`) and the rows' groups
    /// (below `groups`), with the instrument's σ per group when known.
    pub fn from_columns(
        params: Vec<crate::model::Param>,
        b: DMatrix<f64>,
        y: Vec<f64>,
        group: Vec<usize>,
        groups: usize,
        instrument_sigma: Option<Vec<Vector3<f64>>>,
    ) -> Self {
        Self {
            params,
            source: Source::Held(b),
            y,
            group,
            groups,
            instrument_sigma,
            unit_sums: None,
            scalar_groups: 0..0,
            pools: Vec::new(),
        }
    }

    /// The held columns, to change (tests); `None` when not held.
    #[cfg(test)]
    pub(crate) fn held_mut(&mut self) -> Option<&mut DMatrix<f64>> {
        match &mut self.source {
            Source::Held(b) => Some(b),
            Source::Rows(_) => None,
        }
    }

    /// The columns `cols` of the design rows `rows`, into `out` (resized)
    /// in the view's layout: the `k`-th row's axis `a` at
    /// `[(3k + a) n..(3k + a + 1) n]`, `n = cols.len()`.
    pub fn rows_into(&self, rows: &[usize], cols: &[usize], out: &mut Vec<f64>) {
        let n = cols.len();
        out.resize(3 * n * rows.len(), 0.0);
        match &self.source {
            Source::Held(b) => {
                let m3 = b.nrows();
                let data = b.as_slice();
                for (k, &i) in rows.iter().enumerate() {
                    for a in 0..3 {
                        let run = &mut out[(3 * k + a) * n..(3 * k + a + 1) * n];
                        for (v, &c) in run.iter_mut().zip(cols) {
                            *v = data[c * m3 + 3 * i + a];
                        }
                    }
                }
            }
            Source::Rows(r) => {
                let at = Places::of(cols, self.params.len());
                self.computed(r, rows.iter().copied(), |k, c, col| {
                    at.each(c, |j| {
                        for a in 0..3 {
                            out[(3 * k + a) * n + j] = col[a];
                        }
                    });
                });
            }
        }
    }

    /// The columns `cols` of the rows `first..first + len`, column-major
    /// into `out` (resized): column `j`'s `3·len` values at
    /// `[j·3len..(j + 1)·3len]`.
    pub fn columns_into(&self, first: usize, len: usize, cols: &[usize], out: &mut Vec<f64>) {
        let h = 3 * len;
        out.resize(h * cols.len(), 0.0);
        match &self.source {
            Source::Held(b) => {
                for (j, &c) in cols.iter().enumerate() {
                    out[j * h..(j + 1) * h]
                        .copy_from_slice(&b.column(c).as_slice()[3 * first..3 * (first + len)]);
                }
            }
            Source::Rows(r) => {
                let at = Places::of(cols, self.params.len());
                self.computed(r, first..first + len, |k, c, col| {
                    at.each(c, |j| {
                        out[j * h + 3 * k..j * h + 3 * k + 3].copy_from_slice(col.as_slice());
                    });
                });
            }
        }
    }

    /// `f(k, c, column)` for every column `c` of the `k`-th of the design
    /// rows `rows`, computed by `r`. A column that cannot be computed
    /// (which the design's build computed: it cannot happen) is NaN, which
    /// every pass over the columns refuses as not finite.
    fn computed(
        &self,
        r: &Recipe,
        rows: impl Iterator<Item = usize>,
        mut f: impl FnMut(usize, usize, Vector3<f64>),
    ) {
        let n = self.params.len();
        let nan = Vector3::repeat(f64::NAN);
        let Some(all) = r.rows.as_deref() else {
            for (k, _) in rows.enumerate() {
                (0..n).for_each(|c| f(k, c, nan));
            }
            return;
        };
        let columns = Columns {
            params: &self.params,
            si: Cow::Borrowed(&r.si),
            linearised: r.linearised,
            lin: &r.lin,
            mixed: r.mixed,
            markers: &all.markers,
            masses: super::columns::masses(&self.params, Cow::Borrowed(&all.chains), all.gravity),
        };
        let mut frames = crate::robot::Frames::empty();
        for (k, i) in rows.enumerate() {
            let done = all.rows.get(i).ok_or(crate::error::Error::Mismatch {
                what: "a design row the rows do not have",
            });
            let done = done.and_then(|row| {
                all.frames_into(row, &mut frames)?;
                columns.each(row, &frames, all.gravity_unit, |c, col| f(k, c, col))
            });
            if done.is_err() {
                (0..n).for_each(|c| f(k, c, nan));
            }
        }
    }
}

/// Where each of a design's columns is among some columns `cols`: at its
/// own index when `cols` are the leading columns in order (the engine's
/// reads: nothing to look up), else at none, one or more places.
enum Places {
    /// `cols` is `0..len`.
    Leading(usize),
    /// Each column's places.
    Map(Vec<Vec<usize>>),
}

impl Places {
    /// The places of the design's `n` columns among `cols`.
    fn of(cols: &[usize], n: usize) -> Self {
        if cols.iter().enumerate().all(|(j, &c)| j == c) {
            return Self::Leading(cols.len());
        }
        let mut at = vec![Vec::new(); n];
        for (j, &c) in cols.iter().enumerate() {
            if let Some(a) = at.get_mut(c) {
                a.push(j);
            }
        }
        Self::Map(at)
    }

    /// `f(j)` for each place `j` of column `c`.
    fn each(&self, c: usize, mut f: impl FnMut(usize)) {
        match self {
            Self::Leading(len) => {
                if c < *len {
                    f(c);
                }
            }
            Self::Map(at) => at.get(c).into_iter().flatten().for_each(|&j| f(j)),
        }
    }
}
