//! The independence test checked on the columns themselves
//! ([`Design::kept_by_columns`]), where `Λ` is ill-conditioned.

use nalgebra::{DMatrix, DVector};

use crate::calibrate::design::Design;

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
        let mut basis: Vec<DVector<f64>> = Vec::new();
        (0..n)
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
}

/// Rows added to `R` at a time in [`Design::kept_by_columns`].
const QR_ROWS: usize = 4096;
