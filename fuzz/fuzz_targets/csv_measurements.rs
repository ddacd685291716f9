//! Arbitrary bytes as a measurement CSV for a fixed 3-joint robot; the
//! first byte picks the setup (units, load). Invariants:
//! `host_tests::fuzz_io::run_csv`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::sync::OnceLock;

static ROBOT: OnceLock<host_tests::fuzz_io::Robot> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    let robot = ROBOT.get_or_init(host_tests::fuzz_io::csv_robot);
    host_tests::fuzz_io::run_csv(robot, data);
});
