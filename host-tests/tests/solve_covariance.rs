//! Covariances of the estimate: the scalar example of section 4, and the
//! sandwich (eq. 8 / 11) and eq. 13 against the Monte Carlo spread of the
//! estimator under heteroscedastic noise.

use nalgebra::{Const, SMatrix, SVector, Vector3, U1};
use rand::{rngs::StdRng, Rng as _, SeedableRng};
use rand_distr::{Distribution, Normal};
use robcal::estimate::{inverse_sigma, RobustWeight};
use robcal::{Accumulator, Block};

/// Section 4: one parameter, `Δpᵢ = xᵢ X + εᵢ`, `εᵢ ~ N(0, σᵢ²)`.
/// OLS (`W = I`): `var = Σx²σ² / (Σx²)²` (the sandwich, eq. 8).
/// WLS with `w = 1/σ` (eq. 12, `a = 1`): `var = 1 / Σ(x²/σ²)` (eq. 13), and
/// the sandwich (eq. 11) gives the same. The accumulator's covariances
/// must match these closed forms to rounding: `16·m·ε` relative (each side
/// is a sum of `m` positive terms and a division, so both are within a few
/// `m·ε` of the exact value).
#[test]
fn scalar_example_of_section_4() {
    let x = [0.3, -1.2, 2.5, 0.9, -0.4, 1.7, 3.1, -2.2, 0.05, 1.1];
    let sigma = [
        1e-5, 3e-5, 2e-5, 8e-5, 1e-5, 5e-5, 2.5e-5, 1.5e-5, 4e-5, 6e-5,
    ];
    let m = x.len() as f64;
    let tol = 16.0 * m * f64::EPSILON;
    let rel = |a: f64, b: f64| ((a - b) / b).abs();

    let sxx: f64 = x.iter().map(|v| v * v).sum();
    let sxxss: f64 = x.iter().zip(&sigma).map(|(v, s)| v * v * s * s).sum();
    let sx2_s2: f64 = x.iter().zip(&sigma).map(|(v, s)| v * v / (s * s)).sum();
    let var_ols = sxxss / (sxx * sxx);
    let var_wls = 1.0 / sx2_s2;
    assert!(var_wls < var_ols, "WLS must not be worse than OLS");

    let block = |i: usize, w: f64| {
        let mut b = Block::<f64, U1>::new(
            SMatrix::<f64, 3, 1>::new(x[i], 0.0, 0.0),
            Vector3::new(0.7 * x[i], 0.0, 0.0),
        )
        .with_weights(Vector3::new(w, 1.0, 1.0))
        .with_sigma(Vector3::new(sigma[i], 1.0, 1.0));
        b.rows = 1;
        b
    };

    // OLS.
    let mut ols = Accumulator::<f64, U1>::new();
    for i in 0..x.len() {
        ols.update(&block(i, 1.0)).unwrap();
    }
    let sol = ols.solve().unwrap();
    let c = sol.cov_sandwich(&ols.middle());
    assert!(
        rel(c[(0, 0)], var_ols) <= tol,
        "OLS {} vs {var_ols}",
        c[(0, 0)]
    );
    assert!(rel(sol.lambda_inv[(0, 0)], 1.0 / sxx) <= tol);
    assert!((sol.x[0] - 0.7).abs() < 1e-14);

    // WLS, W = Σ⁻¹.
    let mut wls = Accumulator::<f64, U1>::new();
    for (i, s) in sigma.iter().enumerate() {
        wls.update(&block(i, inverse_sigma(1.0, *s).unwrap()))
            .unwrap();
    }
    let sol = wls.solve().unwrap();
    let c13 = sol.cov_information();
    assert!(
        rel(c13[(0, 0)], var_wls) <= tol,
        "eq. 13 {} vs {var_wls}",
        c13[(0, 0)]
    );
    let c11 = sol.cov_sandwich(&wls.middle());
    assert!(
        rel(c11[(0, 0)], var_wls) <= tol,
        "eq. 11 {} vs {var_wls}",
        c11[(0, 0)]
    );

    // w = a/σ with a ≠ 1: Λ⁻¹ is scaled by 1/a², the sandwich is not (the
    // variance of the estimate does not depend on the unit of the weights).
    let a = 1e-5;
    let mut wa = Accumulator::<f64, U1>::new();
    for (i, s) in sigma.iter().enumerate() {
        wa.update(&block(i, inverse_sigma(a, *s).unwrap())).unwrap();
    }
    let sol = wa.solve().unwrap();
    assert!(rel(sol.cov_sandwich(&wa.middle())[(0, 0)], var_wls) <= tol);
    assert!(rel(sol.cov_information()[(0, 0)] * a * a, var_wls) <= tol);
}

const N: usize = 3;
type D = Const<N>;
const BLOCKS: usize = 30;
/// Monte Carlo runs. The sample variance of R Gaussian draws has a relative
/// standard error `√(2/(R−1))` = 1.0 % at R = 20 000; the tolerance is 5
/// standard errors (elementwise, with the off-diagonal standard error
/// `√((CᵢᵢCⱼⱼ + Cᵢⱼ²)/(R−1))`). The estimate is linear in Gaussian noise, so
/// it is exactly Gaussian and these formulas are exact. The seed is fixed.
const RUNS: usize = 20_000;

struct Design {
    b: Vec<SMatrix<f64, 3, N>>,
    sigma: Vec<Vector3<f64>>,
    x_true: SVector<f64, N>,
}

fn design() -> Design {
    let mut rng = StdRng::seed_from_u64(2024);
    let unit = Normal::new(0.0, 1.0).unwrap();
    let b = (0..BLOCKS)
        .map(|_| SMatrix::<f64, 3, N>::from_fn(|_, _| unit.sample(&mut rng)))
        .collect();
    // Heteroscedastic: σ from 10 µm to 300 µm, per block and per axis.
    let sigma = (0..BLOCKS)
        .map(|_| Vector3::from_fn(|_, _| 1e-5 * 10f64.powf(rng.random_range(0.0..1.5))))
        .collect();
    Design {
        b,
        sigma,
        x_true: SVector::<f64, N>::new(1e-3, -2e-3, 5e-4),
    }
}

/// Runs the estimator `RUNS` times with weights `weight(σ)` and compares
/// the sample covariance with the sandwich; returns the sandwich.
fn monte_carlo(weight: impl Fn(f64) -> f64, seed: u64) -> SMatrix<f64, N, N> {
    let d = design();
    let blocks: Vec<Block<f64, D>> = (0..BLOCKS)
        .map(|i| {
            Block::new(d.b[i], d.b[i] * d.x_true)
                .with_weights(d.sigma[i].map(&weight))
                .with_sigma(d.sigma[i])
        })
        .collect();
    // The sandwich from one accumulation (noise does not enter Λ or M).
    let mut acc = Accumulator::<f64, D>::new();
    for b in &blocks {
        acc.update(b).unwrap();
    }
    let sandwich = acc.solve().unwrap().cov_sandwich(&acc.middle());

    let mut rng = StdRng::seed_from_u64(seed);
    let unit = Normal::new(0.0, 1.0).unwrap();
    let mut sum = SVector::<f64, N>::zeros();
    let mut sum2 = SMatrix::<f64, N, N>::zeros();
    for _ in 0..RUNS {
        let mut acc = Accumulator::<f64, D>::new();
        for (b, s) in blocks.iter().zip(&d.sigma) {
            let noise = Vector3::from_fn(|i, _| s[i] * unit.sample(&mut rng));
            let mut nb = *b;
            nb.dp += noise;
            acc.update(&nb).unwrap();
        }
        let e = acc.solve().unwrap().x - d.x_true;
        sum += e;
        sum2 += e * e.transpose();
    }
    let r = RUNS as f64;
    let mean = sum / r;
    let cov = (sum2 - mean * mean.transpose() * r) / (r - 1.0);
    for i in 0..N {
        // Unbiased: the mean error within 5 standard errors of 0.
        let se = (sandwich[(i, i)] / r).sqrt();
        assert!(mean[i].abs() <= 5.0 * se, "bias {i}: {} > 5·{se}", mean[i]);
        for j in 0..N {
            let se = ((sandwich[(i, i)] * sandwich[(j, j)] + sandwich[(i, j)].powi(2)) / (r - 1.0))
                .sqrt();
            let diff = (cov[(i, j)] - sandwich[(i, j)]).abs();
            assert!(
                diff <= 5.0 * se,
                "cov[{i},{j}]: Monte Carlo {} vs sandwich {} (diff {diff:e} > 5·{se:e})",
                cov[(i, j)],
                sandwich[(i, j)]
            );
        }
    }
    sandwich
}

#[test]
fn sandwich_matches_monte_carlo_ols() {
    // W = I: eq. 8.
    monte_carlo(|_| 1.0, 1);
}

#[test]
fn sandwich_matches_monte_carlo_robust_weights() {
    // Eq. 14 with σ0 = 10 µm, λ = 1: W Σ ≠ I, only the sandwich (eq. 11) is
    // the covariance.
    let rw = RobustWeight::new(1e-5, 1.0).unwrap();
    monte_carlo(|s| rw.weight(s).unwrap(), 2);
}

#[test]
fn eq13_matches_monte_carlo_for_inverse_sigma_weights() {
    // W = Σ⁻¹: the sandwich equals Λ⁻¹ (eq. 13), and both match the spread.
    let sandwich = monte_carlo(|s| 1.0 / s, 3);
    let d = design();
    let mut acc = Accumulator::<f64, D>::new();
    for i in 0..BLOCKS {
        acc.update(
            &Block::new(d.b[i], d.b[i] * d.x_true)
                .with_weights(d.sigma[i].map(|s| 1.0 / s))
                .with_sigma(d.sigma[i]),
        )
        .unwrap();
    }
    let c13 = acc.solve().unwrap().cov_information();
    assert!((c13 - sandwich).abs().max() <= 1e-12 * c13.abs().max());
    // And OLS is worse on every parameter (section 4: W Σ = I is optimal).
    let ols = monte_carlo(|_| 1.0, 4);
    for i in 0..N {
        assert!(c13[(i, i)] < ols[(i, i)]);
    }
}
