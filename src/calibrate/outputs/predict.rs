//! The calibrated model applied: where a marker (or any tool point) is for
//! given joint values and payload, and the joint command that puts it at a
//! desired point ([`crate::robot::compensate()`]).
//!
//! A [`Predictor`] holds the final geometry of a calibration (its last
//! Gauss–Newton step applied, as in the calibrated URDF), the base placed
//! in the measurement frame, and the calibrated joint law. A prediction is
//! the exact static equilibrium ([`crate::robot::equilibrium()`]) of the
//! robot commanded to `q` under its own weight (the URDF's link masses) and
//! the payload, whichever deflection model fitted the compliances, with
//! every joint-law term the calibration found (compliances, compensator
//! tables interpolated between their angles, nonlinear stiffness,
//! backlash, the gear's cyclic error, the gravity compliance at the
//! commanded pose) and, to first order as it was fitted, a link's bending
//! under the payload and its own weight
//! ([`crate::model::Param::LinkCompliance`]). Not
//! applied: the drift of the measurement system and the calibration tool's
//! centre-of-mass estimate (properties of the calibration, not of the
//! robot). With the links' thermal expansion, the lengths are the
//! calibration's mean temperature's; [`Predictor::at_temperature`] gives
//! the robot at another. All positions are in metres in the measurement frame; joint
//! values in rad (or m); [`payload`] says when a payload is extrapolated.
//!
//! [`Predictor::predict_covariance`] propagates the calibration's
//! covariance (eq. 8 / 11) to a prediction, `Σₚ = B Σ Bᵀ` with `B = ∂p/∂x`
//! by central differences of the predictor itself (steps of 1 % of each
//! parameter's σ): the error floor a compensation cannot go below.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use crate::calibrate::params::geometry::J;
use crate::calibrate::params::linearisation::Linearisation;
use crate::calibrate::report::calibrated::CalibratedModel;
use crate::calibrate::settings::CalibrationError;
use crate::error::Error;
use crate::io::job::Job;
use crate::model::{Param, Sample};
use crate::robot::{
    compensate, compensate_pose, equilibrium, Chain, CompensateSettings, Compensation, Equilibrium,
    EquilibriumSettings, Loading, PointLoad,
};
pub mod payload;

/// A mass carried by the tool.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Payload {
    /// Mass \[kg\], ≥ 0.
    pub mass_kg: f64,
    /// Centre of mass \[m, tip frame\].
    pub com_m: Vector3<f64>,
}

/// A marker to predict at a command: which marker, the joint values, the
/// payload; its line in a file, for errors.
#[derive(Debug, Clone, PartialEq)]
pub struct Pose {
    /// Its line in the file (the header is line 1).
    pub line: usize,
    /// Marker id.
    pub marker: u32,
    /// Joint values \[rad or m\], chain order.
    pub q: Vec<f64>,
    /// The payload, if loaded.
    pub payload: Option<Payload>,
}

/// The calibrated robot, ready to predict and compensate (see the
/// [module docs](self)).
#[derive(Debug, Clone)]
pub struct Predictor {
    chain: Chain<f64, J>,
    /// A tree's other chains (data contract 7.1): the chain ending at each
    /// other link markers are on, placed. Empty for a serial robot.
    branches: Vec<Chain<f64, J>>,
    /// Each marker's end: 0 for `chain`'s tip, `k` for `branches[k - 1]`.
    marker_ends: Vec<usize>,
    markers: Vec<Vector3<f64>>,
    marker_ids: Vec<u32>,
    gravity_mps2: Vector3<f64>,
    lin: Linearisation,
    /// `(Param::LinkCompliance, estimate)`: applied to first order.
    bending: Vec<(Param, f64)>,
    /// The fitted shift of the calibration load's centre of mass \[m, tip frame\].
    load_com_shift_m: Vector3<f64>,
    joint_names: Vec<String>,
    /// The calibration and its gravity \[m/s², robot base frame\], for
    /// [`Self::predict_covariance`] (absent when read from a model file).
    calibration: Option<(Box<CalibratedModel>, Vector3<f64>)>,
    /// The heaviest payload of the calibration \[kg\] ([`payload`]).
    heaviest_payload_kg: Option<f64>,
    /// The links' thermal expansion ([`Param::ThermalExpansion`]): `α`
    /// \[1/K\] and the temperature \[°C\] this predictor's lengths hold
    /// at.
    thermal: Option<(f64, f64)>,
    /// Whether the links bend under the robot's own weight too, as the
    /// calibration fitted them (absolute rows of a robot with a mass
    /// model), not under the payload alone: `false` for a model file
    /// written before (its geometry absorbed that bending).
    bending_own_weight: bool,
    /// The identified tool frame's rotation ([`Geometry::tool_rotation`]):
    /// a pose's measured frame is the marker's link frame turned by it
    /// (identity for a model file, which does not hold it).
    ///
    /// [`Geometry::tool_rotation`]: crate::calibrate::params::geometry::Geometry::tool_rotation
    tool_rotation: nalgebra::Rotation3<f64>,
}

/// The equilibrium settings of a prediction (the rows' own).
const EQUILIBRIUM: EquilibriumSettings<f64> = EquilibriumSettings {
    tolerance: 1e-13,
    max_iterations: 50,
};

impl Predictor {
    /// The calibrated robot of `model`, for the robot and setup of `job`
    /// (its gravity, given in the robot's base frame).
    pub fn new(model: &CalibratedModel, job: &Job) -> Self {
        let gravity = job
            .setup
            .load
            .map_or(Vector3::new(0.0, 0.0, -9.80665), |l| {
                Vector3::from(l.gravity)
            });
        Self::at(model, gravity, &model.x)
    }

    /// The predictor of `model` with estimate `x` instead of its own.
    fn at(model: &CalibratedModel, gravity_mps2: Vector3<f64>, x: &[f64]) -> Self {
        let mut g = model.geometry.clone();
        g.apply(&model.params, x);
        Self {
            chain: g.placed_chain(),
            branches: g.placed_chains().into_iter().skip(1).collect(),
            marker_ends: g.marker_ends.clone(),
            markers: g.markers.clone(),
            marker_ids: (0..g.markers.len())
                .map(|m| model.names.marker_id(m as u8))
                .collect(),
            gravity_mps2: g.base.rotation * gravity_mps2,
            lin: Linearisation::of(model.linearisation.model, &model.params, x, &model.names),
            bending: model
                .params
                .iter()
                .zip(x)
                .filter(|(p, _)| matches!(p, Param::LinkCompliance { .. }))
                .map(|(p, v)| (*p, *v))
                .collect(),
            load_com_shift_m: model
                .params
                .iter()
                .zip(x)
                .filter_map(|(p, v)| match *p {
                    Param::LoadCom { axis } => {
                        Some(Vector3::ith(usize::from(axis), v * model.names.unit(p).si))
                    }
                    _ => None,
                })
                .sum(),
            joint_names: model.names.joints.clone(),
            calibration: Some((Box::new(model.clone()), gravity_mps2)),
            heaviest_payload_kg: Some(model.heaviest_payload_kg),
            thermal: (model.params.iter().zip(x))
                .find(|(p, _)| matches!(p, Param::ThermalExpansion))
                .zip(model.temperature_ref_c)
                .map(|((p, v), t)| (v * model.names.unit(p).si, t)),
            bending_own_weight: true,
            tool_rotation: g.tool_rotation.to_rotation_matrix(),
        }
    }

    /// A predictor from its parts (a model file): the chain placed in the
    /// measurement frame, marker ids and positions \[m, tip frame\], gravity
    /// \[m/s², measurement frame\], the joint law, the link bending
    /// parameters with their estimates (reported units), the load's
    /// centre-of-mass shift \[m\] and the joint names.
    #[allow(clippy::too_many_arguments)]
    pub fn from_parts(
        chain: Chain<f64, J>,
        markers: Vec<(u32, Vector3<f64>)>,
        gravity_mps2: Vector3<f64>,
        lin: Linearisation,
        bending: Vec<(Param, f64)>,
        load_com_shift_m: Vector3<f64>,
        joint_names: Vec<String>,
    ) -> Self {
        Self {
            branches: Vec::new(),
            marker_ends: vec![0; markers.len()],
            chain,
            marker_ids: markers.iter().map(|m| m.0).collect(),
            markers: markers.iter().map(|m| m.1).collect(),
            gravity_mps2,
            lin,
            bending,
            load_com_shift_m,
            joint_names,
            calibration: None,
            heaviest_payload_kg: None,
            thermal: None,
            bending_own_weight: true,
            tool_rotation: nalgebra::Rotation3::identity(),
        }
    }

    /// This predictor with the links bending under the payload alone
    /// (`false`: a model file written before the calibration fitted their
    /// bending under the robot's own weight) or under the robot's own
    /// weight too (`true`, the default).
    pub fn with_bending_own_weight(mut self, own_weight: bool) -> Self {
        self.bending_own_weight = own_weight;
        self
    }

    /// Whether the links bend under the robot's own weight too
    /// ([`Self::with_bending_own_weight`]).
    pub fn bending_own_weight(&self) -> bool {
        self.bending_own_weight
    }

    /// Whether the model's links bend where no payload is: a bending
    /// under the robot's own weight, and a link with a mass.
    fn bends_unloaded(&self) -> bool {
        !self.bending.is_empty()
            && self.bending_own_weight
            && self.chain.joints().iter().any(|j| j.link.is_some())
    }

    /// This predictor with the links' thermal expansion `α` \[1/K\] about
    /// `reference_c` \[°C\], the temperature its lengths hold at (a model
    /// file's `thermal_expansion`).
    pub fn with_thermal_expansion(mut self, alpha_per_k: f64, reference_c: f64) -> Self {
        self.thermal = Some((alpha_per_k, reference_c));
        self
    }

    /// The links' thermal expansion `(α [1/K], the temperature [°C] the
    /// lengths hold at)`, when the calibration identified one.
    pub fn thermal_expansion(&self) -> Option<(f64, f64)> {
        self.thermal
    }

    /// The robot at `temp_c` \[°C\]: every length from the first joint's
    /// origin `o₁` out (the joints' offsets, the tips, the markers, the
    /// links' centres of mass) stretched by `1 + α (T − T_ref)`
    /// ([`Param::ThermalExpansion`]), so every point on it moves to
    /// `o₁ + (1 + α ΔT)(p − o₁)`. Tool points given to [`Self::predict`]
    /// or [`Self::compensate`] are taken as given. Its
    /// [`Self::predict_covariance`] is not available (the calibration's
    /// covariance is at `T_ref`).
    ///
    /// # Errors
    /// [`CalibrationError::Data`] when the model has no thermal expansion
    /// or `temp_c` is not a temperature from −50 to 150 °C.
    pub fn at_temperature(&self, temp_c: f64) -> Result<Self, CalibrationError> {
        let (alpha, reference) = self.thermal.ok_or_else(|| {
            CalibrationError::Data(
                "the model has no thermal_expansion (a calibration with a temperature_column \
                 identifies one)"
                    .into(),
            )
        })?;
        let range = crate::io::units::MIN_TEMPERATURE_C..=crate::io::units::MAX_TEMPERATURE_C;
        if !range.contains(&temp_c) {
            return Err(CalibrationError::Data(format!(
                "temperature {temp_c} degC is outside [{}, {}] degC",
                range.start(),
                range.end()
            )));
        }
        let s = 1.0 + alpha * (temp_c - reference);
        let stretch = |iso: &mut nalgebra::Isometry3<f64>| iso.translation.vector *= s;
        let mut chain = self.chain.clone();
        let o1 = chain
            .joints()
            .first()
            .map_or(Vector3::zeros(), |j| j.origin.translation.vector);
        for j in 0..chain.dof() {
            let parent = chain.parent(j);
            let joint = &mut chain.joints_mut()[j];
            match parent {
                Some(_) => stretch(&mut joint.origin),
                // Another root than the first (a tree): its origin from o₁.
                None if j > 0 => {
                    let t = &mut joint.origin.translation.vector;
                    *t = o1 + (*t - o1) * s;
                }
                None => {}
            }
            if let Some(link) = joint.link.as_mut() {
                link.com_m *= s;
            }
        }
        // An end on a joint is in that joint's frame; one fixed to the base
        // (a tree's, `joint: None`) is in the measurement frame, about o₁.
        let end_at = |joint: Option<usize>, iso: &mut nalgebra::Isometry3<f64>| match joint {
            Some(_) => stretch(iso),
            None => {
                let t = &mut iso.translation.vector;
                *t = o1 + (*t - o1) * s;
            }
        };
        let branches = self
            .branches
            .iter()
            .map(|b| {
                let mut end = b.tip_end();
                end_at(end.joint, &mut end.origin);
                chain.with_tip(&end)
            })
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| CalibrationError::Data(format!("thermal expansion: {e}")))?;
        let mut tip = *chain.tip();
        end_at(chain.tip_joint(), &mut tip);
        chain.set_tip(tip);
        Ok(Self {
            chain,
            branches,
            markers: self.markers.iter().map(|m| m * s).collect(),
            thermal: Some((alpha, temp_c)),
            ..self.without_calibration()
        })
    }

    /// This predictor without its calibration (no
    /// [`Self::predict_covariance`]): a cheap clone.
    pub fn without_calibration(&self) -> Self {
        Self {
            marker_ids: self.marker_ids.clone(),
            markers: self.markers.clone(),
            marker_ends: self.marker_ends.clone(),
            chain: self.chain.clone(),
            branches: self.branches.clone(),
            gravity_mps2: self.gravity_mps2,
            lin: self.lin.clone(),
            bending: self.bending.clone(),
            load_com_shift_m: self.load_com_shift_m,
            joint_names: self.joint_names.clone(),
            calibration: None,
            heaviest_payload_kg: self.heaviest_payload_kg,
            thermal: self.thermal,
            bending_own_weight: self.bending_own_weight,
            tool_rotation: self.tool_rotation,
        }
    }

    /// The chain, placed in the measurement frame.
    pub fn chain(&self) -> &Chain<f64, J> {
        &self.chain
    }

    /// Sets where each marker is (a tree, data contract 7.1): `ends` the
    /// chain's ends besides its tip's (placed in the measurement frame, as
    /// the chain is), `marker_ends[m]` marker `m`'s end (0: the tip, `k`:
    /// `ends[k - 1]`).
    ///
    /// # Errors
    /// [`Error::OutOfRange`] for an end the chain does not have or a marker
    /// end past `ends`; [`Error::Mismatch`] for one end per marker missing.
    pub fn with_ends(
        mut self,
        ends: &[crate::robot::End<f64>],
        marker_ends: Vec<usize>,
    ) -> Result<Self, Error> {
        if marker_ends.len() != self.markers.len() {
            return Err(Error::Mismatch {
                what: "one end per marker",
            });
        }
        if let Some(&k) = marker_ends.iter().find(|&&k| k > ends.len()) {
            return Err(Error::OutOfRange {
                what: "marker end",
                index: k,
                len: ends.len() + 1,
            });
        }
        self.branches = ends
            .iter()
            .map(|e| self.chain.with_tip(e))
            .collect::<Result<_, _>>()?;
        self.marker_ends = marker_ends;
        Ok(self)
    }

    /// This predictor with its tip at marker `id`'s link: [`Self::predict`],
    /// [`Self::compensate`] and [`Self::compensate_pose`] of a point on that
    /// link (a tree's other branch, data contract 7.1). The same predictor
    /// for a marker on the tip link.
    ///
    /// # Errors
    /// [`CalibrationError::Data`] when there is no marker `id`.
    pub fn for_marker(&self, id: u32) -> Result<Self, CalibrationError> {
        self.marker_m(id)?;
        let m = self.marker_ids.iter().position(|&i| i == id).unwrap_or(0);
        let k = self.marker_ends.get(m).copied().unwrap_or(0);
        if k == 0 {
            return Ok(self.clone());
        }
        let chain = self
            .branches
            .get(k - 1)
            .cloned()
            .unwrap_or_else(|| self.chain.clone());
        Ok(Self {
            branches: Vec::new(),
            marker_ends: vec![0; self.markers.len()],
            chain,
            // The covariance's finite differences rebuild the tip's chain.
            calibration: None,
            ..self.clone()
        })
    }

    /// Marker `id`, or the model's one marker when `id` is `None`: its id,
    /// its calibrated position \[m, tip frame\] and this predictor on its
    /// link ([`Self::for_marker`]).
    ///
    /// # Errors
    /// [`CalibrationError::Data`]: no marker `id`, or `None` when the model
    /// has several ("which marker? the model has markers [..]").
    pub fn at_marker(
        &self,
        id: Option<u32>,
    ) -> Result<(u32, Vector3<f64>, Self), CalibrationError> {
        let id = match (id, self.marker_ids.as_slice()) {
            (Some(id), _) => id,
            (None, [one]) => *one,
            (None, ids) => {
                return Err(CalibrationError::Data(format!(
                    "which marker? the model has markers {ids:?}"
                )))
            }
        };
        Ok((id, self.marker_m(id)?, self.for_marker(id)?))
    }

    /// The chain's ends besides the tip's (placed) and each marker's end, as
    /// [`Predictor::with_ends`] takes them.
    pub fn ends(&self) -> (Vec<crate::robot::End<f64>>, &[usize]) {
        (
            self.branches.iter().map(Chain::tip_end).collect(),
            &self.marker_ends,
        )
    }

    /// Marker ids and calibrated positions \[m, tip frame\].
    pub fn markers(&self) -> impl Iterator<Item = (u32, Vector3<f64>)> + '_ {
        self.marker_ids
            .iter()
            .copied()
            .zip(self.markers.iter().copied())
    }

    /// Gravity \[m/s², measurement frame\].
    pub fn gravity_mps2(&self) -> Vector3<f64> {
        self.gravity_mps2
    }

    /// The calibrated joint law.
    pub fn joint_law(&self) -> &Linearisation {
        &self.lin
    }

    /// The links' bending parameters and their estimates (reported units).
    pub fn bending(&self) -> &[(Param, f64)] {
        &self.bending
    }

    /// The movable joints' names, chain order.
    pub fn joint_names(&self) -> &[String] {
        &self.joint_names
    }

    /// The chain's number of joints.
    pub fn dof(&self) -> usize {
        self.chain.dof()
    }

    /// The calibrated position of marker `id` \[m, tip frame\].
    ///
    /// # Errors
    /// [`CalibrationError::Data`] when the setup has no marker `id`.
    pub fn marker_m(&self, id: u32) -> Result<Vector3<f64>, CalibrationError> {
        self.marker_ids
            .iter()
            .position(|&m| m == id)
            .map(|i| self.markers[i])
            .ok_or_else(|| {
                CalibrationError::Data(format!(
                    "no marker {id} in the calibration (markers {:?})",
                    self.marker_ids
                ))
            })
    }

    /// Where marker `pose.marker` settles \[m, measurement frame\] when
    /// the robot is commanded to `q` (not `pose.q`: a column by central
    /// differences asks for neighbours) with `pose.payload`, on its own link
    /// ([`Self::predict`]).
    ///
    /// # Errors
    /// [`CalibrationError::Data`] naming `pose.line`: no such marker, or a
    /// point the model cannot predict.
    pub fn predict_pose_at(
        &self,
        pose: &Pose,
        q: &[f64],
    ) -> Result<Vector3<f64>, CalibrationError> {
        let at = |e: String| CalibrationError::Data(format!("line {}: {e}", pose.line));
        let tool = self.marker_m(pose.marker).map_err(|e| at(e.to_string()))?;
        self.for_marker(pose.marker)
            .map_err(|e| at(e.to_string()))?
            .predict(&tool, q, pose.payload.as_ref())
            .map_err(|e| at(format!("cannot predict: {e}")))
    }

    /// The fitted shift of the calibration load's centre of mass \[m, tip
    /// frame\] (`load_com_x/y/z`; zero without them).
    pub fn load_com_shift_m(&self) -> Vector3<f64> {
        self.load_com_shift_m
    }

    fn loading(&self, payload: Option<&Payload>) -> Result<Loading<f64>, Error> {
        if let Some(p) = payload {
            if !(p.mass_kg.is_finite() && p.com_m.iter().all(|v| v.is_finite())) {
                return Err(Error::NonFinite { what: "payload" });
            }
            if p.mass_kg < 0.0 {
                return Err(Error::NotPositive {
                    what: "payload mass",
                });
            }
        }
        Ok(Loading {
            load: payload.map(|p| PointLoad {
                mass_kg: p.mass_kg,
                com_m: p.com_m,
                gravity_mps2: self.gravity_mps2,
            }),
            own_weight_mps2: Some(self.gravity_mps2),
        })
    }

    fn check_q(&self, q: &[f64]) -> Result<(), Error> {
        if q.len() != self.dof() {
            return Err(Error::Mismatch {
                what: "joint values: one per joint of the chain",
            });
        }
        if !q.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite {
                what: "joint values",
            });
        }
        Ok(())
    }

    /// Where the point `tool_m` \[m, tip frame\] settles \[m, measurement
    /// frame\] when the robot is commanded to `q` carrying `payload`, under
    /// its own weight.
    ///
    /// # Errors
    /// [`Error::Mismatch`] / [`Error::NonFinite`] for bad joint values or
    /// payload; the errors of [`equilibrium()`].
    pub fn predict(
        &self,
        tool_m: &Vector3<f64>,
        q: &[f64],
        payload: Option<&Payload>,
    ) -> Result<Vector3<f64>, Error> {
        self.predict_with(tool_m, q, payload, true)
    }

    /// The payload's deflection of the point `tool_m` at command `q`: the
    /// point with the payload minus without it, the robot's own weight left
    /// out of both (the same loaded and unloaded) — what a calibration's
    /// deflection rows model, so that `--validate` evaluates the fitted
    /// model on them exactly \[m\].
    ///
    /// # Errors
    /// As [`Self::predict`].
    pub fn predict_deflection(
        &self,
        tool_m: &Vector3<f64>,
        q: &[f64],
        payload: &Payload,
    ) -> Result<Vector3<f64>, Error> {
        Ok(self.predict_with(tool_m, q, Some(payload), false)?
            - self.predict_with(tool_m, q, None, false)?)
    }

    /// [`Self::predict`] of marker index `m` (at its calibrated position, on
    /// its own link: a tree's markers are on several, data contract 7.1).
    ///
    /// # Errors
    /// As [`Self::predict`]; [`Error::OutOfRange`] for no marker `m`.
    pub fn predict_marker(
        &self,
        m: usize,
        q: &[f64],
        payload: Option<&Payload>,
    ) -> Result<Vector3<f64>, Error> {
        let (chain, tool) = self.marker_chain(m)?;
        self.predict_on(chain, &tool, q, payload, true)
    }

    /// [`Self::predict_deflection`] of marker index `m` (see
    /// [`Self::predict_marker`]).
    ///
    /// # Errors
    /// As [`Self::predict_marker`].
    pub fn predict_marker_deflection(
        &self,
        m: usize,
        q: &[f64],
        payload: &Payload,
    ) -> Result<Vector3<f64>, Error> {
        let (chain, tool) = self.marker_chain(m)?;
        Ok(self.predict_on(chain, &tool, q, Some(payload), false)?
            - self.predict_on(chain, &tool, q, None, false)?)
    }

    /// The orientation of marker index `m`'s link frame, turned by the
    /// identified tool frame, at command `q` \[measurement frame\]: what
    /// a 6-D instrument measures beside [`Self::predict_marker`]'s point.
    /// The robot at its equilibrium under its own weight, the links'
    /// bending turning the frame to first order (its turn read from the
    /// bending at the point and at two probes 1 m away, as the
    /// calibration's orientation rows read every column's:
    /// [`crate::model::turn`]).
    ///
    /// # Errors
    /// As [`Self::predict_marker`].
    pub fn predict_marker_rotation(
        &self,
        m: usize,
        q: &[f64],
    ) -> Result<nalgebra::Rotation3<f64>, Error> {
        let (chain, tool) = self.marker_chain(m)?;
        self.rotation_on(chain, &tool, q, None)
    }

    /// The orientation of the tip frame, turned by the identified tool
    /// frame, at command `q` with `payload` \[measurement frame\]: what a
    /// 6-D instrument at the point `tool_m` (tip frame) measures beside
    /// [`Self::predict`]'s point (see [`Self::predict_marker_rotation`]).
    ///
    /// # Errors
    /// As [`Self::predict`].
    pub fn predict_rotation(
        &self,
        tool_m: &Vector3<f64>,
        q: &[f64],
        payload: Option<&Payload>,
    ) -> Result<nalgebra::Rotation3<f64>, Error> {
        self.rotation_on(&self.chain, tool_m, q, payload)
    }

    fn rotation_on(
        &self,
        chain: &Chain<f64, J>,
        tool_m: &Vector3<f64>,
        q: &[f64],
        payload: Option<&Payload>,
    ) -> Result<nalgebra::Rotation3<f64>, Error> {
        use crate::calibrate::rows::orientation::PROBES;
        use crate::model::turn;
        let (eq, loading) = self.settled(chain, q, payload, true)?;
        let p = eq.frames.point_m(tool_m);
        let bent = |d: Vector3<f64>| self.bending_m(chain, &eq.frames, &(p + d), &loading);
        let w = turn(
            &bent(Vector3::zeros())?,
            &bent(PROBES[0])?,
            &bent(PROBES[1])?,
        );
        Ok(nalgebra::Rotation3::new(w)
            * eq.frames.tip().rotation.to_rotation_matrix()
            * self.tool_rotation)
    }

    /// The identified tool frame's rotation a pose's measured frame is
    /// turned by (identity when none was identified).
    pub fn tool_rotation(&self) -> &nalgebra::Rotation3<f64> {
        &self.tool_rotation
    }

    /// This predictor with the tool frame's rotation `r` (a model file's
    /// `tool_quaternion_xyzw`).
    #[must_use]
    pub fn with_tool_rotation(mut self, r: nalgebra::Rotation3<f64>) -> Self {
        self.tool_rotation = r;
        self
    }

    fn marker_chain(&self, m: usize) -> Result<(&Chain<f64, J>, Vector3<f64>), Error> {
        let out = Error::OutOfRange {
            what: "marker",
            index: m,
            len: self.markers.len(),
        };
        let tool = *self.markers.get(m).ok_or(out)?;
        let chain = self
            .marker_ends
            .get(m)
            .and_then(|&k| k.checked_sub(1))
            .and_then(|k| self.branches.get(k))
            .unwrap_or(&self.chain);
        Ok((chain, tool))
    }

    fn predict_with(
        &self,
        tool_m: &Vector3<f64>,
        q: &[f64],
        payload: Option<&Payload>,
        own_weight: bool,
    ) -> Result<Vector3<f64>, Error> {
        self.predict_on(&self.chain, tool_m, q, payload, own_weight)
    }

    fn predict_on(
        &self,
        chain: &Chain<f64, J>,
        tool_m: &Vector3<f64>,
        q: &[f64],
        payload: Option<&Payload>,
        own_weight: bool,
    ) -> Result<Vector3<f64>, Error> {
        let (eq, loading) = self.settled(chain, q, payload, own_weight)?;
        let p = eq.frames.point_m(tool_m);
        Ok(p + self.bending_m(chain, &eq.frames, &p, &loading)?)
    }

    /// The robot on `chain` at command `q` under `payload` (and its own
    /// weight when `own_weight`): its equilibrium under the calibrated
    /// joint law, and that loading.
    fn settled(
        &self,
        chain: &Chain<f64, J>,
        q: &[f64],
        payload: Option<&Payload>,
        own_weight: bool,
    ) -> Result<(Equilibrium<f64, J>, Loading<f64>), Error> {
        self.check_q(q)?;
        let mut loading = self.loading(payload)?;
        if !own_weight {
            loading.own_weight_mps2 = None;
        }
        let eq = equilibrium(chain, q, q, &loading, &self.law_at(q), &EQUILIBRIUM)?;
        Ok((eq, loading))
    }

    /// The calibrated joint law at command `q`, the gravity compliance's
    /// deflection at the commanded pose (as fitted; NaN, so that the
    /// equilibrium fails, if the pose has no frames).
    fn law_at(&self, q: &[f64]) -> crate::calibrate::params::linearisation::Law {
        let gravity = match self.lin.needs_gravity().then(|| self.chain.frames(q)) {
            Some(Ok(f)) => self.lin.gravity_at(&f, &self.gravity_mps2),
            _ => Vec::new(),
        };
        self.lin.joint_law(q, true, &gravity)
    }

    /// The links' bending under `loading` at `frames` on `chain` (first
    /// order, the fitted `LinkCompliance` columns times their estimates):
    /// under the moments about each joint of the payload and, when
    /// `loading` has it, the robot's own weight ([`Loading::moments`])
    /// \[m\].
    fn bending_m(
        &self,
        chain: &Chain<f64, J>,
        frames: &crate::robot::Frames<f64, J>,
        p: &Vector3<f64>,
        loading: &Loading<f64>,
    ) -> Result<Vector3<f64>, Error> {
        let loading = &Loading {
            own_weight_mps2: loading.own_weight_mps2.filter(|_| self.bending_own_weight),
            ..*loading
        };
        if self.bending.is_empty() || (loading.load.is_none() && loading.own_weight_mps2.is_none())
        {
            return Ok(Vector3::zeros());
        }
        let mut moments = [Vector3::zeros(); J];
        let moments = &mut moments[..frames.dof()];
        loading.moments(chain, frames, moments)?;
        let sample = Sample {
            weight_moments_nm: moments,
            ..Sample::absolute(frames, *p, 0, &[])
        };
        self.bending
            .iter()
            .try_fold(Vector3::zeros(), |s, (param, x)| {
                Ok(s + param.column(&sample)? * *x)
            })
    }

    /// [`Self::predict`] and its covariance \[m²\] from the calibration's
    /// parameter covariance (see the [module docs](self)).
    ///
    /// # Errors
    /// As [`Self::predict`]; [`Error::Mismatch`] for a predictor read from
    /// a model file (the covariance is in the file, the calibration's
    /// geometry before folding is not).
    pub fn predict_covariance(
        &self,
        tool_m: &Vector3<f64>,
        q: &[f64],
        payload: Option<&Payload>,
    ) -> Result<(Vector3<f64>, Matrix3<f64>), Error> {
        let p = self.predict(tool_m, q, payload)?;
        let Some((model, gravity)) = &self.calibration else {
            return Err(Error::Mismatch {
                what: "a prediction's covariance needs the calibration, not a model file",
            });
        };
        let n = model.params.len();
        let cov = &model.covariance;
        let mut b = nalgebra::DMatrix::<f64>::zeros(3, n);
        for k in 0..n {
            let sigma = cov[(k, k)].max(0.0).sqrt();
            if sigma == 0.0 || !sigma.is_finite() {
                continue;
            }
            let h = 0.01 * sigma;
            let mut x = model.x.clone();
            x[k] += h;
            let plus = Self::at(model, *gravity, &x).predict(tool_m, q, payload)?;
            x[k] -= 2.0 * h;
            let minus = Self::at(model, *gravity, &x).predict(tool_m, q, payload)?;
            b.set_column(k, &((plus - minus) / (2.0 * h)));
        }
        let c = &b * cov * b.transpose();
        Ok((p, Matrix3::from_fn(|i, j| c[(i, j)])))
    }

    /// The joint command that puts `tool_m` \[m, tip frame\] at `target_m`
    /// \[m, measurement frame\] with `payload`, by Newton's method from
    /// `q_start` ([`compensate()`]; the compensator tables at each step's
    /// command).
    ///
    /// # Errors
    /// As [`Self::predict`] and [`compensate()`] (`NotConverged` for a target
    /// the robot cannot reach near `q_start`).
    pub fn compensate(
        &self,
        tool_m: &Vector3<f64>,
        target_m: &Vector3<f64>,
        q_start: &[f64],
        payload: Option<&Payload>,
        settings: &CompensateSettings<f64>,
    ) -> Result<Compensation<f64, J>, Error> {
        self.check_q(q_start)?;
        let loading = self.loading(payload)?;
        let solve = |target: &Vector3<f64>, start: &[f64]| {
            compensate(
                &self.chain,
                tool_m,
                target,
                start,
                &loading,
                |q: &[f64]| self.law_at(q),
                settings,
            )
        };
        let mut c = solve(target_m, q_start)?;
        if self.bending.is_empty() {
            return Ok(c);
        }
        // The links' bending is not a joint law: aim the rigid-link
        // solution at the target minus the bending there, until the bending
        // stops changing (it is microns on a robot, a few passes).
        let dof = self.dof();
        for _ in 0..settings.max_iterations {
            let bend =
                self.bending_m(&self.chain, &c.equilibrium.frames, &c.reached_m, &loading)?;
            let reached = c.reached_m + bend;
            if (target_m - reached).norm() <= settings.tolerance_m {
                c.error_m = (target_m - reached).norm();
                c.reached_m = reached;
                return Ok(c);
            }
            let aim = target_m - bend;
            let next = solve(&aim, &c.q[..dof])?;
            c = Compensation {
                iterations: c.iterations + next.iterations,
                ..next
            };
        }
        Err(Error::NotConverged {
            iterations: c.iterations,
        })
    }

    /// As [`Self::compensate`] for a pose: `tool_m` at `target_m` with the
    /// tip frame turned to `target_rotation` (measurement frame;
    /// [`compensate_pose`]). The links' bending is not applied here.
    ///
    /// # Errors
    /// As [`Self::compensate`]; [`Error::Mismatch`] when the model has link
    /// bending (a pose compensation would ignore it).
    pub fn compensate_pose(
        &self,
        tool_m: &Vector3<f64>,
        target_m: &Vector3<f64>,
        target_rotation: &UnitQuaternion<f64>,
        q_start: &[f64],
        payload: Option<&Payload>,
        settings: &CompensateSettings<f64>,
    ) -> Result<Compensation<f64, J>, Error> {
        self.check_q(q_start)?;
        if !self.bending.is_empty() && (payload.is_some() || self.bends_unloaded()) {
            return Err(Error::Mismatch {
                what: "a pose compensation of a model with link bending",
            });
        }
        let loading = self.loading(payload)?;
        compensate_pose(
            &self.chain,
            tool_m,
            target_m,
            target_rotation,
            q_start,
            &loading,
            |q: &[f64]| self.law_at(q),
            settings,
        )
    }
}
