//! Row-by-row work on the host's cores: the rows of a relinearisation and
//! the rows of a design are independent of each other. Each thread takes a
//! contiguous run of rows and the results come back in row order, so the
//! answers are the same bits whatever the number of threads.
//!
//! The number of threads is the machine's
//! ([`std::thread::available_parallelism`]), or `ROBCAL_THREADS` when it is
//! set to a positive integer (`ROBCAL_THREADS=1`: one thread), and never
//! more than one per [`MIN_ROWS_PER_THREAD`] rows (a thread costs tens of
//! µs to start; a small job stays on the calling thread).

use std::num::NonZeroUsize;

/// Fewest rows a thread is started for.
pub const MIN_ROWS_PER_THREAD: usize = 4096;

/// Threads for `rows` rows: see the module documentation.
pub fn threads(rows: usize) -> usize {
    let machine = std::thread::available_parallelism().map_or(1, NonZeroUsize::get);
    let cap = std::env::var("ROBCAL_THREADS")
        .ok()
        .and_then(|v| v.trim().parse::<usize>().ok())
        .filter(|&n| n >= 1)
        .unwrap_or(machine);
    cap.min(rows / MIN_ROWS_PER_THREAD).max(1)
}

/// `f` on `threads` contiguous runs of `items` (one run on the calling
/// thread when `threads <= 1`): each run's result, in order.
pub fn map_runs<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&[T]) -> R + Sync,
) -> Vec<R> {
    if threads <= 1 || items.len() < 2 {
        return vec![f(items)];
    }
    let per = items.len().div_ceil(threads);
    let f = &f;
    std::thread::scope(|s| {
        let handles: Vec<_> = items
            .chunks(per)
            .map(|run| s.spawn(move || f(run)))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect()
    })
}

/// `f` on `threads` contiguous runs of `items`, mutably; the first error
/// in item order (each run stops at its first).
///
/// # Errors
/// The first run's error that has one.
pub fn for_runs_mut<T: Send, E: Send>(
    items: &mut [T],
    threads: usize,
    f: impl Fn(&mut [T]) -> Result<(), E> + Sync,
) -> Result<(), E> {
    if threads <= 1 || items.len() < 2 {
        return f(items);
    }
    let per = items.len().div_ceil(threads);
    let f = &f;
    std::thread::scope(|s| {
        let handles: Vec<_> = items
            .chunks_mut(per)
            .map(|run| s.spawn(move || f(run)))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect::<Vec<_>>()
    })
    .into_iter()
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::design::Design;
    use crate::calibrate::{declared, DeflectionModel, Geometry, Linearisation, Names, Rows};
    use nalgebra::Vector3;

    /// The KR-270 job's rows (loaded: the exact model's equilibria) and its
    /// declared design, relinearised and built on 1 and on 3 threads at a
    /// joint law with every compliance at 1 (the reported unit): the same
    /// bits.
    #[test]
    fn rows_and_design_do_not_depend_on_the_threads() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/data/kr270");
        let job = crate::io::Job::load(format!("{dir}/setup.toml")).expect("job");
        let data =
            crate::io::read_measurements(format!("{dir}/measurements.csv"), &job.robot, &job.setup)
                .expect("data");
        let mut names = Names {
            joints: job.robot.joint_names.clone(),
            kinds: job.robot.chain.joints().iter().map(|j| j.kind).collect(),
            markers: job
                .setup
                .markers
                .iter()
                .map(|m| (m.id, Vector3::from(m.xyz)))
                .collect(),
            bins: Default::default(),
        };
        let policy = crate::calibrate::Policy::default();
        let mut rows = Rows::new(
            &job,
            &data,
            declared::needs_absolute(&job),
            &mut names,
            &policy,
        )
        .expect("rows");
        let params = declared::declared(&job, &data.file, &rows, &names).expect("model");
        let markers: Vec<Vector3<f64>> = names.markers.iter().map(|m| m.1).collect();
        let geometry = Geometry::nominal_tree(
            &job.robot.chain,
            &job.robot.ends,
            &markers,
            &crate::calibrate::marker_ends(&job),
        );
        let x = vec![1.0; params.len()];
        let lin = Linearisation::of(DeflectionModel::Exact, &params, &x, &names);
        let mut at = |threads: usize| {
            rows.relinearise_on(&geometry, &lin, threads)
                .expect("relinearise");
            let d = Design::new_on(&rows, &params, &lin, &names, threads).expect("design");
            let r: Vec<_> = rows
                .rows
                .iter()
                .map(|r| (r.y, r.p, r.tau.clone(), r.twists.clone()))
                .collect();
            (r, d.b, d.y)
        };
        let one = at(1);
        assert!(one.0.iter().any(|r| !r.3.is_empty()), "equilibria");
        for threads in [2, 3, 7] {
            assert!(one == at(threads), "{threads} threads");
        }
    }

    #[test]
    fn runs_come_back_in_order() {
        let v: Vec<u32> = (0..1000).collect();
        for t in [1, 2, 3, 7] {
            let sums: Vec<Vec<u32>> = map_runs(&v, t, |r| r.to_vec());
            assert_eq!(sums.concat(), v);
        }
    }

    #[test]
    fn the_first_error_in_item_order() {
        for t in [1, 2, 5] {
            let mut v: Vec<u32> = (0..100).collect();
            let r = for_runs_mut(&mut v, t, |run| {
                for x in run.iter_mut() {
                    if *x == 40 || *x == 90 {
                        return Err(*x);
                    }
                    *x += 1000;
                }
                Ok(())
            });
            assert_eq!(r, Err(40));
            assert_eq!(v[0], 1000);
        }
    }
}
