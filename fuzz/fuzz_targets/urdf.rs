//! Arbitrary `base\0tip\0urdf` text. Invariants: `host_tests::fuzz_io::run_urdf`.
//!
//! robcal turns a panic of urdf-rs's XML parser into an error
//! (`catch_unwind`; the release profile unwinds). libfuzzer-sys's panic hook
//! aborts before any unwinding, so this target replaces it, once, by a
//! silent one: a panic robcal catches passes, and one that escapes still
//! reaches libfuzzer-sys's own `catch_unwind` around the target, which
//! aborts (a crash).
#![no_main]

use libfuzzer_sys::fuzz_target;

static HOOK: std::sync::Once = std::sync::Once::new();

fuzz_target!(|data: &[u8]| {
    HOOK.call_once(|| std::panic::set_hook(Box::new(|_| {})));
    host_tests::fuzz_io::run_urdf(data)
});
