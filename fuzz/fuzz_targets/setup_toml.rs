//! Arbitrary text as a setup TOML. Invariants: `host_tests::fuzz_io::run_setup`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| host_tests::fuzz_io::run_setup(data));
