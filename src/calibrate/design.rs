//! The design: the columns of a list of parameters at every row (`B` of
//! eq. 4, stacked), and which of them the data can tell apart.

use nalgebra::{DMatrix, Dyn, OMatrix, Vector3, U3};

use super::linearisation::Linearisation;
use super::rows::{Row, Rows};
use super::view::View;
use crate::estimate::{
    identifiability_excluding, independence_tolerance, Accumulator, Block, Identifiability,
    IdentifiabilitySettings,
};
use crate::model::Param;
use crate::Error;

mod group_rows;
mod kept;
mod unit_sums;
pub use group_rows::GroupRows;

/// The columns of some parameters at every row: `b` is `3·rows × params`,
/// row `3i + a` is axis `a` of row `i`, each column in its parameter's
/// reported unit.
#[derive(Debug, Clone)]
pub struct Design {
    /// The parameters, in column order.
    pub params: Vec<Param>,
    /// Columns in the reported units.
    pub b: DMatrix<f64>,
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
}

/// Each run's piece of every column of a design's storage `data` (resized
/// to `3·rows × params`, column-major; every element is then written, so
/// storage of the right size is not zeroed first: 300 MB at 10⁶ rows): run
/// `r` is rows `r·per..`, its piece of a column `3·per` values.
fn pieces(data: &mut Vec<f64>, m: usize, n: usize, per: usize) -> Vec<Vec<&mut [f64]>> {
    zeroed(data, 3 * m * n);
    let mut pieces: Vec<Vec<&mut [f64]>> = (0..m.div_ceil(per)).map(|_| Vec::new()).collect();
    for column in data.chunks_mut((3 * m).max(1)) {
        for (piece, run) in column.chunks_mut(3 * per).zip(pieces.iter_mut()) {
            run.push(piece);
        }
    }
    pieces
}

/// `data` resized to `len`: in place when it has the room (the storage of
/// the design before), else a new zeroed allocation, which the system hands
/// out as pages not yet touched (at 10⁶ rows the first design's 360 MB
/// written with zeros on one thread was 0.15 s; its pages are now first
/// touched by the workers that write the columns).
fn zeroed<T: Clone + Default>(data: &mut Vec<T>, len: usize) {
    if data.capacity() < len {
        // (`vec!` of a zero number asks for zeroed memory: no writes.)
        *data = vec![T::default(); len];
    } else {
        data.resize(len, T::default());
    }
}

/// A design's vectors, reused by the next design (each a fresh
/// allocation was page faults: at 10⁶ rows 300 MB of columns, 24 MB of
/// left-hand sides, 8 MB of groups).
#[derive(Default)]
struct Storage {
    /// The columns (`Design::b`'s data).
    b: Vec<f64>,
    /// `Design::y`.
    y: Vec<f64>,
    /// `Design::group`.
    group: Vec<usize>,
}

/// How the columns of some parameters are computed at a row.
struct Columns<'a> {
    params: &'a [Param],
    /// Each parameter's reported unit in SI.
    si: Vec<f64>,
    /// Whether a column needs the joints' compliances (the load's centre of
    /// mass).
    linearised: bool,
    lin: &'a Linearisation,
    /// Whether the rows mix both kinds ([`super::rows::noise_scale`]).
    mixed: bool,
}

impl<'a> Columns<'a> {
    fn new(
        params: &'a [Param],
        lin: &'a Linearisation,
        names: &super::names::Names,
        all: &Rows,
    ) -> Self {
        Self {
            params,
            si: params.iter().map(|p| names.unit(p).si).collect(),
            linearised: params.iter().any(|p| matches!(p, Param::LoadCom { .. })),
            lin,
            mixed: all.mixed(),
        }
    }

    /// The row's columns at its `frames` into row `k` of a run's `piece`
    /// of every column.
    fn write(
        &self,
        row: &Row,
        frames: &crate::robot::Frames<f64, { super::geometry::J }>,
        gravity_unit: Vector3<f64>,
        piece: &mut [&mut [f64]],
        k: usize,
    ) -> Result<(), Error> {
        let compliance = if self.linearised {
            self.lin.compliance_at(&row.q)
        } else {
            Vec::new()
        };
        let sample = row.sample(frames, &compliance, gravity_unit);
        let scale = super::rows::noise_scale(self.mixed, row.kind);
        for ((p, &si), column) in self.params.iter().zip(&self.si).zip(piece.iter_mut()) {
            let mut col = p.column_si(&sample)? * si;
            if scale != 1.0 {
                col *= scale;
            }
            column[3 * k..3 * k + 3].copy_from_slice(col.as_slice());
        }
        Ok(())
    }
}

impl Design {
    /// Columns of `params` at `rows` (at their last relinearisation, each
    /// row's frames recomputed there); `load_com` about the compliances of
    /// `lin`. The rows' columns on [`super::parallel::for_rows`] threads.
    ///
    /// # Errors
    /// [`Error`] when a column cannot be computed (a parameter naming a
    /// joint the chain does not have).
    pub fn new(
        all: &Rows,
        params: &[Param],
        lin: &Linearisation,
        names: &super::names::Names,
    ) -> Result<Self, Error> {
        let threads = super::parallel::for_rows(all.rows.len());
        Self::new_on(all, params, lin, names, threads)
    }

    /// [`Design::new`] into the storage of `old`, a design no longer
    /// needed: the same design, without a fresh allocation (at 10⁶ rows a
    /// design is 300 MB, and each new one was 75 000 page faults).
    ///
    /// # Errors
    /// As [`Design::new`].
    pub fn new_from(
        old: Self,
        all: &Rows,
        params: &[Param],
        lin: &Linearisation,
        names: &super::names::Names,
    ) -> Result<Self, Error> {
        let threads = super::parallel::for_rows(all.rows.len());
        Self::build(all, params, lin, names, threads, old.into_storage())
    }

    /// [`Design::new`] on `threads` threads: the same design whatever their
    /// number.
    ///
    /// # Errors
    /// As [`Design::new`] (the first row's error in row order).
    pub fn new_on(
        all: &Rows,
        params: &[Param],
        lin: &Linearisation,
        names: &super::names::Names,
        threads: usize,
    ) -> Result<Self, Error> {
        Self::build(all, params, lin, names, threads, Storage::default())
    }

    /// [`Design::new_on`] in `storage` (every element written).
    fn build(
        all: &Rows,
        params: &[Param],
        lin: &Linearisation,
        names: &super::names::Names,
        threads: usize,
        storage: Storage,
    ) -> Result<Self, Error> {
        let rows = &all.rows[..];
        let (m, n) = (rows.len(), params.len());
        let columns = Columns::new(params, lin, names, all);
        let per = super::rows::run_length(m, threads);
        let Storage {
            b: mut data,
            y,
            group,
        } = storage;
        let pieces = pieces(&mut data, m, n, per);
        let runs: Vec<(&[Row], Vec<&mut [f64]>)> = rows.chunks(per).zip(pieces).collect();
        super::parallel::for_each_mut(&mut { runs }, threads, |_, (run, piece)| {
            let mut frames = crate::robot::Frames::empty();
            for (k, row) in run.iter().enumerate() {
                all.frames_into(row, &mut frames)?;
                columns.write(row, &frames, all.gravity_unit, piece, k)?;
            }
            Ok::<_, Error>(())
        })?;
        Ok(Self::finish(all, params, Storage { b: data, y, group }))
    }

    /// The rows of `all` relinearised at `geometry` and `lin`
    /// ([`Rows::relinearise`]) and the design of `params` there, built in
    /// the same pass from the frames the relinearisation computes (one
    /// forward kinematics per row, not two), into the storage of `old`
    /// when given: the rows and the design are those of
    /// [`Rows::relinearise`] then [`Design::new`], bit for bit.
    ///
    /// # Errors
    /// The outer error as [`Rows::relinearise`]; when the rows are
    /// relinearised but a column cannot be computed, `Ok(Err(_))` with
    /// [`Design::new`]'s error.
    pub fn relinearised(
        all: &mut Rows,
        geometry: &super::geometry::Geometry,
        lin: &Linearisation,
        params: &[Param],
        names: &super::names::Names,
        old: Option<Self>,
    ) -> Result<Result<Self, Error>, super::settings::CalibrationError> {
        let threads = super::parallel::for_rows(all.rows.len());
        Self::relinearised_on(all, geometry, lin, params, names, old, threads)
    }

    /// [`Design::relinearised`] on `threads` threads.
    ///
    /// # Errors
    /// As [`Design::relinearised`].
    pub fn relinearised_on(
        all: &mut Rows,
        geometry: &super::geometry::Geometry,
        lin: &Linearisation,
        params: &[Param],
        names: &super::names::Names,
        old: Option<Self>,
        threads: usize,
    ) -> Result<Result<Self, Error>, super::settings::CalibrationError> {
        let m = all.rows.len();
        let per = super::rows::run_length(m, threads);
        let Storage {
            b: mut data,
            y,
            group,
        } = old.map(Self::into_storage).unwrap_or_default();
        let columns = Columns::new(params, lin, names, all);
        // With runs that start at the view's blocks, each block's
        // unit-weight sums from its columns as they are written.
        let fuse = unit_sums::aligned(m, per);
        let mut states: Vec<_> = pieces(&mut data, m, params.len(), per)
            .into_iter()
            .enumerate()
            .map(|(r, piece)| {
                (
                    piece,
                    fuse.then(|| unit_sums::RunSums::new(per.min(m - r * per))),
                )
            })
            .collect();
        let columns = &columns;
        let done = all.relinearise_with(
            geometry,
            lin,
            threads,
            states.iter_mut().collect(),
            |(piece, sums), k, row, frames, g| {
                columns.write(row, frames, g, piece, k)?;
                if let Some(sums) = sums {
                    sums.add(piece, k, super::rows::scaled_y(columns.mixed, row).into());
                }
                Ok(())
            },
        )?;
        let sums = fuse.then(|| {
            let runs = states.into_iter().filter_map(|(_, s)| s).collect();
            unit_sums::merge_runs(params.len(), runs)
        });
        Ok(done.map(|()| {
            let mut d = Self::finish(all, params, Storage { b: data, y, group });
            d.unit_sums = sums.flatten();
            d
        }))
    }

    /// The design of the first `n` parameters only: its leading columns,
    /// in place (the storage stays, for the next design).
    pub fn keep_leading(&mut self, n: usize) {
        let n = n.min(self.params.len());
        self.unit_sums = None;
        let m3 = self.b.nrows();
        let b = std::mem::replace(&mut self.b, DMatrix::zeros(0, 0));
        let mut data: Vec<f64> = b.data.into();
        data.truncate(m3 * n);
        self.b = DMatrix::from_vec(m3, n, data);
        self.params.truncate(n);
    }

    /// A design no longer needed as storage for the next one.
    fn into_storage(self) -> Storage {
        Storage {
            b: self.b.data.into(),
            y: self.y,
            group: self.group,
        }
    }

    /// The design of `params` at `all` from its columns in `storage.b`
    /// (column-major `3·rows × params`): the left-hand sides, the groups,
    /// the instrument's σ (into `storage`'s other vectors).
    fn finish(all: &Rows, params: &[Param], storage: Storage) -> Self {
        let (rows, groups) = (&all.rows[..], all.configs.len());
        let Storage {
            b,
            mut y,
            mut group,
        } = storage;
        let b = DMatrix::from_vec(3 * rows.len(), params.len(), b);
        // The left-hand sides and the groups by runs of rows on worker
        // threads (one thread's pass over 10⁶ rows of 240 B each was ~0.05 s
        // per design, four designs a run).
        zeroed(&mut y, 3 * rows.len());
        zeroed(&mut group, rows.len());
        let threads = super::parallel::for_rows(rows.len());
        let per = rows.len().div_ceil(threads).max(1);
        let (y3, _) = y.as_chunks_mut::<3>();
        let mut runs: Vec<_> = y3
            .chunks_mut(per)
            .zip(group.chunks_mut(per))
            .zip(rows.chunks(per))
            .collect();
        let filled = super::parallel::for_each_mut(&mut runs, threads, |_, ((ys, gs), rs)| {
            for ((y, g), r) in ys.iter_mut().zip(gs.iter_mut()).zip(rs.iter()) {
                *y = super::rows::scaled_y(all.mixed(), r).into();
                *g = r.group;
            }
            Ok::<(), std::convert::Infallible>(())
        });
        let Ok(()) = filled;
        let instrument_sigma = rows.iter().all(|r| r.sigma().is_some()).then(|| {
            let mut ss = vec![Vector3::<f64>::zeros(); groups];
            let mut n = vec![0.0_f64; groups];
            for r in rows {
                let sigma = r.sigma().map(|s| s * all.noise_scale(r));
                if let (Some(s), Some(g)) = (sigma, ss.get_mut(r.group)) {
                    *g += s.component_mul(&s);
                    n[r.group] += 1.0;
                }
            }
            ss.iter()
                .zip(&n)
                .map(|(s, &k)| (s / k.max(1.0)).map(f64::sqrt))
                .collect()
        });
        Self {
            params: params.to_vec(),
            b,
            y,
            group,
            groups,
            instrument_sigma,
            unit_sums: None,
        }
    }

    /// The rows of each group, in row order ([`GroupRows`]); `None` when a
    /// row's group is not below [`Design::groups`].
    pub fn group_rows(&self) -> Option<GroupRows> {
        GroupRows::new(&self.group, self.groups)
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
        let mut r = Vector3::new(self.y[3 * i], self.y[3 * i + 1], self.y[3 * i + 2]);
        for (&c, &v) in cols.iter().zip(x) {
            for a in 0..3 {
                r[a] -= self.b[(3 * i + a, c)] * v;
            }
        }
        r
    }

    /// [`Design::residual`] of every row, in metres again
    /// ([`Rows::unscaled`]), by runs of rows on worker threads.
    pub fn residuals(&self, all: &Rows, cols: &[usize], x: &[f64]) -> Vec<Vector3<f64>> {
        let threads = super::parallel::for_rows(self.rows());
        self.residuals_on(cols, x, threads, |i, r| all.unscaled(i, r))
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
        let done = super::parallel::for_runs_mut(&mut out, threads, |first, run| {
            for (i, r) in (first..).zip(run) {
                *r = unscaled(i, self.residual(cols, x, i));
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
        if let Some(acc) = View::new(self, &cols, None, None).information() {
            return self.identifiability_of(&cols, &acc);
        }
        let mut acc = Accumulator::<f64, Dyn>::zeros(Dyn(n));
        let mut block = Block::new(OMatrix::<f64, U3, Dyn>::zeros(n), Vector3::zeros());
        for i in 0..self.rows() {
            for (k, &c) in cols.iter().enumerate() {
                for a in 0..3 {
                    block.b[(a, k)] = self.b[(3 * i + a, c)];
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
mod tests {
    use super::testing::design;

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
