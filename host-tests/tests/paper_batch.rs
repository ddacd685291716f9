//! The grouped accumulator against the batch solution of the stacked
//! 810 × 9 system of the paper's experiment (`data/kr270/`), solved by an
//! independent code path (dense SVD, explicit `W` and `Σ`): OLS, one-step
//! WLS for λ = 0.5, 1, 2, every iteration of the iterative WLS, and their
//! covariances, within 1e-10 relative.

mod paper_common;

use nalgebra::{DMatrix, DVector, SMatrix, SVector};
use paper_common::*;
use robcal::kr270;
use robcal::paper::{self, N};

const RTOL: f64 = 1e-10;

fn assert_x(got: &SVector<f64, N>, want: &DVector<f64>, what: &str) {
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
fn assert_cov(got: &SMatrix<f64, N, N>, want: &DMatrix<f64>, what: &str) {
    for i in 0..N {
        for j in 0..N {
            let scale = (want[(i, i)] * want[(j, j)]).sqrt();
            let e = (got[(i, j)] - want[(i, j)]).abs() / scale;
            assert!(e <= RTOL, "{what}: cov[{i},{j}] rel {e:e}");
        }
    }
}

fn assert_std(got: &SVector<f64, N>, want: &DMatrix<f64>, what: &str) {
    for i in 0..N {
        let w = want[(i, i)].sqrt();
        let e = (got[i] - w).abs() / w;
        assert!(e <= RTOL, "{what}: std[{i}] rel {e:e}");
    }
}

#[test]
fn grouped_fits_equal_the_dense_batch_solution() {
    let (_, exp) = experiment();
    let stats = exp.linear_stats().unwrap();
    let ids: Vec<i32> = stats.groups().iter().map(|g| g.id).collect();
    assert_eq!(
        ids,
        (1..=15).collect::<Vec<_>>(),
        "groups in configuration order"
    );
    let dp: Vec<_> = exp.obs.iter().map(|o| o.dp).collect();
    let s = batch(&exp, &dp);
    assert_eq!((s.b.nrows(), s.b.ncols()), (810, 9));
    let settings = settings();
    let fits = paper::fits(&stats, &settings).unwrap();

    // OLS: estimate, sandwich (8), i.i.d. (7), σ per configuration and axis.
    let ols = batch_fit(&s, &vec![1.0; 810]);
    assert_x(&fits.ols.solution.x, &ols.x, "OLS");
    assert_cov(&fits.ols.covariance, &ols.cov, "OLS (8)");
    assert_cov(&fits.ols_cov_iid, &ols.cov_iid, "OLS (7)");
    for (g, sg) in fits.ols.sigma.iter().enumerate() {
        for a in 0..3 {
            let e = (sg[a] - ols.sigma[g][a]).abs() / ols.sigma[g][a];
            assert!(e <= RTOL, "OLS σ[{g}][{a}] rel {e:e}");
        }
    }

    // One-step WLS, weights eq. 14 from the OLS residuals; covariance (11).
    for (k, lambda) in kr270::LAMBDAS.iter().enumerate() {
        let w = weights_eq14(&s, &ols.sigma, 10e-6, *lambda);
        let wls = batch_fit(&s, &w);
        let what = format!("WLS λ = {lambda}");
        assert_x(&fits.wls[k].solution.x, &wls.x, &what);
        assert_cov(&fits.wls[k].covariance, &wls.cov, &what);
        assert_cov(&fits.wls[k].solution.lambda_inv, &wls.lambda_inv, &what);
    }

    // Iterative WLS: replay every iteration in the batch, weights from the
    // previous batch iteration's residuals.
    assert!(fits.irls.converged);
    assert!(fits.history.len() >= 3, "{} iterations", fits.history.len());
    let mut prev = ols;
    assert_x(&fits.history[0].x, &prev.x, "iteration 0");
    assert_std(&fits.history[0].std, &prev.cov, "iteration 0");
    for (k, h) in fits.history.iter().enumerate().skip(1) {
        let w = weights_eq14(&s, &prev.sigma, 10e-6, 1.0);
        let next = batch_fit(&s, &w);
        assert_x(&h.x, &next.x, &format!("iteration {k}"));
        assert_std(&h.std, &next.cov, &format!("iteration {k}"));
        prev = next;
    }
    assert_x(&fits.irls.solution.x, &prev.x, "iterative WLS, final");
    assert_cov(
        &fits.irls.covariance,
        &prev.cov,
        "iterative WLS (11), final",
    );
    println!(
        "batch agreement within {RTOL:e}: OLS, WLS ×3, {} iterations",
        fits.history.len() - 1
    );
}
