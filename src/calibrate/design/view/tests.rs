//! The view's sums against the core's, bit for bit.

use crate::calibrate::design::testing::{design, rng};
use crate::calibrate::design::view::*;

/// The leverage of one row and axis as [`crate::estimate::leverage`]
/// sums it.
fn one(inv: &[f64], p: usize, b: impl Fn(usize) -> f64) -> f64 {
    let mut q = 0.0;
    for c in 0..p {
        let mut s = 0.0;
        for r in 0..p {
            s += inv[c * p + r] * b(r);
        }
        q += s * b(c);
    }
    q
}

#[test]
fn batched_leverages_are_the_row_by_row_ones_bit_for_bit() {
    let mut next = rng(7);
    for p in [1, 2, 5, 43] {
        let inv: Vec<f64> = (0..p * p).map(|_| next() * 1e3).collect();
        let b: Vec<f64> = (0..3 * p * LANES).map(|_| next()).collect();
        let q = leverage3_rows(&inv, p, &b);
        for j in 0..LANES {
            for a in 0..3 {
                let want = one(&inv, p, |k| b[(3 * k + a) * LANES + j]);
                assert_eq!(q[a * LANES + j].to_bits(), want.to_bits());
            }
        }
    }
}

fn same(a: &[f64], b: &[f64]) {
    assert_eq!(a.len(), b.len());
    for (a, b) in a.iter().zip(b) {
        assert_eq!(a.to_bits(), b.to_bits(), "{a} vs {b}");
    }
}

/// The leverage pass on worker threads (a chunk of rows at a time) is
/// the pass on one thread (inside a worker, [`crate::parallel`]
/// gives one), bit for bit: more rows than a chunk, groups across the
/// threads' runs and the chunks' ends.
#[test]
fn residual_sigma_on_threads_is_the_serial_one() {
    let d = design(5000, 7, 9, 11);
    let cols: Vec<usize> = (0..9).collect();
    let v = View::new(&d, &cols, &[], None);
    let weights: Vec<Vector3<f64>> = (0..d.groups)
        .map(|g| Vector3::new(1.0, 0.5 + (g % 3) as f64, 2.0))
        .collect();
    let fit = v
        .weighted(&weights, None)
        .expect("sums")
        .solve_active(&[true; 9])
        .expect("solution");
    let run = || {
        let mut sigma = vec![Vector3::zeros(); d.groups];
        let mut dof = vec![Vector3::zeros(); d.groups];
        v.residual_sigma_into(&fit, &weights, &mut sigma, &mut dof)
            .expect("sigma");
        let flat =
            |v: Vec<Vector3<f64>>| v.iter().flat_map(|v| v.iter().copied()).collect::<Vec<_>>();
        (flat(sigma), flat(dof))
    };
    let threads = run();
    let serial = crate::parallel::map(2, 2, |k| (k == 0).then(run))
        .into_iter()
        .flatten()
        .next()
        .expect("serial");
    same(&threads.0, &serial.0);
    same(&threads.1, &serial.1);
}

/// The core's accumulator of each block of `v`'s rows (one when it has
/// at most a block of them), merged in order by the core.
fn by_blocks(
    v: &View<'_>,
    weights: &[Vector3<f64>],
    noise: Option<Noise<'_, f64>>,
) -> Accumulator<f64, Dyn> {
    let mut blocks = v
        .rows
        .chunks(v.block)
        .map(|rows| v.streamed_rows(rows, weights, noise).expect("stream"));
    let Some(mut all) = blocks.next() else {
        return v.streamed(weights, noise).expect("stream");
    };
    for b in blocks {
        all.merge(&b).expect("finite");
    }
    all
}

/// A view of several blocks on worker threads (each block on one) sums
/// as on one thread, and as the core's blocks merged, bit for bit.
#[test]
fn blocks_on_threads_are_the_cores_blocks_merged() {
    let d = design(5000, 2, 9, 12);
    let cols: Vec<usize> = (0..9).collect();
    let v = View::new(&d, &cols, &[], None);
    assert!(v.rows.len() > 2 * v.block);
    let weights: Vec<Vector3<f64>> = (0..d.groups)
        .map(|g| Vector3::new(1.0, 0.5 + (g % 3) as f64, 2.0))
        .collect();
    let sigma: Vec<Vector3<f64>> = (0..d.groups)
        .map(|g| Vector3::repeat(1e-5 * (1 + g % 4) as f64))
        .collect();
    let noise = Noise::known(&sigma);
    let run = || {
        let acc = v.weighted(&weights, None).expect("sums");
        let m = v.middle(&weights, noise).expect("middle");
        (acc, m)
    };
    let (threads, m) = run();
    let (serial, m1) = crate::parallel::map(2, 2, |k| (k == 0).then(run))
        .into_iter()
        .flatten()
        .next()
        .expect("serial");
    let core = by_blocks(&v, &weights, Some(noise));
    for acc in [&serial, &core] {
        same(
            threads.information().as_slice(),
            acc.information().as_slice(),
        );
        same(threads.eta().as_slice(), acc.eta().as_slice());
        assert_eq!(threads.weighted_yy().to_bits(), acc.weighted_yy().to_bits());
        assert_eq!(threads.equations(), acc.equations());
    }
    same(m.as_slice(), m1.as_slice());
    same(m.as_slice(), core.middle().as_slice());
}

#[test]
fn the_sums_are_the_cores_bit_for_bit() {
    // Odd and even row counts (the pairs and the last row alone), some
    // zero weights, every column or some.
    for (groups, per, n, seed) in [(5, 3, 7, 1), (4, 4, 43, 2), (1, 1, 3, 3)] {
        let d = design(groups, per, n, seed);
        let mut next = rng(seed + 10);
        let weights: Vec<Vector3<f64>> = (0..groups)
            .map(|g| {
                let w = Vector3::from_fn(|_, _| next() + 0.6);
                if g == 1 {
                    Vector3::new(0.0, w.y, w.z)
                } else {
                    w
                }
            })
            .collect();
        let sigma: Vec<Vector3<f64>> = (0..groups)
            .map(|_| Vector3::from_fn(|_, _| (next() + 0.6) * 1e-5))
            .collect();
        let all: Vec<usize> = (0..n).collect();
        let some: Vec<usize> = (0..n).step_by(2).collect();
        for cols in [&all, &some] {
            for (skip, block) in [
                (&[][..], BLOCK_ROWS),
                (&[0], BLOCK_ROWS),
                (&[], 2),
                (&[1], 4),
                (&[0, 2], 4),
            ] {
                let v = View::blocked(&d, cols, skip, None, block);
                let fast = v.weighted(&weights, None).expect("sums");
                let core = by_blocks(&v, &weights, None);
                assert_eq!(fast.equations(), core.equations());
                assert_eq!(fast.weighted_yy().to_bits(), core.weighted_yy().to_bits());
                same(fast.eta().as_slice(), core.eta().as_slice());
                same(fast.information().as_slice(), core.information().as_slice());
                let noise = Noise::known(&sigma);
                let m = v.middle(&weights, noise).expect("middle");
                let core = by_blocks(&v, &weights, Some(noise));
                same(m.as_slice(), core.middle().as_slice());
            }
        }
    }
}

#[test]
fn the_information_is_the_unit_weight_blocks_bit_for_bit() {
    // What `Design::identifiability` streamed before: blocks of the
    // columns with unit weights and Δp = 0, one `update` per row.
    for (groups, per, n, seed) in [(5, 3, 7, 4), (4, 4, 43, 5), (1, 1, 3, 6)] {
        let d = design(groups, per, n, seed);
        let cols: Vec<usize> = (0..n).rev().step_by(2).collect();
        let fast = View::new(&d, &cols, &[], None)
            .information()
            .expect("finite");
        let mut core = Accumulator::<f64, Dyn>::zeros(Dyn(cols.len()));
        for i in 0..d.rows() {
            let b =
                OMatrix::<f64, U3, Dyn>::from_fn(cols.len(), |a, k| d.held()[(3 * i + a, cols[k])]);
            core.update(&Block::new(b, Vector3::zeros()))
                .expect("finite");
        }
        same(fast.information().as_slice(), core.information().as_slice());
    }
}

#[test]
fn bad_weights_give_the_cores_errors() {
    let d = design(3, 2, 4, 5);
    let cols: Vec<usize> = (0..4).collect();
    let v = View::new(&d, &cols, &[], None);
    for bad in [-1.0, f64::NAN, f64::INFINITY] {
        let mut w = vec![Vector3::repeat(1.0); 3];
        w[1].y = bad;
        assert_eq!(
            v.weighted(&w, None).map(|_| ()),
            v.streamed(&w, None).map(|_| ())
        );
        let sigma = vec![Vector3::repeat(1e-5); 3];
        assert_eq!(
            v.middle(&w, Noise::known(&sigma)).map(|_| ()),
            v.streamed(&w, Some(Noise::known(&sigma))).map(|_| ())
        );
    }
}

#[test]
fn the_residuals_kept_from_the_sigma_pass_are_the_designs() {
    // More rows than a chunk of the σ pass, OLS and IRLS (whose last σ
    // pass is at its estimate or not: kept only when it is).
    use crate::calibrate::fit::{fit_with_residuals, FitSettings, Method, Weighting};
    let d = design(LEVERAGE_CHUNK + 1000, 1, 6, 13);
    let cols: Vec<usize> = (0..6).collect();
    for method in [Method::Ols, Method::Irls] {
        let s = FitSettings {
            method,
            weight: RobustWeight::new(1e-3, 1.0).expect("valid weight"),
            max_iterations: 20,
            tolerance: 1e-3,
            weighting: Weighting::Estimated,
        };
        let (out, kept) = fit_with_residuals(&d, &cols, None, &s).expect("fit");
        if method == Method::Ols {
            assert!(kept.is_some(), "an OLS fit's σ pass is at its estimate");
        }
        if let Some(kept) = kept {
            assert_eq!(kept.len(), d.rows());
            for (i, r) in kept.iter().enumerate() {
                let want = d.residual(&cols, &out.x, i);
                assert_eq!(r.map(f64::to_bits), want.map(f64::to_bits), "row {i}");
            }
        }
    }
    // A view without a group keeps none.
    let v = View::new(&d, &cols, &[0], None).capturing();
    assert!(v.captured.is_none());
}
