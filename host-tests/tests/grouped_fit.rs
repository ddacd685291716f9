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
    stats_with(seed, |_, _| true)
}

/// As [`stats`], `B`'s column `j` zero in group `g` unless `keep(g, j)`.
fn stats_with(seed: u64, keep: impl Fn(usize, usize) -> bool) -> GroupedStats<f64, D, G> {
    let mut rng = StdRng::seed_from_u64(seed);
    let x = SVector::<f64, N>::from_fn(|i, _| (i as f64 - 2.0) * 10f64.powi(i as i32 - 2));
    let mut s = GroupedStats::new();
    for g in 0..G {
        let sigma = Vector3::from_fn(|_, _| rng.random_range(0.01..0.3));
        let rows = if g == 3 { 2 } else { rng.random_range(5..40) };
        for _ in 0..rows {
            let b = SMatrix::<f64, 3, N>::from_fn(|_, j| {
                let v = rng.random_range(-1.0..1.0) * 10f64.powi(2 - j as i32);
                if keep(g, j) {
                    v
                } else {
                    0.0
                }
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

/// Groups whose rows leave columns of `B` zero (as the KR-270's: a
/// compliance of one q2 group, and the shared ones), which the fits leave
/// out of their sums (`GroupedStats`' supports): the generic path's sums
/// (`Λ`, `M` through an `Accumulator`, every element) bit for bit, and the
/// residual σ those of the full traces and quadratic forms.
#[test]
#[allow(clippy::needless_range_loop)] // the sums in the order of their definitions
fn zero_columns_left_out_change_no_bit() {
    // Group 5 has every column (the full path beside the others).
    let keep = |g: usize, j: usize| g == 5 || j == g % 3 || j >= 3;
    let settings = IrlsSettings::new(RobustWeight::new(0.001, 1.0).unwrap());
    for seed in 0..10 {
        let s = stats_with(seed, keep);
        let mut out = Vec::new();
        for fast in [true, false] {
            let (mut w, mut sg, mut d) = (
                vec![Vector3::zeros(); G],
                vec![Vector3::zeros(); G],
                vec![Vector3::zeros(); G],
            );
            let fit = if fast {
                s.fit_irls(&settings, &[true; N], &mut w, &mut sg, &mut d, |_| {})
            } else {
                Generic(&s).fit_irls(&settings, &[true; N], &mut w, &mut sg, &mut d, |_| {})
            }
            .unwrap();
            out.push((fit, w, sg, d));
        }
        same(&out[0].0, &out[1].0);
        assert_eq!(
            (&out[0].1, &out[0].2),
            (&out[1].1, &out[1].2),
            "seed {seed}"
        );

        // The residual σ of the final fit, summed over every element.
        let (fit, w) = (&out[0].0.solution, &out[0].1);
        let (mut sigma, mut dof) = (vec![Vector3::zeros(); G], vec![Vector3::zeros(); G]);
        s.residual_sigma_into(fit, w, &mut sigma, &mut dof).unwrap();
        let (inv, x) = (fit.lambda_inv.as_slice(), fit.x.as_slice());
        for (gi, g) in s.groups().iter().enumerate() {
            for (a, ax) in g.axes.iter().enumerate() {
                let sv = ax.s_upper.as_slice();
                let mut tr = 0.0;
                for c in 0..N {
                    tr += inv[c * N + c] * sv[c * N + c];
                    for r in 0..c {
                        tr += (inv[c * N + r] + inv[c * N + r]) * sv[c * N + r];
                    }
                }
                let rss = ax.rss(&fit.x);
                let mut xu = 0.0;
                for k in 0..N {
                    xu += x[k] * ax.u[k];
                }
                assert_eq!(
                    rss.to_bits(),
                    (ax.yy - 2.0 * xu + {
                        let mut q = 0.0;
                        for i in 0..N {
                            let mut y = 0.0;
                            for k in 0..N {
                                let at = if k < i { i * N + k } else { k * N + i };
                                y += sv[at] * x[k];
                            }
                            q += y * x[i];
                        }
                        q
                    })
                    .max(0.0)
                    .to_bits()
                );
                let h = w[gi][a] * w[gi][a] * tr;
                let want = robcal::estimate::group_sigma(rss, ax.n, h);
                // (`residual_sigma_into` itself does not pool.)
                assert_eq!(
                    sigma[gi][a].to_bits(),
                    want.to_bits(),
                    "seed {seed} {gi} {a}"
                );
                assert_eq!(
                    dof[gi][a].to_bits(),
                    robcal::estimate::group_dof(ax.n, h).to_bits()
                );
            }
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
