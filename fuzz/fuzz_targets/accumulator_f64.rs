//! Sequences of updates, merges, resets and solves of `Accumulator<f64, Const<4>>`
//! with hostile floats; the invariants are asserted inside
//! `host_tests::fuzz_ops::run` (see its module docs).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let ops = host_tests::fuzz_ops::decode(data);
    host_tests::fuzz_ops::run::<f64>(&ops);
});
