//! The TIAGo motion-capture calibration of issue 7 (docs/tiago.md): the
//! FIGAROH table (registration, joint offsets, full joint-frame errors; point
//! BL and all four points) and the closed loop, fitted on the 2021-11-30
//! recording only and evaluated on 2021-11-26.
//!
//! ```text
//! cargo run --release --example tiago
//! ```
//!
//! Reads `shared/datasets/tiago-mocap` beside the repository (or
//! `$ROBCAL_TIAGO_DATA`) and prints Markdown.

#[path = "../host-tests/tests/tiago_common/mod.rs"]
mod tiago_common;

use tiago_common::*;

fn main() {
    let text = with_stack(|| {
        let job = job();
        let dir = temp_dir("example");
        let train = postures(&import(&job, TRAIN, &dir), &job.robot);
        let valid = postures(&import(&job, VALID, &dir), &job.robot);
        let report = report(&job, &train, &valid);
        let _ = std::fs::remove_dir_all(&dir);
        report.markdown(&train, &valid)
    });
    print!("{text}");
}
