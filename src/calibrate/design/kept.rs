//! The independence test checked on the columns themselves
//! ([`Design::kept_by_columns`]), where `Λ` is ill-conditioned.

use nalgebra::{DMatrix, DVector};

use crate::calibrate::design::Design;
use crate::estimate::rank::{ESCALATION, MAX_ESCALATED_TOLERANCE};

impl Design {
    /// Which of the columns `cols` are kept, in order, by the pivots
    /// `1 − R²` (a column regressed on the kept ones before it) of the
    /// columns themselves: `R` of a Householder QR of the rows (block by
    /// block: `R ← qr([R; rows])`), then its columns orthogonalised in
    /// order, twice (Gram–Schmidt). `Λ = BᵀB` squares the condition of `B`:
    /// its pivots carry rounding of about `ε·κ(Λ)`, of the order of the
    /// tolerance past `κ ≈ 10⁸`, where an exactly dependent column can pass
    /// and the weights of a fit then make the solver refuse it (a random
    /// chain: `1 − R²` of 6e-22 from the columns, ~1e-6 from `Λ`). Here the
    /// rounding is about `ε·κ(B)`. A column without information (squared
    /// norm at most `ε²` of the largest) is left out, as in `Λ`.
    pub fn kept_by_columns(&self, cols: &[usize], tolerance: f64) -> Vec<bool> {
        let n = cols.len();
        let mut r = DMatrix::<f64>::zeros(0, n);
        let per = QR_ROWS.max(n);
        let mut start = 0;
        let mut block = Vec::new();
        while start < self.rows() {
            let end = (start + per).min(self.rows());
            let k = r.nrows();
            let h = 3 * (end - start);
            self.columns_into(start, end - start, cols, &mut block);
            let stacked = DMatrix::from_fn(k + h, n, |i, j| {
                if i < k {
                    r[(i, j)]
                } else {
                    block[j * h + i - k]
                }
            });
            r = stacked.qr().r();
            start = end;
        }
        let norms: Vec<f64> = (0..n).map(|j| r.column(j).norm_squared()).collect();
        let floor = f64::EPSILON * f64::EPSILON * norms.iter().copied().fold(0.0, f64::max);
        // As in `Λ` (`crate::estimate::rank`): the tolerance raised tenfold
        // while the kept set breaks the criterion as stated, else the first.
        let mut t = tolerance;
        let first = greedy(&r, &norms, floor, t);
        let mut kept = first.clone();
        while !within_inflation(&r, &norms, &kept, tolerance) {
            t *= ESCALATION;
            if t > MAX_ESCALATED_TOLERANCE {
                return first;
            }
            kept = greedy(&r, &norms, floor, t);
        }
        kept
    }
}

/// The greedy pivots of the columns of `R` (squared norms `norms`, those
/// at most `floor` without information): in order, each orthogonalised
/// twice on the kept ones before it, kept when `1 − R²` exceeds
/// `tolerance`.
fn greedy(r: &DMatrix<f64>, norms: &[f64], floor: f64, tolerance: f64) -> Vec<bool> {
    let mut basis: Vec<DVector<f64>> = Vec::new();
    (0..r.ncols())
        .map(|j| {
            if norms[j].is_nan() || norms[j] <= floor {
                return false;
            }
            let mut v = r.column(j).into_owned();
            for _ in 0..2 {
                for q in &basis {
                    let p = q.dot(&v);
                    v.axpy(-p, q, 1.0);
                }
            }
            let d = v.norm_squared() / norms[j];
            let keep = d > tolerance;
            if keep {
                basis.push(&v / v.norm());
            }
            keep
        })
        .collect()
}

/// Whether every kept column of `R` has `1 − R²` on all the other kept
/// ones (`1/VIF`) above `tolerance`: `VIFᵢ` is the squared norm of row
/// `i` of `R_K⁻¹`, `R_K` the triangle of a QR of the kept columns scaled
/// to unit norm.
fn within_inflation(r: &DMatrix<f64>, norms: &[f64], kept: &[bool], tolerance: f64) -> bool {
    let cols: Vec<usize> = (0..kept.len()).filter(|&j| kept[j]).collect();
    if cols.is_empty() {
        return true;
    }
    let scaled = DMatrix::from_fn(r.nrows(), cols.len(), |i, k| {
        r[(i, cols[k])] / norms[cols[k]].sqrt()
    });
    let rk = scaled.qr().r();
    let k = cols.len();
    let Some(inv) = rk.solve_upper_triangular(&DMatrix::identity(k, k)) else {
        return false;
    };
    (0..k).all(|i| {
        let vif = inv.row(i).norm_squared();
        vif.is_finite() && 1.0 / vif > tolerance
    })
}

/// Rows added to `R` at a time in [`Design::kept_by_columns`].
const QR_ROWS: usize = 4096;

#[cfg(test)]
mod tests {
    use crate::calibrate::design::Design;
    use crate::estimate::rank::independence_tolerance;
    use nalgebra::DMatrix;

    /// The columns of `crate::estimate::rank`'s test (`e0`, `e0 + ε e1`,
    /// `e1 + ε e2`, `e2`; ε = 3e-3) as one row of three equations: the
    /// greedy pivots keep the first three (a VIF of ~1e10); with the
    /// tolerance ×10 the second is left out and the fourth kept, as in `Λ`.
    #[test]
    fn a_near_null_set_is_taken_again_with_a_raised_tolerance() {
        let e = 3e-3;
        let b = DMatrix::from_row_slice(
            3,
            4,
            &[1.0, 1.0, 0.0, 0.0, 0.0, e, 1.0, 0.0, 0.0, 0.0, e, 1.0],
        );
        let d = Design::from_columns(Vec::new(), b, vec![0.0; 3], vec![0], 1, None);
        let kept = d.kept_by_columns(&[0, 1, 2, 3], independence_tolerance());
        assert_eq!(kept, [true, false, true, true]);
    }
}
