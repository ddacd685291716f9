//! Leave-one-configuration-out prediction of an OLS fit without refits.
//!
//! For ordinary least squares at one linearisation the fit without group
//! `g` need not be computed: with `Λ = Bᵀ B` over all rows and
//! `H_gg = B_g Λ⁻¹ B_gᵀ` the block of the hat matrix of the group's rows,
//! the group's residual under the fit without it is
//!
//! ```text
//! e_g(−g) = (I − H_gg)⁻¹ e_g ,    e_g = Δp_g − B_g x̂
//! ```
//!
//! (the block form of the PRESS identity, from the Sherman–Morrison–
//! Woodbury downdate of `Λ`). It costs one factorisation of `Λ` and one
//! small solve per group, instead of one fit over all the other rows per
//! group: linear in the number of configurations, not quadratic. Weighted
//! fits re-estimate their weights without the group (eq. 14), which this
//! identity does not reproduce; the engine refits those from the moments
//! per configuration and axis ([`super::moments`]), without the rows.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

use super::design::{Design, GroupRows};

/// Below this eigenvalue of `I − H_gg` the group carries information no
/// other group has (removing it leaves a parameter unidentified): the
/// caller refits that group.
const MIN_EIGENVALUE: f64 = 1e-9;

/// Whether `I − H_gg` with these eigenvalues leaves the fit without the
/// group identified (every eigenvalue above [`MIN_EIGENVALUE`]).
fn invertible(eigenvalues: &[f64]) -> bool {
    !eigenvalues
        .iter()
        .any(|v| v.is_nan() || *v <= MIN_EIGENVALUE)
}

/// The held-out residuals of [`ols_heldout`], in the order of its
/// [`GroupRows`].
#[derive(Debug, Clone)]
pub struct HeldOut {
    /// The held-out residual \[m\] of every row, group by group as in
    /// [`GroupRows::all`] (zero in a group that is not `ok`).
    pub res: Vec<Vector3<f64>>,
    /// Per group, whether its residuals were computed: `false` when its
    /// removal leaves the fit singular (the caller refits it).
    pub ok: Vec<bool>,
}

/// The held-out residuals of every group of `d` under the OLS fit on the
/// columns `cols` (`by`: `d`'s rows by group); `None` overall when `Λ`
/// itself is not positive definite. The groups on worker threads
/// ([`super::parallel`]), each independent of the others: the same bits
/// on any number of threads.
pub fn ols_heldout(d: &Design, cols: &[usize], by: &GroupRows) -> Option<HeldOut> {
    ols_heldout_on(d, cols, by, super::parallel::for_rows(d.rows()))
}

/// [`ols_heldout`] on `threads` threads.
fn ols_heldout_on(d: &Design, cols: &[usize], by: &GroupRows, threads: usize) -> Option<HeldOut> {
    // All columns in order (the engine's case): the design itself, not a
    // copy of it (with many rows the copy is the largest allocation).
    let selected;
    let b = if cols.len() == d.b.ncols() && cols.iter().enumerate().all(|(i, &c)| i == c) {
        &d.b
    } else {
        selected = d.b.select_columns(cols);
        &selected
    };
    let y = &d.y;
    // `Λ = BᵀB` as nalgebra's `tr_mul` computes it (each element the `dot`
    // of two columns), the upper triangle's dots on worker threads and
    // mirrored: the same bits (a product commutes), half the dots.
    let n = cols.len();
    let pairs: Vec<(usize, usize)> = (0..n).flat_map(|i| (i..n).map(move |j| (i, j))).collect();
    let dots = super::parallel::map(pairs.len(), threads.min(pairs.len()), |k| {
        let (i, j) = pairs[k];
        b.column(i).dot(&b.column(j))
    });
    let mut lambda = DMatrix::zeros(n, n);
    for (&(i, j), &v) in pairs.iter().zip(&dots) {
        lambda[(i, j)] = v;
        lambda[(j, i)] = v;
    }
    let chol = lambda.cholesky()?;
    let x = chol.solve(&b.tr_mul(&DVector::from_column_slice(y)));
    if !x.iter().all(|v| v.is_finite()) {
        return None;
    }
    // A group of one row (one point per configuration: the case with the
    // most groups) in fixed-size arithmetic without an allocation per
    // group: `w_a = Λ⁻¹ b_aᵀ` from the inverse, `H_ab = b_b · w_a`.
    //
    // `w` holds the row's three axes (`[a n..(a + 1) n]`, read once from
    // the design's columns) then `w_a` (`[(3 + a) n..(4 + a) n]`). Each
    // `w_a` is summed over `c` in order, as `(0..n).map(..).sum()` sums it
    // (from its first term: a float sum starts at −0.0), for all `r` side
    // by side (the inverse's column `c` is contiguous): the same bits, where
    // a sum per `r` read the design and the inverse across their strides.
    let inv = chol.inverse();
    let one = |i: usize, w: &mut [f64], out: &mut Vec<Vector3<f64>>| {
        let (bi, w) = w.split_at_mut(3 * n);
        for c in 0..n {
            for a in 0..3 {
                bi[a * n + c] = b[(3 * i + a, c)];
            }
        }
        let mut e = Vector3::from_fn(|a, _| y[3 * i + a]);
        for (c, xc) in x.iter().enumerate() {
            for a in 0..3 {
                e[a] -= bi[a * n + c] * xc;
            }
        }
        for a in 0..3 {
            let (row, wa) = (&bi[a * n..(a + 1) * n], &mut w[a * n..(a + 1) * n]);
            for (c, &bc) in row.iter().enumerate() {
                let column = &inv.as_slice()[c * n..(c + 1) * n];
                if c == 0 {
                    for (wr, &v) in wa.iter_mut().zip(column) {
                        *wr = v * bc;
                    }
                } else {
                    for (wr, &v) in wa.iter_mut().zip(column) {
                        *wr += v * bc;
                    }
                }
            }
        }
        let bg = |a: usize, c: usize| bi[a * n + c];
        let ih = Matrix3::from_fn(|a, c| {
            let h: f64 = (0..n).map(|r| bg(c, r) * w[a * n + r]).sum();
            f64::from(u8::from(a == c)) - h
        });
        // Symmetric by construction; its rounding is not.
        let ih = (ih + ih.transpose()) * 0.5;
        let eig = ih.symmetric_eigen();
        if !invertible(eig.eigenvalues.as_slice()) {
            return false;
        }
        let t = eig.eigenvectors.tr_mul(&e).component_div(&eig.eigenvalues);
        out.push(eig.eigenvectors * t);
        true
    };
    let many = |rs: &[usize], out: &mut Vec<Vector3<f64>>| {
        let m = 3 * rs.len();
        let bg = DMatrix::from_fn(m, n, |r, c| b[(3 * rs[r / 3] + r % 3, c)]);
        let eg = DVector::from_fn(m, |r, _| y[3 * rs[r / 3] + r % 3]) - &bg * &x;
        // I − H_gg, symmetric positive semidefinite.
        let ih = DMatrix::identity(m, m) - &bg * chol.solve(&bg.transpose());
        let eig = ih.symmetric_eigen();
        if !invertible(eig.eigenvalues.as_slice()) {
            return false;
        }
        let e = eig.eigenvectors.tr_mul(&eg);
        let e = DVector::from_fn(m, |r, _| e[r] / eig.eigenvalues[r]);
        let e = &eig.eigenvectors * e;
        out.extend((0..rs.len()).map(|k| Vector3::new(e[3 * k], e[3 * k + 1], e[3 * k + 2])));
        true
    };
    // Contiguous runs of groups, one per thread.
    let groups = by.groups();
    let threads = threads.clamp(1, groups.max(1));
    let runs = super::parallel::map(threads, threads, |k| {
        let (lo, hi) = (k * groups / threads, (k + 1) * groups / threads);
        let mut w = vec![0.0; 6 * n];
        let mut res = Vec::with_capacity(by.offset(hi) - by.offset(lo));
        let mut ok = Vec::with_capacity(hi - lo);
        for g in lo..hi {
            let rs = by.of(g);
            let done = match rs {
                [i] => one(*i, &mut w, &mut res),
                _ => many(rs, &mut res),
            };
            if !done {
                res.extend(rs.iter().map(|_| Vector3::zeros()));
            }
            ok.push(done);
        }
        (res, ok)
    });
    // The first run's vectors grown by the others' (not a third copy).
    let mut runs = runs.into_iter();
    let (res, ok) = runs.next().unwrap_or_default();
    let mut out = HeldOut { res, ok };
    for (res, ok) in runs {
        out.res.extend(res);
        out.ok.extend(ok);
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::fit::{fit, FitSettings, Method};
    use crate::estimate::RobustWeight;

    /// A design of `groups` groups of `per` rows on `n` columns, pseudo-random.
    fn design(groups: usize, per: usize, n: usize, seed: u64) -> Design {
        let mut s = seed;
        let mut next = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let rows = groups * per;
        let b = DMatrix::from_fn(3 * rows, n, |_, _| next());
        let y = (0..3 * rows).map(|_| next()).collect();
        Design {
            params: Vec::new(),
            b,
            y,
            group: (0..rows).map(|i| i / per).collect(),
            groups,
            instrument_sigma: None,
        }
    }

    fn ols() -> FitSettings {
        FitSettings {
            method: Method::Ols,
            weight: RobustWeight::new(1e-5, 0.0).expect("valid weight"),
            max_iterations: 1,
            tolerance: 0.1,
            weighting: super::super::fit::Weighting::Estimated,
        }
    }

    #[test]
    fn matches_the_refit_without_each_group() {
        for (groups, per, n, seed) in [(12, 1, 5, 1), (8, 3, 7, 2), (30, 2, 13, 3)] {
            let d = design(groups, per, n, seed);
            let cols: Vec<usize> = (0..n).collect();
            let by = d.group_rows().expect("groups in range");
            let fast = ols_heldout(&d, &cols, &by).expect("positive definite");
            for g in 0..groups {
                assert!(fast.ok[g], "identifiable without the group");
                let res = &fast.res[by.range(g)];
                let f = fit(&d, &cols, Some(g), &ols()).expect("refit");
                let refit: Vec<_> = (0..d.rows())
                    .filter(|&i| d.group[i] == g)
                    .map(|i| d.residual(&cols, &f.x, i))
                    .collect();
                for (a, b) in res.iter().zip(&refit) {
                    assert!((a - b).norm() <= 1e-10 * (1.0 + b.norm()), "{a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn the_same_bits_on_any_number_of_threads() {
        // Groups of one, two and three rows, one singular (column 0 only in
        // group 0).
        let mut d = design(40, 1, 6, 5);
        d.group = (0..40)
            .map(|i| [0, 1, 1, 2, 3, 3, 3][i % 7] + 4 * (i / 7))
            .collect();
        d.groups = 4 * 6;
        for r in 3..d.b.nrows() {
            d.b[(r, 0)] = 0.0;
        }
        let by = d.group_rows().expect("groups in range");
        let cols: Vec<usize> = (0..6).collect();
        let one = ols_heldout_on(&d, &cols, &by, 1).expect("positive definite");
        assert!(!one.ok[0] && one.ok[1..].iter().all(|&ok| ok));
        for threads in [2, 3, 7, 100] {
            let many = ols_heldout_on(&d, &cols, &by, threads).expect("positive definite");
            assert_eq!(many.ok, one.ok);
            let bits = |h: &HeldOut| -> Vec<u64> {
                h.res
                    .iter()
                    .flat_map(|r| r.iter().map(|v| v.to_bits()))
                    .collect()
            };
            assert_eq!(bits(&many), bits(&one), "{threads} threads");
        }
    }

    #[test]
    fn group_rows_are_in_row_order_and_checked() {
        let by = GroupRows::new(&[2, 0, 2, 1, 0], 4).expect("in range");
        assert_eq!(by.groups(), 4);
        assert_eq!(
            (by.of(0), by.of(1), by.of(2), by.of(3)),
            (&[1, 4][..], &[3][..], &[0, 2][..], &[][..])
        );
        assert_eq!(by.all(), &[1, 4, 3, 0, 2]);
        assert_eq!((by.range(2), by.offset(4), by.of(9)), (3..5, 5, &[][..]));
        assert!(GroupRows::new(&[0, 3], 3).is_none());
        assert!(GroupRows::new(&[usize::MAX], 3).is_none());
    }

    #[test]
    fn a_group_no_other_can_replace_is_left_to_the_refit() {
        // Column 0 is non-zero in group 0 only.
        let mut d = design(6, 1, 3, 4);
        for r in 3..d.b.nrows() {
            d.b[(r, 0)] = 0.0;
        }
        let by = d.group_rows().expect("groups in range");
        let fast = ols_heldout(&d, &[0, 1, 2], &by).expect("positive definite");
        assert!(!fast.ok[0]);
        assert!(fast.ok[1..].iter().all(|&ok| ok));
    }
}
