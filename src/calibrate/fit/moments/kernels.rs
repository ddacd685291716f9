//! The arithmetic kernels of [`crate::calibrate::fit::moments::DesignMoments`]' sums and folds, the
//! two that run over many cells compiled for the widest instruction set
//! ([`crate::calibrate::design::widest`]: the same bits as the baseline).

use crate::calibrate::design::widest::{widest, Kernel};

/// `y += x k`.
#[inline(always)]
pub(super) fn axpy(y: &mut [f64], x: &[f64], k: f64) {
    for (y, &x) in y.iter_mut().zip(x) {
        *y += x * k;
    }
}

/// `Σ aᵢ bᵢ`.
pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

/// `y += Σ_c x_c k_c` over the terms `(x_c, k_c)` in order, each element's
/// sum as one [`axpy`] after the other (`y + x₁k₁`, then `+ x₂k₂`, …), four
/// terms per pass over `y`.
pub(super) fn axpy_cells(y: &mut [f64], terms: &[(&[f64], f64)]) {
    widest(AxpyCells(y, terms));
}

/// [`axpy_cells`] as a [`Kernel`].
struct AxpyCells<'y, 't, 'x>(&'y mut [f64], &'t [(&'x [f64], f64)]);

impl Kernel for AxpyCells<'_, '_, '_> {
    type Output = ();

    #[inline(always)]
    fn run(self) {
        let AxpyCells(y, terms) = self;
        let mut fours = terms.chunks_exact(4);
        for t in fours.by_ref() {
            let (x0, x1, x2, x3) = (
                &t[0].0[..y.len()],
                &t[1].0[..y.len()],
                &t[2].0[..y.len()],
                &t[3].0[..y.len()],
            );
            let (k0, k1, k2, k3) = (t[0].1, t[1].1, t[2].1, t[3].1);
            for (i, y) in y.iter_mut().enumerate() {
                *y = (((*y + x0[i] * k0) + x1[i] * k1) + x2[i] * k2) + x3[i] * k3;
            }
        }
        for &(x, k) in fours.remainder() {
            axpy(y, x, k);
        }
    }
}

/// `(Σ aᵢ sᵢ, Σ bᵢ sᵢ)` of each of three `s` in one pass, each sum in four
/// partial sums (independent chains the processor can overlap), combined
/// as `(p₀ + p₁) + (p₂ + p₃)` and the remainder added after.
pub(super) fn dot2x3(a: &[f64], b: &[f64], s: [&[f64]; 3]) -> [(f64, f64); 3] {
    widest(Dot2x3(a, b, s))
}

/// [`dot2x3`] as a [`Kernel`].
struct Dot2x3<'a>(&'a [f64], &'a [f64], [&'a [f64]; 3]);

impl Kernel for Dot2x3<'_> {
    type Output = [(f64, f64); 3];

    #[inline(always)]
    fn run(self) -> [(f64, f64); 3] {
        let Dot2x3(a, b, s) = self;
        let (mut p, mut q) = ([[0.0; 4]; 3], [[0.0; 4]; 3]);
        let len = 4 * (a.len() / 4);
        for i in (0..len).step_by(4) {
            let (a, b) = (&a[i..i + 4], &b[i..i + 4]);
            for c in 0..3 {
                let s = &s[c][i..i + 4];
                for k in 0..4 {
                    p[c][k] += a[k] * s[k];
                    q[c][k] += b[k] * s[k];
                }
            }
        }
        let mut out = [(0.0, 0.0); 3];
        for c in 0..3 {
            let (p, q) = (p[c], q[c]);
            let (mut p0, mut q0) = ((p[0] + p[1]) + (p[2] + p[3]), (q[0] + q[1]) + (q[2] + q[3]));
            for i in len..a.len() {
                p0 += a[i] * s[c][i];
                q0 += b[i] * s[c][i];
            }
            out[c] = (p0, q0);
        }
        out
    }
}
