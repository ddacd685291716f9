//! The setup file (TOML, data contract section 2).
//!
//! Keys and defaults (every table rejects unknown keys, so a typo is an
//! error naming the key):
//!
//! | key | default |
//! |---|---|
//! | `robot` | required: URDF path, relative to the setup file's directory |
//! | `base_link` | the URDF's root link (error if there are several) |
//! | `tip_link` | the first marker's `link` when every marker names one; else the one leaf link below `base_link` (error if the tree branches) |
//! | `ignore_columns` | `[]`: measurement CSV columns to skip (data contract 7.2) |
//! | `assumed_link_mass_kg` | absent: the URDF's `<inertial>` masses only; a value `m` in (0, 10⁴] kg: a joint whose moving body has no mass in the URDF carries `m` at its frame's origin (docs/formats.md) |
//! | `[units] angle` | `"rad"` (`"deg"` \| `"rad"`) |
//! | `[units] length` | `"m"` (`"mm"` \| `"m"`) |
//! | `[[marker]]` | one marker, `id = 1`, at the origin of `tip_link` |
//! | `[[marker]] id` | required in each table; ids unique |
//! | `[[marker]] xyz` | `[0, 0, 0]` m, in its link |
//! | `[[marker]] link` | `tip_link`; another link makes the chain end there too, a tree when it is off the path to `tip_link` (data contract 7.1; then no `[load]` and no `tool_frame`) |
//! | `[[plane]]` | none: a plane fixed in the measurement frame that markers touch (CSV `plane`); `id` required, unique; `normal` required, non-zero (scaled to unit length); `offset_m` `0`: its points' `n · p` in m |
//! | `[[anchor]]` | none: a point fixed in the measurement frame that distances are measured from (CSV `anchor`, `distance`); `id` required, unique; `xyz` `[0, 0, 0]` m |
//! | `[load]` | absent: no load (a CSV row with `load_kg > 0` is then an error) |
//! | `[load] com` | `[0, 0, 0]` m, in `tip_link` |
//! | `[load] gravity` | `[0, 0, -9.80665]` m/s², base frame |
//! | `[noise] sigma0_um` | `10` µm, `> 0` |
//! | `[noise] lambda` | `1`, `≥ 0` |
//! | `[noise] weights` | `"both"` with `sx, sy, sz` in the data, else `"estimated"` (`"estimated"` \| `"instrument"` \| `"both"`) |
//! | `[model] compliance` | `[]`: joint names, movable joints of the chain |
//! | `[model] compliance_by_angle` | `[]`: revolute/continuous joints of the chain |
//! | `[model] geometry` | `"none"` (`"none"` \| `"joint_offsets"` \| `"full"` \| `"select"`) |
//! | `[model] base_frame` | `false` |
//! | `[model] markers` | `"nominal"` (`"nominal"` \| `"identify"`) |
//! | `[model] tool_frame` | `false` |
//! | `[model] temperature_column` | absent: the CSV column of each point's temperature \[°C\], from −50 to 150; the loop then offers `thermal_expansion` |
//!
//! `geometry = "select"` extends the data contract (an optional value of
//! an existing key; the contract's three values keep their meaning): no
//! joint geometry is declared, but the data's absolute positions are
//! fitted (as for a declared geometry), and the closed loop is offered each
//! joint's offset (`joint_offset`) and its identifiable joint-frame errors
//! (`geometry`) as candidates, added only when the data call for them. It
//! is meant with `base_frame = true` and `markers = "identify"`: the
//! registration declared, the joint geometry selected.
//!
//! `tool_frame = true` extends the data contract (an optional key): the
//! tip link's own 6-D pose error ([`crate::model::Param::Tool`]), which moves
//! every marker rigidly, is identified. It is what predicts a point never
//! measured in a calibration pose (a test point, the tool centre point)
//! from the ones that were: per-marker positions (`markers = "identify"`)
//! move only the measured markers.
//!
//! A joint may be in both `compliance` and `compliance_by_angle` (as in the
//! contract's example); what that means is the model's business, not the
//! reader's.

use std::path::{Path, PathBuf};

/// Largest marker or load offset from its link \[m\]: a tool is not
/// 100 m long; larger values are another unit or an overflow.
pub const MAX_OFFSET_M: f64 = 100.0;
/// Smallest gravity norm with a `[load]` \[m/s²\] (the Moon's is 1.6).
pub const MIN_GRAVITY_MPS2: f64 = 0.1;
/// Largest gravity norm \[m/s²\] (no robot is calibrated at 10 g).
pub const MAX_GRAVITY_MPS2: f64 = 100.0;

use serde::{Deserialize, Serialize};

use crate::io::error::{ErrorKind, InputError};
pub use crate::io::units::{AngleUnit, LengthUnit, Units};
use crate::io::urdf::Robot;

/// `[[marker]]`: a point on the robot that the measuring system sees.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Marker {
    /// Id used in the CSV's `marker` column.
    pub id: u32,
    /// Nominal position \[m\] in its link.
    #[serde(default)]
    pub xyz: [f64; 3],
    /// The URDF link the marker is fixed to (data contract 7.1); `None`:
    /// `tip_link`. Markers on links off the path to `tip_link` make the
    /// chain a tree.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<String>,
}

/// `[[plane]]`: a plane fixed in the measurement frame that markers touch
/// (a measurement of one number: the point's distance from it, along its
/// normal; issue 53). Its points `p` satisfy `n · p = offset`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plane {
    /// Id used in the CSV's `plane` column.
    pub id: u32,
    /// Its normal in the measurement frame (unit length after reading:
    /// [`Plane::unit_normal`]).
    pub normal: [f64; 3],
    /// `n · p` of its points \[m\], `n` the unit normal.
    #[serde(default)]
    pub offset_m: f64,
}

impl Plane {
    /// The normal scaled to unit length (a zero normal is refused by
    /// [`Setup::validate`]).
    pub fn unit_normal(&self) -> [f64; 3] {
        let [x, y, z] = self.normal;
        let n = (x * x + y * y + z * z).sqrt();
        [x / n, y / n, z / n]
    }
}

/// `[[anchor]]`: a point fixed in the measurement frame that distances are
/// measured from (a ballbar's pivot, a draw-wire sensor's exit; issue 53).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Anchor {
    /// Id used in the CSV's `anchor` column.
    pub id: u32,
    /// Its position in the measurement frame \[m\].
    #[serde(default)]
    pub xyz: [f64; 3],
}

/// `[load]`: where the external load hangs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Load {
    /// Point \[m\] in `tip_link` where the hanging mass acts.
    #[serde(default)]
    pub com: [f64; 3],
    /// Gravity \[m/s²\] in the base frame.
    #[serde(default = "default_gravity")]
    pub gravity: [f64; 3],
}

fn default_gravity() -> [f64; 3] {
    [0.0, 0.0, -9.80665]
}

impl Default for Load {
    fn default() -> Self {
        Self {
            com: [0.0; 3],
            gravity: default_gravity(),
        }
    }
}

/// `[noise]`: the measuring system's claimed precision (eq. 14).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Noise {
    /// `σ0` \[µm\], `> 0`.
    #[serde(default = "default_sigma0")]
    pub sigma0_um: f64,
    /// `λ`, the eq. 14 tuning factor, `≥ 0`.
    #[serde(default = "default_lambda")]
    pub lambda: f64,
    /// Which σ enters eq. 14's weights (an extension; `None`: `both` when
    /// the measurements carry the instrument's `sx, sy, sz`, else
    /// `estimated`).
    #[serde(default)]
    pub weights: Option<Weighting>,
}

/// `[noise] weights`: which σ enters the weights `w = σ0 / (σ0 + λσ)` of
/// eq. 14, per configuration and axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Weighting {
    /// σ estimated from the residuals (eq. 14, iterated): the paper's.
    #[default]
    Estimated,
    /// The instrument's σ (`sx, sy, sz`), known in advance: one weighted fit.
    Instrument,
    /// The estimated σ, never below the instrument's (the instrument's σ
    /// as a floor), iterated.
    Both,
}

impl Weighting {
    /// Its name in the setup and the report.
    pub fn name(self) -> &'static str {
        match self {
            Weighting::Estimated => "estimated",
            Weighting::Instrument => "instrument",
            Weighting::Both => "both",
        }
    }
}

fn default_sigma0() -> f64 {
    10.0
}

fn default_lambda() -> f64 {
    1.0
}

impl Default for Noise {
    fn default() -> Self {
        Self {
            sigma0_um: default_sigma0(),
            lambda: default_lambda(),
            weights: None,
        }
    }
}

/// `[model] geometry`: which geometric errors are identified.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GeometryModel {
    /// None (default).
    #[default]
    None,
    /// One zero offset per joint.
    JointOffsets,
    /// Full joint-frame errors.
    Full,
    /// None declared; joint offsets and joint-frame errors are candidates
    /// of the closed loop (an extension of the contract, see the module doc).
    Select,
}

/// `[model] markers`: whether marker positions are identified.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MarkerModel {
    /// Use the setup's `xyz` as exact (default).
    #[default]
    Nominal,
    /// Identify each marker's position.
    Identify,
}

/// `[model]`: the declared model.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model {
    /// Joints with a compliance parameter.
    #[serde(default)]
    pub compliance: Vec<String>,
    /// Joints with one compliance per distinct angle (compensator).
    #[serde(default)]
    pub compliance_by_angle: Vec<String>,
    /// Geometric errors identified.
    #[serde(default)]
    pub geometry: GeometryModel,
    /// Identify the base pose in the measurement frame.
    #[serde(default)]
    pub base_frame: bool,
    /// Marker positions nominal or identified.
    #[serde(default)]
    pub markers: MarkerModel,
    /// Identify the tool frame: a 6-D error of the tip link that moves every
    /// marker together (extension of the contract; default `false`).
    #[serde(default)]
    pub tool_frame: bool,
    /// The measurement CSV's column of the temperature \[°C\] at each
    /// point (extension of the contract; absent: none): the closed loop
    /// then offers the links' thermal expansion (`thermal_expansion`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temperature_column: Option<String>,
}

/// The setup file. See the module doc for keys and defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Setup {
    /// URDF path, relative to the setup file's directory (or absolute).
    pub robot: PathBuf,
    /// Base frame; `None`: the URDF's root link.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_link: Option<String>,
    /// Tip frame; `None`: the one leaf below the base.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tip_link: Option<String>,
    /// `[units]`.
    #[serde(default)]
    pub units: Units,
    /// `[[marker]]` tables.
    #[serde(default = "default_markers", rename = "marker")]
    pub markers: Vec<Marker>,
    /// `[load]`, if there is one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load: Option<Load>,
    /// `[noise]`.
    #[serde(default)]
    pub noise: Noise,
    /// `[model]`.
    #[serde(default)]
    pub model: Model,
    /// Measurement CSV columns to leave out (data contract 7.2: a tracker
    /// export's extra columns, e.g. `temperature`); any other column that
    /// is neither a fixed column nor a joint is an error.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ignore_columns: Vec<String>,
    /// An assumed mass model for a URDF without one (extension of the
    /// contract): every joint whose moving body (its child link and the
    /// links fixed to it) has no `<inertial>` mass carries this mass \[kg\]
    /// at the joint frame's origin. The robot's own weight then loads its
    /// joints (absolute positions with compliances) like a URDF's masses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub assumed_link_mass_kg: Option<f64>,
    /// `[[plane]]` tables: planes markers touch (extension of the contract).
    #[serde(default, rename = "plane", skip_serializing_if = "Vec::is_empty")]
    pub planes: Vec<Plane>,
    /// `[[anchor]]` tables: points distances are measured from (extension
    /// of the contract).
    #[serde(default, rename = "anchor", skip_serializing_if = "Vec::is_empty")]
    pub anchors: Vec<Anchor>,
}

/// The largest [`Setup::assumed_link_mass_kg`] \[kg\].
pub const MAX_ASSUMED_LINK_MASS_KG: f64 = 1e4;

fn default_markers() -> Vec<Marker> {
    vec![Marker {
        id: 1,
        xyz: [0.0; 3],
        link: None,
    }]
}

impl Setup {
    /// A setup with every default and the given robot path.
    pub fn new(robot: impl Into<PathBuf>) -> Self {
        Self {
            robot: robot.into(),
            base_link: None,
            tip_link: None,
            units: Units::default(),
            markers: default_markers(),
            load: None,
            noise: Noise::default(),
            model: Model::default(),
            ignore_columns: Vec::new(),
            assumed_link_mass_kg: None,
            planes: Vec::new(),
            anchors: Vec::new(),
        }
    }

    /// Reads and checks a setup file (without the robot; see
    /// [`crate::io::job::Job::load`]).
    ///
    /// # Errors
    /// Unreadable file, TOML syntax, unknown key, wrong type, or a value
    /// [`Setup::validate`] rejects; the error names `path` and, for TOML
    /// errors, the line.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, InputError> {
        let path = path.as_ref();
        let text =
            crate::io::input::read_text(path, "the setup", crate::io::input::MAX_SETUP_BYTES)?;
        Self::parse(&text, path)
    }

    /// As [`Setup::load`], from the TOML text; `file` names it in errors.
    ///
    /// # Errors
    /// As [`Setup::load`].
    pub fn parse(text: &str, file: impl Into<PathBuf>) -> Result<Self, InputError> {
        let file = file.into();
        let setup: Setup = toml::from_str(text).map_err(|e| {
            let message = e.message().trim_end();
            let kind = if message.starts_with("unknown field") {
                ErrorKind::UnknownKey
            } else {
                ErrorKind::Syntax
            };
            let err = InputError::new(file.clone(), kind, message);
            match e.span() {
                Some(span) => err.at_line(crate::io::error::line_of_offset(text, span.start)),
                None => err,
            }
        })?;
        setup.validate(&file)?;
        Ok(setup)
    }

    /// The setup as TOML text ([`Setup::parse`] reads it back to an equal setup).
    ///
    /// # Panics
    /// Does not: every field of these types has a TOML form (non-finite
    /// numbers are written as `nan`/`inf`, which [`Setup::parse`] rejects).
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("setup serializes to TOML")
    }

    /// Checks what can be checked without the robot: finite numbers,
    /// offsets within [`MAX_OFFSET_M`], gravity within
    /// [`MIN_GRAVITY_MPS2`]..[`MAX_GRAVITY_MPS2`] with a `[load]`,
    /// `sigma0_um > 0`, `lambda ≥ 0`, at least one marker, unique marker
    /// ids, no joint twice in a `[model]` list. `file` names the setup in
    /// errors.
    ///
    /// # Errors
    /// The first violation, naming the key.
    pub fn validate(&self, file: &Path) -> Result<(), InputError> {
        let err = |kind, message: String| Err(InputError::new(file, kind, message));
        let non_finite = |v: &[f64]| v.iter().any(|x| !x.is_finite());
        if self.markers.is_empty() {
            return err(ErrorKind::InvalidValue, "marker: no marker declared".into());
        }
        for (i, m) in self.markers.iter().enumerate() {
            if non_finite(&m.xyz) {
                return err(
                    ErrorKind::NonFinite,
                    format!("marker[{i}].xyz: non-finite {:?}", m.xyz),
                );
            }
            if m.xyz.iter().any(|v| v.abs() > MAX_OFFSET_M) {
                return err(
                    ErrorKind::InvalidValue,
                    format!(
                        "marker[{i}].xyz: {:?} m is more than {MAX_OFFSET_M} m from its link",
                        m.xyz
                    ),
                );
            }
            if let Some(j) = self.markers[..i].iter().position(|o| o.id == m.id) {
                return err(
                    ErrorKind::Duplicate,
                    format!("marker[{i}].id: marker id {} is also marker[{j}]", m.id),
                );
            }
        }
        for (i, p) in self.planes.iter().enumerate() {
            if non_finite(&p.normal) || !p.offset_m.is_finite() {
                return err(
                    ErrorKind::NonFinite,
                    format!("plane[{i}]: non-finite normal or offset_m"),
                );
            }
            if p.normal.iter().map(|v| v * v).sum::<f64>() < 1e-12 {
                return err(
                    ErrorKind::InvalidValue,
                    format!("plane[{i}].normal: {:?} has no direction", p.normal),
                );
            }
            if p.offset_m.abs() > crate::io::units::MAX_POSITION_M {
                return err(
                    ErrorKind::InvalidValue,
                    format!(
                        "plane[{i}].offset_m: {} m is more than {} m from the origin",
                        p.offset_m,
                        crate::io::units::MAX_POSITION_M
                    ),
                );
            }
            if let Some(j) = self.planes[..i].iter().position(|o| o.id == p.id) {
                return err(
                    ErrorKind::Duplicate,
                    format!("plane[{i}].id: plane id {} is also plane[{j}]", p.id),
                );
            }
        }
        for (i, a) in self.anchors.iter().enumerate() {
            if non_finite(&a.xyz) {
                return err(
                    ErrorKind::NonFinite,
                    format!("anchor[{i}].xyz: non-finite {:?}", a.xyz),
                );
            }
            if a.xyz
                .iter()
                .any(|v| v.abs() > crate::io::units::MAX_POSITION_M)
            {
                return err(
                    ErrorKind::InvalidValue,
                    format!(
                        "anchor[{i}].xyz: {:?} m is more than {} m from the origin",
                        a.xyz,
                        crate::io::units::MAX_POSITION_M
                    ),
                );
            }
            if let Some(j) = self.anchors[..i].iter().position(|o| o.id == a.id) {
                return err(
                    ErrorKind::Duplicate,
                    format!("anchor[{i}].id: anchor id {} is also anchor[{j}]", a.id),
                );
            }
        }
        if let Some(load) = &self.load {
            if non_finite(&load.com) {
                return err(
                    ErrorKind::NonFinite,
                    format!("load.com: non-finite {:?}", load.com),
                );
            }
            if non_finite(&load.gravity) {
                return err(
                    ErrorKind::NonFinite,
                    format!("load.gravity: non-finite {:?}", load.gravity),
                );
            }
            if load.com.iter().any(|v| v.abs() > MAX_OFFSET_M) {
                return err(
                    ErrorKind::InvalidValue,
                    format!(
                        "load.com: {:?} m is more than {MAX_OFFSET_M} m from the tip",
                        load.com
                    ),
                );
            }
            let g = load.gravity.iter().map(|v| v * v).sum::<f64>().sqrt();
            if !(MIN_GRAVITY_MPS2..=MAX_GRAVITY_MPS2).contains(&g) {
                return err(
                    ErrorKind::InvalidValue,
                    format!(
                        "load.gravity: {:?} m/s² has norm {g} m/s², outside \
                         [{MIN_GRAVITY_MPS2}, {MAX_GRAVITY_MPS2}] (a load needs gravity to \
                         deflect the robot; Earth's is 9.81)",
                        load.gravity
                    ),
                );
            }
        }
        if let Some(m) = self.assumed_link_mass_kg {
            if !m.is_finite() {
                return err(ErrorKind::NonFinite, format!("assumed_link_mass_kg: {m}"));
            }
            if m <= 0.0 || m > MAX_ASSUMED_LINK_MASS_KG {
                return err(
                    ErrorKind::InvalidValue,
                    format!(
                        "assumed_link_mass_kg: must be in (0, {MAX_ASSUMED_LINK_MASS_KG}] kg, got {m}"
                    ),
                );
            }
        }
        let n = &self.noise;
        if !n.sigma0_um.is_finite() {
            return err(
                ErrorKind::NonFinite,
                format!("noise.sigma0_um: {}", n.sigma0_um),
            );
        }
        if n.sigma0_um <= 0.0 {
            return err(
                ErrorKind::InvalidValue,
                format!("noise.sigma0_um: must be > 0, got {}", n.sigma0_um),
            );
        }
        if !n.lambda.is_finite() {
            return err(ErrorKind::NonFinite, format!("noise.lambda: {}", n.lambda));
        }
        if n.lambda < 0.0 {
            return err(
                ErrorKind::InvalidValue,
                format!("noise.lambda: must be >= 0, got {}", n.lambda),
            );
        }
        for (key, list) in [
            ("model.compliance", &self.model.compliance),
            ("model.compliance_by_angle", &self.model.compliance_by_angle),
        ] {
            for (i, name) in list.iter().enumerate() {
                if list[..i].contains(name) {
                    return err(
                        ErrorKind::Duplicate,
                        format!("{key}: joint '{name}' listed twice"),
                    );
                }
            }
        }
        Ok(())
    }

    /// Checks the setup against the robot: every `[model]` joint is a
    /// movable joint of the chain, `compliance_by_angle` joints rotate.
    ///
    /// # Errors
    /// The first violation, naming the key and the joint.
    pub fn check_robot(&self, robot: &Robot, file: &Path) -> Result<(), InputError> {
        for (key, list) in [
            ("model.compliance", &self.model.compliance),
            ("model.compliance_by_angle", &self.model.compliance_by_angle),
        ] {
            for name in list {
                let Some(index) = robot.joint_index(name) else {
                    return Err(InputError::new(
                        file,
                        ErrorKind::UnknownKey,
                        format!(
                            "{key}: '{name}' is not a movable joint of the chain from '{}' to '{}' \
                             (joints: {})",
                            robot.base_link,
                            robot.tip_link,
                            robot.joint_names.join(", ")
                        ),
                    ));
                };
                if key == "model.compliance_by_angle" && !robot.joint_kinds[index].is_angular() {
                    return Err(InputError::new(
                        file,
                        ErrorKind::InvalidValue,
                        format!("{key}: '{name}' is prismatic; it has no angle"),
                    ));
                }
            }
        }
        // On a tree (markers on links off the path to the tip) the load
        // hangs from tip_link while a marker may sit on another branch, and
        // the tool frame would move every end: neither is built.
        let off_tip = self
            .markers
            .iter()
            .find(|m| m.link.as_deref().is_some_and(|l| l != robot.tip_link));
        if let Some(m) = off_tip {
            let link = m.link.as_deref().unwrap_or_default();
            if self.load.is_some() {
                return Err(InputError::new(
                    file,
                    ErrorKind::InvalidValue,
                    format!(
                        "load: marker {} is on '{link}', not on tip_link '{}': a load with \
                         markers on other links is not supported",
                        m.id, robot.tip_link
                    ),
                ));
            }
            if self.model.tool_frame {
                return Err(InputError::new(
                    file,
                    ErrorKind::InvalidValue,
                    format!(
                        "model.tool_frame: marker {} is on '{link}', not on tip_link '{}': \
                         the tool frame is tip_link's, give markers there or leave it out",
                        m.id, robot.tip_link
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The tip link the robot is read with: `tip_link`, or when it is not
    /// given and every marker names its link, the first marker's link (a
    /// tree's default: its other markers' links are ends too); `None`: the
    /// URDF's one leaf.
    pub fn tip(&self) -> Option<&str> {
        self.tip_link.as_deref().or_else(|| {
            let links: Option<Vec<&str>> = self.markers.iter().map(|m| m.link.as_deref()).collect();
            links.and_then(|l| l.first().copied())
        })
    }

    /// The links markers are fixed to other than the tip ([`Setup::tip`];
    /// data contract 7.1), in marker order, once each.
    pub fn marker_links(&self) -> Vec<&str> {
        let mut links: Vec<&str> = Vec::new();
        for l in self.markers.iter().filter_map(|m| m.link.as_deref()) {
            if !links.contains(&l) && Some(l) != self.tip() {
                links.push(l);
            }
        }
        links
    }

    /// The URDF path: `robot` resolved against the directory of `setup_path`.
    pub fn robot_path(&self, setup_path: &Path) -> PathBuf {
        match setup_path.parent() {
            Some(dir) if self.robot.is_relative() => dir.join(&self.robot),
            _ => self.robot.clone(),
        }
    }
}
