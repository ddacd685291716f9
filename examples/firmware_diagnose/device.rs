//! The bare-metal side: entry point, defmt logs of the loop's steps, the
//! stack high-water mark, fault handlers.

use cortex_m as _; // its critical section (single core)
use cortex_m_rt::{entry, exception, ExceptionFrame};
use defmt::{error, info};
use defmt_semihosting as _; // the global defmt logger (semihosting stdout)
use robcal::estimate::screen::Rule;
use semihosting::process::exit;

use crate::closed_loop::{self, Step};
use crate::table;

/// A value in µm with one decimal (defmt has no float precision).
struct Tenths(f64);

impl defmt::Format for Tenths {
    fn format(&self, f: defmt::Formatter<'_>) {
        // Rounded half away from zero; i32 (hardware division: an i64 one
        // links 0.9 KB of software division).
        let t = (self.0 * 10.0 + if self.0 < 0.0 { -0.5 } else { 0.5 }) as i32;
        defmt::write!(f, "{=i32}.{=i32}", t / 10, (t % 10).abs());
    }
}

/// ` on a<j>` for a joint's effect.
struct On(Option<u8>);

impl defmt::Format for On {
    fn format(&self, f: defmt::Formatter<'_>) {
        if let Some(j) = self.0 {
            defmt::write!(f, " on a{=u8}", j + 1);
        }
    }
}

fn log_step(s: &Step) {
    info!(
        "diagnosis: added {=str}{}, rms {} -> {} um (F {=f64}, p {=f64}, {=usize} tried)",
        s.effect.name(),
        On(s.joint),
        Tenths(s.rms_um.0),
        Tenths(s.rms_um.1),
        s.test.f,
        s.test.p_value,
        s.tried
    );
}

/// One case: the loop on the table (with the injected backlash or not).
#[inline(never)]
fn case(inject: bool) -> (heapless::Vec<Step, { closed_loop::MAX_EFFECTS }>, f64) {
    // Matched by reference: the table is not copied out of the result.
    let data = table::Table::<f32>::new(inject);
    let data = match &data {
        Ok(d) => d,
        Err(e) => fail("table", *e),
    };
    let settings = table::settings().unwrap_or_else(|e| fail("settings", e));
    let out = closed_loop::run(
        data,
        &table::naive_model(),
        &settings,
        &Rule::default(),
        log_step,
    )
    .unwrap_or_else(|e| fail("closed loop", e));
    let tested = out.first_tried;
    info!(
        "diagnosis: declared rms {} um, {=usize} candidates tested in the first pass, final rms {} um with {=usize} parameters",
        Tenths(out.declared_rms_um),
        tested,
        Tenths(out.last.rms_um),
        out.last.layout.len()
    );
    (out.steps, out.declared_rms_um)
}

#[entry]
fn main() -> ! {
    info!(
        "robcal firmware_diagnose: the closed loop on the device, {=str}",
        if cfg!(target_abi = "eabihf") {
            "Cortex-M4F (hard float)"
        } else {
            "Cortex-M3 (soft float)"
        }
    );
    info!("diagnosis: KR-270 table, naive model k_a2..k_a6");
    let (kr270, _) = case(false);
    info!("diagnosis: KR-270 table with a backlash of 0.3 mrad on a5 injected");
    let (injected, _) = case(true);
    let rms = kr270.first().map_or((0.0, 0.0), |s| s.rms_um);
    info!("stack high-water mark: {=usize} bytes", stack_high_water());
    if crate::check(&kr270, rms, &injected) {
        info!("PASS");
        exit(0)
    } else {
        error!("FAIL: the device's decisions differ from the host's");
        exit(1)
    }
}

fn fail(what: &str, e: robcal::Error) -> ! {
    error!("FAIL: {=str}: {}", what, e);
    exit(1)
}

/// Bytes of the stack ever used (cortex-m-rt paints it at reset).
fn stack_high_water() -> usize {
    extern "C" {
        // Top of the stack (highest address + 1), from cortex-m-rt's link.x.
        static _stack_start: u32;
    }
    let bottom = cortex_m_rt::heap_start() as usize;
    let top = core::ptr::addr_of!(_stack_start) as usize;
    let mut p = bottom;
    // The only unsafe code of the example (as in examples/firmware).
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

/// Logs where, not the message: formatting a message links `core::fmt`
/// with its float printing (10 KB of flash).
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    match info.location() {
        Some(l) => error!("panic at {=str}:{=u32}", l.file(), l.line()),
        None => error!("panic"),
    }
    exit(101)
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    error!("HardFault at pc = {=u32:#010x}", frame.pc());
    exit(3)
}
