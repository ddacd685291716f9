//! Independent computations of the engine on worker threads, with the
//! answers of the serial order (issue 16).
//!
//! The held-out folds of a weighted fit
//! ([`super::engine::Engine::heldout`]) are independent of one another:
//! each item is computed by the same code as in a serial loop, on one
//! thread, from the same inputs, and the results are handed back by index.
//! The answers are therefore bit for bit those of the serial loop, whatever
//! the number of threads (tests: `tests` below, and `tests/cli_threads.rs`
//! on the TIAGo runs).
//!
//! The number of threads is `ROBCAL_THREADS` (a positive integer; `1` runs
//! everything on the calling thread), else
//! [`std::thread::available_parallelism`]. Work that is already on a
//! worker runs serially on it: no nesting.
//! The calling thread works too; no thread outlives the call.

use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::OnceLock;

thread_local! {
    /// Whether this thread is running an item of [`map_until`].
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

/// `f(0), …, f(n − 1)` in order, on up to `threads` threads.
pub fn map<T: Send>(n: usize, threads: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    map_until(n, threads, f, |_| false)
}

/// `f(0), f(1), …` in order up to and including the first `i` whose
/// result `stop`s (all `n` when none does), on up to `threads` threads.
/// The items are started in index order; once an item stops, no later one
/// is started (later ones already running finish, and are dropped). With
/// one thread (or one item) this is the serial loop.
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
        let workers: Vec<_> = (1..threads).map(|_| s.spawn(work)).collect();
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_come_back_in_order() {
        for threads in [1, 2, 3, 8] {
            let out = map(50, threads, |i| i * i);
            assert_eq!(out, (0..50).map(|i| i * i).collect::<Vec<_>>());
        }
        assert!(map(0, 4, |i| i).is_empty());
    }

    #[test]
    fn a_stop_ends_the_list_there_as_the_serial_loop() {
        for threads in [1, 2, 4] {
            let out = map_until(40, threads, |i| i, |&i| i % 7 == 6);
            assert_eq!(out, (0..7).collect::<Vec<_>>());
            let out = map_until(5, threads, |i| i, |_| false);
            assert_eq!(out, vec![0, 1, 2, 3, 4]);
        }
    }

    #[test]
    fn work_on_a_worker_is_serial() {
        let inner = map(4, 4, |_| threads());
        assert_eq!(inner, vec![1; 4]);
    }
}
