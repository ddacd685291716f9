//! The product (`robcal::calibrate`, declared model, no diagnosis) against
//! the batch solution of the stacked 810 × 9 system of the paper's
//! experiment (`data/kr270/`), solved by an independent code path (dense
//! SVD, explicit `W` and `Σ`, its own columns): OLS, one-step WLS for
//! λ = 0.5, 1, 2, every iteration of the iterative WLS, σ per configuration
//! and axis, and the covariances, within 1e-10 relative. The core's eq. 7
//! covariance of the same rows too.

use crate::paper_common;

use nalgebra::{DMatrix, DVector, Vector3};
use paper_common::*;
use robcal::calibrate::{Method, Report};
use robcal_paper::kr270;

const RTOL: f64 = 1e-10;

fn assert_x(got: &[f64], want: &DVector<f64>, what: &str) {
    for i in 0..N {
        let e = (got[i] - want[i]).abs() / want[i].abs();
        assert!(
            e <= RTOL,
            "{what}: x[{i}] = {} vs batch {} (rel {e:e})",
            got[i],
            want[i]
        );
    }
}

/// Element-wise, relative to the diagonal scale `√(Cᵢᵢ Cⱼⱼ)`.
fn assert_cov(got: &DMatrix<f64>, want: &DMatrix<f64>, what: &str) {
    for i in 0..N {
        for j in 0..N {
            let scale = (want[(i, i)] * want[(j, j)]).sqrt();
            let e = (got[(i, j)] - want[(i, j)]).abs() / scale;
            assert!(e <= RTOL, "{what}: cov[{i},{j}] rel {e:e}");
        }
    }
}

fn assert_std(got: &[f64], want: &DMatrix<f64>, what: &str) {
    for i in 0..N {
        let w = want[(i, i)].sqrt();
        let e = (got[i] - w).abs() / w;
        assert!(e <= RTOL, "{what}: std[{i}] rel {e:e}");
    }
}

fn assert_report(r: &Report, b: &BatchFit, what: &str) {
    let (x, sd) = x_sd(r);
    assert_x(&x, &b.x, what);
    assert_std(&sd, &b.cov, what);
    assert_cov(&r.covariance, &b.cov, what);
    for (n, s) in r.noise.iter().zip(&b.sigma) {
        for (&got_um, &want_m) in n.sigma_um.iter().zip(s.iter()) {
            let e = (got_um * 1e-6 - want_m).abs() / want_m;
            assert!(
                e <= RTOL,
                "{what}: σ of configuration {} rel {e:e}",
                n.config
            );
        }
    }
}

#[test]
fn the_products_fits_equal_the_dense_batch_solution() {
    let (job, data) = experiment();
    let s = batch(&job, &data);
    assert_eq!((s.b.nrows(), s.b.ncols()), (810, 9));

    // OLS: estimate, sandwich (8), σ per configuration and axis.
    let ols_report = fit(&job, &data, Method::Ols, None);
    let configs: Vec<i64> = ols_report.noise.iter().map(|n| n.config).collect();
    assert_eq!(configs, (1..=15).collect::<Vec<_>>(), "configuration order");
    let ols = batch_fit(&s, &vec![1.0; 810], false);
    assert_report(&ols_report, &ols, "OLS");

    // Eq. 7 of the same rows, with the core.
    let stats = core_stats(&job, &data);
    let ones = vec![Vector3::new(1.0, 1.0, 1.0); G];
    let iid = stats
        .weighted(&ones, None)
        .unwrap()
        .solve()
        .unwrap()
        .cov_iid();
    let iid = DMatrix::from_iterator(N, N, iid.iter().copied());
    assert_cov(&iid, &ols.cov_iid, "OLS (7), core");

    // One-step WLS, weights eq. 14 from the OLS residuals; covariance (11).
    for lambda in kr270::LAMBDAS {
        let w = weights_eq14(&s, &ols.sigma, 10e-6, lambda);
        let wls = batch_fit(&s, &w, true);
        let r = fit(&job, &data, Method::Wls, Some(lambda));
        assert_report(&r, &wls, &format!("WLS λ = {lambda}"));
    }

    // Iterative WLS: replay every iteration in the batch, weights from the
    // previous batch iteration's residuals.
    let irls = fit(&job, &data, Method::Irls, None);
    assert!(irls.converged);
    assert!(irls.history.len() >= 3, "{} iterations", irls.history.len());
    let mut prev = ols;
    assert_x(&irls.history[0].x, &prev.x, "iteration 0");
    assert_std(&irls.history[0].std, &prev.cov, "iteration 0");
    for (k, h) in irls.history.iter().enumerate().skip(1) {
        let w = weights_eq14(&s, &prev.sigma, 10e-6, 1.0);
        let next = batch_fit(&s, &w, true);
        assert_x(&h.x, &next.x, &format!("iteration {k}"));
        assert_std(&h.std, &next.cov, &format!("iteration {k}"));
        prev = next;
    }
    assert_report(&irls, &prev, "iterative WLS, final");
    println!(
        "batch agreement within {RTOL:e}: OLS, WLS ×3, {} iterations",
        irls.history.len() - 1
    );
}
