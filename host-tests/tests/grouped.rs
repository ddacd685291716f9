//! Grouped sufficient statistics and the iterative reweighting, against
//! direct computations on the raw rows.

use nalgebra::{Const, SMatrix, SVector, Vector3, U2};
use rand::{rngs::StdRng, Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use robcal::estimate::{Fit, GroupedStats, IrlsSettings, Iteration, Reweightable, RobustWeight};
use robcal::{Accumulator, Block};

const N: usize = 4;
const G: usize = 6;
type D = Const<N>;

struct Data {
    rows: Vec<(i32, SMatrix<f64, 3, N>, Vector3<f64>)>,
    sigma: Vec<Vector3<f64>>,
}

/// Heteroscedastic data: σ differs per group and axis (like Table 1).
fn data(seed: u64) -> Data {
    let mut rng = StdRng::seed_from_u64(seed);
    let x_true = SVector::<f64, N>::new(1.0, -2.0, 0.5, 3.0);
    let sigma: Vec<Vector3<f64>> = (0..G)
        .map(|_| Vector3::from_fn(|_, _| rng.random_range(0.02..0.2)))
        .collect();
    let mut rows = Vec::new();
    for (g, s) in sigma.iter().enumerate() {
        for _ in 0..60 {
            let b = SMatrix::<f64, 3, N>::from_fn(|_, _| rng.random_range(-1.0..1.0));
            let noise = Vector3::from_fn(|a, _| Normal::new(0.0, s[a]).unwrap().sample(&mut rng));
            rows.push((g as i32 * 10, b, b * x_true + noise));
        }
    }
    Data { rows, sigma }
}

fn grouped(d: &Data) -> GroupedStats<f64, D, G> {
    let mut s = GroupedStats::new();
    for (g, b, dp) in &d.rows {
        s.update(*g, b, dp).unwrap();
    }
    s
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-300)
}

#[test]
fn weighted_grouped_equals_direct_accumulation() {
    let d = data(1);
    let stats = grouped(&d);
    let weights: Vec<Vector3<f64>> = d.sigma.iter().map(|s| s.map(|v| 1.0 / v)).collect();
    let from_groups = stats.weighted(&weights, Some(&d.sigma)).unwrap();
    let mut direct = Accumulator::<f64, D>::new();
    for (g, b, dp) in &d.rows {
        let gi = (*g / 10) as usize;
        direct
            .update(
                &Block::new(*b, *dp)
                    .with_weights(weights[gi])
                    .with_sigma(d.sigma[gi]),
            )
            .unwrap();
    }
    let (a, b) = (from_groups.information(), direct.information());
    for (x, y) in a.iter().zip(b.iter()) {
        assert!(rel(*x, *y) < 1e-12, "{x} vs {y}");
    }
    for (x, y) in from_groups.middle().iter().zip(direct.middle().iter()) {
        assert!(rel(*x, *y) < 1e-12, "{x} vs {y}");
    }
    assert!(rel(from_groups.weighted_yy(), direct.weighted_yy()) < 1e-12);
    assert_eq!(from_groups.equations(), direct.equations());
    let (s1, s2) = (from_groups.solve().unwrap(), direct.solve().unwrap());
    assert!((s1.x - s2.x).norm() / s2.x.norm() < 1e-12);
}

#[test]
fn residual_sigma_equals_direct_residuals() {
    let d = data(2);
    let stats = grouped(&d);
    // A weighted fit, so that the leverage has weights in it.
    let weights: Vec<Vector3<f64>> = (0..G)
        .map(|g| Vector3::new(1.0, 0.5 + g as f64, 2.0))
        .collect();
    let fit = stats.weighted(&weights, None).unwrap().solve().unwrap();
    let (mut sigma, mut dof) = (vec![Vector3::zeros(); G], vec![Vector3::zeros(); G]);
    stats
        .residual_sigma_into(&fit, &weights, &mut sigma, &mut dof)
        .unwrap();
    // One σ per group, or a `Mismatch`.
    let mut short = vec![Vector3::zeros(); G - 1];
    assert!(matches!(
        stats.residual_sigma_into(&fit, &weights, &mut short, &mut dof),
        Err(robcal::Error::Mismatch { .. })
    ));
    let mut total_h = 0.0;
    for (gi, (s, nu)) in sigma.iter().zip(&dof).enumerate() {
        for a in 0..3 {
            let rows: Vec<_> = d
                .rows
                .iter()
                .filter(|(g, _, _)| *g == gi as i32 * 10)
                .collect();
            let rss: f64 = rows
                .iter()
                .map(|(_, b, dp)| (dp[a] - (b.row(a) * fit.x)[0]).powi(2))
                .sum();
            // The group and axis's part of the hat matrix's trace.
            let h: f64 = rows
                .iter()
                .map(|(_, b, _)| {
                    let r = b.row(a);
                    weights[gi][a].powi(2) * (r * fit.lambda_inv * r.transpose())[0]
                })
                .sum();
            total_h += h;
            let direct = (rss / (rows.len() as f64 - h)).sqrt();
            assert!(
                rel(s[a], direct) < 1e-9,
                "group {gi} axis {a}: {} vs {direct}",
                s[a]
            );
            assert!(rel(nu[a], rows.len() as f64 - h) < 1e-9);
        }
    }
    // The shares add up to the number of parameters.
    assert!((total_h - N as f64).abs() < 1e-9, "Σ h = {total_h}");
}

#[test]
fn new_group_beyond_capacity_is_an_error_and_changes_nothing() {
    let mut s = GroupedStats::<f64, U2, 1>::new();
    let b = SMatrix::<f64, 3, 2>::identity();
    s.update(0, &b, &Vector3::new(1.0, 2.0, 3.0)).unwrap();
    let before = s.clone();
    assert!(matches!(
        s.update(1, &b, &Vector3::zeros()),
        Err(robcal::Error::CapacityExceeded { capacity: 1, .. })
    ));
    assert_eq!(s, before);
    assert!(s.update(0, &b, &Vector3::new(f64::NAN, 0.0, 0.0)).is_err());
    assert_eq!(s, before);
    // An existing group still takes data.
    s.update(0, &b, &Vector3::zeros()).unwrap();
}

#[test]
fn irls_recovers_sigma_and_beats_ols() {
    let d = data(3);
    let stats = grouped(&d);
    let all = [true; N];
    let (mut weights, mut sigma) = (vec![Vector3::zeros(); G], vec![Vector3::zeros(); G]);
    let mut dof = vec![Vector3::zeros(); G];
    let ols: Fit<f64, D> = stats
        .fit_ols(&all, &mut weights, &mut sigma, &mut dof)
        .unwrap();
    assert!(weights.iter().all(|w| *w == Vector3::repeat(1.0)));
    let settings = IrlsSettings::new(RobustWeight::new(0.001, 1.0).unwrap());
    let mut history = Vec::<Iteration<f64, D>>::new();
    let fit: Fit<f64, D> = stats
        .fit_irls(&settings, &all, &mut weights, &mut sigma, &mut dof, |it| {
            history.push(*it)
        })
        .unwrap();
    assert!(fit.converged, "iterations {}", fit.iterations);
    assert_eq!(history.len(), fit.iterations + 1);
    assert_eq!(history[0].x, ols.solution.x);
    // The last recorded change is below the tolerance, earlier ones are not.
    assert!(history.last().unwrap().change < settings.tolerance);
    // Weights are eq. 14 of the previous iteration's σ (here: the final σ
    // of a converged fit is close to the one that made its weights).
    for (w, s) in weights.iter().zip(d.sigma.iter()) {
        for a in 0..3 {
            // The weights follow eq. 14 of the true σ within the sampling
            // error of σ estimated from 60 rows (≈ 9 %; the bound is 4.4 of
            // those, over 18 group-axes).
            let ideal = 0.001 / (0.001 + s[a]);
            assert!((w[a] / ideal - 1.0).abs() < 0.4, "{} vs {ideal}", w[a]);
        }
    }
    // On return `sigma` is the residual σ of the final estimate (these
    // groups have 60 rows: none is pooled).
    let (mut again, mut again_dof) = (vec![Vector3::zeros(); G], vec![Vector3::zeros(); G]);
    stats
        .residual_sigma_into(&fit.solution, &weights, &mut again, &mut again_dof)
        .unwrap();
    assert_eq!(sigma, again);
    assert_eq!(dof, again_dof);
    // WLS reports smaller variances than OLS on heteroscedastic data.
    let (so, sw) = (ols.std(), fit.std());
    assert!((0..N).all(|i| sw[i] < so[i]), "{so} vs {sw}");
}

/// One IRLS iteration: X̂, its standard deviations, the change.
type Step = (Vec<f64>, Vec<f64>, f64);

/// IRLS on the same grouped statistics at `Const<N>` (the device) and at
/// `Dyn` (the host), every iteration recorded.
struct Both {
    history: [Vec<Step>; 2],
    fits: (Fit<f64, D>, Fit<f64, nalgebra::Dyn>),
    weights: [Vec<Vector3<f64>>; 2],
    sigma: [Vec<Vector3<f64>>; 2],
}

fn irls_at_both_sizes(seed: u64) -> Both {
    use nalgebra::Dyn;
    let d = data(seed);
    let fixed = grouped(&d);
    let mut dynamic = GroupedStats::<f64, Dyn, G>::with_dim(Dyn(N));
    for (g, b, dp) in &d.rows {
        let b = nalgebra::OMatrix::<f64, nalgebra::U3, Dyn>::from_column_slice(b.as_slice());
        dynamic.update(*g, &b, dp).unwrap();
    }
    let settings = IrlsSettings::new(RobustWeight::new(0.001, 1.0).unwrap());
    let all = [true; N];
    let (mut wf, mut sf) = (vec![Vector3::zeros(); G], vec![Vector3::zeros(); G]);
    let mut nf = vec![Vector3::zeros(); G];
    let mut hf = Vec::new();
    let ff = fixed
        .fit_irls(&settings, &all, &mut wf, &mut sf, &mut nf, |it| {
            hf.push((
                it.x.as_slice().to_vec(),
                it.std.as_slice().to_vec(),
                it.change,
            ))
        })
        .unwrap();
    let (mut wd, mut sd) = (vec![Vector3::zeros(); G], vec![Vector3::zeros(); G]);
    let mut nd = vec![Vector3::zeros(); G];
    let mut hd = Vec::new();
    let fd = dynamic
        .fit_irls(&settings, &all, &mut wd, &mut sd, &mut nd, |it| {
            hd.push((
                it.x.as_slice().to_vec(),
                it.std.as_slice().to_vec(),
                it.change,
            ))
        })
        .unwrap();
    assert!(hf.len() > 2, "a few iterations");
    Both {
        history: [hf, hd],
        fits: (ff, fd),
        weights: [wf, wd],
        sigma: [sf, sd],
    }
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// The same grouped statistics at `Dyn` iterate as at `Const<N>`, bit for
/// bit: every iteration's estimate, σ and change, the weights, the residual
/// σ and the covariance. (Porting this test found that nalgebra's `dot`
/// sums static 4-vectors as `(a₀b₀ + a₂b₂) + (a₁b₁ + a₃b₃)` and `Dyn` ones in
/// order, and that its matrix product goes another way at `Dyn`: the core
/// sums them in its own loops now, `estimate::linalg`.)
#[test]
fn irls_at_dyn_equals_const_bitwise() {
    let b = irls_at_both_sizes(4);
    let [hf, hd] = &b.history;
    let all_bits = |h: &[Step]| {
        h.iter()
            .map(|(x, s, c)| (bits(x), bits(s), c.to_bits()))
            .collect::<Vec<_>>()
    };
    assert_eq!(all_bits(hf), all_bits(hd));
    assert_eq!(
        bits(b.fits.0.covariance.as_slice()),
        bits(b.fits.1.covariance.as_slice())
    );
    let flat = |v: &[Vector3<f64>]| v.iter().flat_map(|x| x.iter().copied()).collect::<Vec<_>>();
    assert_eq!(bits(&flat(&b.weights[0])), bits(&flat(&b.weights[1])));
    assert_eq!(bits(&flat(&b.sigma[0])), bits(&flat(&b.sigma[1])));
}

/// `rows` (group, `B` column-major `3 × p`, `Δp`) streamed in order into
/// grouped statistics of `p` parameters.
fn dyn_stats(p: usize, rows: &[(i32, Vec<f64>, [f64; 3])]) -> GroupedStats<f64, nalgebra::Dyn, 4> {
    let mut s = GroupedStats::<f64, nalgebra::Dyn, 4>::with_dim(nalgebra::Dyn(p));
    for (g, b, y) in rows {
        let b = nalgebra::OMatrix::<f64, nalgebra::U3, nalgebra::Dyn>::from_column_slice(b);
        s.update(*g, &b, &Vector3::from(*y)).unwrap();
    }
    s
}

/// One axis's moments: `S` (column-major, upper triangle), `u`, `yy`, rows.
type Moments = (Vec<f64>, Vec<f64>, f64, usize);
/// A group's id and its three axes' moments.
type Group = (i32, [Moments; 3]);

/// The moments as the definition adds them, row after row, one element at
/// a time (`S` upper triangle `+= bᵢ bⱼ`, `u += b y`, `yy += y²`).
fn naive(p: usize, rows: &[(i32, Vec<f64>, [f64; 3])]) -> Vec<Group> {
    let mut out: Vec<Group> = Vec::new();
    for (g, b, y) in rows {
        let i = match out.iter().position(|o| o.0 == *g) {
            Some(i) => i,
            None => {
                let zero = || (vec![0.0; p * p], vec![0.0; p], 0.0, 0);
                out.push((*g, [zero(), zero(), zero()]));
                out.len() - 1
            }
        };
        for a in 0..3 {
            let m = &mut out[i].1[a];
            for j in 0..p {
                for r in 0..=j {
                    m.0[j * p + r] += b[3 * r + a] * b[3 * j + a];
                }
                m.1[j] += b[3 * j + a] * y[a];
            }
            m.2 += y[a] * y[a];
            m.3 += 1;
        }
    }
    out
}

fn assert_bitwise<Dm: nalgebra::Dim, const GG: usize>(s: &GroupedStats<f64, Dm, GG>, want: &[Group])
where
    nalgebra::DefaultAllocator: robcal::estimate::Alloc<Dm>,
{
    assert_eq!(s.groups().len(), want.len());
    for (g, w) in s.groups().iter().zip(want) {
        assert_eq!(g.id, w.0);
        for (ax, m) in g.axes.iter().zip(&w.1) {
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(ax.s_upper.as_slice()), bits(&m.0));
            assert_eq!(bits(ax.u.as_slice()), bits(&m.1));
            assert_eq!(ax.yy.to_bits(), m.2.to_bits());
            assert_eq!(ax.n, m.3);
        }
    }
}

/// `update`'s moments are the definition's sums bit for bit, at sizes
/// below and above its block of rows, groups revisited out of order; and
/// values near the overflow threshold (where the bound of the guard gives
/// up and every new value is checked) are taken or refused as the value
/// by value check decides, the statistics unchanged on refusal.
#[test]
fn update_is_the_definitions_sums_bit_for_bit() {
    let mut rng = StdRng::seed_from_u64(5);
    for p in [1usize, 2, 5, 9, 12, 13, 30] {
        let rows: Vec<(i32, Vec<f64>, [f64; 3])> = (0..90)
            .map(|k| {
                let g = [3, 3, 1, 7, 1, 3][k % 6];
                let scale = 10f64.powi(rng.random_range(-3..4));
                let b = (0..3 * p)
                    .map(|_| rng.random_range(-1.0..1.0) * scale)
                    .collect();
                (g, b, [rng.random_range(-1.0..1.0); 3].map(|v| v * scale))
            })
            .collect();
        let want = naive(p, &rows);
        assert_bitwise(&dyn_stats(p, &rows), &want);
    }
    // Near the threshold: 1e153² = 1e306, a few of them still fit.
    let mut s = GroupedStats::<f64, U2, 2>::new();
    let big = SMatrix::<f64, 3, 2>::from_element(1e153);
    let mut rows = Vec::new();
    let mut refused = 0;
    for k in 0..400 {
        let before = s.clone();
        match s.update(k % 2, &big, &Vector3::repeat(1.0)) {
            Ok(()) => rows.push((k % 2, big.as_slice().to_vec(), [1.0; 3])),
            Err(e) => {
                assert_eq!(e, robcal::Error::NonFinite { what: "overflow" });
                assert_eq!(s, before);
                refused += 1;
            }
        }
    }
    assert!(refused > 0 && !rows.is_empty());
    assert_bitwise(&s, &naive(2, &rows));
    // The statistics still take ordinary rows after a refusal.
    s.update(0, &SMatrix::<f64, 3, 2>::identity(), &Vector3::zeros())
        .unwrap();
}

/// Rows with zero columns of `B` (on all three axes, as a configuration
/// that does not move some parameters, or on one axis only), negative
/// values among the rest (products `−x · 0 = −0`): the update leaves a
/// zero column out, and the moments are still the definition's sums bit
/// for bit, at the sizes of its one-block path and above.
#[test]
fn update_with_zero_columns_is_the_definitions_sums_bit_for_bit() {
    let mut rng = StdRng::seed_from_u64(17);
    for p in [1usize, 3, 9, 12, 13, 30] {
        let rows: Vec<(i32, Vec<f64>, [f64; 3])> = (0..120)
            .map(|k| {
                let g = [2, 2, 5, 2, 5, 8][k % 6];
                // Per group a fixed set of zero columns, and now and then
                // one more zero column or one zero value.
                let mut b: Vec<f64> = (0..3 * p).map(|_| rng.random_range(-1.0..1.0)).collect();
                for j in 0..p {
                    let (per_group, extra) = (
                        (j + g as usize).is_multiple_of(3),
                        rng.random_range(0..5) == 0,
                    );
                    if per_group || extra {
                        b[3 * j..3 * j + 3].fill(0.0);
                    } else if rng.random_range(0..7) == 0 {
                        b[3 * j + rng.random_range(0..3)] = 0.0;
                    }
                }
                (g, b, [0.0; 3].map(|_: f64| rng.random_range(-1.0..1.0)))
            })
            .collect();
        let want = naive(p, &rows);
        assert_bitwise(&dyn_stats(p, &rows), &want);
    }
}

/// A value that is not finite is refused with what it is in (`B` before
/// `Δp`), and finite values whose squares overflow as an overflow, the
/// statistics unchanged each time.
#[test]
fn update_names_the_non_finite_input() {
    use robcal::Error::NonFinite;
    let mut s = GroupedStats::<f64, U2, 2>::new();
    let b = SMatrix::<f64, 3, 2>::new(1.0, -2.0, 0.5, 0.0, 3.0, -1.0);
    s.update(0, &b, &Vector3::new(1.0, 2.0, 3.0)).unwrap();
    let before = s.clone();
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut bb = b;
        bb[(1, 1)] = bad;
        let dp = Vector3::new(0.0, bad, 1.0);
        assert_eq!(
            s.update(0, &bb, &Vector3::zeros()),
            Err(NonFinite { what: "row" })
        );
        assert_eq!(s.update(1, &b, &dp), Err(NonFinite { what: "dp" }));
        assert_eq!(s.update(0, &bb, &dp), Err(NonFinite { what: "row" }));
        assert_eq!(s, before);
    }
    let huge = SMatrix::<f64, 3, 2>::from_element(1e200);
    assert_eq!(
        s.update(0, &huge, &Vector3::zeros()),
        Err(NonFinite { what: "overflow" })
    );
    assert_eq!(
        s.update(1, &b, &Vector3::repeat(-1e200)),
        Err(NonFinite { what: "overflow" })
    );
    assert_eq!(s, before);
    s.update(1, &b, &Vector3::repeat(1e100)).unwrap();
}
