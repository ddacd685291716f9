//! Tail probabilities and the nested F test of the diagnosis.

use nalgebra::{Const, SMatrix, SVector, U3};
use rand::{rngs::StdRng, Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use robcal::estimate::{distributions as stats, nested_test};
use robcal::{Accumulator, Block};

#[test]
fn chi2_tails_match_closed_forms() {
    for &x in &[0.01, 0.5, 1.0, 3.0, 10.0, 40.0, 200.0] {
        // χ²₂: exp(−x/2); χ²₁: erfc(√(x/2)); χ²₄: (1 + x/2) exp(−x/2).
        let e2 = (-x / 2.0f64).exp();
        assert!((stats::chi2_sf(x, 2) / e2 - 1.0).abs() < 1e-12, "k=2 x={x}");
        let e1 = libm::erfc((x / 2.0f64).sqrt());
        assert!((stats::chi2_sf(x, 1) / e1 - 1.0).abs() < 1e-10, "k=1 x={x}");
        let e4 = (1.0 + x / 2.0) * e2;
        assert!((stats::chi2_sf(x, 4) / e4 - 1.0).abs() < 1e-12, "k=4 x={x}");
    }
    assert_eq!(stats::chi2_sf(0.0, 3), 1.0);
    assert!(stats::chi2_sf(1.0, 0).is_nan());
}

#[test]
fn f_tails_match_closed_forms() {
    for &f in &[0.01, 0.3, 1.0, 2.5, 10.0, 100.0] {
        for &d2 in &[2usize, 5, 30, 800] {
            // F(2, d2): (d2 / (d2 + 2f))^(d2/2).
            let e = (d2 as f64 / (d2 as f64 + 2.0 * f)).powf(d2 as f64 / 2.0);
            let p = stats::f_sf(f, 2, d2);
            assert!((p / e - 1.0).abs() < 1e-10, "f={f} d2={d2}: {p} vs {e}");
        }
    }
    // F(1, d) = t²_d; for d = 1 (Cauchy): P(|t| > √f) = 1 − 2/π·atan(√f).
    for &f in &[0.2, 1.0, 7.0] {
        let e = 1.0 - 2.0 / std::f64::consts::PI * f64::sqrt(f).atan();
        assert!((stats::f_sf(f, 1, 1) / e - 1.0).abs() < 1e-10);
    }
}

const N: usize = 5;

/// Rows with columns 0..3 the model and 3..5 a candidate effect of size
/// `effect` in column 3.
fn problem(seed: u64, effect: f64) -> Accumulator<f64, Const<N>> {
    let mut rng = StdRng::seed_from_u64(seed);
    let x = SVector::<f64, N>::new(1.0, -0.5, 2.0, effect, 0.0);
    let noise = Normal::new(0.0, 0.1).unwrap();
    let mut acc = Accumulator::new();
    for _ in 0..40 {
        let b = SMatrix::<f64, 3, N>::from_fn(|_, _| rng.random_range(-1.0..1.0));
        let dp = b * x + nalgebra::Vector3::from_fn(|_, _| noise.sample(&mut rng));
        acc.update(&Block::new(b, dp)).unwrap();
    }
    acc
}

#[test]
fn delta_rss_equals_the_drop_between_two_fits() {
    let acc = problem(7, 0.05);
    let model = [true, true, true, false, false];
    let candidate = [false, false, false, true, true];
    let fit = acc.solve_active(&model).unwrap();
    let t = nested_test(&acc, &model, &fit, &candidate).unwrap();
    let full = acc.solve().unwrap();
    let drop = fit.wrss - full.wrss;
    assert!(
        (t.delta_rss - drop).abs() < 1e-9 * fit.wrss,
        "{} vs {drop}",
        t.delta_rss
    );
    assert_eq!((t.dof_num, t.dof_den), (2, 120 - 5));
    let f = (drop / 2.0) / (full.wrss / 115.0);
    assert!((t.f / f - 1.0).abs() < 1e-9);
}

#[test]
fn p_values_are_uniform_without_the_effect_and_small_with_it() {
    let model = [true, true, true, false, false];
    let candidate = [false, false, false, true, true];
    let runs = 400;
    let mut rejected = 0;
    for seed in 0..runs {
        let acc = problem(1000 + seed, 0.0);
        let fit = acc.solve_active(&model).unwrap();
        if nested_test(&acc, &model, &fit, &candidate).unwrap().p_value < 0.05 {
            rejected += 1;
        }
    }
    // Binomial(400, 0.05): mean 20, sd 4.4; accept 8..=34 (±3.2 sd).
    assert!(
        (8..=34).contains(&rejected),
        "{rejected} of {runs} rejected at 5 %"
    );
    let acc = problem(5, 0.2);
    let fit = acc.solve_active(&model).unwrap();
    assert!(nested_test(&acc, &model, &fit, &candidate).unwrap().p_value < 1e-10);
}

#[test]
fn a_candidate_the_model_already_spans_is_not_identifiable() {
    // Rounding leaves a residue of either sign; try many data sets.
    for seed in 0..20 {
        let mut acc = Accumulator::<f64, U3>::new();
        let mut rng = StdRng::seed_from_u64(seed);
        for _ in 0..10 {
            let mut b = SMatrix::<f64, 3, 3>::from_fn(|_, _| rng.random_range(-1.0..1.0));
            // Column 2 = 0.3 · column 0 + 0.7 · column 1 (inexact in binary,
            // so what is left of it after the model is rounding noise).
            for r in 0..3 {
                b[(r, 2)] = 0.3 * b[(r, 0)] + 0.7 * b[(r, 1)];
            }
            acc.update(&Block::new(b, b.column(0).into_owned()))
                .unwrap();
        }
        let model = [true, true, false];
        let fit = acc.solve_active(&model).unwrap();
        let t = nested_test(&acc, &model, &fit, &[false, false, true]);
        assert!(
            matches!(t, Err(robcal::Error::NotIdentifiable { column: 2, .. })),
            "seed {seed}: {t:?}"
        );
    }
}
