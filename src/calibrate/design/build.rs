//! How a [`Design`] is built: its columns computed at every row, into
//! the storage of the design before, held or not ([`crate::calibrate::design::source`]), and
//! in the pass of a relinearisation ([`Design::relinearised`]).

use std::borrow::Cow;

use nalgebra::{DMatrix, Vector3};

use crate::calibrate::design::columns::Columns;
use crate::calibrate::design::{source, unit_sums, Design};
use crate::calibrate::params::linearisation::Linearisation;
use crate::calibrate::rows::{Row, Rows};
use crate::error::Error;
use crate::model::Param;

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
pub struct Storage {
    /// The columns (`Design::b`'s data).
    b: Vec<f64>,
    /// `Design::y`.
    y: Vec<f64>,
    /// `Design::group`.
    group: Vec<usize>,
}

impl Design {
    /// Columns of `params` at `rows` (at their last relinearisation, each
    /// row's frames recomputed there); `load_com` about the compliances of
    /// `lin`. The rows' columns on [`crate::parallel::for_rows`] threads.
    ///
    /// # Errors
    /// [`Error`] when a column cannot be computed (a parameter naming a
    /// joint the chain does not have).
    pub fn new(
        all: &Rows,
        params: &[Param],
        lin: &Linearisation,
        names: &crate::calibrate::params::names::Names,
    ) -> Result<Self, Error> {
        let threads = crate::parallel::for_rows(all.rows.len());
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
        names: &crate::calibrate::params::names::Names,
    ) -> Result<Self, Error> {
        let threads = crate::parallel::for_rows(all.rows.len());
        Self::build(all, params, lin, names, threads, old.into_storage(), true)
    }

    /// [`Design::new`] into `old`'s storage when given, its columns held
    /// when the rows are at most `max_held`
    /// ([`crate::calibrate::settings::Policy::max_held_design_rows`]), else computed from the
    /// rows where read (after [`Design::reading`]; the build computes each
    /// once, for its errors).
    ///
    /// # Errors
    /// As [`Design::new`].
    pub fn built(
        all: &Rows,
        params: &[Param],
        lin: &Linearisation,
        names: &crate::calibrate::params::names::Names,
        old: Option<Storage>,
        max_held: usize,
    ) -> Result<Self, Error> {
        let threads = crate::parallel::for_rows(all.rows.len());
        let hold = all.rows.len() <= max_held;
        Self::build(
            all,
            params,
            lin,
            names,
            threads,
            old.unwrap_or_default(),
            hold,
        )
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
        names: &crate::calibrate::params::names::Names,
        threads: usize,
    ) -> Result<Self, Error> {
        Self::build(all, params, lin, names, threads, Storage::default(), true)
    }

    /// [`Design::new_on`] in `storage` (every element written), its
    /// columns held when `hold`.
    fn build(
        all: &Rows,
        params: &[Param],
        lin: &Linearisation,
        names: &crate::calibrate::params::names::Names,
        threads: usize,
        storage: Storage,
        hold: bool,
    ) -> Result<Self, Error> {
        let rows = &all.rows[..];
        let (m, n) = (rows.len(), params.len());
        let columns = Columns::new(
            params,
            lin,
            names,
            all,
            &all.markers,
            Cow::Borrowed(&all.chains),
        );
        let per = crate::calibrate::rows::run_length(m, threads);
        let Storage {
            b: mut data,
            mut y,
            group,
        } = storage;
        // The left-hand sides from the frames the columns are computed at
        // ([`Rows::y`]: the rows keep none).
        zeroed(&mut y, 3 * m);
        let y_runs = y.as_chunks_mut::<3>().0.chunks_mut(per);
        let lhs = |row: &Row,
                   frames: &crate::robot::Frames<
            f64,
            { crate::calibrate::params::geometry::J },
        >| {
            crate::calibrate::rows::scaled_y(columns.mixed, row, all.y(row, frames)).into()
        };
        if !hold {
            // Each column once, for its error.
            let mut runs: Vec<_> = rows.chunks(per).zip(y_runs).collect();
            crate::parallel::for_each_mut(&mut runs, threads, |_, (run, ys)| {
                let mut frames = crate::robot::Frames::empty();
                for (row, y) in run.iter().zip(ys.iter_mut()) {
                    all.frames_into(row, &mut frames)?;
                    columns.each(row, &frames, all.gravity_unit, |_, _| {})?;
                    *y = lhs(row, &frames);
                }
                Ok::<_, Error>(())
            })?;
            let storage = Storage {
                b: Vec::new(),
                y,
                group,
            };
            return Ok(Self::finish(
                all,
                params,
                storage,
                Some(source::Recipe::of(&columns)),
            ));
        }
        let pieces = pieces(&mut data, m, n, per);
        let mut runs: Vec<_> = rows.chunks(per).zip(pieces).zip(y_runs).collect();
        crate::parallel::for_each_mut(&mut runs, threads, |_, ((run, piece), ys)| {
            let mut frames = crate::robot::Frames::empty();
            for (k, (row, y)) in run.iter().zip(ys.iter_mut()).enumerate() {
                all.frames_into(row, &mut frames)?;
                columns.write(row, &frames, all.gravity_unit, piece, k)?;
                *y = lhs(row, &frames);
            }
            Ok::<_, Error>(())
        })?;
        Ok(Self::finish(
            all,
            params,
            Storage { b: data, y, group },
            None,
        ))
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
        geometry: &crate::calibrate::params::geometry::Geometry,
        lin: &Linearisation,
        params: &[Param],
        names: &crate::calibrate::params::names::Names,
        old: Option<Storage>,
        max_held: usize,
    ) -> Result<Result<Self, Error>, crate::calibrate::settings::CalibrationError> {
        let threads = crate::parallel::for_rows(all.rows.len());
        let hold = all.rows.len() <= max_held;
        Self::relinearised_on(all, geometry, lin, params, names, old, threads, hold)
    }

    /// [`Design::relinearised`] on `threads` threads, its columns held
    /// when `hold` (else computed where read, after [`Design::reading`]).
    ///
    /// # Errors
    /// As [`Design::relinearised`].
    #[allow(clippy::too_many_arguments)]
    pub fn relinearised_on(
        all: &mut Rows,
        geometry: &crate::calibrate::params::geometry::Geometry,
        lin: &Linearisation,
        params: &[Param],
        names: &crate::calibrate::params::names::Names,
        old: Option<Storage>,
        threads: usize,
        hold: bool,
    ) -> Result<Result<Self, Error>, crate::calibrate::settings::CalibrationError> {
        let (m, n) = (all.rows.len(), params.len());
        let per = crate::calibrate::rows::run_length(m, threads);
        let Storage {
            b: mut data,
            mut y,
            group,
        } = old.unwrap_or_default();
        // (The rows' chains are the geometry's once relinearised below.)
        let chains = if params.iter().any(|p| matches!(p, Param::LinkMass { .. })) {
            Cow::Owned(geometry.placed_chains())
        } else {
            Cow::Borrowed(&[][..])
        };
        let columns = Columns::new(params, lin, names, all, &geometry.markers, chains);
        // Each run's left-hand sides, from the frames computed there
        // ([`Rows::y`]: the rows keep none).
        zeroed(&mut y, 3 * m);
        let y_runs = y.as_chunks_mut::<3>().0.chunks_mut(per);
        // With runs that start at the view's blocks, each block's
        // unit-weight sums from its columns as they are written.
        let fuse = unit_sums::aligned(m, per);
        let sums = |r: usize| fuse.then(|| unit_sums::RunSums::new(per.min(m - r * per)));
        // Each run's piece of every column, or (not held) one row's
        // columns at a time.
        let mut states: Vec<_> = if hold {
            pieces(&mut data, m, n, per)
                .into_iter()
                .zip(y_runs)
                .enumerate()
                .map(|(r, (piece, ys))| (Some(piece), Vec::new(), sums(r), ys))
                .collect()
        } else {
            data = Vec::new();
            (y_runs.enumerate())
                .map(|(r, ys)| (None, vec![0.0; 3 * n], sums(r), ys))
                .collect()
        };
        let markers = &geometry.markers;
        let tool = geometry.tool_rotation.to_rotation_matrix();
        let columns = &columns;
        let done = all.relinearise_with(
            geometry,
            lin,
            threads,
            states.iter_mut().collect(),
            |(piece, one, sums, ys), k, row, frames, g| {
                let y = crate::calibrate::rows::lhs(markers, &tool, row, frames);
                let y: [f64; 3] = crate::calibrate::rows::scaled_y(columns.mixed, row, y).into();
                if let Some(at) = ys.get_mut(k) {
                    *at = y;
                }
                match piece {
                    Some(piece) => {
                        columns.write(row, frames, g, piece, k)?;
                        if let Some(sums) = sums {
                            sums.add(n, |c, a| piece[c][3 * k + a], k, y, row.live());
                        }
                    }
                    None => {
                        columns.each(row, frames, g, |c, col| {
                            one[3 * c..3 * c + 3].copy_from_slice(col.as_slice());
                        })?;
                        if let Some(sums) = sums {
                            sums.add(n, |c, a| one[3 * c + a], k, y, row.live());
                        }
                    }
                }
                Ok(())
            },
        )?;
        let sums = fuse.then(|| {
            let runs = states.into_iter().filter_map(|(_, _, s, _)| s).collect();
            unit_sums::merge_runs(n, runs)
        });
        let recipe = (!hold).then(|| source::Recipe::of(columns));
        Ok(done.map(|()| {
            let mut d = Self::finish(all, params, Storage { b: data, y, group }, recipe);
            d.unit_sums = sums.flatten();
            d
        }))
    }

    /// The design of the first `n` parameters only: its leading columns,
    /// in place (the storage stays, for the next design).
    pub fn keep_leading(&mut self, n: usize) {
        let n = n.min(self.params.len());
        self.unit_sums = None;
        match &mut self.source {
            source::Source::Held(held) => {
                let m3 = held.nrows();
                let b = std::mem::replace(held, DMatrix::zeros(0, 0));
                let mut data: Vec<f64> = b.data.into();
                data.truncate(m3 * n);
                *held = DMatrix::from_vec(m3, n, data);
            }
            source::Source::Rows(r) => r.si.truncate(n),
        }
        self.params.truncate(n);
    }

    /// A design no longer needed as storage for the next one (the rows it
    /// reads, when not held, let go).
    pub fn into_storage(self) -> Storage {
        let b = match self.source {
            source::Source::Held(b) => b.data.into(),
            source::Source::Rows(_) => Vec::new(),
        };
        Storage {
            b,
            y: self.y,
            group: self.group,
        }
    }

    /// The design of `params` at `all` from its columns in `storage.b`
    /// (column-major `3·rows × params`): the left-hand sides, the groups,
    /// the instrument's σ (into `storage`'s other vectors).
    fn finish(
        all: &Rows,
        params: &[Param],
        storage: Storage,
        recipe: Option<source::Recipe>,
    ) -> Self {
        let (rows, groups) = (&all.rows[..], all.configs.len());
        let Storage { b, y, mut group } = storage;
        let source = match recipe {
            Some(r) => source::Source::Rows(r),
            None => source::Source::Held(DMatrix::from_vec(3 * rows.len(), params.len(), b)),
        };
        // The groups by runs of rows on worker threads (the left-hand sides
        // are the passes' that computed the columns).
        zeroed(&mut group, rows.len());
        let threads = crate::parallel::for_rows(rows.len());
        let per = rows.len().div_ceil(threads).max(1);
        let mut runs: Vec<_> = group.chunks_mut(per).zip(rows.chunks(per)).collect();
        let filled = crate::parallel::for_each_mut(&mut runs, threads, |_, (gs, rs)| {
            for (g, r) in gs.iter_mut().zip(rs.iter()) {
                *g = r.group();
            }
            Ok::<(), std::convert::Infallible>(())
        });
        let Ok(()) = filled;
        let instrument_sigma = rows.iter().all(|r| r.sigma().is_some()).then(|| {
            let mut ss = vec![Vector3::<f64>::zeros(); groups];
            let mut n = vec![0.0_f64; groups];
            for r in rows {
                // (The kind's scale alone: a robust loss's weight is the
                // row's, not its instrument's.)
                let sigma = r
                    .sigma()
                    .map(|s| s * crate::calibrate::rows::noise_scale(all.mixed(), r.kind));
                if let (Some(s), Some(g)) = (sigma, ss.get_mut(r.group())) {
                    *g += s.component_mul(&s);
                    n[r.group()] += 1.0;
                }
            }
            ss.iter()
                .zip(&n)
                .map(|(s, &k)| (s / k.max(1.0)).map(f64::sqrt))
                .collect()
        });
        Self {
            params: params.to_vec(),
            source,
            y,
            group,
            groups,
            instrument_sigma,
            unit_sums: None,
            scalar_groups: all.scalar_range(),
            pools: all.pools(),
        }
    }
}
