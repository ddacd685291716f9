//! Choosing the poses on the controller (issue 54): of the KR-270's 15
//! configurations, the device chooses eight, one at a time, each the one
//! whose rows raise `ln det` of its accumulator's information most
//! (`robcal::estimate::plan::next_best`, the matrix determinant lemma),
//! as it would between measurements. Bare metal under QEMU:
//!
//! ```text
//! cargo firmware-plan      # Cortex-M4F (thumbv7em-none-eabihf)
//! cargo firmware-plan-m3   # Cortex-M3, soft float (thumbv7m-none-eabi)
//! ```
//!
//! Exit status 0 when the device's choices are the host's
//! ([`HOST_SEQUENCE`]: `robcal::calibrate::plan::choose` on the same
//! configurations and payloads, f64; `host-tests/tests/plan.rs` checks
//! that they are); 1 otherwise, 101 on a panic, 3 on a HardFault. The
//! argument `mismatch` checks against a wrong sequence and must fail. On
//! the host the example is a plain program running the same steps in f32
//! and f64 (`cargo run --example firmware_plan`).
//!
//! Modules: `sequence.rs` (the steps, generic over the scalar) and the
//! firmware example's `kr270.rs` (the robot, its rows) by path.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[allow(dead_code)]
#[path = "../firmware/kr270.rs"]
mod kr270;
pub mod sequence;

/// The host's choices, 0-based configurations of Table 2 in the order
/// chosen (`robcal::calibrate::plan::choose`, greedy, criterion `d`, on
/// the 15 configurations under their payloads).
pub const HOST_SEQUENCE: [usize; sequence::PICKS] = [9, 13, 6, 5, 1, 14, 11, 7];

/// Whether a run chose the host's configurations (`mismatch`: against a
/// sequence with its last two swapped, which must fail).
pub fn check(chosen: &[usize; sequence::PICKS], mismatch: bool) -> bool {
    let mut want = HOST_SEQUENCE;
    if mismatch {
        want.swap(sequence::PICKS - 2, sequence::PICKS - 1);
    }
    *chosen == want
}

#[cfg(not(target_os = "none"))]
fn main() {
    let mismatch = std::env::args().nth(1).as_deref() == Some("mismatch");
    let t32 = sequence::table(&kr270::Kr270::<f32>::new().expect("model")).expect("rows");
    let t64 = sequence::table(&kr270::Kr270::<f64>::new().expect("model")).expect("rows");
    let (c32, g32) = sequence::sequence(&t32).expect("f32 plan");
    let (c64, g64) = sequence::sequence(&t64).expect("f64 plan");
    for k in 0..sequence::PICKS {
        println!(
            "choice {}: configuration {} (f32), {} (f64); gain of ln det {:.6} (f32), {:.6} (f64)",
            k + 1,
            c32[k] + 1,
            c64[k] + 1,
            g32[k],
            g64[k]
        );
    }
    let ok = check(&c32, mismatch) && check(&c64, mismatch);
    println!("{}", if ok { "PASS" } else { "FAIL" });
    std::process::exit(if ok { 0 } else { 1 });
}

#[cfg(target_os = "none")]
mod device;
