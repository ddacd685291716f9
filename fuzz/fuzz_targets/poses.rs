//! Arbitrary text as a wide pose file (`robcal import poses`).
//! Invariants: `host_tests::fuzz_io::run_poses`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| host_tests::fuzz_io::run_poses(data));
