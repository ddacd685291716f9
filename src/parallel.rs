//! Independent computations of the engine on worker threads, with the
//! answers of the serial order (issue 16).
//!
//! - The held-out folds of a weighted fit
//!   ([`crate::calibrate::engine::Engine::heldout`]): each item is computed by the
//!   same code as in a serial loop, on one thread, from the same inputs,
//!   and the results are handed back by index ([`map`], [`map_until`]).
//! - The tests of a round's candidates (`diagnosis.rs`, up to the first
//!   error, [`map_until`]) and their trials ([`crate::calibrate::diagnosis::trial`]), each on a
//!   copy of the engine's state, in order up to the first admissible one
//!   ([`map_until`]), when the rows are too few for the item below.
//! - The rows of a relinearisation ([`crate::calibrate::rows::Rows::relinearise`])
//!   and of a design ([`crate::calibrate::design::Design::new`]): contiguous runs of
//!   rows, about eight per thread ([`crate::calibrate::rows::run_length`]), each taken
//!   by the next free thread, the results in row order ([`for_each_mut`]);
//!   a design's left-hand sides and a fit's residuals by runs of rows
//!   ([`for_each_mut`], [`for_runs_mut`]); never more than one thread per
//!   [`MIN_ROWS_PER_THREAD`] rows ([`for_rows`]: a thread costs tens of µs
//!   to start, a small job stays on the calling thread).
//! - The angle bins of each joint (`rows/build.rs`: each sorts every
//!   value) and the chunks of a large measurement file
//!   (`io::measurements`, joined in file order).
//! - The OLS held-out's column dots (`heldout/dots.rs`): a run of the
//!   pairs per thread, each dot summed in its own order whatever the
//!   thread.
//! - The pieces of a large input file (`io::input`, [`for_runs_mut`]: one
//!   positioned read a piece).
//!
//! The answers are therefore bit for bit those of the serial loop, whatever
//! the number of threads (tests: `tests` below, and `tests/cli/threads.rs`
//! on the TIAGo runs).
//!
//! The number of threads is `ROBCAL_THREADS` (a positive integer; `1` runs
//! everything on the calling thread), else
//! [`std::thread::available_parallelism`]. Work that is already on a
//! worker runs serially on it: no nesting.
//! The calling thread works too; no thread outlives the call. A thread the
//! system refuses to start (a process limit, memory) is not an error: its
//! work is done on the calling thread, with the same answers.

use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, OnceLock};

thread_local! {
    /// Whether this thread is running an item of [`map_until`] or a run of
    /// [`for_runs_mut`].
    static INSIDE: Cell<bool> = const { Cell::new(false) };
}

/// The threads the engine may use for independent work: 1 on a thread
/// that is already running such work, else `ROBCAL_THREADS` or the
/// processors available (read once).
pub fn threads() -> usize {
    if INSIDE.with(Cell::get) {
        return 1;
    }
    static THREADS: OnceLock<usize> = OnceLock::new();
    *THREADS.get_or_init(|| {
        std::env::var("ROBCAL_THREADS")
            .ok()
            .and_then(|v| v.trim().parse::<usize>().ok())
            .filter(|&n| n > 0)
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
    })
}

/// Marks the current thread as running an item while it lives.
struct Inside(bool);

impl Inside {
    fn enter() -> Self {
        Self(INSIDE.with(|c| c.replace(true)))
    }
}

impl Drop for Inside {
    fn drop(&mut self) {
        INSIDE.with(|c| c.set(self.0));
    }
}

/// A worker thread of the scope `s` running `f`, or the system's refusal
/// (too many threads or processes: `RLIMIT_NPROC`, memory): the callers
/// then do that work on the calling thread, not panic as
/// `Scope::spawn` would.
fn spawn<'s, 'e, R: Send + 's>(
    s: &'s std::thread::Scope<'s, 'e>,
    f: impl FnOnce() -> R + Send + 's,
) -> Option<std::thread::ScopedJoinHandle<'s, R>> {
    #[cfg(test)]
    if REFUSE
        .with(|r| r.get().checked_sub(1).map(|left| r.set(left)))
        .is_some()
    {
        return None;
    }
    std::thread::Builder::new().spawn_scoped(s, f).ok()
}

#[cfg(test)]
thread_local! {
    /// Tests: the next this many [`spawn`]s on this thread are refused.
    static REFUSE: Cell<usize> = const { Cell::new(0) };
}

/// `f(0), …, f(n − 1)` in order, on up to `threads` threads.
pub fn map<T: Send>(n: usize, threads: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    map_until(n, threads, f, |_| false)
}

/// `f(0), f(1), …` in order up to and including the first `i` whose
/// result `stop`s (all `n` when none does), on up to `threads` threads.
/// The items are started in index order; once an item stops, no later one
/// is started (later ones already running finish, and are dropped). With
/// one thread (or one item) this is the serial loop; a thread the system
/// refuses is one thread fewer (the calling thread takes every item no
/// worker took).
pub fn map_until<T: Send>(
    n: usize,
    threads: usize,
    f: impl Fn(usize) -> T + Sync,
    stop: impl Fn(&T) -> bool + Sync,
) -> Vec<T> {
    let threads = threads.min(n);
    if threads <= 1 {
        let mut out = Vec::with_capacity(n);
        for i in 0..n {
            let t = f(i);
            let done = stop(&t);
            out.push(t);
            if done {
                break;
            }
        }
        return out;
    }
    let next = AtomicUsize::new(0);
    let first_stop = AtomicUsize::new(usize::MAX);
    let work = || {
        let _inside = Inside::enter();
        let mut done = Vec::new();
        loop {
            // Indices are taken in increasing order: every index below the
            // first stop is taken, and finished, before the threads join.
            let i = next.fetch_add(1, Ordering::SeqCst);
            if i >= n || i > first_stop.load(Ordering::SeqCst) {
                return done;
            }
            let t = f(i);
            if stop(&t) {
                first_stop.fetch_min(i, Ordering::SeqCst);
            }
            done.push((i, t));
        }
    };
    let mut all = std::thread::scope(|s| {
        let workers: Vec<_> = (1..threads).filter_map(|_| spawn(s, work)).collect();
        let mut all = work();
        for w in workers {
            match w.join() {
                Ok(done) => all.extend(done),
                Err(panic) => std::panic::resume_unwind(panic),
            }
        }
        all
    });
    let end = first_stop.into_inner().saturating_add(1).min(n);
    all.retain(|(i, _)| *i < end);
    all.sort_unstable_by_key(|(i, _)| *i);
    all.into_iter().map(|(_, t)| t).collect()
}

/// `f(k, item)` for every item, on up to `threads` threads that each take
/// the next item not yet taken (in index order): for items that take
/// unequal times, or threads that the system slows unequally, where
/// [`for_runs_mut`]'s one run per thread waits for the slowest. The first
/// error in item order, every item before it done; once an item fails no
/// later one is started, but later items already taken (running, or taken
/// just before the failure was known) run to their end and keep what they
/// changed in their items (as [`for_runs_mut`]'s runs after a failing one;
/// with one thread, the serial loop, which stops at the failure).
///
/// # Errors
/// The first item's error that has one.
pub fn for_each_mut<T: Send, E: Send>(
    items: &mut [T],
    threads: usize,
    f: impl Fn(usize, &mut T) -> Result<(), E> + Sync,
) -> Result<(), E> {
    if threads <= 1 || items.len() < 2 {
        return items.iter_mut().enumerate().try_for_each(|(k, t)| f(k, t));
    }
    // Each item once, to the thread that takes its index.
    let slots: Vec<Mutex<Option<&mut T>>> = items.iter_mut().map(|t| Mutex::new(Some(t))).collect();
    let take = |k: usize| slots[k].lock().ok().and_then(|mut slot| slot.take());
    map_until(
        slots.len(),
        threads,
        |k| take(k).map_or(Ok(()), |t| f(k, t)),
        Result::is_err,
    )
    .into_iter()
    .collect()
}

/// Fewest rows a thread is started for.
pub const MIN_ROWS_PER_THREAD: usize = 4096;

/// Threads for `rows` rows: [`threads`], at most one per
/// [`MIN_ROWS_PER_THREAD`] rows.
pub fn for_rows(rows: usize) -> usize {
    threads().min(rows / MIN_ROWS_PER_THREAD).max(1)
}

/// `f(first, run)` on `threads` contiguous runs of `items`, mutably
/// (`first`: the index of the run's first item); the first error in item
/// order (each run stops at its first; the runs after it have run). A run
/// whose thread the system refuses runs on the calling thread.
///
/// # Errors
/// The first run's error that has one.
pub fn for_runs_mut<T: Send, E: Send>(
    items: &mut [T],
    threads: usize,
    f: impl Fn(usize, &mut [T]) -> Result<(), E> + Sync,
) -> Result<(), E> {
    if threads <= 1 || items.len() < 2 {
        return f(0, items);
    }
    let per = items.len().div_ceil(threads);
    let f = &f;
    let run_here = |first: usize, run: &mut [T]| {
        let _inside = Inside::enter();
        f(first, run)
    };
    std::thread::scope(|s| {
        // Each run is sent to its worker once the worker has started, so
        // that a refused worker leaves its run here.
        let slots: Vec<_> = items
            .chunks_mut(per)
            .enumerate()
            .map(|(k, run)| {
                let (tx, rx) = std::sync::mpsc::channel::<&mut [T]>();
                let worker = spawn(s, move || rx.recv().ok().map(|run| run_here(k * per, run)));
                match worker {
                    Some(h) => match tx.send(run) {
                        Ok(()) => Err(h),
                        Err(back) => Ok(run_here(k * per, back.0)),
                    },
                    None => Ok(run_here(k * per, run)),
                }
            })
            .collect();
        slots
            .into_iter()
            .map(|slot| match slot {
                Ok(done) => Some(done),
                Err(h) => h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)),
            })
            .collect::<Vec<_>>()
    })
    .into_iter()
    .try_for_each(|done| done.unwrap_or(Ok(())))
}

#[cfg(test)]
mod tests;
