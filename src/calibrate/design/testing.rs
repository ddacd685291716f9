//! Pseudo-random designs for the tests.

use crate::calibrate::design::Design;
use nalgebra::DMatrix;

/// Uniform values in (−0.5, 0.5) from `seed` (a linear congruential
/// generator: the same sequence on every machine).
pub(crate) fn rng(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed;
    move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }
}

/// `groups` groups of `per` rows on `n` columns, pseudo-random (the
/// columns, then the left-hand sides scaled by 1e-3).
pub(crate) fn design(groups: usize, per: usize, n: usize, seed: u64) -> Design {
    let mut next = rng(seed);
    let rows = groups * per;
    let b = DMatrix::from_fn(3 * rows, n, |_, _| next());
    let y = (0..3 * rows).map(|_| next() * 1e-3).collect();
    Design::from_columns(
        Vec::new(),
        b,
        y,
        (0..rows).map(|i| i / per).collect(),
        groups,
        None,
    )
}
