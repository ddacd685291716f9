//! The bare-metal side: entry point, fault handlers, defmt logging, the
//! instruction-count marks and the stack high-water mark.

use core::hint::black_box;

use cortex_m_rt::{entry, exception, ExceptionFrame};
use defmt::{error, info};
use defmt_semihosting as _; // the global defmt logger (semihosting stdout)
use nalgebra::Vector3;
use robcal::estimate::RobustWeight;
use robcal::{Accumulator, Block, Error, JointKind, LinkInertia, Reweightable};
use semihosting::process::exit;

use crate::kr270::{self, Kr270, G, HISTORY};
use crate::problem::{self, check, rejects_bad_block, stream, Dn, Gen, N};
use crate::SelfTest;

/// Exit status of a failed check (a panic exits 101, a HardFault 3).
const EXIT_FAIL: i32 = 1;

#[entry]
fn main() -> ! {
    info!(
        "robcal firmware: N = {=usize}, {=usize} blocks, {=str}",
        N,
        problem::BLOCKS,
        if cfg!(target_abi = "eabihf") {
            "Cortex-M4F (hard float)"
        } else {
            "Cortex-M3 (soft float)"
        }
    );
    let fault = fault_arg();
    match fault {
        SelfTest::Panic => panic!("deliberate panic (self-test)"),
        // UDF escalates to a HardFault (UsageFault is not enabled).
        SelfTest::HardFault => cortex_m::asm::udf(),
        SelfTest::Mismatch => info!("self-test: checking against a wrong X_true"),
        SelfTest::None => {}
    }

    // Separate, non-inlined phases: their stack frames do not add up.
    log_types();
    let mut k = 0;
    benchmarks(&mut k);
    let pass = fit(fault);
    let pass_kr270 = kr270_fit(&mut k, fault);
    // Measured last, after the deepest call.
    info!("stack high-water mark: {=usize} bytes", stack_high_water());
    if pass && pass_kr270 {
        info!("PASS");
        exit(0)
    } else {
        error!("FAIL: estimates outside tolerance");
        exit(EXIT_FAIL)
    }
}

/// The fit: streams the problem in, solves in both precisions, checks and
/// logs the estimates. Returns whether every check passed.
#[inline(never)]
fn fit(fault: SelfTest) -> bool {
    let mut acc32 = Accumulator::<f32, Dn>::new();
    let mut acc64 = Accumulator::<f64, Dn>::new();
    if let Err(e) = stream(&mut acc32, &mut acc64, |b| info!("first block: {}", b)) {
        fail("update refused a valid block", e);
    }
    info!(
        "streamed: {=usize} equations, {=usize} with sigma; eta = {=[?]}; sum dp'W²dp = {=f32}",
        acc32.equations(),
        acc32.sigma_rows(),
        acc32.eta().as_slice(),
        acc32.weighted_yy()
    );
    let bad = rejects_bad_block(&mut acc32);
    match bad {
        Some(e) => info!("bad block rejected, state unchanged: {}", e),
        None => error!("a non-finite block was accepted or changed the state"),
    }
    let s32 = acc32.solve().unwrap_or_else(|e| fail("f32 solve", e));
    let s64 = acc64.solve().unwrap_or_else(|e| fail("f64 solve", e));
    info!("Solution<f32>: {}", s32);

    let v = check(&s32, &s64, &acc64, &crate::expected_x(fault));
    info!("param  x (f64) +/- 3 sigma [m|rad]   x (f32)   |err|/sigma  |f32-f64|/sigma");
    for (i, p) in v.params.iter().enumerate() {
        info!(
            "{=usize}  {=f64} +/- {=f64}  {=f32}  {=f64}  {=f64}",
            i,
            p.x64,
            3.0 * p.sd,
            p.x32,
            p.err_sigmas,
            p.f32_sigmas
        );
    }
    info!(
        "sigma_hat / sigma = {=f64} (tolerances: {=f64} sigma to X_true, {=f64} sigma f32 vs f64, {=f64} on sigma_hat)",
        v.sigma_hat_ratio,
        problem::TOL_SIGMAS,
        problem::TOL_F32_SIGMAS,
        problem::TOL_SIGMA_HAT
    );
    v.pass && bad.is_some()
}

/// The paper's experiment on the device, in f32: the 270 deflections
/// streamed from flash on every pass, rows computed from the joint angles,
/// the iterative WLS to convergence, the estimates ± 3σ logged and checked
/// against the host's f64 result. The costs of its parts are bench phases:
/// the rows of one configuration, the OLS start (two passes), one
/// iteration (one pass: `kr270::Kr270::sweep`), and the whole iterative
/// WLS (whose result is checked).
#[inline(never)]
fn kr270_fit(k: &mut usize, fault: SelfTest) -> bool {
    let src = Kr270::<f32>::new().unwrap_or_else(|e| fail("KR-270 model", e));
    let settings = kr270::settings::<f32>().unwrap_or_else(|e| fail("settings", e));
    info!(
        "KR-270 (section 5): {=usize} deflections in flash, {=usize} configurations, layout {}",
        kr270::KEYS.len(),
        G,
        src.layout().columns()[0]
    );
    info!(
        "settings: {}; table quantisation moves the host estimate by {=f64} sigma",
        settings,
        kr270::QUANTISATION_SIGMAS
    );
    kr270_parts(k, &src, &settings);
    let fit = kr270_irls(k, &src, &settings);
    kr270_report(&fit, fault) && kr270_compensate(k, &fit)
}

/// Compensation on the device (issue 14) with the calibrated compliances:
/// the taught point of configuration 1 reached under a 270 kg payload. A
/// bench phase; checked by a separate equilibrium at the command.
#[inline(never)]
fn kr270_compensate(k: &mut usize, fit: &kr270::Estimate<f32>) -> bool {
    let settings = kr270::compensate_settings::<f32>();
    let problem = kr270::Compensation::new(&fit.x).unwrap_or_else(|e| fail("compensation", e));
    let problem = black_box(&problem);
    let c = phase(
        k,
        "kr270 compensate f32 (payload 270 kg, Newton on the equilibrium)",
        || problem.solve(&settings),
    )
    .unwrap_or_else(|e| fail("compensate", e));
    let check = problem
        .miss_m(&c.q, &settings.equilibrium)
        .unwrap_or_else(|e| fail("check", e));
    let sag = problem
        .miss_m(&problem.q, &settings.equilibrium)
        .unwrap_or_else(|e| fail("sag", e));
    let q = &c.q;
    info!(
        "compensation: sag {=f32} mm uncompensated -> {=f32} um in {=usize} steps (check {=f32} um); command [rad] {=f32} {=f32} {=f32} {=f32} {=f32} {=f32}",
        sag * 1e3,
        c.error_m * 1e6,
        c.iterations,
        check * 1e6,
        q[0], q[1], q[2], q[3], q[4], q[5]
    );
    c.iterations <= kr270::COMPENSATE_MAX_STEPS && check <= 2e-6
}

/// Checks the estimate against the host's and logs it.
#[inline(never)]
fn kr270_report(fit: &kr270::Estimate<f32>, fault: SelfTest) -> bool {
    let expected = crate::kr270_expected(fault);
    let (params, pass) = kr270::check(fit, &expected);
    info!(
        "KR-270 iterative WLS (f32): {=usize} iterations (host f64: {=usize}), converged: {=bool}",
        fit.iterations,
        kr270::HOST_ITERATIONS,
        fit.converged
    );
    info!("param  x +/- 3 sigma [urad/(N*m)]  host x  |x-host|/sigma  |sd/host-1|");
    for (i, p) in params.iter().enumerate() {
        info!(
            "{=str}  {=f64} +/- {=f64}  {=f64}  {=f64}  {=f64}",
            robcal_paper::kr270::PAPER_SYMBOLS[i],
            p.x,
            3.0 * p.sd,
            expected[i],
            p.x_sigmas,
            p.sd_rel
        );
    }
    info!(
        "tolerances: {=f64} sigma on x, {=f64} relative on sigma; {=str}",
        kr270::TOL_X_SIGMAS,
        kr270::TOL_SD_REL,
        if pass {
            "KR-270 check passed"
        } else {
            "KR-270 check FAILED"
        }
    );
    pass
}

/// The parts of the KR-270 fit as bench phases, each in its own frame (not
/// inlined), so that none of them adds to the stack of another or of the
/// whole fit.
#[inline(never)]
fn kr270_parts(k: &mut usize, src: &Kr270<f32>, settings: &robcal::IrlsSettings<f32>) {
    kr270_rows(k, src);
    kr270_iteration(k, src, settings);
}

#[inline(never)]
fn kr270_rows(k: &mut usize, src: &Kr270<f32>) {
    let first = phase(
        k,
        "kr270 rows of one configuration f32 (FK, load torques, 3 markers)",
        || src.config_blocks(0),
    )
    .unwrap_or_else(|e| fail("rows", e));
    info!(
        "B of configuration 1, marker 1 [m per urad/(N*m)]: {}",
        robcal::estimate::fmt::rows(&first[0])
    );
}

#[inline(never)]
fn kr270_iteration(k: &mut usize, src: &Kr270<f32>, settings: &robcal::IrlsSettings<f32>) {
    let active = [true; kr270::N];
    let mut weights = [nalgebra::Vector3::zeros(); G];
    let mut sigma = [nalgebra::Vector3::zeros(); G];
    let mut dof = [nalgebra::Vector3::zeros(); G];
    phase(k, "kr270 OLS start f32 (2 passes, solve, sandwich)", || {
        src.fit_ols(&active, &mut weights, &mut sigma, &mut dof)
    })
    .unwrap_or_else(|e| fail("OLS", e));
    let one = phase(
        k,
        "kr270 one IRLS iteration f32 (weights, solve, 1 pass, sandwich)",
        || {
            src.fit_reweighted(
                &settings.weight,
                &active,
                &mut weights,
                &mut sigma,
                &mut dof,
            )
        },
    )
    .unwrap_or_else(|e| fail("one iteration", e));
    info!("first WLS step (Fit): {}", one);
}

/// The whole iterative WLS (a bench phase); logs the convergence of k21
/// (the paper's Figure 3) and returns the estimate.
#[inline(never)]
fn kr270_irls(
    k: &mut usize,
    src: &Kr270<f32>,
    settings: &robcal::IrlsSettings<f32>,
) -> kr270::Estimate<f32> {
    let mut history = heapless::Vec::<_, HISTORY>::new();
    let mut weights = [nalgebra::Vector3::zeros(); G];
    let mut sigma = [nalgebra::Vector3::zeros(); G];
    let mut dof = [nalgebra::Vector3::zeros(); G];
    let fit = phase(
        k,
        "kr270 whole iterative WLS f32 (OLS start + iterations)",
        || {
            src.fit_irls(
                settings,
                &[true; kr270::N],
                &mut weights,
                &mut sigma,
                &mut dof,
                |it| {
                    let _ = history.push(*it);
                },
            )
        },
    )
    .unwrap_or_else(|e| fail("iterative WLS", e));
    info!("convergence of k21 (Figure 3): iteration, k21, 3 sigma, change [sigma]");
    for (i, it) in history.iter().enumerate() {
        info!(
            "  {=usize}  {=f32}  {=f32}  {=f32}",
            i,
            it.x[0],
            3.0 * it.std[0],
            it.change
        );
    }
    info!("last iteration (Iteration): {}", history.last());
    (&fit).into()
}

/// The failure self-test named by the first semihosting command-line
/// argument (`-semihosting-config ...,arg=firmware,arg=mismatch`).
fn fault_arg() -> SelfTest {
    let Ok(args) = semihosting::experimental::env::args::<64>() else {
        return SelfTest::None;
    };
    let mut args = &args; // the iterator is `&Args`
    SelfTest::parse(args.nth(1).and_then(Result::ok))
}

fn fail(what: &str, e: Error) -> ! {
    error!("FAIL: {=str}: {}", what, e);
    exit(EXIT_FAIL)
}

/// Logs one value of every public type of robcal that has (or should have)
/// `defmt::Format`, so that a missing derive, or a dependency's missing
/// `defmt` feature, fails this build. `Block` and `Solution` are logged in
/// `fit`, `Fit` and `Iteration` in the KR-270 fit, `Error` here and on a
/// failure; robcal prints its matrices and vectors as plain lists
/// (`robcal::estimate::fmt`).
#[inline(never)]
fn log_types() {
    let e = Accumulator::<f32, Dn>::new().solve().err();
    info!("Error (solving an empty accumulator): {}", e);
    info!("RobustWeight: {}", RobustWeight::new(10e-6f32, 1.0).ok());
    let joint = robcal::Joint::from_urdf(
        Vector3::new(0.0f32, 0.0, 0.675),
        Vector3::zeros(),
        Vector3::z(),
        JointKind::Revolute,
    )
    .map(|mut j| {
        j.link = Some(LinkInertia {
            mass_kg: 1.0,
            com_m: Vector3::new(0.0, 0.0, 0.1),
        });
        j
    });
    info!("Joint: {}", joint);
}

/// Marks a phase boundary for the instruction counter (`tools/insnmark.c`
/// prints the running instruction count each time this function's first
/// instruction executes). `black_box` keeps the call from being removed; the
/// name is unmangled so the script finds it with `llvm-nm`.
#[inline(never)]
#[no_mangle]
fn bench_mark() {
    black_box(());
}

/// Runs `f` between two marks and logs the phase's index and name. The
/// script pairs the marks (2k, 2k+1) with the k-th `bench phase` line.
fn phase<R>(k: &mut usize, name: &str, f: impl FnOnce() -> R) -> R {
    bench_mark();
    let r = black_box(f());
    bench_mark();
    info!("bench phase {=usize}: {=str}", *k, name);
    *k += 1;
    r
}

/// One update of a 3-row block (N = 9) with and without σ, and one solve,
/// in f32 then in f64, each between two marks (phase 0 is empty: the
/// bracket overhead).
#[inline(never)]
fn benchmarks(k: &mut usize) {
    phase(k, "empty (bracket overhead)", || ());
    let ok32 = bench_precision::<f32>(k, "f32", problem::to_f32);
    let ok64 = bench_precision::<f64>(k, "f64", |b| *b);
    if !(ok32 && ok64) {
        error!("a benchmark call failed");
        exit(EXIT_FAIL)
    }
}

/// The phases of one precision. The accumulator is first filled with a few
/// blocks; the inputs are prepared outside the marks and passed through
/// `black_box`, so the counts hold only the call itself. Not inlined, so
/// that the two precisions' frames do not add up on the stack.
#[inline(never)]
fn bench_precision<T: nalgebra::RealField + Copy>(
    k: &mut usize,
    precision: &str,
    convert: impl Fn(&Block<f64, Dn>) -> Block<T, Dn>,
) -> bool {
    let mut gen = Gen::new(problem::SEED ^ 0xBEEF);
    let mut acc = Accumulator::<T, Dn>::new();
    for _ in 0..8 {
        let _ = acc.update(&convert(&gen.block()));
    }
    let with_sigma = black_box(convert(&gen.block()));
    let plain = black_box(Block::new(with_sigma.b, with_sigma.dp));
    let acc = black_box(&mut acc);
    let names: [&str; 3] = match precision {
        "f32" => [
            "update f32 N=9 (3 rows)",
            "update f32 N=9 (3 rows, sigma)",
            "solve f32 N=9",
        ],
        _ => [
            "update f64 N=9 (3 rows)",
            "update f64 N=9 (3 rows, sigma)",
            "solve f64 N=9",
        ],
    };
    let r1 = phase(k, names[0], || acc.update(&plain));
    let r2 = phase(k, names[1], || acc.update(&with_sigma));
    let r3 = phase(k, names[2], || acc.solve().map(|s| s.x));
    r1.is_ok() && r2.is_ok() && r3.is_ok()
}

/// Bytes of stack ever used: cortex-m-rt's `paint-stack` feature fills the
/// stack (`_stack_end` .. `_stack_start`) with `STACK_PAINT_VALUE` before
/// `main`; the lowest word that no longer holds it marks the deepest point.
fn stack_high_water() -> usize {
    extern "C" {
        // Top of the stack (highest address + 1), from cortex-m-rt's link.x.
        static _stack_start: u32;
    }
    // `heap_start()` is `_stack_end`: the stack's lowest address.
    let bottom = cortex_m_rt::heap_start() as usize;
    let top = core::ptr::addr_of!(_stack_start) as usize;
    let mut p = bottom;
    // The only unsafe code of the example. SAFETY: `bottom..top` is RAM
    // reserved for the stack by the linker script; reading it (volatile,
    // word-aligned, below the live stack frames) has no side effects.
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
