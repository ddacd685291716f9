//! robcal on a microcontroller: a streaming weighted-least-squares fit on a
//! Cortex-M under QEMU, with defmt logs over semihosting.
//!
//! Bare metal (`thumbv7em-none-eabihf`, Cortex-M4F on QEMU's `mps2-an386`,
//! or `thumbv7m-none-eabi`, Cortex-M3 on `lm3s6965evb`):
//!
//! ```text
//! cargo firmware       # = cargo run --profile firmware --target thumbv7em-none-eabihf --example firmware
//! cargo firmware-m3    # = cargo run --profile firmware --target thumbv7m-none-eabi --example firmware
//! ```
//!
//! The runner (`tools/qemu-run.sh`) boots the ELF in QEMU, decodes the defmt
//! frames with `defmt-print` and returns the firmware's exit status: 0 when
//! every check passes, non-zero on a failed check (1), a panic (101) or a
//! HardFault (3).
//!
//! What it does (see `problem.rs`): streams 60 synthetic three-row
//! measurements (`N = 9` parameters) into an f32 and an f64
//! `robcal::Accumulator`, one block at a time, solves both, and checks the
//! estimates against the known truth within stated tolerances. It also logs
//! every public type of robcal once (so a missing `defmt::Format` fails the
//! build), brackets single updates and solves with `bench_mark()` calls for
//! the instruction counter (`tools/insn-count.sh`), and reports the stack
//! high-water mark.
//!
//! On the host the example is an ordinary program that runs the same
//! problem and checks and prints the verdict (`cargo run --example firmware`).
//!
//! Self-tests of the failure paths: run with the argument `mismatch`,
//! `panic` or `hardfault` (`cargo firmware -- mismatch`; the runner passes it
//! to the firmware as its semihosting command line) to make the check fail,
//! panic, or fault; each must end QEMU with a non-zero status.
#![cfg_attr(target_os = "none", no_std, no_main)]

mod problem;

#[cfg(target_os = "none")]
mod device;

/// A failure self-test, chosen by the first command-line argument.
#[derive(Clone, Copy, PartialEq)]
enum SelfTest {
    None,
    /// The check compares with a wrong `X_true` and must fail.
    Mismatch,
    /// A panic.
    Panic,
    /// A HardFault (device only; on the host it is a panic too).
    HardFault,
}

impl SelfTest {
    fn parse(arg: Option<&str>) -> Self {
        match arg {
            Some("mismatch") => Self::Mismatch,
            Some("panic") => Self::Panic,
            Some("hardfault") => Self::HardFault,
            _ => Self::None,
        }
    }
}

/// `X_true` as the checks see it: with [`SelfTest::Mismatch`] one value is
/// moved by 1 mm, far outside any tolerance, so the check must fail.
fn expected_x(fault: SelfTest) -> [f64; problem::N] {
    let mut x = problem::X_TRUE;
    if fault == SelfTest::Mismatch {
        x[4] += 1e-3;
    }
    x
}

#[cfg(not(target_os = "none"))]
fn main() {
    use problem::{check, rejects_bad_block, stream, N};

    let fault = SelfTest::parse(std::env::args().nth(1).as_deref());
    if matches!(fault, SelfTest::Panic | SelfTest::HardFault) {
        panic!("deliberate panic (self-test)");
    }
    let mut acc32 = robcal::Accumulator::new();
    let mut acc64 = robcal::Accumulator::new();
    stream(&mut acc32, &mut acc64, |_| {}).expect("valid stream");
    let bad = rejects_bad_block(&mut acc32);
    let s32 = acc32.solve().expect("f32 solve");
    let s64 = acc64.solve().expect("f64 solve");
    let v = check(&s32, &s64, &acc64, &expected_x(fault));
    println!(
        "robcal firmware example, host build: N = {N}, {} equations",
        s64.equations
    );
    println!("param  x (f64) [m|rad]   3 sigma     x (f32)          |err|/sigma  |f32-f64|/sigma");
    for (i, p) in v.params.iter().enumerate() {
        println!(
            "{i:5} {:16.9e} {:10.3e} {:16.9e} {:9.3} {:12.2e}",
            p.x64,
            3.0 * p.sd,
            p.x32,
            p.err_sigmas,
            p.f32_sigmas
        );
    }
    println!(
        "sigma_hat / sigma = {:.4}; bad block rejected: {:?}",
        v.sigma_hat_ratio, bad
    );
    let ok = v.pass && bad.is_some();
    println!("{}", if ok { "PASS" } else { "FAIL" });
    std::process::exit(if ok { 0 } else { 1 });
}
