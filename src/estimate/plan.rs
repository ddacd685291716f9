//! Choosing the next measurement before it is made: of a table of candidate
//! poses, the one whose rows raise `ln det Λ` most (D-optimal design, one
//! candidate at a time), from the information the accumulator holds.
//!
//! A candidate's rows `G` (its blocks, one per marker, each row times its
//! weight: eq. 9) raise the information `Λ = Σ BᵀW²B` (eq. 10) to
//! `Λ + GᵀG`, and by the matrix determinant lemma
//!
//! ```text
//!   ln det(Λ + GᵀG) − ln det Λ = ln det(I + G Λ⁻¹ Gᵀ) = ln det(I + XᵀX),
//!   X = L⁻¹ S Gᵀ                      (the rows whitened by Λ's Factor)
//! ```
//!
//! an `r × r` determinant, `r` the candidate's rows (3 per block, at most
//! [`MAX_BLOCKS`] blocks): `r` forward substitutions of `n²/2` and an
//! `r × r` Cholesky, with no `n × n` work per candidate. `ln det Λ` is the
//! volume of the confidence ellipsoid of the estimate (eq. 13's covariance
//! is `Λ⁻¹`) to the power `−2`: the candidate that raises it most shrinks
//! that volume most.
//!
//! Before the measurements identify every parameter, `Λ` is singular: the
//! information is then `Λ + diag(λ₀)`, a prior of `1/λ₀ⱼ` variance on each
//! parameter ([`next_best`]; the host's planner starts from the same).
//!
//! The same arithmetic serves the host's `robcal plan` (greedy selection
//! and exchange over a pool, `crate::calibrate::plan`) and a device that
//! measures, updates and chooses as it goes.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, RealField, SMatrix};

use super::block::Block;
use super::factor::Factor;
use super::Alloc;
use crate::error::Error;

/// Blocks (markers) of one candidate at most: 4, so that `I + XᵀX` is at
/// most 12 × 12 on the stack.
pub const MAX_BLOCKS: usize = 4;

/// Rows of one candidate at most.
const MAX_ROWS: usize = 3 * MAX_BLOCKS;

/// `ln det(I + G Λ⁻¹ Gᵀ)`: by how much the rows of `blocks` (each row
/// times its weight; the rows past a block's `rows` ignored) raise
/// `ln det Λ` on the active parameters of `factor` (the
/// [module docs](self)). Never negative.
///
/// # Errors
/// [`Error::CapacityExceeded`] for more than [`MAX_BLOCKS`] blocks;
/// [`Error::Mismatch`] for a block of another number of parameters;
/// a block's own [`Block::validate`] error. Nothing is changed.
pub fn gain<T: RealField + Copy, D: Dim>(
    factor: &Factor<T, D>,
    blocks: &[Block<T, D>],
) -> Result<T, Error>
where
    DefaultAllocator: Alloc<D>,
{
    if blocks.len() > MAX_BLOCKS {
        return Err(Error::CapacityExceeded {
            what: "blocks of a candidate",
            capacity: MAX_BLOCKS,
        });
    }
    for b in blocks {
        if b.b.ncols() != factor.parameters() {
            return Err(Error::Mismatch {
                what: "a candidate's parameters and the information's",
            });
        }
        b.validate()?;
    }
    // The whitened rows, one at a time; `I + XᵀX` as they come.
    let mut x: [Option<OVector<T, D>>; MAX_ROWS] = core::array::from_fn(|_| None);
    let mut s = SMatrix::<T, MAX_ROWS, MAX_ROWS>::identity();
    let mut r = 0;
    for block in blocks {
        for a in 0..block.rows {
            let w = block.w[a];
            let row = block.b.row(a).transpose() * w;
            let xr = factor.whiten(&row);
            for (k, xk) in x.iter().take(r).enumerate() {
                if let Some(xk) = xk {
                    let v = xk.dot(&xr);
                    s[(r, k)] = v;
                    s[(k, r)] = v;
                }
            }
            s[(r, r)] += xr.dot(&xr);
            x[r] = Some(xr);
            r += 1;
        }
    }
    // ln det of the leading r × r block by Cholesky (symmetric, ≥ I).
    let mut log_det = T::zero();
    for j in 0..r {
        let mut d = s[(j, j)];
        for k in 0..j {
            d -= s[(j, k)] * s[(j, k)];
        }
        if d <= T::zero() || !d.is_finite() {
            return Err(Error::NonFinite {
                what: "candidate gain",
            });
        }
        let l = d.sqrt();
        s[(j, j)] = l;
        for i in (j + 1)..r {
            let mut v = s[(i, j)];
            for k in 0..j {
                v -= s[(i, k)] * s[(j, k)];
            }
            s[(i, j)] = v / l;
        }
        log_det += d.ln();
    }
    Ok(log_det)
}

/// `Λ + diag(prior)` factored on the `active` parameters: the information
/// of the measurements so far with a prior of `1/priorⱼ` variance on each
/// parameter (0: none), so that the first candidates can be compared
/// before the measurements identify every parameter.
///
/// # Errors
/// [`Error::Mismatch`] when `prior` or `active` is not one per parameter;
/// [`Error::NonFinite`] or [`Error::NotPositive`] for a prior that is not
/// finite and ≥ 0; [`Factor::new`]'s errors.
pub fn with_prior<T: RealField + Copy, D: Dim>(
    lambda: &OMatrix<T, D, D>,
    prior: &OVector<T, D>,
    active: &[bool],
) -> Result<Factor<T, D>, Error>
where
    DefaultAllocator: Alloc<D>,
{
    if prior.len() != lambda.nrows() {
        return Err(Error::Mismatch {
            what: "one prior per parameter",
        });
    }
    for &p in prior.iter() {
        if !p.is_finite() {
            return Err(Error::NonFinite { what: "prior" });
        }
        if p < T::zero() {
            return Err(Error::NotPositive { what: "prior" });
        }
    }
    let mut l = lambda.clone();
    for j in 0..prior.len() {
        l[(j, j)] += prior[j];
    }
    Factor::new(&l, active)
}

/// The prior of a plan's first choices ([`with_prior`]), from the
/// candidates of `table`, into `out`: `priorⱼ = 10⁻⁶ · m · sⱼ²`, where
/// `sⱼ² = mean over blocks of Σ bₐⱼ²` (the rows a block uses, unweighted)
/// and `m` the mean over candidates of `Σ wₐ² Σⱼ (bₐⱼ/sⱼ)² / n`: a
/// millionth of one candidate's information per parameter, in each
/// parameter's own unit (the same prior whatever the units: the host's
/// scaled columns give `sⱼ = 1`). A parameter no block moves gets 1.
///
/// # Errors
/// [`Error::Mismatch`] for a block of another number of parameters than
/// `out`; a block's [`Block::validate`] error. `out` is then unchanged.
pub fn prior<T: RealField + Copy, D: Dim, C: AsRef<[Block<T, D>]>>(
    table: &[C],
    out: &mut OVector<T, D>,
) -> Result<(), Error>
where
    DefaultAllocator: Alloc<D>,
{
    let n = out.len();
    for c in table {
        for b in c.as_ref() {
            if b.b.ncols() != n {
                return Err(Error::Mismatch {
                    what: "a candidate's parameters and the prior's",
                });
            }
            b.validate()?;
        }
    }
    let mut s2 = out.clone();
    s2.fill(T::zero());
    let mut blocks = 0usize;
    for c in table {
        for b in c.as_ref() {
            for a in 0..b.rows {
                for j in 0..n {
                    s2[j] += b.b[(a, j)] * b.b[(a, j)];
                }
            }
            blocks += 1;
        }
    }
    let count = |k: usize| -> T { nalgebra::convert(k.max(1) as f64) };
    for v in s2.iter_mut() {
        *v /= count(blocks);
        if *v <= T::zero() || !v.is_finite() {
            *v = T::one();
        }
    }
    let mut m = T::zero();
    for c in table {
        for b in c.as_ref() {
            for a in 0..b.rows {
                let w2 = b.w[a] * b.w[a];
                for j in 0..n {
                    m += w2 * b.b[(a, j)] * b.b[(a, j)] / s2[j];
                }
            }
        }
    }
    m /= count(table.len() * n);
    if m <= T::zero() || !m.is_finite() {
        m = T::one();
    }
    let scale: T = nalgebra::convert(1e-6);
    for j in 0..n {
        out[j] = scale * m * s2[j];
    }
    Ok(())
}

/// The candidate of `table` not yet `taken` whose blocks raise
/// `ln det(Λ + diag(prior))` most, and by how much ([`gain`]; the first of
/// equal gains); `None` when every candidate is taken. `lambda` is the
/// accumulator's information ([`super::Accumulator::information`]),
/// `active` the parameters to plan for.
///
/// # Errors
/// [`Error::Mismatch`] when `taken` is not one flag per candidate;
/// [`with_prior`]'s and [`gain`]'s errors. Nothing is changed.
pub fn next_best<T: RealField + Copy, D: Dim, C: AsRef<[Block<T, D>]>>(
    lambda: &OMatrix<T, D, D>,
    prior: &OVector<T, D>,
    active: &[bool],
    table: &[C],
    taken: &[bool],
) -> Result<Option<(usize, T)>, Error>
where
    DefaultAllocator: Alloc<D>,
{
    if taken.len() != table.len() {
        return Err(Error::Mismatch {
            what: "one taken flag per candidate",
        });
    }
    let factor = with_prior(lambda, prior, active)?;
    let mut best: Option<(usize, T)> = None;
    for (i, c) in table.iter().enumerate() {
        if taken[i] {
            continue;
        }
        let g = gain(&factor, c.as_ref())?;
        if best.is_none_or(|(_, b)| g > b) {
            best = Some((i, g));
        }
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3x4, Matrix4, Vector3, Vector4, U4};

    fn block(b: Matrix3x4<f64>) -> Block<f64, U4> {
        Block::new(b, Vector3::zeros())
    }

    /// The gain is the change of `ln det` computed directly.
    #[test]
    fn the_gain_is_the_log_det_change_of_the_information() {
        let lambda = Matrix4::new(
            5.0, 1.0, 0.5, 0.0, 1.0, 4.0, 0.2, 0.1, 0.5, 0.2, 3.0, 0.3, 0.0, 0.1, 0.3, 2.0,
        );
        let b1 = Matrix3x4::new(1.0, 2.0, 0.0, 1.0, 0.0, 1.0, 3.0, 0.5, 2.0, 0.0, 1.0, 1.0);
        let b2 = Matrix3x4::new(0.3, 0.0, 1.0, 2.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.5, 0.5, 0.5);
        let blocks = [
            block(b1).with_weights(Vector3::new(1.0, 0.5, 2.0)),
            block(b2),
        ];
        let f = Factor::new(&lambda, &[true; 4]).unwrap();
        let g = gain(&f, &blocks).unwrap();
        let w1 = Matrix3x4::from_rows(&[b1.row(0) * 1.0, b1.row(1) * 0.5, b1.row(2) * 2.0]);
        let after = lambda + w1.transpose() * w1 + b2.transpose() * b2;
        let want = after.determinant().ln() - lambda.determinant().ln();
        assert!((g - want).abs() < 1e-12 * want.abs(), "{g} {want}");
        assert!((f.log_det() - lambda.determinant().ln()).abs() < 1e-12);
    }

    /// An inactive parameter's column counts for nothing.
    #[test]
    fn an_inactive_parameter_does_not_count() {
        let lambda = Matrix4::from_diagonal(&Vector4::new(2.0, 3.0, 4.0, 5.0));
        let b = Matrix3x4::new(1.0, 0.0, 0.0, 7.0, 0.0, 1.0, 0.0, 7.0, 0.0, 0.0, 1.0, 7.0);
        let f = Factor::new(&lambda, &[true, true, true, false]).unwrap();
        let g = gain(&f, &[block(b)]).unwrap();
        let want = (1.5_f64 * (4.0 / 3.0) * 1.25).ln();
        assert!((g - want).abs() < 1e-14, "{g} {want}");
    }

    /// The next best candidate is the one the direct determinants prefer;
    /// a taken one is skipped; five blocks are refused.
    #[test]
    fn the_next_best_is_the_largest_gain_not_taken() {
        let lambda = Matrix4::<f64>::zeros();
        let prior = Vector4::repeat(1e-3);
        let table = [
            [block(Matrix3x4::new(
                1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0,
            ))],
            [block(
                Matrix3x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0) * 2.0,
            )],
            [block(Matrix3x4::new(
                1.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0,
            ))],
        ];
        let best = next_best(&lambda, &prior, &[true; 4], &table, &[false; 3]).unwrap();
        assert_eq!(best.map(|b| b.0), Some(1));
        let next = next_best(&lambda, &prior, &[true; 4], &table, &[false, true, false]).unwrap();
        assert_eq!(next.map(|b| b.0), Some(0));
        assert_eq!(
            next_best(&lambda, &prior, &[true; 4], &table, &[true; 3]).unwrap(),
            None
        );
        let f = with_prior(&lambda, &prior, &[true; 4]).unwrap();
        let five = [table[0][0]; 5];
        assert!(matches!(
            gain(&f, &five),
            Err(Error::CapacityExceeded { .. })
        ));
        assert!(matches!(
            with_prior(&lambda, &Vector4::repeat(-1.0), &[true; 4]),
            Err(Error::NotPositive { .. })
        ));
    }

    /// The prior is a millionth of one candidate's information, in each
    /// parameter's unit: scaling a column by `c` scales its prior by `c²`.
    #[test]
    fn the_prior_follows_each_parameters_unit() {
        let b = Matrix3x4::new(1.0, 2.0, 0.0, 1.0, 0.0, 1.0, 3.0, 0.5, 2.0, 0.0, 1.0, 1.0);
        let table = [[block(b)], [block(b * 2.0)]];
        let mut p = Vector4::zeros();
        prior(&table, &mut p).unwrap();
        // s² per column: mean over the two blocks of the column's squares.
        let s2 = Vector4::new(5.0, 5.0, 10.0, 2.25) * 2.5;
        // m: Σ (b/s)² over both candidates (4 columns each of unit mean
        // over blocks: 2 × 4 in total), over 2 candidates × 4 parameters.
        let m = 8.0 / 8.0;
        for j in 0..4 {
            assert!((p[j] - 1e-6 * m * s2[j]).abs() < 1e-18, "{j}: {}", p[j]);
        }
        let mut q = Vector4::zeros();
        let mut t = table;
        for c in &mut t {
            c[0].b.column_mut(1).scale_mut(10.0);
        }
        prior(&t, &mut q).unwrap();
        assert!((q[1] / p[1] - 100.0).abs() < 1e-9);
        assert!((q[0] - p[0]).abs() < 1e-18);
    }
}
