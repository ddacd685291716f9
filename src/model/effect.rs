//! The effect library's vocabulary (data contract §6) and the candidates a
//! device can test from a stream of deflections (`no_std`).
//!
//! The host's loop (`calibrate::effects::candidates`) lists, for a model,
//! every effect it lacks. A device that streams **deflections** (loaded −
//! unloaded position of a marker, eq. 3) carries per measurement the joint
//! angles, the load's torques and wrench, and optionally the time: from
//! those it computes the columns of every effect that acts on a deflection —
//! compensator (per-angle compliance), joint compliance, nonlinear stiffness,
//! backlash, link compliance, load centre of mass, drift. The geometric
//! effects (joint offset, joint frame, gear cyclic, marker, base) act on
//! absolute positions only (their deflection columns are zero) and need the
//! host's Gauss–Newton on the geometry: [`stream_candidates`] lists the
//! former, in the host's order and with the host's conditions, as bit masks
//! over one [`Layout`] that holds the model's columns first and then every
//! candidate's ([`crate::estimate::screen::Augmented`] accumulates them in
//! one pass).

use nalgebra::RealField;

use super::layout::Layout;
use super::param::{angle_urad, Param, BIN_TOLERANCE_RAD};
use crate::robot::{Chain, JointKind};
use crate::Error;

/// An effect of the library (data contract §6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Effect {
    /// A joint's compliance varies with that joint's angle (gravity
    /// compensator): one compliance per angle.
    Compensator,
    /// A joint compliance that the declared model left out.
    JointCompliance,
    /// A joint's deflection is not linear in its torque (`τ|τ|`).
    NonlinearStiffness,
    /// A joint deflects by a constant angle in the direction of its torque.
    Backlash,
    /// A link bends under the load.
    LinkCompliance,
    /// The load acts at another point than the declared one.
    LoadCom,
    /// The measurement drifts with time (needs `t`).
    Drift,
    /// A joint's zero is off.
    JointOffset,
    /// A joint frame's position or orientation is off.
    Geometry,
    /// A joint has a periodic error over its angle (first harmonic).
    GearCyclic,
    /// A marker sits elsewhere than declared.
    Marker,
    /// The base is placed or turned elsewhere than declared.
    BaseFrame,
}

impl Effect {
    /// Every effect, in the contract's order.
    pub const ALL: [Effect; 12] = [
        Effect::Compensator,
        Effect::JointCompliance,
        Effect::NonlinearStiffness,
        Effect::Backlash,
        Effect::LinkCompliance,
        Effect::LoadCom,
        Effect::Drift,
        Effect::JointOffset,
        Effect::Geometry,
        Effect::GearCyclic,
        Effect::Marker,
        Effect::BaseFrame,
    ];

    /// Its name in the data contract (§6).
    pub fn name(self) -> &'static str {
        match self {
            Effect::Compensator => "compensator",
            Effect::JointCompliance => "joint_compliance",
            Effect::NonlinearStiffness => "nonlinear_stiffness",
            Effect::Backlash => "backlash",
            Effect::LinkCompliance => "link_compliance",
            Effect::LoadCom => "load_com",
            Effect::Drift => "drift",
            Effect::JointOffset => "joint_offset",
            Effect::Geometry => "geometry",
            Effect::GearCyclic => "gear_cyclic",
            Effect::Marker => "marker",
            Effect::BaseFrame => "base_frame",
        }
    }

    /// Whether the effect is traced along a joint's angle (its plot's
    /// variable), rather than along a torque, the load or the time.
    pub fn follows_angle(self) -> bool {
        matches!(
            self,
            Effect::Compensator | Effect::JointOffset | Effect::GearCyclic | Effect::Geometry
        )
    }
}

impl core::fmt::Display for Effect {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// One candidate of a stream: the effect, its joint, and its parameters as
/// bit masks over the columns of the augmented [`Layout`] (bit `i` =
/// column `i`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StreamCandidate {
    /// The effect.
    pub effect: Effect,
    /// Joint index, for per-joint effects.
    pub joint: Option<u8>,
    /// Columns whose significance is tested.
    pub test: u64,
    /// Columns the model loses when the effect is accepted (a constant
    /// compliance replaced by its angle bins).
    pub remove: u64,
    /// Columns the model gains.
    pub add: u64,
}

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

/// The column of `p` in `layout`, pushed if it is not there; its bit.
fn bit<T: RealField + Copy, const J: usize, const P: usize>(
    layout: &mut Layout<P>,
    chain: &Chain<T, J>,
    p: Param,
) -> Result<u64, Error> {
    let i = match layout.index_of(&p) {
        Some(i) => i,
        None => layout.push(chain, p)?,
    };
    if i >= 64 {
        return Err(Error::CapacityExceeded {
            what: "candidate columns (bit masks)",
            capacity: 64,
        });
    }
    Ok(1u64 << i)
}

/// Every effect of a stream of deflections that `model` lacks, in the
/// host's order and under the host's conditions (`calibrate::effects::
/// candidates` with deflection rows, no absolute rows, a time column when
/// `time`), and the augmented layout: `model` first (columns `0..n`), then
/// every candidate's parameters. `bins[j]` are joint `j`'s angle bins
/// ([`joint_bins`]).
///
/// # Errors
/// [`Error::CapacityExceeded`] when the layout (`P`, at most 64) or the
/// list (`K`) is full; [`Error::Mismatch`] for a parameter twice in `model`
/// or fewer bins than joints; as [`Layout::push`].
pub fn stream_candidates<
    T: RealField + Copy,
    const J: usize,
    const P: usize,
    const K: usize,
    const B: usize,
>(
    chain: &Chain<T, J>,
    model: &[Param],
    bins: &[JointBins<B>],
    time: bool,
) -> Result<(Layout<P>, heapless::Vec<StreamCandidate, K>), Error> {
    let dof = chain.dof();
    if bins.len() < dof {
        return Err(Error::Mismatch {
            what: "one set of angle bins per joint",
        });
    }
    let mut layout = Layout::<P>::new();
    for p in model {
        layout.push(chain, *p)?;
    }
    let has = |p: &Param| model.contains(p);
    let any = |f: &dyn Fn(&Param) -> bool| model.iter().any(f);
    let mut out: heapless::Vec<StreamCandidate, K> = heapless::Vec::new();
    let mut add = |c: StreamCandidate| {
        out.push(c).map_err(|_| Error::CapacityExceeded {
            what: "candidates",
            capacity: K,
        })
    };
    let any_compliance = any(&|p| p.is_compliance());
    for j in 0..dof {
        let joint = j as u8;
        let k = Param::Compliance { joint };
        let binned = any(&|p| matches!(p, Param::ComplianceAt { joint: i, .. } if *i == joint));
        let compliant = has(&k) || binned;
        let jb = &bins[j];
        if !binned && jb.compensator_ok {
            let (mut test, mut all) = (0u64, 0u64);
            for (b, &angle_urad) in jb.angles_urad.iter().enumerate() {
                let m = bit(
                    &mut layout,
                    chain,
                    Param::ComplianceAt { joint, angle_urad },
                )?;
                all |= m;
                // With a constant k in the model the bins minus one are
                // tested (k stays); on acceptance k is replaced by the bins.
                if !(has(&k) && b == 0) {
                    test |= m;
                }
            }
            let remove = if has(&k) {
                bit(&mut layout, chain, k)?
            } else {
                0
            };
            add(StreamCandidate {
                effect: Effect::Compensator,
                joint: Some(joint),
                test,
                remove,
                add: all,
            })?;
        }
        let mut single = |effect, p: Param, layout: &mut Layout<P>| -> Result<(), Error> {
            let m = bit(layout, chain, p)?;
            add(StreamCandidate {
                effect,
                joint: Some(joint),
                test: m,
                remove: 0,
                add: m,
            })
        };
        if !compliant {
            single(Effect::JointCompliance, k, &mut layout)?;
        }
        let p = Param::NonlinearStiffness { joint };
        if compliant && !has(&p) {
            single(Effect::NonlinearStiffness, p, &mut layout)?;
        }
        let p = Param::Backlash { joint };
        if !has(&p) {
            single(Effect::Backlash, p, &mut layout)?;
        }
        let p = Param::LinkCompliance { joint };
        let revolute = chain.joints().get(j).map(|jt| jt.kind) == Some(JointKind::Revolute);
        if revolute && !has(&p) {
            single(Effect::LinkCompliance, p, &mut layout)?;
        }
    }
    let mut triple = |effect, ps: [Param; 3], layout: &mut Layout<P>| -> Result<(), Error> {
        let mut m = 0;
        for p in ps {
            m |= bit(layout, chain, p)?;
        }
        add(StreamCandidate {
            effect,
            joint: None,
            test: m,
            remove: 0,
            add: m,
        })
    };
    if any_compliance && !any(&|p| matches!(p, Param::LoadCom { .. })) {
        triple(
            Effect::LoadCom,
            [0, 1, 2].map(|axis| Param::LoadCom { axis }),
            &mut layout,
        )?;
    }
    if time && !any(&|p| matches!(p, Param::Drift { .. })) {
        triple(
            Effect::Drift,
            [0, 1, 2].map(|axis| Param::Drift { axis }),
            &mut layout,
        )?;
    }
    Ok((layout, out))
}

/// The first of `added` whose estimate is not physical (the host's
/// `calibrate::effects::inadmissible`, for the effects of a stream): a
/// compliance or a backlash below zero, or a drift of more than
/// `max_drift_mm_per_h` (norm over x, y, z; the estimate in µm/s). `x[i]`
/// is the estimate of `params[i]` in its reported unit.
pub fn inadmissible<'a>(
    params: &[Param],
    x: &[f64],
    added: impl IntoIterator<Item = &'a Param>,
    max_drift_mm_per_h: f64,
) -> Option<Param> {
    let value = |p: &Param| {
        params
            .iter()
            .position(|u| u == p)
            .and_then(|i| x.get(i).copied())
    };
    for p in added {
        let Some(v) = value(p) else { continue };
        let bad = match *p {
            Param::Compliance { .. } | Param::ComplianceAt { .. } | Param::Backlash { .. } => {
                v < 0.0
            }
            Param::Drift { axis: 0 } => {
                // |v| · 3.6 > limit, squared (µm/s → mm/h): no square root.
                let norm2: f64 = (0..3)
                    .map(|axis| {
                        let d = value(&Param::Drift { axis }).unwrap_or(0.0);
                        d * d
                    })
                    .sum();
                norm2 * 3.6 * 3.6 > max_drift_mm_per_h * max_drift_mm_per_h
            }
            _ => false,
        };
        if bad {
            return Some(*p);
        }
    }
    None
}
