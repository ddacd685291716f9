//! Arbitrary `base\0tip\0urdf` text. Invariants: `host_tests::fuzz_io::run_urdf`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| host_tests::fuzz_io::run_urdf(data));
