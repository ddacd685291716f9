//! The effect library's vocabulary (data contract §6), its rule, and the
//! candidates a device can test from a stream of deflections (`no_std`).
//!
//! The rule, [`candidates`], exists once: for a model and what the data
//! carry ([`DataKinds`]), every effect the model lacks, the parameters it
//! tests, removes and adds, in one order. The host's loop
//! (`calibrate::effects::candidates`) turns them into owned lists with
//! joint and marker names; a device, [`stream_candidates`].
//!
//! A device that streams **deflections** (loaded − unloaded position of a
//! marker, eq. 3) carries per measurement the joint angles, the load's
//! torques and wrench, and optionally the time: from those it computes the
//! columns of every effect that acts on a deflection — compensator
//! (per-angle compliance), joint compliance, nonlinear stiffness, backlash,
//! link compliance, load centre of mass, drift. The geometric effects
//! (joint offset, joint frame, gear cyclic, marker, base) and the bending
//! under the robot's own weight (gravity compliance) act on absolute
//! positions only (their deflection columns are zero) and need the host's
//! Gauss–Newton on the geometry: with no absolute rows the rule lists none
//! of them. [`stream_candidates`] gives the rule's candidates as bit masks
//! over one [`Layout`] that holds the model's columns first and then every
//! candidate's ([`crate::estimate::screen::Augmented`] accumulates them in
//! one pass).

use nalgebra::RealField;

pub use super::bins::{joint_bins, JointBins, MAX_CONFIGS};
use super::layout::Layout;
use super::param::Param;
use crate::error::Error;
use crate::robot::{Chain, JointKind};

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
    /// A joint bends under the robot's own weight, the masses unknown
    /// (lumped gravity compliance, `Param::GravityCompliance`; host only,
    /// `std`).
    #[cfg(feature = "std")]
    GravityCompliance,
    /// A joint's moving body weighs other than the mass model says
    /// (`Param::LinkMass`, seen through the compliances it loads; host
    /// only, `std`).
    #[cfg(feature = "std")]
    LinkMass,
    /// The links expand with the temperature (`Param::ThermalExpansion`;
    /// needs the setup's temperature column; host only, `std`).
    #[cfg(feature = "std")]
    ThermalExpansion,
    /// A marker sits elsewhere than declared.
    Marker,
    /// The base is placed or turned elsewhere than declared.
    BaseFrame,
}

impl Effect {
    /// Every effect, in the contract's order.
    #[cfg(feature = "std")]
    pub const ALL: [Effect; 15] = [
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
        Effect::GravityCompliance,
        Effect::LinkMass,
        Effect::ThermalExpansion,
        Effect::Marker,
        Effect::BaseFrame,
    ];

    /// Every effect, in the contract's order (without `std`, no gravity
    /// compliance).
    #[cfg(not(feature = "std"))]
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
            #[cfg(feature = "std")]
            Effect::GravityCompliance => "gravity_compliance",
            #[cfg(feature = "std")]
            Effect::LinkMass => "link_mass",
            #[cfg(feature = "std")]
            Effect::ThermalExpansion => "thermal_expansion",
            Effect::Marker => "marker",
            Effect::BaseFrame => "base_frame",
        }
    }

    /// Whether the effect is traced along a joint's angle (its plot's
    /// variable), rather than along a torque, the load or the time.
    pub fn follows_angle(self) -> bool {
        #[cfg(feature = "std")]
        if self == Effect::GravityCompliance {
            return true;
        }
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

/// Which kinds of rows a data set has (what it can show).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DataKinds {
    /// Deflection rows (a load).
    pub deflections: bool,
    /// Absolute rows (geometric calibration).
    pub absolute: bool,
    /// A time column.
    pub time: bool,
    /// Absolute rows of a robot with a mass model: its own weight loads
    /// and bends its links. Host only (`std`).
    #[cfg(feature = "std")]
    pub own_weight: bool,
    /// A temperature column (`[model] temperature_column`): the links'
    /// thermal expansion can be traced. Host only (`std`).
    #[cfg(feature = "std")]
    pub temperature: bool,
}

/// The parameters a [`Candidate`] adds to the model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Params<'a> {
    /// One compliance per angle bin of `joint` (`k_<joint>@<angle>`).
    Bins {
        /// The joint.
        joint: u8,
        /// Its bins \[µrad\].
        angles_urad: &'a [i32],
    },
    /// The first `len` of `list`.
    List {
        /// The parameters (padded with the first).
        list: [Param; 6],
        /// How many.
        len: u8,
    },
}

impl Params<'_> {
    fn of(ps: &[Param]) -> Self {
        let mut list = [ps[0]; 6];
        list[..ps.len()].copy_from_slice(ps);
        Params::List {
            list,
            len: ps.len() as u8,
        }
    }

    /// How many parameters.
    pub fn len(&self) -> usize {
        match self {
            Params::Bins { angles_urad, .. } => angles_urad.len(),
            Params::List { len, .. } => usize::from(*len),
        }
    }

    /// Whether there is none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The `i`-th parameter.
    pub fn get(&self, i: usize) -> Option<Param> {
        match self {
            Params::Bins { joint, angles_urad } => {
                angles_urad.get(i).map(|&angle_urad| Param::ComplianceAt {
                    joint: *joint,
                    angle_urad,
                })
            }
            Params::List { list, len } => list[..usize::from(*len)].get(i).copied(),
        }
    }

    /// The parameters, in order.
    pub fn iter(&self) -> impl Iterator<Item = Param> + '_ {
        (0..self.len()).filter_map(|i| self.get(i))
    }
}

/// One candidate extension of a model ([`candidates`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate<'a> {
    /// The effect.
    pub effect: Effect,
    /// Joint index, for per-joint effects.
    pub joint: Option<u8>,
    /// Marker index, for [`Effect::Marker`].
    pub marker: Option<u8>,
    /// Parameters the model gains when the effect is accepted.
    pub add: Params<'a>,
    /// How many of `add`'s first parameters are not tested: 1 for a
    /// compensator on a joint whose constant compliance is in the model
    /// (the constant stays during the test, so the bins minus one are
    /// tested), else 0.
    pub untested: usize,
    /// The parameter the model loses when the effect is accepted (the
    /// constant compliance a compensator replaces).
    pub remove: Option<Param>,
}

impl Candidate<'_> {
    /// Parameters whose significance is tested (added to the model as it
    /// is).
    pub fn test(&self) -> impl Iterator<Item = Param> + '_ {
        self.add.iter().skip(self.untested)
    }
}

/// The effect library's rule (data contract §6), the one both the host's
/// loop (`calibrate::effects::candidates`) and a device's
/// ([`stream_candidates`]) are built on: every effect `model` lacks that the
/// data can show, in this order, each passed to `emit`:
///
/// per joint `j` (`dof` joints; `revolute(j)` its kind), with deflection or
/// absolute rows:
/// 1. `compensator`, when the joint has no angle bins in the model and
///    `bins(j)` gives its bins (`Some` when they make a compensator
///    candidate): one compliance per bin; with a constant `k_j` in the
///    model the bins minus one are tested and `k_j` is removed on
///    acceptance;
/// 2. `joint_compliance` (`k_j`), when the joint has no compliance;
/// 3. `nonlinear_stiffness`, when it has one;
/// 4. `backlash`;
///
/// with deflection rows, or (host only, `std`) absolute rows of a robot
/// with a mass model (`own_weight`), for a revolute joint:
/// 5. `link_compliance`;
///
/// with absolute rows:
/// 6. `joint_offset`, when the joint has neither an offset nor a frame
///    error;
/// 7. `geometry` (six frame errors), when it has no frame error and is not
///    the first joint (whose frame error is, to first order, the base's:
///    `base_frame`);
/// 8. `gear_cyclic` (sine, cosine), for a revolute joint;
/// 9. `gravity_compliance` (`a`, `b`; host only, `std`), for a revolute
///    joint without a compliance (with one, the robot's weight already
///    loads it through the URDF's masses): after `gear_cyclic`, which it
///    equals on a horizontal joint whose gravity direction only its own
///    angle turns;
/// 10. `link_mass` (host only, `std`), with absolute rows of a robot with
///    a mass model (`own_weight`) and a compliance or a link's bending in
///    the model (a mass is seen only through what it bends);
///
/// then, for the model:
/// 11. `load_com`, with deflection rows and a compliance in the model (the
///    load's position only moves a deflection through a compliance);
/// 12. `drift`, with a time column;
/// 13. `thermal_expansion` (host only, `std`), with a temperature column;
/// 14. `marker` for each of the `markers` markers, with absolute rows;
/// 15. `base_frame`, with absolute rows.
///
/// An effect already in the model (any of its parameters) is not a
/// candidate. `emit`'s first error ends the list and is returned.
///
/// # Errors
/// `emit`'s.
pub fn candidates<'b, E>(
    model: &[Param],
    dof: usize,
    revolute: impl Fn(usize) -> bool,
    markers: u8,
    data: DataKinds,
    bins: impl Fn(usize) -> Option<&'b [i32]>,
    mut emit: impl FnMut(Candidate<'b>) -> Result<(), E>,
) -> Result<(), E> {
    let has = |p: &Param| model.contains(p);
    let any = |f: &dyn Fn(&Param) -> bool| model.iter().any(f);
    let one = |effect, joint, ps: &[Param]| Candidate {
        effect,
        joint,
        marker: None,
        add: Params::of(ps),
        untested: 0,
        remove: None,
    };
    let any_compliance = any(&|p| p.is_compliance());
    // Whether the robot's own weight bends the model (a mass is seen only
    // through what it bends).
    #[cfg(feature = "std")]
    let bending_model = any_compliance || any(&|p| matches!(p, Param::LinkCompliance { .. }));
    for j in 0..dof {
        let joint = j as u8;
        let on = Some(joint);
        let k = Param::Compliance { joint };
        let binned = any(&|p| matches!(p, Param::ComplianceAt { joint: i, .. } if *i == joint));
        let compliant = has(&k) || binned;
        if data.deflections || data.absolute {
            if let Some(angles_urad) = bins(j).filter(|_| !binned) {
                emit(Candidate {
                    effect: Effect::Compensator,
                    joint: on,
                    marker: None,
                    add: Params::Bins { joint, angles_urad },
                    untested: usize::from(has(&k)),
                    remove: has(&k).then_some(k),
                })?;
            }
            if !compliant {
                emit(one(Effect::JointCompliance, on, &[k]))?;
            }
            let p = Param::NonlinearStiffness { joint };
            if compliant && !has(&p) {
                emit(one(Effect::NonlinearStiffness, on, &[p]))?;
            }
            let p = Param::Backlash { joint };
            if !has(&p) {
                emit(one(Effect::Backlash, on, &[p]))?;
            }
        }
        let p = Param::LinkCompliance { joint };
        #[cfg(feature = "std")]
        let bends = data.deflections || data.own_weight;
        #[cfg(not(feature = "std"))]
        let bends = data.deflections;
        if bends && revolute(j) && !has(&p) {
            emit(one(Effect::LinkCompliance, on, &[p]))?;
        }
        if data.absolute {
            let p = Param::JointOffset { joint };
            let frame = any(&|p| matches!(p, Param::JointFrame { joint: i, .. } if *i == joint));
            if !has(&p) && !frame {
                emit(one(Effect::JointOffset, on, &[p]))?;
            }
            if !frame && j > 0 {
                let ps = [0, 1, 2, 3, 4, 5].map(|axis| Param::JointFrame { joint, axis });
                emit(one(Effect::Geometry, on, &ps))?;
            }
            if revolute(j) && !has(&Param::GearCyclic { joint, cos: false }) {
                let ps = [false, true].map(|cos| Param::GearCyclic { joint, cos });
                emit(one(Effect::GearCyclic, on, &ps))?;
            }
            #[cfg(feature = "std")]
            if revolute(j) && !compliant && !has(&Param::GravityCompliance { joint, b: false }) {
                let ps = [false, true].map(|b| Param::GravityCompliance { joint, b });
                emit(one(Effect::GravityCompliance, on, &ps))?;
            }
        }
        #[cfg(feature = "std")]
        if data.own_weight && bending_model && !has(&Param::LinkMass { joint }) {
            emit(one(Effect::LinkMass, on, &[Param::LinkMass { joint }]))?;
        }
    }
    if data.deflections && any_compliance && !any(&|p| matches!(p, Param::LoadCom { .. })) {
        let ps = [0, 1, 2].map(|axis| Param::LoadCom { axis });
        emit(one(Effect::LoadCom, None, &ps))?;
    }
    if data.time && !any(&|p| matches!(p, Param::Drift { .. })) {
        let ps = [0, 1, 2].map(|axis| Param::Drift { axis });
        emit(one(Effect::Drift, None, &ps))?;
    }
    #[cfg(feature = "std")]
    if data.temperature && !has(&Param::ThermalExpansion) {
        emit(one(
            Effect::ThermalExpansion,
            None,
            &[Param::ThermalExpansion],
        ))?;
    }
    if data.absolute {
        for m in 0..markers {
            if !any(&|p| matches!(p, Param::Marker { marker, .. } if *marker == m)) {
                let ps = [0, 1, 2].map(|axis| Param::Marker { marker: m, axis });
                emit(Candidate {
                    marker: Some(m),
                    ..one(Effect::Marker, None, &ps)
                })?;
            }
        }
        if !any(&|p| matches!(p, Param::Base { .. })) {
            let ps = [0, 1, 2, 3, 4, 5].map(|axis| Param::Base { axis });
            emit(one(Effect::BaseFrame, None, &ps))?;
        }
    }
    Ok(())
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

/// Every effect of a stream of deflections that `model` lacks: the rule
/// [`candidates`] with deflection rows, no absolute rows and a time column
/// when `time` (what the host's loop lists for the same data), as bit masks
/// over the augmented layout: `model` first (columns `0..n`), then every
/// candidate's parameters in the order the candidates add them. `bins[j]`
/// are joint `j`'s angle bins ([`joint_bins`]).
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
    let mut out: heapless::Vec<StreamCandidate, K> = heapless::Vec::new();
    let data = DataKinds {
        deflections: true,
        absolute: false,
        time,
        #[cfg(feature = "std")]
        own_weight: false,
        #[cfg(feature = "std")]
        temperature: false,
    };
    let revolute = |j: usize| chain.joints().get(j).map(|jt| jt.kind) == Some(JointKind::Revolute);
    let compensator = |j: usize| bins[j].compensator_ok.then_some(&bins[j].angles_urad[..]);
    candidates(model, dof, revolute, 0, data, compensator, |c| {
        let (mut test, mut add) = (0u64, 0u64);
        for i in 0..c.add.len() {
            let m = match c.add.get(i) {
                Some(p) => bit(&mut layout, chain, p)?,
                None => 0,
            };
            add |= m;
            if i >= c.untested {
                test |= m;
            }
        }
        let remove = match c.remove {
            Some(p) => bit(&mut layout, chain, p)?,
            None => 0,
        };
        out.push(StreamCandidate {
            effect: c.effect,
            joint: c.joint,
            test,
            remove,
            add,
        })
        .map_err(|_| Error::CapacityExceeded {
            what: "candidates",
            capacity: K,
        })
    })?;
    Ok((layout, out))
}

/// Why an estimate is not physical ([`unphysical`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Unphysical {
    /// A compliance or a backlash below zero: its value.
    Negative(f64),
    /// A drift faster than the limit: its norm \[mm/h\].
    Drift(f64),
}

/// Whether the estimate of `p` is physical, the rule for the effects a
/// stream of deflections can add (the host adds the gear cyclic limit,
/// `calibrate::effects::inadmissible`). Physics, not tuning:
/// - a compliance (`k_<joint>`, `k_<joint>@<angle>`) is ≥ 0: a joint
///   yields in the direction of its torque;
/// - a backlash (`δq = b · sign τ`) is ≥ 0: the joint rests on the side of
///   its play that its torque pushes it to;
/// - a drift (judged at its x component, over x, y, z; estimated in µm/s)
///   is at most `max_drift_mm_per_h`.
///
/// `value(q)` is the estimate of `q` in its reported unit, `None` when `q`
/// is not estimated (then `p` is not judged).
pub fn unphysical(
    p: &Param,
    value: impl Fn(&Param) -> Option<f64>,
    max_drift_mm_per_h: f64,
) -> Option<Unphysical> {
    let v = value(p)?;
    match *p {
        Param::Compliance { .. } | Param::ComplianceAt { .. } | Param::Backlash { .. } => {
            (v < 0.0).then_some(Unphysical::Negative(v))
        }
        Param::Drift { axis: 0 } => {
            let norm2: f64 = (0..3)
                .map(|axis| {
                    let d = value(&Param::Drift { axis }).unwrap_or(0.0);
                    d * d
                })
                .sum();
            // µm/s → mm/h.
            let norm = libm::sqrt(norm2) * 3.6;
            (norm > max_drift_mm_per_h).then_some(Unphysical::Drift(norm))
        }
        _ => None,
    }
}

/// The first of `added` whose estimate is not physical ([`unphysical`]).
/// `x[i]` is the estimate of `params[i]` in its reported unit.
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
    added
        .into_iter()
        .find(|p| unphysical(p, value, max_drift_mm_per_h).is_some())
        .copied()
}
