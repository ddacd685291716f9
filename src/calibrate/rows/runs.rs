//! How the rows of a pass are split between worker threads.

use crate::calibrate::design::view::BLOCK_ROWS;

/// Rows a run of [`crate::calibrate::rows::Rows::relinearise_with`] has on `threads` threads
/// (the last run fewer): all of them on one thread; else about eight runs
/// per thread (`RUNS_PER_THREAD`), taken in turn, so that a thread the
/// system slows leaves the others the runs it has not started (one run per
/// thread waited ~0.05–0.1 s per relinearisation of 10⁶ rows for the slower
/// thread on a shared machine). Runs of four of a view's blocks of rows or
/// more are whole blocks, so that a design's pass can make the blocks' sums
/// ([`crate::calibrate::design::Design::relinearised`]).
pub fn run_length(rows: usize, threads: usize) -> usize {
    if threads <= 1 {
        return rows.max(1);
    }
    let per = rows.div_ceil(threads * RUNS_PER_THREAD).max(1);
    if per >= 4 * BLOCK_ROWS {
        per.next_multiple_of(BLOCK_ROWS)
    } else {
        per
    }
}

/// Runs per thread of [`crate::calibrate::rows::Rows::relinearise_with`] ([`run_length`]).
const RUNS_PER_THREAD: usize = 8;

#[cfg(test)]
mod tests {
    use crate::calibrate::rows::runs::*;

    #[test]
    fn long_runs_are_whole_blocks() {
        assert_eq!(run_length(1000, 1), 1000);
        assert_eq!(run_length(1000, 2), 63);
        assert_eq!(run_length(1_000_000, 2), 16 * BLOCK_ROWS);
        assert_eq!(run_length(4 * BLOCK_ROWS * 16, 2), 4 * BLOCK_ROWS);
        assert_eq!(run_length(0, 2), 1);
    }
}
