//! The paper's experiment on the committed data (`data/kr270/`): every
//! estimate within ±3σ of the truth, WLS never worse than OLS, and the
//! non-linearity of the deflection model (bias of the linear model eq. 3,
//! and the Gauss–Newton refinement that removes it).

mod paper_common;

use nalgebra::{SMatrix, SVector, Vector3};
use paper_common::*;
use robcal::irls::Fit;
use robcal::kr270::{self, PAPER_SYMBOLS};
use robcal::paper::{self, G, N};
use robcal::Reweightable;

fn within_3_sigma(name: &str, fit: &Fit<f64, N, G>) {
    let t = paper::truth();
    let s = fit.std();
    for i in 0..N {
        let z = (fit.solution.x[i] - t[i]) / s[i];
        assert!(
            z.abs() <= 3.0,
            "{name}: {} off by {z:.2}σ",
            PAPER_SYMBOLS[i]
        );
    }
}

/// True covariance of a weighted fit under Table 1's Σ: the sandwich (11)
/// with the true σ instead of the residual σ.
fn true_cov(stats: &paper::Stats, w: &[Vector3<f64>]) -> SMatrix<f64, N, N> {
    let sigma: Vec<Vector3<f64>> = stats
        .groups()
        .iter()
        .map(|g| Vector3::from(kr270::SIGMA_UM[(g.id - 1) as usize]) * 1e-6)
        .collect();
    let acc = stats.weighted(w, Some(&sigma)).unwrap();
    let sol = acc.solve().unwrap();
    sol.cov_sandwich(&acc.middle())
}

#[test]
fn every_estimate_lies_within_3_sigma_of_the_truth() {
    let (_, exp) = experiment();
    let stats = exp.linear_stats().unwrap();
    let settings = settings();
    let f = paper::fits(&stats, &settings).unwrap();
    within_3_sigma("OLS", &f.ols);
    for (k, w) in f.wls.iter().enumerate() {
        within_3_sigma(&format!("WLS λ = {}", kr270::LAMBDAS[k]), w);
    }
    within_3_sigma("iterative WLS", &f.irls);
    let (ols, _) = exp
        .refine(&f.ols.solution.x, 1e-6, 20, |s| s.fit_ols(&[true; N]))
        .unwrap();
    within_3_sigma("OLS, exact model", &ols);
    let (irls, _) = exp
        .refine(&f.irls.solution.x, 1e-6, 20, |s| {
            let mut h = heapless::Vec::<_, 1>::new();
            s.fit_irls(&settings, &[true; N], &mut h)
        })
        .unwrap();
    within_3_sigma("iterative WLS, exact model", &irls);
}

#[test]
fn wls_never_has_a_larger_variance_than_ols() {
    let (_, exp) = experiment();
    let stats = exp.linear_stats().unwrap();
    let f = paper::fits(&stats, &settings()).unwrap();
    let ones = vec![Vector3::repeat(1.0); 15];
    let ols_true = true_cov(&stats, &ones);
    let so = f.ols.std();
    for (name, fit) in [
        ("WLS λ = 0.5", &f.wls[0]),
        ("WLS λ = 1", &f.wls[1]),
        ("WLS λ = 2", &f.wls[2]),
        ("iterative WLS", &f.irls),
    ] {
        let sw = fit.std();
        let wt = true_cov(&stats, &fit.weights);
        for i in 0..N {
            // Reported σ: (11) against (8), both from the residuals.
            assert!(
                sw[i] <= so[i],
                "{name}: reported σ of {} {} > OLS {}",
                PAPER_SYMBOLS[i],
                sw[i],
                so[i]
            );
            // True variance under Table 1's Σ with the weights this fit used.
            assert!(
                wt[(i, i)] <= ols_true[(i, i)],
                "{name}: true variance of {}",
                PAPER_SYMBOLS[i]
            );
        }
    }
}

#[test]
fn linear_model_bias_and_its_gauss_newton_refinement() {
    let (_, exp) = experiment();
    let truth = paper::truth();
    let rows = exp.linear_rows().unwrap();
    let clean = exp.exact_deflections(&truth).unwrap();
    let stats = exp.linear_stats().unwrap();
    let f = paper::fits(&stats, &settings()).unwrap();

    // The exact model's Jacobian is the compliance columns at the deflected
    // pose: check it against central differences.
    let o = &exp.obs[100];
    let (_, jac) = exp.exact(o, &truth).unwrap();
    for i in 0..N {
        let h = 1e-4;
        let mut xp = truth;
        let mut xm = truth;
        xp[i] += h;
        xm[i] -= h;
        let d = (exp.exact(o, &xp).unwrap().0 - exp.exact(o, &xm).unwrap().0) / (2.0 * h);
        let want: Vector3<f64> = jac.column(i).into();
        assert!(
            (d - want).norm() <= 1e-7 * want.norm().max(1e-9),
            "column {i}: {d:?} vs {want:?}"
        );
    }

    // Bias of the linear model: fit noise-free exact deflections.
    let clean_stats = paper::stats_of(&exp.obs, &rows, &clean).unwrap();
    let b_ols = clean_stats.fit_ols::<G>(&[true; N]).unwrap().solution.x - truth;
    let b_irls = clean_stats
        .fit_weighted::<G>(&f.irls.weights, &[true; N])
        .unwrap()
        .solution
        .x
        - truth;
    let (so, si) = (f.ols.std(), f.irls.std());
    let worst: f64 = (0..N)
        .map(|i| (b_ols[i] / so[i]).abs().max((b_irls[i] / si[i]).abs()))
        .fold(0.0, f64::max);
    for i in 0..N {
        println!(
            "{:<4} bias OLS {:+.3}σ  iterative WLS {:+.3}σ",
            PAPER_SYMBOLS[i],
            b_ols[i] / so[i],
            b_irls[i] / si[i]
        );
    }
    // Measured: up to 2.1σ (k22, iterative WLS) — why the refinement exists.
    assert!(worst > 0.2, "the linear model's bias is {worst}σ");

    // Gauss–Newton on the exact model recovers the truth from noise-free
    // data (rounding only), with either weighting.
    let clean_exp = paper::Experiment {
        obs: exp
            .obs
            .iter()
            .zip(&clean)
            .map(|(o, c)| paper::Obs {
                dp: *c,
                ..o.clone()
            })
            .collect(),
        ..exp.clone()
    };
    let start: SVector<f64, N> = truth + b_ols;
    let (r, steps) = clean_exp
        .refine(&start, 1e-9, 20, |s| s.fit_ols(&[true; N]))
        .unwrap();
    assert!(steps <= 5, "{steps} relinearisations");
    let e = (r.solution.x - truth).abs().max() / truth.abs().min();
    assert!(e < 1e-10, "refined OLS off the truth by {e:e}");
    let (r, _) = clean_exp
        .refine(&start, 1e-9, 20, |s| {
            s.fit_weighted(&f.irls.weights, &[true; N])
        })
        .unwrap();
    let e = (r.solution.x - truth).abs().max() / truth.abs().min();
    assert!(e < 1e-10, "refined WLS off the truth by {e:e}");
}

/// The Kantorovich (Bloomfield–Watson) bound: with Table 1's σ from 17 to
/// 153 µm, no weighting can make any parameter's σ smaller than OLS's by
/// more than `(1 + 9²)/(2·9) ≈ 4.56`. Our design: OLS's true σ over the
/// Cramér–Rao σ is 1.3–1.7; the paper's Table 4 claims 27–42.
#[test]
fn kantorovich_bound_on_the_gain_of_weighting() {
    let (_, exp) = experiment();
    let stats = exp.linear_stats().unwrap();
    let flat: Vec<f64> = kr270::SIGMA_UM.iter().flatten().copied().collect();
    let (lo, hi) = flat
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(l, h), s| (l.min(*s), h.max(*s)));
    let root_kappa = hi / lo;
    let bound = (1.0 + root_kappa * root_kappa) / (2.0 * root_kappa);
    assert!((bound - 4.56).abs() < 0.01, "{bound}");
    let ones = vec![Vector3::repeat(1.0); 15];
    let ols = true_cov(&stats, &ones);
    let inv: Vec<Vector3<f64>> = stats
        .groups()
        .iter()
        .map(|g| Vector3::from(kr270::SIGMA_UM[(g.id - 1) as usize]).map(|s| 1e6 / s))
        .collect();
    let crb = stats
        .weighted(&inv, None)
        .unwrap()
        .solve()
        .unwrap()
        .lambda_inv;
    for i in 0..N {
        let gain = (ols[(i, i)] / crb[(i, i)]).sqrt();
        println!("{:<4} σ_OLS/σ_CRB = {gain:.2}", PAPER_SYMBOLS[i]);
        assert!(
            (1.0..=bound).contains(&gain),
            "{}: {gain}",
            PAPER_SYMBOLS[i]
        );
        // The paper's claim is beyond the bound for every parameter.
        assert!(kr270::SIGMA_RATIO[i] > 5.0 * bound);
    }
}
