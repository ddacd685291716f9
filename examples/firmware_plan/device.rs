//! The bare-metal side: entry point, defmt logs of the choices, the
//! instruction-count marks, the stack high-water mark, fault handlers.

use core::hint::black_box;

use cortex_m as _; // its critical section (single core)
use cortex_m_rt::{entry, exception, ExceptionFrame};
use defmt::{error, info};
use defmt_semihosting as _; // the global defmt logger (semihosting stdout)
use nalgebra::SVector;
use robcal::{Accumulator, Error};
use semihosting::process::exit;

use crate::kr270::{Kr270, G, N};
use crate::sequence::{self, PICKS};

#[entry]
fn main() -> ! {
    info!(
        "robcal firmware_plan: {=usize} of {=usize} configurations, N = {=usize}, {=str}",
        PICKS,
        G,
        N,
        if cfg!(target_abi = "eabihf") {
            "Cortex-M4F (hard float)"
        } else {
            "Cortex-M3 (soft float)"
        }
    );
    let mismatch = mismatch_arg();
    let mut k = 0;
    let chosen = run(&mut k);
    info!("stack high-water mark: {=usize} bytes", stack_high_water());
    if crate::check(&chosen, mismatch) {
        info!("PASS: the host's choices");
        exit(0)
    } else {
        error!("FAIL: not the host's choices {=[?]}", crate::HOST_SEQUENCE);
        exit(1)
    }
}

/// The rows of every configuration, one step alone (bench phase), then
/// the whole sequence; its choices logged.
#[inline(never)]
fn run(k: &mut usize) -> [usize; PICKS] {
    phase(k, "empty (bracket overhead)", || ());
    let src = Kr270::<f32>::new().unwrap_or_else(|e| fail("model", e));
    let mut table = sequence::empty::<f32>();
    phase(k, "rows of 15 configurations x 3 markers, f32", || {
        sequence::fill(&src, &mut table)
    })
    .unwrap_or_else(|e| fail("rows", e));
    let mut base = SVector::<f32, N>::zeros();
    let prior = phase(k, "prior of the first choice, f32", || {
        robcal::estimate::plan::prior(&table, &mut base)
    });
    prior.unwrap_or_else(|e| fail("prior", e));
    let acc = Accumulator::<f32, crate::kr270::Dn>::new();
    let first = phase(
        k,
        "next best of 15 configurations (factor + 15 gains), f32, N = 9",
        || sequence::step(&acc, &base, 0, &table, &[false; G]),
    );
    first.unwrap_or_else(|e| fail("step", e));
    let (chosen, gains) = phase(
        k,
        "8 choices, each measured into the accumulator, f32",
        || sequence::sequence(&table),
    )
    .unwrap_or_else(|e| fail("sequence", e));
    for (i, (c, g)) in chosen.iter().zip(gains.iter()).enumerate() {
        info!(
            "choice {=usize}: configuration {=usize}, gain of ln det {=f32}",
            i + 1,
            c + 1,
            *g
        );
    }
    chosen
}

fn mismatch_arg() -> bool {
    let Ok(args) = semihosting::experimental::env::args::<64>() else {
        return false;
    };
    let mut args = &args; // the iterator is `&Args`
    args.nth(1).and_then(Result::ok) == Some("mismatch")
}

fn fail(what: &str, e: Error) -> ! {
    error!("FAIL: {=str}: {}", what, e);
    exit(1)
}

/// Marks a phase boundary for the instruction counter
/// (`tools/insnmark.c`), as the firmware example's.
#[inline(never)]
#[no_mangle]
fn bench_mark() {
    black_box(());
}

/// Runs `f` between two marks and logs the phase's index and name.
fn phase<R>(k: &mut usize, name: &str, f: impl FnOnce() -> R) -> R {
    bench_mark();
    let r = black_box(f());
    bench_mark();
    info!("bench phase {=usize}: {=str}", *k, name);
    *k += 1;
    r
}

/// Bytes of stack ever used (the painted stack scanned, as the firmware
/// example's).
fn stack_high_water() -> usize {
    extern "C" {
        static _stack_start: u32;
    }
    let bottom = cortex_m_rt::heap_start() as usize;
    let top = core::ptr::addr_of!(_stack_start) as usize;
    let mut p = bottom;
    // SAFETY: `bottom..top` is RAM reserved for the stack by the linker
    // script; reading it (volatile, word-aligned, below the live stack
    // frames) has no side effects.
    while p < top
        && unsafe { core::ptr::read_volatile(p as *const u32) } == cortex_m_rt::STACK_PAINT_VALUE
    {
        p += 4;
    }
    top - p
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    error!("panic: {}", defmt::Display2Format(info));
    exit(101)
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    error!("HardFault at pc = {=u32:#010x}", frame.pc());
    exit(3)
}
