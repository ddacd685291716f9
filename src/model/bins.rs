//! The angle bins of a joint (`no_std`): the distinct angles it takes over
//! the configurations, whose per-angle compliances make the compensator
//! candidate of the effect rule ([`super::effect::candidates`]). The rule
//! exists once, here: [`clusters`], [`by_first_appearance`],
//! [`compensator_eligible`]; the host (`calibrate::rows`, any number of
//! rows) and a device ([`joint_bins`], one angle per configuration) both
//! use it.

use nalgebra::RealField;

use super::param::{angle_urad, Param, BIN_TOLERANCE_RAD};
use crate::error::Error;

/// The angle bins of one joint: its distinct angles \[µrad\] over the
/// configurations, in order of first appearance, and whether they make a
/// compensator candidate.
#[derive(Debug, Clone, PartialEq)]
pub struct JointBins<const B: usize> {
    /// The bins (empty when the joint takes more than `B` angles).
    pub angles_urad: heapless::Vec<i32, B>,
    /// [`compensator_eligible`]: [`COMPENSATOR_BINS`], each seen in at
    /// least [`COMPENSATOR_MIN_CONFIGS`] configurations.
    pub compensator_ok: bool,
}

/// Most configurations [`joint_bins`] takes.
pub const MAX_CONFIGS: usize = 64;

/// The angle bins of one joint, as the host's (`calibrate::rows`):
/// `angles` holds the joint's angle \[rad\] in each configuration, once;
/// the bins are their [`clusters`] [`by_first_appearance`], a compensator
/// candidate by [`compensator_eligible`] with the default policy.
///
/// # Errors
/// [`Error::CapacityExceeded`] for more than [`MAX_CONFIGS`] angles;
/// [`Error::NonFinite`].
pub fn joint_bins<T: RealField + Copy, const B: usize>(
    angles: &[T],
) -> Result<JointBins<B>, Error> {
    if angles.len() > MAX_CONFIGS {
        return Err(Error::CapacityExceeded {
            what: "configurations",
            capacity: MAX_CONFIGS,
        });
    }
    let mut v = [0.0f64; MAX_CONFIGS];
    for (o, a) in v.iter_mut().zip(angles) {
        *o = nalgebra::try_convert::<T, f64>(*a).unwrap_or(f64::NAN);
        if !o.is_finite() {
            return Err(Error::NonFinite {
                what: "joint angle",
            });
        }
    }
    let values = &v[..angles.len()];
    let mut sorted = v;
    let sorted = &mut sorted[..angles.len()];
    // Insertion sort: a few dozen angles, and a fraction of the flash of
    // the standard library's sort on a microcontroller.
    for i in 1..sorted.len() {
        let mut j = i;
        while j > 0 && sorted[j].total_cmp(&sorted[j - 1]).is_lt() {
            sorted.swap(j, j - 1);
            j -= 1;
        }
    }
    let mut centres: heapless::Vec<f64, MAX_CONFIGS> = heapless::Vec::new();
    // At most one cluster per angle: within capacity.
    clusters(sorted, |c| {
        let _ = centres.push(c);
    });
    by_first_appearance(&mut centres, values);
    let mut out = JointBins {
        angles_urad: heapless::Vec::new(),
        compensator_ok: false,
    };
    if centres.len() > B {
        return Ok(out);
    }
    let mut configs: heapless::Vec<usize, B> = heapless::Vec::new();
    for &c in &centres {
        let _ = configs.push(values.iter().filter(|&&x| near(x, c)).count());
        // `centres.len() ≤ B`.
        let _ = out.angles_urad.push(angle_urad(c));
    }
    let ok = compensator_eligible(&configs, COMPENSATOR_BINS, COMPENSATOR_MIN_CONFIGS);
    out.compensator_ok = ok;
    Ok(out)
}

/// Whether `x` falls in the bin centred at `c`.
fn near(x: f64, c: f64) -> bool {
    libm::fabs(x - c) <= BIN_TOLERANCE_RAD
}

/// The bin rule's clusters: over `sorted` (ascending), an angle within
/// [`BIN_TOLERANCE_RAD`] of the current cluster's running mean joins it,
/// else it opens the next; `emit` gets each cluster's mean, ascending.
pub fn clusters(sorted: &[f64], mut emit: impl FnMut(f64)) {
    let mut cur: Option<(f64, usize)> = None;
    for &x in sorted {
        match &mut cur {
            Some((c, n)) if near(x, *c / *n as f64) => {
                *c += x;
                *n += 1;
            }
            _ => {
                if let Some((c, n)) = cur {
                    emit(c / n as f64);
                }
                cur = Some((x, 1));
            }
        }
    }
    if let Some((c, n)) = cur {
        emit(c / n as f64);
    }
}

/// Orders the bin `centres` by their first appearance in `values` (the
/// first value in the bin), stably: the bins are numbered as the data
/// first show them (`k21`, `k22`, … of the paper).
pub fn by_first_appearance(centres: &mut [f64], values: &[f64]) {
    let first = |c: f64| {
        values
            .iter()
            .position(|&x| near(x, c))
            .unwrap_or(usize::MAX)
    };
    // Stable insertion sort: a few bins, and a fraction of the flash of the
    // standard library's sort on a microcontroller.
    for i in 1..centres.len() {
        let mut j = i;
        while j > 0 && first(centres[j]) < first(centres[j - 1]) {
            centres.swap(j, j - 1);
            j -= 1;
        }
    }
}

/// Fewest and most bins of a compensator candidate (the default of
/// `calibrate::Policy::compensator_bins`, and the device's).
pub const COMPENSATOR_BINS: (usize, usize) = (2, 8);
/// Fewest configurations each bin of a compensator candidate is seen in
/// (the default of `calibrate::Policy::compensator_min_configs`, and the
/// device's).
pub const COMPENSATOR_MIN_CONFIGS: usize = 2;

/// Whether a joint's angle bins, seen in `bin_configs` configurations
/// each, make a compensator candidate: `bins.0` to `bins.1` bins, each in
/// at least `min_configs` configurations (a per-angle compliance needs two
/// angles to differ from a constant, and a repetition to be told from the
/// noise).
pub fn compensator_eligible(
    bin_configs: &[usize],
    bins: (usize, usize),
    min_configs: usize,
) -> bool {
    (bins.0..=bins.1).contains(&bin_configs.len()) && bin_configs.iter().all(|&n| n >= min_configs)
}

/// Whether joint `joint` at value `qj` \[rad\] is in one of the angle bins
/// ([`super::Param::ComplianceAt`]) among `params`.
pub fn in_some_bin<'a, T: RealField + Copy>(
    params: impl IntoIterator<Item = &'a Param>,
    joint: u8,
    qj: T,
) -> bool {
    params.into_iter().any(|p| match *p {
        Param::ComplianceAt {
            joint: j,
            angle_urad,
        } => j == joint && in_bin(angle_urad, qj),
        _ => false,
    })
}

/// Whether a joint value `qj` \[rad\] is within [`BIN_TOLERANCE_RAD`] of a
/// bin's angle \[µrad\] ([`super::Param::ComplianceAt`]).
pub fn in_bin<T: RealField + Copy>(angle_urad: i32, qj: T) -> bool {
    let centre: T = nalgebra::convert(f64::from(angle_urad) * 1e-6);
    (qj - centre).abs() <= nalgebra::convert(BIN_TOLERANCE_RAD)
}
