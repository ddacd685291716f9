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
//! per configuration and axis ([`crate::calibrate::fit::moments`]), without the rows.

use std::borrow::Cow;

use nalgebra::{Cholesky, DMatrix, DVector, Dyn, Matrix3, Vector3};

use crate::calibrate::design::{Design, GroupRows};
use crate::estimate::Accumulator;

mod dots;

/// Below this eigenvalue of `I − H_gg` the group carries information no
/// other group has (removing it leaves a parameter unidentified): the
/// caller refits that group.
const MIN_EIGENVALUE: f64 = 1e-9;

/// Rows whose held-out residuals are computed at a time
/// ([`OlsHeldOut::window`]): 1.5 MB of residuals.
pub const WINDOW_ROWS: usize = 1 << 16;

/// Whether `I − H_gg` with these eigenvalues leaves the fit without the
/// group identified (every eigenvalue above [`MIN_EIGENVALUE`]).
fn invertible(eigenvalues: &[f64]) -> bool {
    !eigenvalues
        .iter()
        .any(|v| v.is_nan() || *v <= MIN_EIGENVALUE)
}

/// The held-out residuals of some groups under an [`OlsHeldOut`], in the
/// order of its [`GroupRows`]: [`OlsHeldOut::groups`].
#[derive(Debug, Clone)]
pub struct HeldOut {
    /// The first group.
    pub first: usize,
    /// The held-out residual \[m\] of every row of the groups, group by
    /// group as in [`GroupRows::all`] (zero in a group that is not `ok`);
    /// group `g`'s are at [`GroupRows::range`]`(g)` less
    /// [`GroupRows::offset`]`(first)`.
    pub res: Vec<Vector3<f64>>,
    /// Per group from `first`, whether its residuals were computed:
    /// `false` when its removal leaves the fit singular (the caller refits
    /// it).
    pub ok: Vec<bool>,
}

impl HeldOut {
    /// Group `g`'s held-out residuals, when they are here and computed.
    pub fn of(&self, by: &GroupRows, g: usize) -> Option<&[Vector3<f64>]> {
        let k = g.checked_sub(self.first)?;
        if self.ok.get(k) != Some(&true) {
            return None;
        }
        let base = by.offset(self.first);
        let r = by.range(g);
        self.res.get(r.start - base..r.end - base)
    }
}

/// The OLS fit on some columns of a design, factorised once, whose
/// held-out residuals are computed for a range of groups at a time
/// ([`OlsHeldOut::groups`]): at a million configurations the residuals of
/// them all were 24 MB at the run's peak.
pub struct OlsHeldOut<'a> {
    d: &'a Design,
    /// The columns of the fit.
    cols: Vec<usize>,
    x: DVector<f64>,
    chol: Cholesky<f64, Dyn>,
    /// `L` of `Λ = L Lᵀ` by rows: row `r`'s `L_rc`, `c < r`, at
    /// `[r n..r n + r]`.
    l_rows: Vec<f64>,
    /// `1 / L_rr`.
    l_inv_diag: Vec<f64>,
    threads: usize,
}

/// The OLS fit on the columns `cols` of `d`, ready for the held-out
/// residuals of its groups; `None` when `Λ` itself is not positive
/// definite or the estimate is not finite (and for a design whose `Δp` is
/// not one value per row, which none is). `Λ` and `Bᵀ Δp` are `sums`, the
/// fit's own unit-weight sums of these columns when given (the engine's:
/// no pass of their own), else the columns' dots. The groups on worker
/// threads ([`crate::parallel`]), each independent of the others: the same
/// bits on any number of threads.
pub fn ols_heldout<'a>(
    d: &'a Design,
    cols: &[usize],
    sums: Option<&Accumulator<f64, Dyn>>,
) -> Option<OlsHeldOut<'a>> {
    let threads = crate::parallel::for_rows(d.rows());
    if d.y.len() != 3 * d.rows() {
        return None;
    }
    match sums {
        Some(s) if s.eta().len() == cols.len() => {
            solved(d, cols, s.information(), s.eta().clone(), threads)
        }
        _ => ols_heldout_on(d, cols, threads),
    }
}

/// [`ols_heldout`] from the columns' dots, on `threads` threads.
fn ols_heldout_on<'a>(d: &'a Design, cols: &[usize], threads: usize) -> Option<OlsHeldOut<'a>> {
    // `Λ = BᵀB` and `Bᵀ Δp` as nalgebra's `tr_mul` computes them (each
    // element the `dot` of two columns), the upper triangle's dots mirrored
    // (a product commutes): all of them in one pass over the rows per
    // thread ([`dots::column_dots`], the same bits).
    let n = cols.len();
    let m = 3 * d.rows();
    if d.y.len() != m {
        return None;
    }
    let pairs: Vec<(usize, usize)> = (0..n)
        .flat_map(|i| (i..n).map(move |j| (i, j)))
        .chain((0..n).map(|i| (i, n)))
        .collect();
    let dots = if d.is_held() {
        // All columns in order (the engine's case): the design itself, not
        // a copy of it (with many rows the copy is the largest allocation).
        let every = cols.len() == d.params.len() && cols.iter().enumerate().all(|(i, &c)| i == c);
        let b = if every {
            d.held()
        } else {
            Cow::Owned(d.held().select_columns(cols))
        };
        let columns: Vec<&[f64]> = (0..n)
            .map(|c| &b.as_slice()[c * m..(c + 1) * m])
            .chain([d.y.as_slice()])
            .collect();
        dots::column_dots(&columns, &pairs, threads)
    } else {
        dots::design_dots(d, cols, &pairs, threads)
    };
    let mut lambda = DMatrix::zeros(n, n);
    let mut eta = DVector::zeros(n);
    for (&(i, j), &v) in pairs.iter().zip(&dots) {
        if j == n {
            eta[i] = v;
        } else {
            lambda[(i, j)] = v;
            lambda[(j, i)] = v;
        }
    }
    solved(d, cols, lambda, eta, threads)
}

/// The OLS fit of `Λ x = η` on the columns `cols` of `d`, factorised for
/// the held-out residuals of its groups on `threads` threads.
fn solved<'a>(
    d: &'a Design,
    cols: &[usize],
    lambda: DMatrix<f64>,
    eta: DVector<f64>,
    threads: usize,
) -> Option<OlsHeldOut<'a>> {
    let n = cols.len();
    let chol = lambda.cholesky()?;
    let x = chol.solve(&eta);
    if !x.iter().all(|v| v.is_finite()) {
        return None;
    }
    let l = chol.l();
    let mut l_rows = vec![0.0; n * n];
    for r in 0..n {
        for c in 0..r {
            l_rows[r * n + c] = l[(r, c)];
        }
    }
    let l_inv_diag = (0..n).map(|r| 1.0 / l[(r, r)]).collect();
    Some(OlsHeldOut {
        d,
        cols: cols.to_vec(),
        x,
        chol,
        l_rows,
        l_inv_diag,
        threads,
    })
}

impl OlsHeldOut<'_> {
    /// The held-out residuals of the groups `range` (`by`: the design's
    /// rows by group), contiguous runs of them on worker threads.
    pub fn groups(&self, by: &GroupRows, range: std::ops::Range<usize>) -> HeldOut {
        let count = range.len();
        let threads = self.threads.clamp(1, count.max(1));
        let n = self.x.len();
        let runs = crate::parallel::map(threads, threads, |k| {
            let (lo, hi) = (
                range.start + k * count / threads,
                range.start + (k + 1) * count / threads,
            );
            let mut z = vec![0.0; 3 * n];
            let mut b = Vec::new();
            let mut res = Vec::with_capacity(by.offset(hi) - by.offset(lo));
            let mut ok = Vec::with_capacity(hi - lo);
            for g in lo..hi {
                let rs = &*by.of(g);
                self.d.rows_into(rs, &self.cols, &mut b);
                let done = match rs {
                    [] => true,
                    [i] => self.one(*i, &b, &mut z, &mut res),
                    _ => self.many(rs, &b, &mut res),
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
        let mut out = HeldOut {
            first: range.start,
            res,
            ok,
        };
        for (res, ok) in runs {
            out.res.extend(res);
            out.ok.extend(ok);
        }
        out
    }

    /// The groups from `first` whose rows add up to about `rows` (at least
    /// one group; none past the last): [`OlsHeldOut::groups`]' next range.
    pub fn window(by: &GroupRows, first: usize, rows: usize) -> std::ops::Range<usize> {
        let (groups, first) = (by.groups(), first.min(by.groups()));
        let target = by.offset(first).saturating_add(rows);
        // The first group past `first` from which `offset` reaches the
        // target (offsets ascend with the group), at most the last.
        let (mut lo, mut hi) = (first + 1, groups);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if by.offset(mid) >= target {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        first..lo.min(groups)
    }

    /// A group of one row `i` (one point per configuration: the case with
    /// the most groups), its columns `b` ([`Design::rows_into`]: axis `a`
    /// at `[a n..(a + 1) n]`), in fixed-size arithmetic without an allocation per
    /// group: `z_a = L⁻¹ b_aᵀ` by forward substitution (`z` holds the three
    /// axes of each column side by side, `[3c..3c + 3]`),
    /// `H_ab = z_a · z_b`, and `(I − H) e(−g) = e` solved by Cholesky once
    /// every eigenvalue of `I − H` is above [`MIN_EIGENVALUE`]
    /// ([`definite_beyond`]). (The inverse of `Λ` times each axis and a
    /// 3 × 3 eigendecomposition were half of a million rows' held-out
    /// error.)
    fn one(&self, i: usize, b: &[f64], z: &mut [f64], out: &mut Vec<Vector3<f64>>) -> bool {
        let n = self.x.len();
        let mut e = Vector3::from_fn(|a, _| self.d.y[3 * i + a]);
        for (c, xc) in self.x.iter().enumerate() {
            for a in 0..3 {
                e[a] -= b[a * n + c] * xc;
            }
        }
        // The three axes' substitutions side by side (three independent
        // chains of sums, each in the order of one axis alone: the same
        // bits; one after the other they were a chain of dependent adds).
        let (z, _) = z.as_chunks_mut::<3>();
        let z = &mut z[..n];
        for r in 0..n {
            let lr = &self.l_rows[r * n..r * n + r];
            let mut s = [b[r], b[n + r], b[2 * n + r]];
            for (l, zc) in lr.iter().zip(&z[..r]) {
                s[0] -= l * zc[0];
                s[1] -= l * zc[1];
                s[2] -= l * zc[2];
            }
            let d = self.l_inv_diag[r];
            z[r] = [s[0] * d, s[1] * d, s[2] * d];
        }
        let z = &*z;
        let dot = |a: usize, c: usize| -> f64 { z.iter().map(|z| z[a] * z[c]).sum() };
        let (h01, h02, h12) = (dot(0, 1), dot(0, 2), dot(1, 2));
        let ih = Matrix3::new(
            1.0 - dot(0, 0),
            -h01,
            -h02,
            -h01,
            1.0 - dot(1, 1),
            -h12,
            -h02,
            -h12,
            1.0 - dot(2, 2),
        );
        if !definite_beyond(&ih, MIN_EIGENVALUE) {
            return false;
        }
        let Some(chol) = ih.cholesky() else {
            return false;
        };
        out.push(chol.solve(&e));
        true
    }

    /// A group of several rows `rs`, their columns `b`
    /// ([`Design::rows_into`]): `I − H_gg` from the factorisation of `Λ`,
    /// its eigendecomposition, the residuals through it.
    fn many(&self, rs: &[usize], b: &[f64], out: &mut Vec<Vector3<f64>>) -> bool {
        let (y, n) = (&self.d.y, self.x.len());
        let m = 3 * rs.len();
        let bg = DMatrix::from_fn(m, n, |r, c| b[r * n + c]);
        let eg = DVector::from_fn(m, |r, _| y[3 * rs[r / 3] + r % 3]) - &bg * &self.x;
        // I − H_gg, symmetric positive semidefinite.
        let ih = DMatrix::identity(m, m) - &bg * self.chol.solve(&bg.transpose());
        let eig = ih.symmetric_eigen();
        if !invertible(eig.eigenvalues.as_slice()) {
            return false;
        }
        let e = eig.eigenvectors.tr_mul(&eg);
        let e = DVector::from_fn(m, |r, _| e[r] / eig.eigenvalues[r]);
        let e = &eig.eigenvectors * e;
        out.extend((0..rs.len()).map(|k| Vector3::new(e[3 * k], e[3 * k + 1], e[3 * k + 2])));
        true
    }
}

/// Whether every eigenvalue of the symmetric 3 × 3 matrix `m` is above
/// `floor` (the rule of [`invertible`]): whether `m − floor·I` has a
/// Cholesky factor, which decides it to a rounding of a few `ε` times `m`'s
/// largest element, as an eigendecomposition does. (A closed-form smallest
/// eigenvalue was off by ~√ε where the two smallest are nearly equal: a
/// second reading found {5e-9, 5e-9, 1} read as 3.3e-11.) Not finite:
/// `false`.
fn definite_beyond(m: &Matrix3<f64>, floor: f64) -> bool {
    m.iter().all(|v| v.is_finite()) && (m - Matrix3::identity() * floor).cholesky().is_some()
}

#[cfg(test)]
mod tests {
    use crate::calibrate::fit::heldout::*;
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
        Design::from_columns(
            Vec::new(),
            b,
            y,
            (0..rows).map(|i| i / per).collect(),
            groups,
            None,
        )
    }

    fn ols() -> FitSettings {
        FitSettings {
            method: Method::Ols,
            weight: RobustWeight::new(1e-5, 0.0).expect("valid weight"),
            max_iterations: 1,
            tolerance: 0.1,
            weighting: crate::calibrate::fit::Weighting::Estimated,
        }
    }

    #[test]
    fn matches_the_refit_without_each_group() {
        for (groups, per, n, seed) in [(12, 1, 5, 1), (8, 3, 7, 2), (30, 2, 13, 3)] {
            let d = design(groups, per, n, seed);
            let cols: Vec<usize> = (0..n).collect();
            let by = d.group_rows().expect("groups in range");
            // From the columns' dots, and from the fit's own sums (the
            // engine's).
            let sums = crate::calibrate::fit::information(&d, &cols).expect("finite");
            for sums in [None, Some(&sums)] {
                let fast = ols_heldout(&d, &cols, sums)
                    .expect("positive definite")
                    .groups(&by, 0..groups);
                for g in 0..groups {
                    assert!(fast.ok[g], "identifiable without the group");
                    let res = &fast.res[by.range(g)];
                    let f = fit(&d, &cols, &[g], &ols()).expect("refit");
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
    }

    /// [`design`] of `rows` rows in groups of one, two and three rows
    /// (every seventh row starts four groups), the last ones empty.
    fn mixed(rows: usize, n: usize, seed: u64, groups: usize) -> Design {
        let mut d = design(rows, 1, n, seed);
        d.group = (0..rows)
            .map(|i| [0, 1, 1, 2, 3, 3, 3][i % 7] + 4 * (i / 7))
            .collect();
        d.groups = groups;
        d
    }

    #[test]
    fn the_same_bits_on_any_number_of_threads() {
        // Groups of one, two and three rows, one singular (column 0 only in
        // group 0).
        let mut d = mixed(40, 6, 5, 4 * 6);
        let b = d.held_mut().expect("held");
        for r in 3..b.nrows() {
            b[(r, 0)] = 0.0;
        }
        let by = d.group_rows().expect("groups in range");
        let cols: Vec<usize> = (0..6).collect();
        let all = 0..by.groups();
        let one = ols_heldout_on(&d, &cols, 1)
            .expect("positive definite")
            .groups(&by, all.clone());
        assert!(!one.ok[0] && one.ok[1..].iter().all(|&ok| ok));
        for threads in [2, 3, 7, 100] {
            let many = ols_heldout_on(&d, &cols, threads)
                .expect("positive definite")
                .groups(&by, all.clone());
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
            (&*by.of(0), &*by.of(1), &*by.of(2), &*by.of(3)),
            (&[1, 4][..], &[3][..], &[0, 2][..], &[][..])
        );
        assert_eq!(by.all(), [1, 4, 3, 0, 2]);
        assert_eq!((by.range(2), by.offset(4), &*by.of(9)), (3..5, 5, &[][..]));
        assert!(GroupRows::new(&[0, 3], 3).is_none());
        assert!(GroupRows::new(&[usize::MAX], 3).is_none());
        // Row `g` group `g`'s one row: the same rows, none held.
        let one = GroupRows::new(&[0, 1, 2], 3).expect("in range");
        let held = GroupRows::new(&[0, 1, 2, 0], 3).expect("in range");
        assert_eq!(
            (one.groups(), one.all(), &*one.of(1), &*one.of(3)),
            (3, vec![0, 1, 2], &[1][..], &[][..])
        );
        assert_eq!((one.range(2), one.offset(3), one.offset(7)), (2..3, 3, 3));
        assert_eq!((&*held.of(0), held.groups()), (&[0, 3][..], 3));
        assert!(GroupRows::new(&[0, 1, 1], 3).is_some_and(|g| g.of(2).is_empty()));
    }

    #[test]
    fn a_group_no_other_can_replace_is_left_to_the_refit() {
        // Column 0 is non-zero in group 0 only.
        let mut d = design(6, 1, 3, 4);
        let b = d.held_mut().expect("held");
        for r in 3..b.nrows() {
            b[(r, 0)] = 0.0;
        }
        let by = d.group_rows().expect("groups in range");
        let fast = ols_heldout(&d, &[0, 1, 2], None)
            .expect("positive definite")
            .groups(&by, 0..6);
        assert!(!fast.ok[0]);
        assert!(fast.ok[1..].iter().all(|&ok| ok));
        assert!(fast.of(&by, 0).is_none() && fast.of(&by, 6).is_none());
    }

    #[test]
    fn windows_of_groups_give_the_residuals_of_all_at_once() {
        let d = mixed(50, 5, 9, 4 * 8);
        let by = d.group_rows().expect("groups in range");
        let cols: Vec<usize> = (0..5).collect();
        let fit = ols_heldout(&d, &cols, None).expect("positive definite");
        let all = fit.groups(&by, 0..by.groups());
        for rows in [1, 2, 5, 1000] {
            let mut first = 0;
            let mut seen = 0;
            while first < by.groups() {
                let range = OlsHeldOut::window(&by, first, rows);
                assert!(range.start == first && range.end > first, "{range:?}");
                let part = fit.groups(&by, range.clone());
                for g in range.clone() {
                    assert_eq!(part.of(&by, g), all.of(&by, g));
                    seen += 1;
                }
                first = range.end;
            }
            assert_eq!(seen, by.groups());
        }
        assert_eq!(
            OlsHeldOut::window(&by, by.groups(), 4),
            by.groups()..by.groups()
        );
    }

    #[test]
    fn the_definiteness_rule_is_the_eigenvalues_own() {
        // Eigenvalues {λ, λ, 1} and {1, 1, λ} in rotated frames, λ on both
        // sides of the floor (within 2 %), and diagonal ones.
        let mut next = crate::calibrate::design::testing::rng(11);
        let floor = MIN_EIGENVALUE;
        for k in 0..3000 {
            let a = Matrix3::from_fn(|_, _| next());
            let q = a.qr().q();
            let lambda = floor * [0.5, 0.98, 1.02, 5.0, 1e3][k % 5];
            let d = if k % 2 == 0 {
                Matrix3::from_diagonal(&nalgebra::Vector3::new(lambda, lambda, 1.0))
            } else {
                Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, lambda))
            };
            let m = q * d * q.transpose();
            let m = (m + m.transpose()) * 0.5;
            assert_eq!(definite_beyond(&m, floor), lambda > floor, "{k}: {lambda}");
            let eig = m.symmetric_eigenvalues();
            assert_eq!(invertible(eig.as_slice()), lambda > floor, "{k}: {lambda}");
        }
        let diag =
            |a: f64, b: f64, c: f64| Matrix3::from_diagonal(&nalgebra::Vector3::new(a, b, c));
        assert!(definite_beyond(&diag(5.0, 3.0, 3.0), floor));
        assert!(!definite_beyond(&diag(1.0, 1.0, 0.0), floor));
        assert!(!definite_beyond(&diag(1.0, -1.0, 1.0), floor));
        assert!(!definite_beyond(&diag(1.0, f64::NAN, 1.0), floor));
        assert!(!definite_beyond(&diag(1.0, f64::INFINITY, 1.0), floor));
    }
}
