//! Arbitrary text as a FIGAROH mocap export (`robcal import figaroh-mocap`).
//! Invariants: `host_tests::fuzz_io::run_mocap`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| host_tests::fuzz_io::run_mocap(data));
