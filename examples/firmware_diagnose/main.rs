//! The closed loop on a microcontroller (issue 17): the device fits the
//! KR-270's naive model (one compliance per joint a2…a6) from the
//! firmware's flash table, tests every effect the model lacks from
//! cross-products accumulated in one pass (`robcal::estimate::screen`),
//! names the winner by the host's rule, refits, and logs
//!
//! ```text
//! diagnosis: added compensator on a2, rms 263.7 -> 123.8 um
//! ```
//!
//! then does the same on the table with a backlash on a5 injected
//! (`table.rs`) and must name it. Bare metal under QEMU, as the firmware
//! example:
//!
//! ```text
//! cargo firmware-diagnose      # Cortex-M4F (thumbv7em-none-eabihf)
//! cargo firmware-diagnose-m3   # Cortex-M3, soft float (thumbv7m-none-eabi)
//! ```
//!
//! Exit status 0 when both decisions are the expected ones (the host's:
//! `host-tests/tests/device_diagnosis.rs` checks that they are, with F,
//! p and RMS) and the KR-270 RMS is within 0.1 µm of the host's; 1
//! otherwise, 101 on a panic, 3 on a HardFault. On the host the example is
//! a plain program running the same loop in f32 and f64
//! (`cargo run --example firmware_diagnose`).
//!
//! Modules: `closed_loop.rs` (the loop, generic over the scalar and the
//! data), `table.rs` (the flash table as its data), and the firmware
//! example's `kr270.rs` (the robot and the table) by path.
#![cfg_attr(target_os = "none", no_std, no_main)]

// Not every field is read by both builds (device, host).
#[allow(dead_code)]
mod closed_loop;
#[allow(dead_code)]
#[path = "../firmware/kr270.rs"]
mod kr270;
mod table;

use closed_loop::Step;
use robcal::model::effect::Effect;

/// The host's decisions (`robcal calibrate --linear`, checked equal to the
/// device's by `host-tests/tests/device_diagnosis.rs`): the KR-270 naive
/// model gains the compensator on a2 …
pub const KR270_EXPECTED: &[(Effect, Option<u8>)] = &[(Effect::Compensator, Some(1))];
/// … with the RMS before and after \[µm\] (the host's, to 1e-3 µm).
pub const KR270_RMS_UM: (f64, f64) = (263.683, 123.813);
/// … and with a backlash on a5 injected, the backlash is named.
pub const INJECTED_EXPECTED: (Effect, Option<u8>) = (Effect::Backlash, Some(4));
/// The device's RMS may differ from the host's by this much \[µm\] (f32:
/// measured 6e-3 µm).
pub const RMS_TOL_UM: f64 = 0.1;

/// Whether a run took the expected decisions.
pub fn check(kr270: &[Step], kr270_rms: (f64, f64), injected: &[Step]) -> bool {
    let ok_kr270 = kr270.len() == KR270_EXPECTED.len()
        && kr270
            .iter()
            .zip(KR270_EXPECTED)
            .all(|(s, e)| (s.effect, s.joint) == *e);
    let ok_rms = libm::fabs(kr270_rms.0 - KR270_RMS_UM.0) <= RMS_TOL_UM
        && libm::fabs(kr270_rms.1 - KR270_RMS_UM.1) <= RMS_TOL_UM;
    let ok_injected = injected
        .iter()
        .any(|s| (s.effect, s.joint) == INJECTED_EXPECTED);
    ok_kr270 && ok_rms && ok_injected
}

#[cfg(not(target_os = "none"))]
fn main() {
    use nalgebra::RealField;
    use robcal::estimate::screen::Rule;

    fn run<T: RealField + Copy>(inject: bool) -> closed_loop::Outcome<T> {
        let data = table::Table::<T>::new(inject).expect("table");
        closed_loop::run(
            &data,
            &table::naive_model(),
            &table::settings().expect("settings"),
            &Rule::default(),
            |s| {
                println!(
                    "diagnosis: added {}{}, rms {:.1} -> {:.1} um (F {:.1}, p {:.1e}, {} tried)",
                    s.effect,
                    s.joint
                        .map(|j| format!(" on a{}", j + 1))
                        .unwrap_or_default(),
                    s.rms_um.0,
                    s.rms_um.1,
                    s.test.f,
                    s.test.p_value,
                    s.tried
                )
            },
        )
        .expect("closed loop")
    }
    let mut ok = true;
    for (name, bits) in [("f32", 32), ("f64", 64)] {
        println!("{name}: KR-270, naive model");
        let (k, k_rms, i) = if bits == 32 {
            let k = run::<f32>(false);
            let rms = k.steps.first().map_or((0.0, 0.0), |s| s.rms_um);
            println!("{name}: KR-270 with a backlash of 0.3 mrad on a5 injected");
            (k.steps, rms, run::<f32>(true).steps)
        } else {
            let k = run::<f64>(false);
            let rms = k.steps.first().map_or((0.0, 0.0), |s| s.rms_um);
            println!("{name}: KR-270 with a backlash of 0.3 mrad on a5 injected");
            (k.steps, rms, run::<f64>(true).steps)
        };
        ok &= check(&k, k_rms, &i);
    }
    println!("{}", if ok { "PASS" } else { "FAIL" });
    std::process::exit(if ok { 0 } else { 1 });
}

#[cfg(target_os = "none")]
mod device;
