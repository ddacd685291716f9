//! The angle bins of a joint (`no_std`): the distinct angles a joint takes
//! over the configurations, the host's rule (`calibrate::rows`) for a
//! device that sees one configuration at a time; they make the
//! compensator candidate of the effect rule
//! ([`super::effect::candidates`]).

use nalgebra::RealField;

use super::param::{angle_urad, BIN_TOLERANCE_RAD};
use crate::Error;

/// The angle bins of one joint: its distinct angles \[µrad\] over the
/// configurations, in order of first appearance, and whether they make a
/// compensator candidate.
#[derive(Debug, Clone, PartialEq)]
pub struct JointBins<const B: usize> {
    /// The bins (empty when the joint takes more than `B` angles).
    pub angles_urad: heapless::Vec<i32, B>,
    /// 2 to 8 bins (`calibrate::Policy::compensator_bins`), each seen in at
    /// least 2 configurations (`compensator_min_configs`).
    pub compensator_ok: bool,
}

/// Most configurations [`joint_bins`] takes.
pub const MAX_CONFIGS: usize = 64;

/// The host's angle bins of one joint (`calibrate::rows`): `angles` holds
/// the joint's angle \[rad\] in each configuration, once; angles within
/// [`BIN_TOLERANCE_RAD`] of a cluster's running mean join it (sorted), the
/// bins are the clusters' means in order of first appearance.
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
    // Clusters (sum, count), as the host's `cluster`.
    let mut clusters: heapless::Vec<(f64, usize), MAX_CONFIGS> = heapless::Vec::new();
    for &x in sorted.iter() {
        match clusters.last_mut() {
            Some((c, n)) if libm::fabs(x - *c / *n as f64) <= BIN_TOLERANCE_RAD => {
                *c += x;
                *n += 1;
            }
            // At most one cluster per angle: within capacity.
            _ => {
                let _ = clusters.push((x, 1));
            }
        }
    }
    let first = |c: f64| {
        values
            .iter()
            .position(|x| libm::fabs(x - c) <= BIN_TOLERANCE_RAD)
            .unwrap_or(usize::MAX)
    };
    let mut centres: heapless::Vec<f64, MAX_CONFIGS> =
        clusters.iter().map(|(c, n)| c / *n as f64).collect();
    // Stable insertion sort by first appearance.
    for i in 1..centres.len() {
        let mut j = i;
        while j > 0 && first(centres[j]) < first(centres[j - 1]) {
            centres.swap(j, j - 1);
            j -= 1;
        }
    }
    let mut out = JointBins {
        angles_urad: heapless::Vec::new(),
        compensator_ok: false,
    };
    if centres.len() > B {
        return Ok(out);
    }
    let mut ok = (2..=8).contains(&centres.len());
    for &c in &centres {
        let configs = values
            .iter()
            .filter(|x| libm::fabs(*x - c) <= BIN_TOLERANCE_RAD)
            .count();
        ok &= configs >= 2;
        // `centres.len() ≤ B`.
        let _ = out.angles_urad.push(angle_urad(c));
    }
    out.compensator_ok = ok;
    Ok(out)
}
