//! The core's F and χ² tails (`robcal::estimate::distributions`, no_std,
//! hand-written from Numerical Recipes because the device needs them)
//! against statrs, an independent, well-kept implementation: the p-values
//! of the diagnosis and the lack-of-fit tests agree to 1e-10 relative over
//! the degrees of freedom and statistics robcal meets.

use robcal::estimate::distributions::{chi2_sf, f_sf};
use statrs::distribution::{ChiSquared, ContinuousCDF, FisherSnedecor};

fn close(got: f64, want: f64, what: &str) {
    // Relative where the tail is representable, absolute near underflow.
    let tol = 1e-10 * want.abs() + 1e-280;
    assert!(
        (got - want).abs() <= tol,
        "{what}: {got:e} vs statrs {want:e}"
    );
}

#[test]
fn chi2_tail_agrees_with_statrs() {
    for k in [1usize, 2, 3, 5, 9, 17, 60, 250, 1000] {
        let d = ChiSquared::new(k as f64).unwrap();
        for x in [0.01, 0.5, 1.0, 3.0, 7.5, 20.0, 80.0, 300.0, 1200.0] {
            close(chi2_sf(x, k), d.sf(x), &format!("chi2({k}) > {x}"));
        }
    }
}

#[test]
fn f_tail_agrees_with_statrs() {
    for d1 in [1usize, 2, 3, 5, 9, 18] {
        for d2 in [4usize, 12, 45, 100, 801, 5000] {
            let d = FisherSnedecor::new(d1 as f64, d2 as f64).unwrap();
            for f in [0.05, 0.5, 1.0, 1.5, 3.58, 10.0, 87.0, 400.0] {
                close(f_sf(f, d1, d2), d.sf(f), &format!("F({d1}, {d2}) > {f}"));
            }
        }
    }
}
