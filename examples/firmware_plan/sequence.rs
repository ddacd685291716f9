//! The controller's plan: of the KR-270's 15 configurations (the rows of
//! its three markers under the configuration's payload, computed on the
//! device as the firmware example does), choose one at a time the one
//! whose rows raise `ln det Λ` of the accumulator most
//! (`robcal::estimate::plan::next_best`), "measure" it (its rows into the
//! accumulator), and choose again: the same steps as the host's greedy
//! `robcal plan` (`robcal::calibrate::plan::choose`), from the same prior
//! (`robcal::estimate::plan::prior`, times the configurations chosen so
//! far). Generic over the scalar: f32 on the device, f32 and f64 on the
//! host.

use nalgebra::{RealField, SVector, Vector3};
use robcal::estimate::plan::{next_best, prior};
use robcal::{Accumulator, Block, Error};

use crate::kr270::{Dn, Kr270, G, N};

/// Configurations chosen.
pub const PICKS: usize = 8;

/// The candidates' blocks: three markers per configuration.
pub type Table<T> = [[Block<T, Dn>; 3]; G];

/// An empty table, to fill in place ([`fill`]: 6.8 KB in f32, not copied).
pub fn empty<T: RealField + Copy>() -> Table<T> {
    [[Block::new(nalgebra::SMatrix::zeros(), Vector3::zeros()); 3]; G]
}

/// Every configuration's three marker blocks into `out`, unit weights
/// (the weights of the host's plan, `1/σ0`, are the same for every row:
/// the gains' order does not depend on them, nor on the parameters'
/// units).
pub fn fill<T: RealField + Copy>(src: &Kr270<T>, out: &mut Table<T>) -> Result<(), Error> {
    for (g, c) in out.iter_mut().enumerate() {
        let blocks = src.config_blocks(g)?;
        for (b, rows) in c.iter_mut().zip(blocks) {
            b.b = rows;
        }
    }
    Ok(())
}

/// [`fill`] into a new table (host).
pub fn table<T: RealField + Copy>(src: &Kr270<T>) -> Result<Table<T>, Error> {
    let mut out = empty();
    fill(src, &mut out)?;
    Ok(out)
}

/// One step: the next best configuration not `taken` given the
/// accumulator `acc` and the `k` chosen so far (`base`: the prior of the
/// first choice).
pub fn step<T: RealField + Copy>(
    acc: &Accumulator<T, Dn>,
    base: &SVector<T, N>,
    k: usize,
    table: &Table<T>,
    taken: &[bool; G],
) -> Result<Option<(usize, T)>, Error> {
    let times: T = nalgebra::convert(k.max(1) as f64);
    next_best(
        &acc.information(),
        &(base * times),
        &[true; N],
        table,
        taken,
    )
}

/// The configurations chosen, in order (0-based), and each choice's gain
/// of `ln det`.
pub fn sequence<T: RealField + Copy>(
    table: &Table<T>,
) -> Result<([usize; PICKS], [T; PICKS]), Error> {
    let mut base = SVector::<T, N>::zeros();
    prior(table, &mut base)?;
    let mut acc = Accumulator::<T, Dn>::new();
    let mut taken = [false; G];
    let mut chosen = [0; PICKS];
    let mut gains = [T::zero(); PICKS];
    for k in 0..PICKS {
        let Some((c, gain)) = step(&acc, &base, k, table, &taken)? else {
            return Err(Error::CapacityExceeded {
                what: "configurations to choose from",
                capacity: G,
            });
        };
        taken[c] = true;
        chosen[k] = c;
        gains[k] = gain;
        for b in &table[c] {
            acc.update(b)?;
        }
    }
    Ok((chosen, gains))
}
