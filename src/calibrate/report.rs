//! What a calibration reports: the final model, the errors, the effects the
//! diagnosis added with the errors before and after each, and what is left.
//! The CLI prints it (`Display`) or writes the contract's JSON.
//!
//! Also here: the calibrated model the report carries ([`calibrated`]), and
//! the rules that judge a result — errors, warnings and whether it is a
//! calibration at all ([`plausibility`]).

pub mod calibrated;
pub mod plausibility;

use std::collections::BTreeMap;
use std::fmt;

use nalgebra::Vector3;

use crate::calibrate::effects::Effect;
use crate::calibrate::fit::residuals::LackOfFit;
use crate::calibrate::report::calibrated::CalibratedModel;
mod per_row;
pub use per_row::{ConfigNoise, ConfigNoises, RowError, RowErrors};

/// One candidate's test in a diagnosis round.
#[derive(Debug, Clone, PartialEq)]
pub struct Tested {
    /// The effect.
    pub effect: Effect,
    /// Joint or marker it is about.
    pub about: Option<String>,
    /// Columns tested.
    pub q: usize,
    /// F statistic.
    pub f: f64,
    /// p-value.
    pub p_value: f64,
    /// Drop of the weighted RSS.
    pub delta_rss: f64,
}

/// One estimated parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct Parameter {
    /// Contract name (`k_a2`, `k_a2@-0.01`, `a3.offset`, `backlash_a4`, …).
    pub name: String,
    /// Estimate, in `unit`.
    pub value: f64,
    /// One standard deviation (sandwich covariance).
    pub std: f64,
    /// Unit (`urad/(N*m)`, `mm`, `mrad`, …).
    pub unit: String,
    /// Whether the data tell the estimate from 0: `|value|` at least
    /// [`crate::calibrate::settings::Policy::determined_sigmas`] (2) σ.
    /// `false`: the value read as 0 ± 2σ, the nominal robot's (the table's
    /// flag, and a warning, `plausibility`). Always `true` for the base
    /// frame, whose value is its pose, not a change from a nominal one.
    pub determined: bool,
}

/// One effect the diagnosis added.
#[derive(Debug, Clone, PartialEq)]
pub struct EffectStep {
    /// The effect (contract §6).
    pub effect: Effect,
    /// Joint, for per-joint effects.
    pub joint: Option<String>,
    /// Marker id, for `marker`.
    pub marker: Option<u32>,
    /// p-value of its nested F test (before the Bonferroni factor).
    pub p_value: f64,
    /// F statistic.
    pub f: f64,
    /// Candidates tested in that round (the Bonferroni factor).
    pub tried: usize,
    /// RMS \[µm\] before.
    pub rms_um_before: f64,
    /// RMS \[µm\] after.
    pub rms_um_after: f64,
    /// Held-out RMS \[µm\] before.
    pub heldout_rms_um_before: Option<f64>,
    /// Held-out RMS \[µm\] after.
    pub heldout_rms_um_after: Option<f64>,
    /// The model's parameters before.
    pub parameters_before: Vec<Parameter>,
    /// The model's parameters after.
    pub parameters_after: Vec<Parameter>,
}

/// Structure left that no effect of the library explains.
#[derive(Debug, Clone, PartialEq)]
pub struct Unexplained {
    /// The variable the residuals follow most (`q_a3`, `tau_a2`, `load_kg`, `t`, `marker`).
    pub variable: String,
    /// Lack-of-fit F statistic.
    pub statistic: f64,
    /// Its p-value.
    pub p_value: f64,
}

/// A kept parameter that absorbs a left-out one.
#[derive(Debug, Clone, PartialEq)]
pub struct Absorbed {
    /// The kept parameter's name.
    pub name: String,
    /// A true value `x` of the left-out parameter shows up as
    /// `coefficient · x` in this one (in `unit`).
    pub coefficient: f64,
    /// Unit of the coefficient: the kept parameter's unit per the left-out
    /// one's (`mrad/mrad`, `mm/mrad`, …).
    pub unit: String,
}

/// A declared parameter the data cannot identify, left out of the fit
/// ([`crate::estimate::rank`]).
#[derive(Debug, Clone, PartialEq)]
pub struct LeftOut {
    /// Its name.
    pub name: String,
    /// The kept parameters its column is a combination of, largest share
    /// first; empty when its column carries no information at all (e.g. a
    /// rotation about an axis through every marker).
    pub absorbed_by: Vec<Absorbed>,
}

/// A kept parameter of the final model that the data determine poorly: its
/// column is nearly a combination of the others'.
#[derive(Debug, Clone, PartialEq)]
pub struct NearDependent {
    /// Its name.
    pub name: String,
    /// Variance inflation `1/(1 − R²)` of its (unweighted) column on the
    /// other parameters' ([`crate::estimate::Identifiability::inflation`]),
    /// at least [`crate::calibrate::settings::Policy::max_variance_inflation`].
    pub inflation: f64,
    /// The parameters its value trades against, largest share first.
    pub with: Vec<String>,
}

/// `--validate`: the final model on another file.
#[derive(Debug, Clone, PartialEq)]
pub struct Validation {
    /// Norm RMSE of the position errors \[mm\].
    pub rms_mm: f64,
    /// Per marker id.
    pub per_marker_rms_mm: BTreeMap<String, f64>,
    /// Mean position error norm per marker id \[mm\].
    pub per_marker_mean_mm: BTreeMap<String, f64>,
    /// Largest position error norm per marker id \[mm\].
    pub per_marker_max_mm: BTreeMap<String, f64>,
    /// Points evaluated.
    pub points: usize,
    /// Points at which a compensator table was interpolated between its
    /// calibrated angles (or held at its first or last one).
    pub interpolated_points: usize,
    /// RMS of the points as measured, in the calibration's measurement
    /// frame \[mm\]: [`Validation::rms_mm`] unless re-registered.
    pub as_measured_rms_mm: f64,
    /// The file's measurement frame re-fitted with the calibrated model
    /// held fixed, when it has three absolute points or more.
    pub reregistration: Option<Reregistration>,
    /// Whether the errors above are those after the re-registration
    /// (`--reregister`), not those as measured.
    pub reregistered: bool,
    /// The file's measured orientations (6-D poses, `rx, ry, rz`) against
    /// the model's, as measured (a re-registration moves the points);
    /// `None` without orientations.
    pub orientation: Option<OrientationValidation>,
    /// The file's plane contacts and distances against the calibrated
    /// model (in a file of those alone, also the errors above: its
    /// `points` are they); `None` without them.
    pub scalars: Option<ScalarValidation>,
}

/// A validation file's measured orientations against the calibrated
/// model's ([`crate::calibrate::outputs::predict::Predictor::predict_marker_rotation`]):
/// the angle of each pose's rotation left, `|log(R_meas R_predᵀ)|`
/// \[µrad\].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct OrientationValidation {
    /// Poses with an orientation.
    pub poses: usize,
    /// RMS \[µrad\].
    pub rms_urad: f64,
    /// Mean \[µrad\].
    pub mean_urad: f64,
    /// Largest \[µrad\].
    pub max_urad: f64,
}

/// A validation file's plane contacts and distances against the
/// calibrated model (module [`crate::calibrate::rows::scalar`]): each row's
/// measured number against the one of the model's point
/// ([`crate::calibrate::outputs::predict::Predictor::predict_marker`]),
/// as measured \[µm\].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ScalarValidation {
    /// Plane contacts and distances.
    pub rows: usize,
    /// RMS \[µm\].
    pub rms_um: f64,
    /// Mean of the absolute values \[µm\].
    pub mean_um: f64,
    /// Largest \[µm\].
    pub max_um: f64,
}

/// The measurement frame of a validation file re-fitted, everything of the
/// calibrated model held fixed (`--reregister`,
/// [`crate::calibrate::outputs::validate`]): the rigid transform that best
/// maps the model's predicted points onto the file's, as the calibration
/// registers its base (unweighted). A tracker set up elsewhere moves
/// every point by it; the error left is the model's.
#[derive(Debug, Clone, PartialEq)]
pub struct Reregistration {
    /// Norm RMSE after it \[mm\].
    pub rms_mm: f64,
    /// Per marker id, after it \[mm\].
    pub per_marker_rms_mm: BTreeMap<String, f64>,
    /// Mean position error norm per marker id, after it \[mm\].
    pub per_marker_mean_mm: BTreeMap<String, f64>,
    /// Largest position error norm per marker id, after it \[mm\].
    pub per_marker_max_mm: BTreeMap<String, f64>,
    /// How far the centroid of the predicted absolute points moved \[mm,
    /// the calibration's measurement frame\].
    pub translation_mm: [f64; 3],
    /// The frame's turn, as a rotation vector \[mrad\].
    pub rotation_mrad: [f64; 3],
    /// One σ of each translation component \[mm\] (the rigid fit's
    /// residual scatter, `s/√n`).
    pub translation_std_mm: [f64; 3],
    /// One σ of each rotation component \[mrad\] (`s² (Σ [q]ₓᵀ[q]ₓ)⁻¹`,
    /// `q` the points about their centroid).
    pub rotation_std_mrad: [f64; 3],
}

impl Reregistration {
    /// How far the frame moved the points' centroid \[mm\].
    pub fn shift_mm(&self) -> f64 {
        nalgebra::Vector3::from(self.translation_mm).norm()
    }

    /// The frame's turn \[mrad\].
    pub fn turn_mrad(&self) -> f64 {
        nalgebra::Vector3::from(self.rotation_mrad).norm()
    }

    /// Whether the frame moved beyond `sigmas` σ in some component.
    pub fn moved(&self, sigmas: f64) -> bool {
        (0..3).any(|k| {
            self.translation_mm[k].abs() > sigmas * self.translation_std_mm[k]
                || self.rotation_mrad[k].abs() > sigmas * self.rotation_std_mrad[k]
        })
    }
}

/// The error of the declared model before any parameter is identified
/// (data contract 7.5): the nominal robot, its base placed by the rigid
/// registration when the base frame is declared; over every row, the norm
/// of the 3-D position error (a deflection row: the measured deflection).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Nominal {
    /// RMS \[µm\].
    pub rms_um: f64,
    /// Mean \[µm\].
    pub mean_um: f64,
    /// Largest \[µm\].
    pub max_um: f64,
}

impl Nominal {
    /// The statistics of residuals `res` \[m\].
    pub fn of(res: &[nalgebra::Vector3<f64>]) -> Self {
        if res.is_empty() {
            return Self::default();
        }
        let n = res.len() as f64;
        Self {
            rms_um: (res.iter().map(|r| r.norm_squared()).sum::<f64>() / n).sqrt() * 1e6,
            mean_um: res.iter().map(|r| r.norm()).sum::<f64>() / n * 1e6,
            max_um: res.iter().map(|r| r.norm()).fold(0.0, f64::max) * 1e6,
        }
    }
}

/// The error of the measured poses' orientations (a 6-D instrument's
/// `rx, ry, rz`, module [`crate::calibrate::rows::orientation`]): the angle
/// of each pose's rotation left \[µrad\], before calibration (the nominal
/// robot, as [`Nominal`]) and after. The points' errors ([`Nominal`],
/// [`Report::rms_um`]) leave them out.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct OrientationErrors {
    /// Poses with an orientation.
    pub poses: usize,
    /// RMS before calibration \[µrad\].
    pub nominal_rms_urad: f64,
    /// RMS after \[µrad\].
    pub rms_urad: f64,
    /// Mean after \[µrad\].
    pub mean_urad: f64,
    /// Largest after \[µrad\].
    pub max_urad: f64,
    /// The parameters the points alone would leave out and the
    /// orientations determine ([`crate::calibrate::engine::Engine::identified_by_orientations`]).
    pub identified: Vec<String>,
    /// The rotation left of each orientation row after calibration
    /// \[µrad\], in row order (what `--robust` weighs them by).
    pub residuals_urad: Vec<nalgebra::Vector3<f64>>,
}

impl OrientationErrors {
    /// Of the rotations left before (`nominal`) and after (`fitted`)
    /// \[rad\]; `None` without any.
    pub fn of(
        nominal: &[nalgebra::Vector3<f64>],
        fitted: &[nalgebra::Vector3<f64>],
    ) -> Option<Self> {
        if fitted.is_empty() {
            return None;
        }
        let (n, a) = (Nominal::of(nominal), Nominal::of(fitted));
        Some(Self {
            poses: fitted.len(),
            nominal_rms_urad: n.rms_um,
            rms_urad: a.rms_um,
            mean_urad: a.mean_um,
            max_urad: a.max_um,
            identified: Vec::new(),
            residuals_urad: fitted.iter().map(|r| r * 1e6).collect(),
        })
    }
}

impl fmt::Display for OrientationErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} poses: RMS {:.1} urad before, {:.1} urad after (mean {:.1}, max {:.1} urad)",
            self.poses, self.nominal_rms_urad, self.rms_urad, self.mean_urad, self.max_urad
        )?;
        if !self.identified.is_empty() {
            write!(
                f,
                "; they determine {}, which the points alone leave out",
                self.identified.join(", ")
            )?;
        }
        Ok(())
    }
}

/// The error of the plane contacts and distances (module
/// [`crate::calibrate::rows::scalar`]): each row's number left \[µm\],
/// before calibration (the nominal robot, as [`Nominal`]) and after. Beside
/// points, the points' errors ([`Nominal`], [`Report::rms_um`]) leave them
/// out; in data of those alone, they are those errors too.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ScalarErrors {
    /// Plane contacts and distances.
    pub rows: usize,
    /// RMS before calibration \[µm\].
    pub nominal_rms_um: f64,
    /// RMS after \[µm\].
    pub rms_um: f64,
    /// Mean of the absolute values after \[µm\].
    pub mean_um: f64,
    /// Largest after \[µm\].
    pub max_um: f64,
    /// Each row's number left after calibration \[µm, on axis 0\], in
    /// row order (what `--robust` weighs them by).
    pub residuals_um: Vec<nalgebra::Vector3<f64>>,
}

impl ScalarErrors {
    /// Of the rows' numbers left before (`nominal`) and after (`fitted`)
    /// \[m, on axis 0\]; `None` without any.
    pub fn of(
        nominal: &[nalgebra::Vector3<f64>],
        fitted: &[nalgebra::Vector3<f64>],
    ) -> Option<Self> {
        if fitted.is_empty() {
            return None;
        }
        let (n, a) = (Nominal::of(nominal), Nominal::of(fitted));
        Some(Self {
            rows: fitted.len(),
            nominal_rms_um: n.rms_um,
            rms_um: a.rms_um,
            mean_um: a.mean_um,
            max_um: a.max_um,
            residuals_um: fitted.iter().map(|r| r * 1e6).collect(),
        })
    }
}

impl fmt::Display for ScalarErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} rows: RMS {:.1} um before, {:.1} um after (mean {:.1}, max {:.1} um)",
            self.rows, self.nominal_rms_um, self.rms_um, self.mean_um, self.max_um
        )
    }
}

impl fmt::Display for Nominal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "RMS {:.1} um, mean {:.1} um, max {:.1} um",
            self.rms_um, self.mean_um, self.max_um
        )
    }
}

/// Residuals against the variable an effect was traced by, before and after
/// it was added (for `--plots`).
#[derive(Debug, Clone, PartialEq)]
pub struct PlotSeries {
    /// Effect and joint.
    pub title: String,
    /// Variable name and unit.
    pub variable: String,
    /// Its value per row.
    pub x: Vec<f64>,
    /// Residual per row before \[µm\].
    pub before_um: Vec<Vector3<f64>>,
    /// Residual per row after \[µm\] (empty for unexplained structure).
    pub after_um: Vec<Vector3<f64>>,
}

/// The outcome of [`crate::calibrate::run::calibrate`].
#[derive(Debug, Clone)]
pub struct Report {
    /// `irls` | `wls` | `ols`.
    pub method: &'static str,
    /// Which σ entered eq. 14's weights: `estimated` (the paper's),
    /// `instrument` (`sx, sy, sz`), `both` (the estimate, floored at the
    /// instrument's), or `none` (OLS).
    pub weights: &'static str,
    /// The declared model's error before calibration.
    pub nominal: Nominal,
    /// Reweighting iterations of the final fit.
    pub iterations: usize,
    /// Whether IRLS converged.
    pub converged: bool,
    /// Gauss–Newton relinearisations of the final fit.
    pub relinearisations: usize,
    /// The deflection model of the rows: `exact` (the equilibrium of the
    /// deflected robot) or `linear` (eq. 3).
    pub deflection_model: &'static str,
    /// The final model.
    pub parameters: Vec<Parameter>,
    /// Covariance of the final estimate (sandwich, eq. 8 / 11), in the
    /// parameters' reported units, in the order of `parameters`.
    pub covariance: nalgebra::DMatrix<f64>,
    /// The final fit's steps: the OLS start and every reweighting after it
    /// (the paper's Figure 3), estimates in the order of `parameters`
    /// (geometric ones as steps from the final linearisation).
    pub history: Vec<crate::calibrate::fit::Step>,
    /// The residual σ and the weights of the final fit per configuration.
    pub noise: ConfigNoises,
    /// RMS of the final model's position residuals \[µm\].
    pub rms_um: f64,
    /// Leave-one-configuration-out RMS \[µm\].
    pub heldout_rms_um: Option<f64>,
    /// RMS of the declared model \[µm\].
    pub declared_rms_um: f64,
    /// Held-out RMS of the declared model \[µm\].
    pub declared_heldout_rms_um: Option<f64>,
    /// The declared model's lack of fit and the variable its residuals
    /// follow most (whether or not significant).
    pub declared_structure: Option<Unexplained>,
    /// Effects added, in order.
    pub effects: Vec<EffectStep>,
    /// Structure left unexplained.
    pub unexplained: Option<Unexplained>,
    /// Lack-of-fit test of the final model (needs repetitions).
    pub lack_of_fit: Option<LackOfFit>,
    /// `--validate` result.
    pub validation: Option<Validation>,
    /// The tests of the last diagnosis round, most significant first.
    pub last_round: Vec<Tested>,
    /// Declared parameters the data cannot identify (left out), with what
    /// absorbed them.
    pub left_out: Vec<LeftOut>,
    /// Parameters of the final model that are identifiable but poorly
    /// (variance inflation at least
    /// [`crate::calibrate::settings::Policy::max_variance_inflation`]), largest first.
    pub near_dependent: Vec<NearDependent>,
    /// Rows (3 equations each, a plane contact or a distance 1).
    pub rows: usize,
    /// Equations: 3 a row, 1 a plane contact or a distance.
    pub equations: usize,
    /// Configurations.
    pub configurations: usize,
    /// Plot data.
    pub plots: Vec<PlotSeries>,
    /// Every row's error before and after, in the rows' order (deflections
    /// first, then absolute positions, in file order).
    pub row_errors: RowErrors,
    /// The measured poses' orientations' errors, when the data have them.
    pub orientation: Option<OrientationErrors>,
    /// The plane contacts' and distances' errors, when the data have them.
    pub scalars: Option<ScalarErrors>,
    /// The calibrated model (for validation and prediction).
    pub model: CalibratedModel,
    /// What the run changed on its own and why (e.g. IRLS → OLS when a
    /// configuration has too few rows to estimate its σ).
    pub notes: Vec<String>,
    /// What `robot.urdf` holds when the final model has parameters a URDF
    /// cannot hold (`export::rigid_urdf`); `None` when the URDF
    /// predicts what the model does, or without absolute rows.
    pub rigid: Option<RigidUrdf>,
    /// Plausibility findings that did not stop the run
    /// ([`crate::calibrate::report::plausibility`]), the input readers' warnings included.
    pub warnings: Vec<String>,
    /// Why this result is not a calibration, when it is not one
    /// ([`crate::calibrate::report::plausibility::failure`]): the fit did not converge, or
    /// its model fits its own data worse than the nominal robot. The
    /// report is still complete, for inspection; `robcal calibrate` exits
    /// non-zero unless asked to accept it (`--accept-unconverged`).
    pub failure: Option<String>,
}

/// What `robot.urdf` holds for a model with parameters a URDF cannot hold
/// (compliances, backlash, gear cyclic errors, drift, …;
/// `export::rigid_urdf`).
#[derive(Debug, Clone)]
pub struct RigidUrdf {
    /// The model's geometric parameters refitted as a rigid robot (none of
    /// the others), when that fit succeeded; else the URDF holds the
    /// model's own geometry.
    pub refit: Option<CalibratedModel>,
    /// RMS \[µm\] over the absolute rows of what the URDF holds.
    pub rms_um: f64,
    /// RMS \[µm\] over the absolute rows of the model's own geometry alone.
    pub own_rms_um: f64,
}

impl Report {
    /// Sets the validation `v` and adds the warnings of its rule
    /// ([`plausibility::check_validation`]): a file measured in another
    /// frame does not pass silently.
    pub fn set_validation(&mut self, v: Validation) {
        self.warnings
            .extend(plausibility::check_validation(&v, &self.model.policy));
        self.validation = Some(v);
    }

    /// The model whose geometry `robot.urdf` holds: the rigid refit of
    /// [`Report::rigid`] when there is one, else [`Report::model`].
    pub fn urdf_model(&self) -> &CalibratedModel {
        self.rigid
            .as_ref()
            .and_then(|r| r.refit.as_ref())
            .unwrap_or(&self.model)
    }

    /// The final model's error per point over the calibration data, as
    /// [`Nominal`] is before calibration: RMS, mean and max of the norm of
    /// each row's 3-D residual \[µm\].
    pub fn final_error(&self) -> Nominal {
        let res: Vec<_> = self
            .row_errors
            .final_um()
            .iter()
            .map(|e| e * 1e-6)
            .collect();
        Nominal::of(&res)
    }
}

impl LeftOut {
    /// `a3.offset left out: absorbed by base.rz (1 mrad/mrad), …` or
    /// `… left out: no information in these data`.
    pub fn line(&self) -> String {
        if self.absorbed_by.is_empty() {
            return format!("{} left out: no information in these data", self.name);
        }
        let by: Vec<String> = self
            .absorbed_by
            .iter()
            .map(|a| format!("{} ({:.3} {})", a.name, a.coefficient, a.unit))
            .collect();
        format!("{} left out: absorbed by {}", self.name, by.join(", "))
    }
}

impl NearDependent {
    /// `elbow.ty: variance inflation 2.3e3, with a2.rz, …`.
    pub fn line(&self) -> String {
        // The three largest shares (JSON has them all).
        let with = if self.with.is_empty() {
            String::new()
        } else {
            let top: Vec<&str> = self.with.iter().take(3).map(String::as_str).collect();
            format!(", with {}", top.join(", "))
        };
        format!(
            "{}: variance inflation {:.3e}{with}",
            self.name, self.inflation
        )
    }
}

fn opt(v: Option<f64>) -> String {
    v.map_or_else(|| "n/a".into(), |v| format!("{v:.1}"))
}

fn about(s: &EffectStep) -> String {
    match (&s.joint, s.marker) {
        (Some(j), _) => format!(" on {j}"),
        (None, Some(m)) => format!(" on marker {m}"),
        _ => String::new(),
    }
}

/// What the weights were, in words, for `[noise] weights` = `w`.
pub fn weights_line(w: &str) -> &'static str {
    match w {
        "instrument" => {
            "eq. 14 at the instrument's sigma (sx, sy, sz; sd), known in advance: one weighted fit"
        }
        "both" => {
            "eq. 14 at the estimated sigma per configuration and axis, never below the \
             instrument's (sx, sy, sz; sd), iterated"
        }
        "none" => "none (OLS)",
        _ => "eq. 14 at the sigma estimated per configuration and axis, iterated",
    }
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "robcal calibrate: {} rows ({} equations), {} configurations, method {}",
            self.rows, self.equations, self.configurations, self.method
        )?;
        if self.weights != "estimated" && self.weights != "none" {
            writeln!(f, "weights: {}", weights_line(self.weights))?;
        }
        writeln!(f, "nominal (before calibration): {}", self.nominal)?;
        if let Some(s) = &self.scalars {
            writeln!(f, "plane contacts and distances: {s}")?;
        }
        if let Some(o) = &self.orientation {
            writeln!(f, "orientation of the measured poses: {o}")?;
        }
        if let Some(why) = &self.failure {
            writeln!(f, "error: NOT A CALIBRATION: {why}")?;
        }
        for n in &self.notes {
            writeln!(f, "note: {n}")?;
        }
        for w in &self.warnings {
            writeln!(f, "warning: {w}")?;
        }
        if !self.left_out.is_empty() {
            writeln!(
                f,
                "identifiability: {} declared parameter(s) left out, dependent on kept ones",
                self.left_out.len()
            )?;
            for l in &self.left_out {
                writeln!(f, "  {}", l.line())?;
            }
        }
        if !self.near_dependent.is_empty() {
            writeln!(
                f,
                "identifiability: {} parameter(s) poorly determined (variance inflation; \
                 their values trade against the ones named)",
                self.near_dependent.len()
            )?;
            for n in &self.near_dependent {
                writeln!(f, "  {}", n.line())?;
            }
        }
        writeln!(f)?;
        writeln!(
            f,
            "declared model: RMS {:.1} um, held-out RMS {} um",
            self.declared_rms_um,
            opt(self.declared_heldout_rms_um)
        )?;
        if let Some(d) = &self.declared_structure {
            writeln!(
                f,
                "  lack of fit F = {:.2} (p = {:.2e}){}",
                d.statistic,
                d.p_value,
                if d.p_value < 0.01 {
                    ": structure beyond the noise"
                } else {
                    ""
                }
            )?;
        }
        if self.effects.is_empty() {
            writeln!(f, "diagnosis: no effect added")?;
        }
        for (i, s) in self.effects.iter().enumerate() {
            writeln!(
                f,
                "step {}: added {}{}  (F = {:.1}, p = {:.2e}, {} candidates tried)",
                i + 1,
                s.effect,
                about(s),
                s.f,
                s.p_value,
                s.tried
            )?;
            writeln!(
                f,
                "        RMS {:.1} -> {:.1} um, held-out RMS {} -> {} um",
                s.rms_um_before,
                s.rms_um_after,
                opt(s.heldout_rms_um_before),
                opt(s.heldout_rms_um_after)
            )?;
            for a in &s.parameters_after {
                let before = s.parameters_before.iter().find(|b| b.name == a.name);
                match before {
                    Some(b) => writeln!(
                        f,
                        "          {:<24} {:>12.4} -> {:>12.4} {}",
                        a.name, b.value, a.value, a.unit
                    )?,
                    None => writeln!(
                        f,
                        "          {:<24} {:>12} -> {:>12.4} {}  (new)",
                        a.name, "", a.value, a.unit
                    )?,
                }
            }
            for b in &s.parameters_before {
                if !s.parameters_after.iter().any(|a| a.name == b.name) {
                    writeln!(f, "          {:<24} {:>12.4} -> removed", b.name, b.value)?;
                }
            }
        }
        match &self.unexplained {
            Some(u) => writeln!(
                f,
                "unexplained structure left: residuals follow {} most (lack-of-fit F = {:.2}, p = {:.2e}); no effect of the library explains it",
                u.variable, u.statistic, u.p_value
            )?,
            None => match &self.lack_of_fit {
                Some(l) => writeln!(
                    f,
                    "lack of fit (repetitions as pure error): F = {:.2}, p = {:.2e}{}",
                    l.f,
                    l.p_value,
                    if l.p_value < 0.01 { "" } else { ": no structure left beyond the noise" }
                )?,
                None => writeln!(f, "lack of fit: not testable (no repetitions)")?,
            },
        }
        if let Some(t) = self.last_round.first() {
            writeln!(
                f,
                "most significant remaining candidate: {}{} (p = {:.2e}, {} tried)",
                t.effect,
                t.about
                    .as_deref()
                    .map(|a| format!(" on {a}"))
                    .unwrap_or_default(),
                t.p_value,
                self.last_round.len()
            )?;
        }
        writeln!(f)?;
        writeln!(
            f,
            "final model ({} deflection model, {} iterations{}{}):",
            self.deflection_model,
            self.iterations,
            if self.converged {
                ", converged"
            } else {
                ", NOT converged"
            },
            if self.relinearisations > 0 {
                format!(
                    ", {} Gauss-Newton relinearisation{}",
                    self.relinearisations,
                    if self.relinearisations == 1 { "" } else { "s" }
                )
            } else {
                String::new()
            }
        )?;
        // Names as long as `gear_cyclic_shoulder_lift_joint.sin` keep the
        // columns aligned.
        let w = self
            .parameters
            .iter()
            .map(|p| p.name.chars().count())
            .max()
            .unwrap_or(0)
            .max(24);
        // t = value / σ (statsmodels' column); units last, any length.
        writeln!(
            f,
            "  {:<w$} {:>12} ± {:<10} {:>8}  unit",
            "parameter", "value", "1 sd", "t"
        )?;
        // `*`: within 2 σ of 0 (`Parameter::determined`).
        for p in &self.parameters {
            writeln!(
                f,
                "  {:<w$} {:>12.4} ± {:<10.4} {:>8.1}{} {}",
                p.name,
                p.value,
                p.std,
                p.value / p.std,
                if p.determined { " " } else { "*" },
                p.unit
            )?;
        }
        if self.parameters.iter().any(|p| !p.determined) {
            writeln!(
                f,
                "  * within 2 sd of 0: the data do not tell it from the nominal robot's value"
            )?;
        }
        writeln!(
            f,
            "RMS {:.1} um, held-out RMS {} um",
            self.rms_um,
            opt(self.heldout_rms_um)
        )?;
        let e = self.final_error();
        writeln!(
            f,
            "error per point after calibration: mean {:.1} um, max {:.1} um (before: mean {:.1} um, max {:.1} um)",
            e.mean_um, e.max_um, self.nominal.mean_um, self.nominal.max_um
        )?;
        if let Some(r) = &self.rigid {
            writeln!(
                f,
                "robot.urdf (a rigid robot, none of model.json's other parameters): RMS {:.1} \
                 um over the absolute rows",
                r.rms_um
            )?;
        }
        if let Some(v) = &self.validation {
            write!(
                f,
                "validation{}: RMS {:.4} mm",
                if v.reregistered {
                    " (measurement frame re-registered)"
                } else {
                    ""
                },
                v.rms_mm
            )?;
            for (m, r) in &v.per_marker_rms_mm {
                write!(f, ", marker {m} {r:.4} mm")?;
            }
            writeln!(f)?;
            if let Some(g) = &v.reregistration {
                writeln!(
                    f,
                    "validation: as measured RMS {:.4} mm; re-registered RMS {:.4} mm, the frame \
                     moved {:.3} mm and turned {:.3} mrad",
                    v.as_measured_rms_mm,
                    g.rms_mm,
                    g.shift_mm(),
                    g.turn_mrad()
                )?;
            }
            if let Some(o) = &v.orientation {
                writeln!(
                    f,
                    "validation: orientation of {} poses: RMS {:.1} urad, mean {:.1} urad, \
                     max {:.1} urad",
                    o.poses, o.rms_urad, o.mean_urad, o.max_urad
                )?;
            }
            if let Some(s) = &v.scalars {
                writeln!(
                    f,
                    "validation: plane contacts and distances of {} rows: RMS {:.1} um, mean \
                     {:.1} um, max {:.1} um",
                    s.rows, s.rms_um, s.mean_um, s.max_um
                )?;
            }
            if v.interpolated_points > 0 {
                writeln!(
                    f,
                    "validation: {} of {} points at angles between the calibrated ones \
                     (compensator table interpolated linearly, held at its ends)",
                    v.interpolated_points, v.points
                )?;
            }
        }
        Ok(())
    }
}
