//! The TIAGo motion-capture calibration (issue 7, docs/tiago.md) through
//! the product: FIGAROH's table — registration, joint offsets, full
//! joint-frame errors, fitted on point BL and on all four points — and the
//! closed loop of `robcal calibrate` chosen by its committed protocol; all
//! fitted on the 2021-11-30 recording and evaluated on 2021-11-26.
//!
//! ```text
//! cargo run --release --example tiago
//! ```
//!
//! Reads `shared/datasets/tiago-mocap` beside the repository (or
//! `$ROBCAL_TIAGO_DATA`) and prints Markdown. Every number is
//! `robcal::calibrate` (fit) or `robcal::calibrate::validate` (prediction).

#[path = "../host-tests/tests/tiago_common/mod.rs"]
mod tiago_common;

use robcal::calibrate::{self, Method, Settings};
use tiago_common::*;

/// FIGAROH's published BL norm RMSE (training, validation) [mm] and
/// parameter count: registration, joint offsets, full.
const FIGAROH: [(f64, f64, usize); 3] = [(3.37, 4.87, 9), (2.88, 4.23, 14), (1.64, 3.07, 31)];

fn main() {
    let Some(data) = data_dir() else {
        eprintln!("shared/datasets/tiago-mocap not found beside the repository");
        std::process::exit(1);
    };
    let job = job(&data, "setup.toml");
    let train = import(&job, &data, TRAIN);
    let valid = import(&job, &data, VALID);
    let bl = BL.to_string();

    println!("## FIGAROH's models through `robcal calibrate` (OLS, no diagnosis)\n");
    println!("Training 2021-11-30 (37 postures), validation 2021-11-26 (62 postures); norm RMSE in mm.\n");
    println!("| model | points fitted | params | BL train | BL valid | all points train | all points valid | FIGAROH (BL train / valid, params) |");
    println!("|---|---|---|---|---|---|---|---|");
    for points in [&[1][..], &[1, 2, 3, 4][..]] {
        for (k, model) in [Model::Registration, Model::Offsets, Model::Full]
            .into_iter()
            .enumerate()
        {
            let j = variant(&job, model, points);
            let (tr, va) = (only(&train, points), only(&valid, points));
            let r = fit_ols(&j, &tr);
            let (ptr, atr) = rmse_mm(&r, &j, &tr);
            let (pva, ava) = rmse_mm(&r, &j, &va);
            let all = |v: f64| {
                if points.len() > 1 {
                    format!("{v:.2}")
                } else {
                    "—".into()
                }
            };
            let (ft, fv, fp) = FIGAROH[k];
            println!(
                "| {} | {} | {} | {:.2} | {:.2} | {} | {} | {ft} / {fv} ({fp}) |",
                model.name(),
                if points.len() > 1 {
                    "BL+BR+TR+TL"
                } else {
                    "BL"
                },
                r.parameters.len(),
                ptr[&bl],
                pva[&bl],
                all(atr),
                all(ava),
            );
        }
    }

    println!("\n## The closed loop: `robcal calibrate`, the committed protocol\n");
    println!("Four runs on training; the model is the run with the lowest leave-one-posture-out RMS; then each is validated once.\n");
    println!("| setup | method | effects added | train RMS | leave-one-out RMS | BL valid | all points valid |");
    println!("|---|---|---|---|---|---|---|");
    let mut best = (f64::INFINITY, String::new(), 0.0);
    for setup in ["setup.toml", "setup-select.toml"] {
        for method in [Method::Irls, Method::Ols] {
            let j = tiago_common::job(&data, setup);
            let settings = Settings {
                method,
                ..Settings::default()
            };
            let r = calibrate::calibrate(&j, &train, &settings, &mut |_| {}).expect("calibration");
            let (pva, ava) = rmse_mm(&r, &j, &valid);
            let effects: Vec<String> = r
                .effects
                .iter()
                .map(|e| format!("{} {}", e.effect, e.joint.clone().unwrap_or_default()))
                .collect();
            let loo = r.heldout_rms_um.unwrap_or(f64::NAN) * 1e-3;
            println!(
                "| {setup} | {} | {} | {:.2} | {loo:.2} | {:.2} | {ava:.2} |",
                method.name(),
                effects.join("; "),
                r.rms_um * 1e-3,
                pva[&bl],
            );
            if loo < best.0 {
                best = (loo, format!("{setup}, {}", method.name()), pva[&bl]);
            }
        }
    }
    println!(
        "\nChosen on training (lowest leave-one-out RMS): {} — BL validation {:.2} mm (FIGAROH's full model: 3.07 mm).",
        best.1, best.2
    );
}
