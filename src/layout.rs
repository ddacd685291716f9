//! Parameter layout: what each column of `B = [J  A]` (eq. 4) means, and
//! which of those parameters the data can identify.
//!
//! A [`Layout`] is a fixed-capacity list of [`Column`]s, one per parameter
//! of `X = [ΔΠ, k]`, each with its [`Param`] kind, its unit and the SI value
//! of one unit. Columns are built **in the reported unit**: column `i` of
//! `B` is `∂p \[m\] / ∂xᵢ \[unit\]`, so the estimate `X̂` of the accumulator is
//! directly in `mm`, `mrad`, `urad/(N*m)`, ... and its scale is moderate
//! (a compliance of 0.3 µrad/(N·m) is 0.3, not 3e-7). `si_per_unit`
//! converts: `x_SI = si_per_unit · x`.
//!
//! | kind | unit | `si_per_unit` |
//! |---|---|---|
//! | joint offset, revolute / prismatic | `mrad` / `mm` | 1e-3 |
//! | joint-frame or base translation, marker | `mm` | 1e-3 |
//! | joint-frame or base rotation | `mrad` | 1e-3 |
//! | compliance, revolute / prismatic | `urad/(N*m)` / `um/N` | 1e-6 |
//!
//! Geometric parameters are defined in [`crate::geometric`], compliances in
//! [`crate::elastostatic`].
//!
//! [`identifiability`] selects the identifiable subset of a candidate layout
//! from its information matrix `Λ` (eq. 10) and reports what was dropped and
//! which kept parameters absorb each dropped one.

use core::fmt;

use nalgebra::{RealField, SMatrix, Vector3};

use crate::chain::{Chain, JointKind};
use crate::elastostatic::{self, PointLoad};
use crate::geometric;
use crate::kinematics::Frames;
use crate::Error;

/// What one parameter is. Joint indices count movable joints from the base,
/// starting at 0. `axis` of a 6-D error: 0..3 = translation x, y, z;
/// 3..6 = small rotation about x, y, z.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Param {
    /// Zero offset `δqⱼ` of a joint.
    JointOffset {
        /// Joint index.
        joint: u8,
    },
    /// One of the 6 components of a joint-frame error, in the joint's own
    /// frame at zero joint value (see [`crate::geometric`]).
    JointFrame {
        /// Joint index.
        joint: u8,
        /// 0..6 (tx, ty, tz, rx, ry, rz).
        axis: u8,
    },
    /// One of the 6 components of the base pose in the measurement frame.
    Base {
        /// 0..6 (tx, ty, tz, rx, ry, rz).
        axis: u8,
    },
    /// One coordinate of a marker's position in the tip frame.
    Marker {
        /// Marker id (as in the setup).
        id: u8,
        /// 0..3 (x, y, z).
        axis: u8,
    },
    /// Compliance `kⱼ` of a joint.
    Compliance {
        /// Joint index.
        joint: u8,
    },
    /// Compliance of a joint that holds only while that joint is at one
    /// angle (the gravity compensator of the KR-270's A2: `k21…k25`,
    /// section 5). The column is non-zero only for observations with
    /// `|q_joint − angle| ≤` [`Layout::angle_tolerance_rad`].
    ComplianceByAngle {
        /// Joint index.
        joint: u8,
        /// Bin number (0 for `k21`, 1 for `k22`, …), for naming.
        bin: u8,
        /// The bin's joint angle \[µrad\].
        angle_urad: i32,
    },
}

impl fmt::Display for Param {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const SIX: [&str; 6] = ["tx", "ty", "tz", "rx", "ry", "rz"];
        const XYZ: [&str; 3] = ["x", "y", "z"];
        let six = |a: u8| SIX.get(usize::from(a)).copied().unwrap_or("?");
        match *self {
            Param::JointOffset { joint } => write!(f, "joint{joint}.offset"),
            Param::JointFrame { joint, axis } => write!(f, "joint{joint}.{}", six(axis)),
            Param::Base { axis } => write!(f, "base.{}", six(axis)),
            Param::Marker { id, axis } => write!(
                f,
                "marker{id}.{}",
                XYZ.get(usize::from(axis)).copied().unwrap_or("?")
            ),
            Param::Compliance { joint } => write!(f, "k_joint{joint}"),
            Param::ComplianceByAngle {
                joint, angle_urad, ..
            } => write!(
                f,
                "k_joint{joint}@{:.2}deg",
                f64::from(angle_urad) * 1e-6 * 180.0 / core::f64::consts::PI
            ),
        }
    }
}

/// One column of the layout: the parameter, its unit and scale.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Column {
    /// What the parameter is.
    pub param: Param,
    /// Unit of the estimate (e.g. `"mm"`, `"mrad"`, `"urad/(N*m)"`).
    pub unit: &'static str,
    /// SI value of one unit: `x_SI = si_per_unit · x` (m, rad, rad/(N·m),
    /// m/N).
    pub si_per_unit: f64,
}

/// A marker: its id and nominal position in the tip frame.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Marker<T: RealField + Copy> {
    /// Id (matches [`Param::Marker`]).
    pub id: u8,
    /// Position \[m\] in the tip frame.
    pub xyz_m: Vector3<T>,
}

/// The parameter layout of `X` (at most `N` parameters). See the
/// [module docs](self).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Layout<const N: usize> {
    columns: heapless::Vec<Column, N>,
    /// Half-width \[rad\] of a [`Param::ComplianceByAngle`] bin (default
    /// 1e-3 rad ≈ 0.06°).
    pub angle_tolerance_rad: f64,
}

impl<const N: usize> Default for Layout<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Layout<N> {
    /// An empty layout.
    pub fn new() -> Self {
        Self {
            columns: heapless::Vec::new(),
            angle_tolerance_rad: 1e-3,
        }
    }

    /// Appends a parameter with the unit of the [module table](self) (it
    /// depends on the joint's kind, hence the chain). Returns its column
    /// index.
    ///
    /// # Errors
    /// [`Error::OutOfRange`] for a joint index `≥ dof` or an axis out of
    /// range; [`Error::Mismatch`] when the parameter is already in the
    /// layout; [`Error::CapacityExceeded`] when the layout holds `N` columns.
    /// The layout is unchanged on error.
    pub fn push<T: RealField + Copy, const J: usize>(
        &mut self,
        chain: &Chain<T, J>,
        param: Param,
    ) -> Result<usize, Error> {
        let kind = |joint: u8| {
            chain
                .joints()
                .get(usize::from(joint))
                .map(|j| j.kind)
                .ok_or(Error::OutOfRange {
                    what: "joint",
                    index: usize::from(joint),
                    len: chain.dof(),
                })
        };
        let axis_ok = |axis: u8, len: usize| {
            if usize::from(axis) < len {
                Ok(())
            } else {
                Err(Error::OutOfRange {
                    what: "axis",
                    index: usize::from(axis),
                    len,
                })
            }
        };
        let (unit, si_per_unit) = match param {
            Param::JointOffset { joint } => match kind(joint)? {
                JointKind::Revolute => ("mrad", 1e-3),
                JointKind::Prismatic => ("mm", 1e-3),
            },
            Param::JointFrame { joint, axis } => {
                kind(joint)?;
                axis_ok(axis, 6)?;
                if axis < 3 {
                    ("mm", 1e-3)
                } else {
                    ("mrad", 1e-3)
                }
            }
            Param::Base { axis } => {
                axis_ok(axis, 6)?;
                if axis < 3 {
                    ("mm", 1e-3)
                } else {
                    ("mrad", 1e-3)
                }
            }
            Param::Marker { axis, .. } => {
                axis_ok(axis, 3)?;
                ("mm", 1e-3)
            }
            Param::Compliance { joint } | Param::ComplianceByAngle { joint, .. } => {
                match kind(joint)? {
                    JointKind::Revolute => ("urad/(N*m)", 1e-6),
                    JointKind::Prismatic => ("um/N", 1e-6),
                }
            }
        };
        if self.columns.iter().any(|c| c.param == param) {
            return Err(Error::Mismatch {
                what: "parameter already in the layout",
            });
        }
        let index = self.columns.len();
        self.columns
            .push(Column {
                param,
                unit,
                si_per_unit,
            })
            .map_err(|_| Error::CapacityExceeded {
                what: "layout columns",
                capacity: N,
            })?;
        Ok(index)
    }

    /// The columns, in order.
    pub fn columns(&self) -> &[Column] {
        &self.columns
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.columns.len()
    }

    /// Whether the layout has no parameter.
    pub fn is_empty(&self) -> bool {
        self.columns.is_empty()
    }

    /// Column index of a parameter, if present.
    pub fn index_of(&self, param: &Param) -> Option<usize> {
        self.columns.iter().position(|c| c.param == *param)
    }

    /// Writes the three rows (x, y, z) of `B` (eq. 4) for one marker into
    /// `b`, in the units of the layout. `frames` is the pose
    /// ([`Chain::frames`]); `tau` the joint torques of the load whose
    /// deflection is measured (N·m or N, [`elastostatic`]); it may be empty
    /// when the layout has no compliance. Columns past [`Layout::len`] are
    /// set to zero. `b` is left unchanged on error.
    ///
    /// A [`Param::Marker`] column is non-zero only for the marker with that
    /// id; a [`Param::ComplianceByAngle`] column only when its joint is in
    /// the bin.
    ///
    /// # Errors
    /// [`Error::Mismatch`] when a compliance is in the layout and `tau` is
    /// shorter than the dof, or when a joint with angle bins is at an angle
    /// that matches none of them; [`Error::OutOfRange`] when the layout names
    /// a joint the frames do not have.
    pub fn fill<T: RealField + Copy, const J: usize, const M: usize>(
        &self,
        frames: &Frames<T, J>,
        marker: &Marker<T>,
        tau: &[T],
        b: &mut SMatrix<T, 3, M>,
    ) -> Result<(), Error> {
        if self.len() > M {
            return Err(Error::Mismatch {
                what: "layout has more parameters than B has columns",
            });
        }
        let q = frames.q();
        let p = frames.point_m(&marker.xyz_m);
        let tol: T = nalgebra::convert(self.angle_tolerance_rad);
        let mut out = SMatrix::<T, 3, M>::zeros();
        for (i, c) in self.columns.iter().enumerate() {
            let col = match c.param {
                Param::JointOffset { joint } => {
                    geometric::joint_offset_column(frames, usize::from(joint), &p)?
                }
                Param::JointFrame { joint, axis } => {
                    geometric::joint_frame_columns(frames, usize::from(joint), &p)?
                        [usize::from(axis) % 6]
                }
                Param::Base { axis } => geometric::base_columns(&p)[usize::from(axis) % 6],
                Param::Marker { id, axis } => {
                    if id == marker.id {
                        geometric::marker_columns(frames)[usize::from(axis) % 3]
                    } else {
                        Vector3::zeros()
                    }
                }
                Param::Compliance { joint } => compliance(frames, joint, tau, &p)?,
                Param::ComplianceByAngle {
                    joint, angle_urad, ..
                } => {
                    let j = usize::from(joint);
                    let qj = *q.get(j).ok_or(Error::OutOfRange {
                        what: "joint",
                        index: j,
                        len: q.len(),
                    })?;
                    let centre: T = nalgebra::convert(f64::from(angle_urad) * 1e-6);
                    if (qj - centre).abs() <= tol {
                        compliance(frames, joint, tau, &p)?
                    } else {
                        if !self.in_some_bin(joint, qj, tol) {
                            return Err(Error::Mismatch {
                                what: "joint angle matches no compliance bin",
                            });
                        }
                        Vector3::zeros()
                    }
                }
            };
            let s: T = nalgebra::convert(c.si_per_unit);
            out.set_column(i, &(col * s));
        }
        if !out.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite { what: "row" });
        }
        *b = out;
        Ok(())
    }

    /// `B` (eq. 4) for one marker at joint values `q` under an optional
    /// hanging load (the elastostatic experiment: the measured `Δp` is the
    /// loaded minus the unloaded position, so only the load's torques
    /// enter). Without a load, compliance columns are zero.
    ///
    /// # Errors
    /// As [`Chain::frames`] and [`Layout::fill`].
    pub fn block<T: RealField + Copy, const J: usize, const M: usize>(
        &self,
        chain: &Chain<T, J>,
        q: &[T],
        marker: &Marker<T>,
        load: Option<&PointLoad<T>>,
    ) -> Result<SMatrix<T, 3, M>, Error> {
        let frames = chain.frames(q)?;
        let mut tau = [T::zero(); J];
        if let Some(load) = load {
            elastostatic::joint_torques(&frames, &load.wrench(&frames), &mut tau)?;
        }
        let mut b = SMatrix::zeros();
        self.fill(&frames, marker, &tau[..frames.dof()], &mut b)?;
        Ok(b)
    }

    fn in_some_bin<T: RealField + Copy>(&self, joint: u8, qj: T, tol: T) -> bool {
        self.columns.iter().any(|c| match c.param {
            Param::ComplianceByAngle {
                joint: j,
                angle_urad,
                ..
            } if j == joint => {
                let centre: T = nalgebra::convert(f64::from(angle_urad) * 1e-6);
                (qj - centre).abs() <= tol
            }
            _ => false,
        })
    }
}

fn compliance<T: RealField + Copy, const J: usize>(
    frames: &Frames<T, J>,
    joint: u8,
    tau: &[T],
    p: &Vector3<T>,
) -> Result<Vector3<T>, Error> {
    let j = usize::from(joint);
    let jf = frames.joint(j)?;
    let t = *tau.get(j).ok_or(Error::Mismatch {
        what: "joint torques shorter than the chain's dof",
    })?;
    Ok(jf.twist_column(p) * t)
}

/// Angle \[rad\] → the `angle_urad` of a [`Param::ComplianceByAngle`]
/// (rounded to the nearest µrad; saturates outside ±2147 rad).
pub fn angle_urad(angle_rad: f64) -> i32 {
    let v = libm::round(angle_rad * 1e6);
    if v >= f64::from(i32::MAX) {
        i32::MAX
    } else if v <= f64::from(i32::MIN) {
        i32::MIN
    } else {
        v as i32
    }
}

// ---------------------------------------------------------------------------
// Identifiability

/// Most absorbing parameters reported per dropped parameter.
pub const MAX_ABSORBERS: usize = 6;

/// Order in which the pivoted Cholesky factorization takes parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Pivoting {
    /// Largest remaining pivot first (classic rank-revealing pivoted
    /// Cholesky; ties go to the earlier column). Keeps the best-determined
    /// parameters.
    Largest,
    /// Layout order: a parameter is kept unless it is (numerically) a
    /// combination of the *kept parameters before it*. Put the parameters
    /// you prefer to keep first (e.g. the base frame before joint offsets).
    LayoutOrder,
}

/// Settings of [`identifiability`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IdentifiabilitySettings<T: RealField + Copy> {
    /// A parameter is dropped when its pivot (`1 − R²` of its column
    /// regressed on the kept ones, column-scaled) is at or below this.
    /// Default `√ε` (as [`crate::solve::pivot_tolerance`]).
    pub tolerance: T,
    /// Kept parameters whose scaled regression coefficient on a dropped one
    /// is at least this (in absolute value) are reported as absorbing it.
    /// Default 0.05.
    pub absorb_threshold: T,
    /// A parameter whose `Λᵢᵢ ≤ negligible · maxₖ Λₖₖ` carries no
    /// information (its column, in layout units, is below `√negligible` of
    /// the largest: rounding noise, e.g. the torque of a vertical force on a
    /// vertical axis) and is dropped without absorbers. Default `ε`.
    pub negligible: T,
    /// Pivot order.
    pub pivoting: Pivoting,
}

impl<T: RealField + Copy> Default for IdentifiabilitySettings<T> {
    fn default() -> Self {
        Self {
            tolerance: crate::solve::pivot_tolerance(),
            absorb_threshold: nalgebra::convert(0.05),
            negligible: T::default_epsilon(),
            pivoting: Pivoting::LayoutOrder,
        }
    }
}

/// A kept parameter that absorbs a dropped one.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Absorber<T: RealField + Copy> {
    /// Column index of the kept parameter.
    pub param: usize,
    /// Regression coefficient in layout units: `col_dropped ≈ Σ c · col_kept`,
    /// so a true value `x` of the dropped parameter shows up as `c · x` in
    /// this one.
    pub coefficient: T,
    /// The same coefficient on unit-norm (column-scaled) columns,
    /// dimensionless; the report is sorted by its magnitude.
    pub scaled: T,
}

/// A parameter the data cannot identify.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Dropped<T: RealField + Copy> {
    /// Column index.
    pub param: usize,
    /// `1 − R²` of its scaled column regressed on all kept parameters: 0 =
    /// fully absorbed. 0 with no absorbers: the column carries no
    /// information (`Λᵢᵢ` negligible, see [`IdentifiabilitySettings::negligible`]).
    pub residual: T,
    /// The kept parameters that absorb it, largest first (at most
    /// [`MAX_ABSORBERS`]).
    pub absorbed_by: heapless::Vec<Absorber<T>, MAX_ABSORBERS>,
}

/// Which parameters of a candidate set are identifiable.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Identifiability<T: RealField + Copy, const N: usize> {
    /// `true` for kept parameters: pass it to
    /// [`crate::Accumulator::solve_active`].
    pub kept: [bool; N],
    /// The dropped parameters, in column order.
    pub dropped: heapless::Vec<Dropped<T>, N>,
    /// Smallest over largest pivot of the kept parameters (scaled), in
    /// (0, 1]; 0 when nothing is kept.
    pub rcond: T,
}

impl<T: RealField + Copy, const N: usize> Identifiability<T, N> {
    /// Number of kept parameters.
    pub fn rank(&self) -> usize {
        self.kept.iter().filter(|k| **k).count()
    }

    /// The report entry of a dropped parameter, if it was dropped.
    pub fn dropped_param(&self, param: usize) -> Option<&Dropped<T>> {
        self.dropped.iter().find(|d| d.param == param)
    }
}

/// Selects the identifiable subset of the parameters marked in `candidates`
/// from the information matrix `Λ` (eq. 10, full symmetric `N × N`, e.g.
/// [`crate::Accumulator::information`]) by a pivoted Cholesky factorization
/// of the column-scaled `Λs = S Λ S`, `S = diag(Λ)^(-1/2)`, and reports each
/// dropped parameter with the kept ones that absorb it (the regression of
/// its column on the kept columns, `Λs_KK β = Λs_Kd`).
///
/// Parameters not in `candidates` are ignored (neither kept nor reported).
///
/// # Errors
/// [`Error::NonFinite`] when `Λ` holds NaN or ±∞.
pub fn identifiability<T: RealField + Copy, const N: usize>(
    lambda: &SMatrix<T, N, N>,
    candidates: &[bool; N],
    settings: &IdentifiabilitySettings<T>,
) -> Result<Identifiability<T, N>, Error> {
    if !lambda.iter().all(|v| v.is_finite()) {
        return Err(Error::NonFinite {
            what: "information",
        });
    }
    let mut kept = [false; N];
    let mut dropped_flag = [false; N];
    // Scaling; parameters without information are dropped outright.
    let mut s = [T::zero(); N];
    let mut open = [false; N];
    let mut dmax_info = T::zero();
    for i in (0..N).filter(|&i| candidates[i]) {
        dmax_info = dmax_info.max(lambda[(i, i)]);
    }
    let floor = settings.negligible * dmax_info;
    for i in 0..N {
        if !candidates[i] {
            continue;
        }
        let d = lambda[(i, i)];
        if d > floor && d > T::zero() {
            s[i] = T::one() / d.sqrt();
            open[i] = true;
        } else {
            dropped_flag[i] = true;
        }
    }
    let mut r = SMatrix::<T, N, N>::from_fn(|i, j| {
        if open[i] && open[j] {
            lambda[(i, j)] * s[i] * s[j]
        } else {
            T::zero()
        }
    });
    let a = r;
    // Pivoted outer-product Cholesky on the open set.
    let (mut dmin, mut dmax) = (T::one(), T::zero());
    loop {
        let pick = match settings.pivoting {
            Pivoting::LayoutOrder => (0..N).find(|&i| open[i]),
            Pivoting::Largest => {
                let mut best: Option<usize> = None;
                for i in (0..N).filter(|&i| open[i]) {
                    if best.map_or(true, |b| r[(i, i)] > r[(b, b)]) {
                        best = Some(i);
                    }
                }
                best
            }
        };
        let Some(p) = pick else { break };
        open[p] = false;
        let d = r[(p, p)];
        if d.partial_cmp(&settings.tolerance) != Some(core::cmp::Ordering::Greater) {
            dropped_flag[p] = true;
            continue;
        }
        kept[p] = true;
        dmin = dmin.min(d);
        dmax = dmax.max(d);
        for j in (0..N).filter(|&j| open[j]) {
            let f = r[(p, j)] / d;
            for i in (0..N).filter(|&i| open[i]) {
                let v = r[(i, p)] * f;
                r[(i, j)] -= v;
            }
        }
    }
    // Regression of each dropped column on all kept columns.
    let mut kk = SMatrix::<T, N, N>::identity();
    for j in 0..N {
        for i in 0..N {
            if kept[i] && kept[j] {
                kk[(i, j)] = a[(i, j)];
            }
        }
    }
    // Plain Cholesky (every positive pivot accepted), as in `solve`.
    let l = crate::solve::cholesky_checked(&kk, T::zero())
        .ok()
        .map(|(l, _, _)| l);
    let mut dropped = heapless::Vec::new();
    for d in (0..N).filter(|&d| dropped_flag[d]) {
        let mut entry = Dropped {
            param: d,
            residual: T::zero(),
            absorbed_by: heapless::Vec::new(),
        };
        if s[d] > T::zero() {
            // Regression on the kept columns (an informative column).
            let rhs =
                nalgebra::SVector::<T, N>::from_fn(
                    |i, _| if kept[i] { a[(i, d)] } else { T::zero() },
                );
            let beta = match &l {
                Some(l) => crate::solve::solve_upper_t(l, &crate::solve::solve_lower(l, &rhs)),
                None => nalgebra::SVector::zeros(),
            };
            entry.residual = (T::one() - beta.dot(&rhs)).max(T::zero());
            // Insert absorbers by descending |β|, keeping the largest few.
            for k in (0..N).filter(|&k| kept[k] && beta[k].abs() >= settings.absorb_threshold) {
                let ab = Absorber {
                    param: k,
                    coefficient: beta[k] * s[k] / s[d],
                    scaled: beta[k],
                };
                let pos = entry
                    .absorbed_by
                    .iter()
                    .position(|x| x.scaled.abs() < ab.scaled.abs())
                    .unwrap_or(entry.absorbed_by.len());
                if pos < MAX_ABSORBERS {
                    if entry.absorbed_by.is_full() {
                        entry.absorbed_by.pop();
                    }
                    // Room was made above; cannot fail.
                    let _ = entry.absorbed_by.insert(pos, ab);
                }
            }
        }
        // At most N dropped entries; cannot fail.
        let _ = dropped.push(entry);
    }
    Ok(Identifiability {
        kept,
        dropped,
        rcond: if dmax > T::zero() {
            dmin / dmax
        } else {
            T::zero()
        },
    })
}
