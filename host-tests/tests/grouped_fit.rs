//! `GroupedStats`' own fits (`estimate::grouped_fit`: `Λ` and `η` once from
//! the cells' upper triangles, the sandwich's middle term alone) against
//! the trait's generic path (`Reweightable::fit_weighted` / `fit_reweighted`
//! through an `Accumulator`), which a wrapper that forwards only `weighted`
//! and `residual_sigma_into` still takes: the same estimate, `Λ⁻¹`,
//! covariance, σ, degrees of freedom, iterations and errors, bit for bit.

use nalgebra::{Const, DefaultAllocator, Dim, SMatrix, SVector, Vector3};
use rand::{rngs::StdRng, Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use robcal::estimate::{
    Alloc, Fit, GroupedStats, IrlsSettings, Noise, Reweightable, RobustWeight, Solution,
};
use robcal::{Accumulator, Error};

const N: usize = 5;
const G: usize = 8;
type D = Const<N>;

/// The generic path: only the two required methods, forwarded.
struct Generic<'a, Dm: Dim>(&'a GroupedStats<f64, Dm, G>)
where
    DefaultAllocator: Alloc<Dm>;

impl<Dm: Dim> Reweightable<f64, Dm> for Generic<'_, Dm>
where
    DefaultAllocator: Alloc<Dm>,
{
    fn group_count(&self) -> usize {
        self.0.groups().len()
    }
    fn weighted(
        &self,
        weights: &[Vector3<f64>],
        noise: Option<Noise<'_, f64>>,
    ) -> Result<Accumulator<f64, Dm>, Error> {
        self.0.weighted_noise(weights, noise)
    }
    fn residual_sigma_into(
        &self,
        fit: &Solution<f64, Dm>,
        weights: &[Vector3<f64>],
        sigma: &mut [Vector3<f64>],
        dof: &mut [Vector3<f64>],
    ) -> Result<(), Error> {
        self.0.residual_sigma_into(fit, weights, sigma, dof)
    }
}

/// Heteroscedastic rows, groups of different sizes (one with 2 rows, so
/// its σ is pooled), `x` of different scales.
fn stats(seed: u64) -> GroupedStats<f64, D, G> {
    let mut rng = StdRng::seed_from_u64(seed);
    let x = SVector::<f64, N>::from_fn(|i, _| (i as f64 - 2.0) * 10f64.powi(i as i32 - 2));
    let mut s = GroupedStats::new();
    for g in 0..G {
        let sigma = Vector3::from_fn(|_, _| rng.random_range(0.01..0.3));
        let rows = if g == 3 { 2 } else { rng.random_range(5..40) };
        for _ in 0..rows {
            let b = SMatrix::<f64, 3, N>::from_fn(|_, j| {
                rng.random_range(-1.0..1.0) * 10f64.powi(2 - j as i32)
            });
            let e = Vector3::from_fn(|a, _| Normal::new(0.0, sigma[a]).unwrap().sample(&mut rng));
            s.update(g as i32, &b, &(b * x + e)).unwrap();
        }
    }
    s
}

fn same(a: &Fit<f64, D>, b: &Fit<f64, D>) {
    assert_eq!(a.solution.x, b.solution.x);
    assert_eq!(a.solution.lambda_inv, b.solution.lambda_inv);
    assert_eq!(a.solution.active, b.solution.active);
    assert_eq!(a.solution.equations, b.solution.equations);
    assert_eq!(a.solution.wrss.to_bits(), b.solution.wrss.to_bits());
    assert_eq!(a.solution.rcond.to_bits(), b.solution.rcond.to_bits());
    assert_eq!(a.covariance, b.covariance);
    assert_eq!((a.iterations, a.converged), (b.iterations, b.converged));
}

#[test]
fn irls_is_the_generic_path_bit_for_bit() {
    for seed in 0..20 {
        let s = stats(seed);
        let settings = IrlsSettings::new(RobustWeight::new(0.001, 1.0).unwrap());
        for active in [[true; N], [true, false, true, true, false]] {
            let mut out = Vec::new();
            for fast in [true, false] {
                let (mut w, mut sg, mut d) = (
                    vec![Vector3::zeros(); G],
                    vec![Vector3::zeros(); G],
                    vec![Vector3::zeros(); G],
                );
                let mut steps = Vec::new();
                let fit = if fast {
                    s.fit_irls(&settings, &active, &mut w, &mut sg, &mut d, |it| {
                        steps.push(it.x)
                    })
                } else {
                    Generic(&s).fit_irls(&settings, &active, &mut w, &mut sg, &mut d, |it| {
                        steps.push(it.x)
                    })
                }
                .unwrap();
                out.push((fit, w, sg, d, steps));
            }
            let (a, b) = (&out[0], &out[1]);
            same(&a.0, &b.0);
            assert_eq!(
                (&a.1, &a.2, &a.3, &a.4),
                (&b.1, &b.2, &b.3, &b.4),
                "seed {seed}"
            );
            assert!(
                a.4.len() > 2,
                "seed {seed}: the reweighting took {} steps",
                a.4.len()
            );
        }
    }
}

#[test]
fn single_fits_and_errors_are_the_generic_paths() {
    let s = stats(99);
    let active = [true; N];
    let w: Vec<Vector3<f64>> = (0..G)
        .map(|g| Vector3::new(1.0, 0.5 + g as f64, 2.0))
        .collect();
    let (mut s1, mut d1, mut s2, mut d2) = (
        vec![Vector3::zeros(); G],
        vec![Vector3::zeros(); G],
        vec![Vector3::zeros(); G],
        vec![Vector3::zeros(); G],
    );
    same(
        &s.fit_weighted(&w, &active, &mut s1, &mut d1).unwrap(),
        &Generic(&s)
            .fit_weighted(&w, &active, &mut s2, &mut d2)
            .unwrap(),
    );
    assert_eq!((&s1, &d1), (&s2, &d2));
    // Hostile weights: the same error from both paths.
    let bad: [(usize, f64); 4] = [(2, f64::NAN), (5, -1.0), (0, f64::INFINITY), (7, 1e200)];
    for (g, v) in bad {
        let mut w2 = w.clone();
        w2[g].y = v;
        let (mut s1, mut d1, mut s2, mut d2) = (
            vec![Vector3::zeros(); G],
            vec![Vector3::zeros(); G],
            vec![Vector3::zeros(); G],
            vec![Vector3::zeros(); G],
        );
        let a = s
            .fit_weighted(&w2, &active, &mut s1, &mut d1)
            .map(|f| f.solution.x);
        let b = Generic(&s)
            .fit_weighted(&w2, &active, &mut s2, &mut d2)
            .map(|f| f.solution.x);
        assert_eq!(a, b, "weight {v} in group {g}");
        assert!(a.is_err(), "weight {v} in group {g} was accepted");
    }
    // Too few groups of weights.
    let a = s
        .fit_weighted(&w[..G - 1], &active, &mut s1, &mut d1)
        .map(|f| f.solution.x);
    let b = Generic(&s)
        .fit_weighted(&w[..G - 1], &active, &mut s2, &mut d2)
        .map(|f| f.solution.x);
    assert_eq!(a, b);
    assert!(a.is_err());
}

#[test]
fn an_overflow_and_a_bad_weight_give_the_generic_paths_first_error() {
    let s = stats(7);
    let active = [true; N];
    let w: Vec<Vector3<f64>> = vec![Vector3::repeat(1.0); G];
    // (group, axis, weight) pairs: the overflow (1e200) before or after a
    // bad weight (NaN, negative), in both orders; and two overflows.
    let cases: [[(usize, usize, f64); 2]; 5] = [
        [(1, 0, 1e200), (4, 2, f64::NAN)],
        [(1, 0, f64::NAN), (4, 2, 1e200)],
        [(2, 1, 1e200), (2, 2, -1.0)],
        [(2, 1, -1.0), (6, 0, 1e200)],
        [(0, 0, 1e200), (7, 2, 1e200)],
    ];
    for case in cases {
        let mut w2 = w.clone();
        for (g, a, v) in case {
            w2[g][a] = v;
        }
        let (mut s1, mut d1, mut s2, mut d2) = (
            vec![Vector3::zeros(); G],
            vec![Vector3::zeros(); G],
            vec![Vector3::zeros(); G],
            vec![Vector3::zeros(); G],
        );
        let a = s
            .fit_weighted(&w2, &active, &mut s1, &mut d1)
            .map(|f| f.solution.x);
        let b = Generic(&s)
            .fit_weighted(&w2, &active, &mut s2, &mut d2)
            .map(|f| f.solution.x);
        assert_eq!(a, b, "{case:?}");
        assert!(a.is_err(), "{case:?} was accepted");
    }
}
