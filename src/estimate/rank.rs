//! Which parameters the data can identify: the one column-independence test
//! of robcal.
//!
//! A pivoted Cholesky factorisation of the column-scaled information matrix
//! `Λs = S Λ S`, `S = diag(Λ)^(-1/2)` (so that units do not decide), keeps a
//! parameter when the part of its column not explained by the kept ones,
//! `1 − R²` (the pivot), exceeds one tolerance, [`independence_tolerance`];
//! every other parameter is left out and reported with the kept parameters
//! that absorb it (the regression of its column on the kept columns,
//! `Λs_KK β = Λs_Kd`).
//!
//! A kept parameter can still be poorly determined: its **variance
//! inflation** `VIFᵢ = 1/(1 − R²ᵢ) = (Λs_KK⁻¹)ᵢᵢ` (its column regressed on
//! the other kept ones) is the factor by which its variance exceeds what its
//! column alone would give. [`Identifiability::inflation`] returns it and
//! [`Identifiability::explained_by`] the kept parameters its column leans on
//! (`βₖ = −(Λs_KK⁻¹)ₖᵢ / (Λs_KK⁻¹)ᵢᵢ`), so that a report can flag the values
//! not to trust. Each pivot exceeds the tolerance when its parameter is
//! taken, but later parameters can still lean on it, so the VIF of a kept
//! parameter is not bounded by `1/tolerance` (7e6 was seen with layout-order
//! pivoting on a random arm).
//!
//! The tolerance is `1e-6` in f64: a parameter 99.9999 % explained by the
//! others is left out. It lies a factor ~64 above the solver's own guard
//! ([`super::pivot_tolerance`], `√ε`), so that a model reduced here is never
//! refused by the solver when the weights of a fit move the pivots. In f32,
//! where `√ε` is 3.5e-4, it is `64·√ε`.
//!
//! The host calibration applies it to the unweighted columns of the
//! declared model and of every candidate effect
//! (`calibrate::design::Design::independent`); the firmware can apply it to
//! an [`super::Accumulator`]'s `Λ`.

use super::Alloc;
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector, RealField};

use super::accumulator::Accumulator;
use super::factor::{solve_lower_in_place, solve_upper_t_in_place};
use super::linalg::dot;
use crate::error::Error;

mod kept;
use kept::{kept_factor, verify_kept};

/// Margin of [`independence_tolerance`] over the solver's `√ε`.
pub const INDEPENDENCE_MARGIN: f64 = 64.0;

/// The tolerance on `1 − R²` below which a parameter is left out:
/// `max(1e-6, 64·√ε)` (1e-6 in f64, 0.022 in f32). See the
/// [module docs](self).
pub fn independence_tolerance<T: RealField + Copy>() -> T {
    let floor: T = nalgebra::convert(1e-6);
    let margin: T = nalgebra::convert(INDEPENDENCE_MARGIN);
    floor.max(margin * super::pivot_tolerance::<T>())
}

/// Most absorbing parameters reported per left-out parameter.
pub const MAX_ABSORBERS: usize = 6;

/// Order in which the pivoted Cholesky factorisation takes parameters.
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
    /// A parameter is left out when its pivot (`1 − R²` of its column
    /// regressed on the kept ones, column-scaled) is at or below this.
    /// Default [`independence_tolerance`].
    pub tolerance: T,
    /// Kept parameters whose scaled regression coefficient on a left-out one
    /// is at least this (in absolute value) are reported as absorbing it.
    /// Default 0.05.
    pub absorb_threshold: T,
    /// A parameter whose `Λᵢᵢ ≤ negligible · maxₖ Λₖₖ` carries no
    /// information: its column is below `√negligible` of the largest, which
    /// only rounding noise is (the torque of a vertical force on a vertical
    /// axis, computed as `zᵀ((c − o) × F)`, is ~1e-16 of the torques on the
    /// other joints); it is left out without absorbers. Default `ε²`: a
    /// column below `ε` (2.2e-16 in f64) of the largest. Physical columns
    /// in robcal's units stay far above it (a `τ|τ|` stiffness of a wrist
    /// joint under 1 N·m is 1e-10 of a millimetre column), so units do not
    /// decide.
    pub negligible: T,
    /// Pivot order.
    pub pivoting: Pivoting,
}

impl<T: RealField + Copy> Default for IdentifiabilitySettings<T> {
    fn default() -> Self {
        Self {
            tolerance: independence_tolerance(),
            absorb_threshold: nalgebra::convert(0.05),
            negligible: T::default_epsilon() * T::default_epsilon(),
            pivoting: Pivoting::LayoutOrder,
        }
    }
}

/// A kept parameter that absorbs a left-out one.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Absorber<T: RealField + Copy> {
    /// Index of the kept parameter.
    pub param: usize,
    /// Regression coefficient in layout units: `col_left_out ≈ Σ c · col_kept`,
    /// so a true value `x` of the left-out parameter shows up as `c · x` in
    /// this one.
    pub coefficient: T,
    /// The same coefficient on unit-norm (column-scaled) columns,
    /// dimensionless; the report is sorted by its magnitude.
    pub scaled: T,
}

/// Which parameters of a candidate set are identifiable.
#[derive(Debug, Clone, PartialEq)]
pub struct Identifiability<T: RealField + Copy, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    /// `true` for kept parameters: pass it to
    /// [`super::Accumulator::solve_active`].
    pub kept: OVector<bool, D>,
    /// `true` for candidates left out.
    left_out: OVector<bool, D>,
    /// `1 − R²` of each parameter's scaled column regressed on the kept ones
    /// (the *other* kept ones for a kept parameter: `1/VIF`); 0 for a
    /// left-out one fully absorbed or without information.
    residual: OVector<T, D>,
    /// Column `d`: the scaled regression coefficients of `d` on the (other)
    /// kept parameters.
    beta: OMatrix<T, D, D>,
    /// `S` (0 for a column without information).
    scale: OVector<T, D>,
    absorb_threshold: T,
    /// Smallest over largest pivot of the kept parameters (scaled), in
    /// (0, 1]; 0 when nothing is kept.
    pub rcond: T,
}

/// The flags, residuals and scales as lists, `β` row by row (not
/// nalgebra's internals).
#[cfg(feature = "defmt")]
impl<T: RealField + Copy + defmt::Format, D: Dim> defmt::Format for Identifiability<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    fn format(&self, f: defmt::Formatter<'_>) {
        use super::fmt::rows;
        defmt::write!(
            f,
            "Identifiability {{ kept: {}, left_out: {}, residual: {}, beta: {}, scale: {}, absorb_threshold: {}, rcond: {} }}",
            rows(&self.kept),
            rows(&self.left_out),
            rows(&self.residual),
            rows(&self.beta),
            rows(&self.scale),
            self.absorb_threshold,
            self.rcond
        )
    }
}

impl<T: RealField + Copy, D: Dim> Identifiability<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    /// Number of kept parameters.
    pub fn rank(&self) -> usize {
        self.kept.iter().filter(|k| **k).count()
    }

    /// The left-out parameters, in order.
    pub fn left_out(&self) -> impl Iterator<Item = usize> + '_ {
        self.left_out
            .iter()
            .enumerate()
            .filter(|(_, l)| **l)
            .map(|(i, _)| i)
    }

    /// Whether `param` was left out.
    pub fn is_left_out(&self, param: usize) -> bool {
        self.left_out.get(param).copied().unwrap_or(false)
    }

    /// `1 − R²` of a left-out parameter's column on the kept ones (0 when
    /// it is not left out).
    pub fn residual(&self, param: usize) -> T {
        if self.is_left_out(param) {
            self.residual[param]
        } else {
            T::zero()
        }
    }

    /// Variance inflation `1/(1 − R²)` of a kept parameter's column on the
    /// other kept ones (1: orthogonal to them);
    /// `None` for a parameter that is not kept. Infinite only when the kept
    /// block could not be factored (never with the default tolerance).
    pub fn inflation(&self, param: usize) -> Option<T> {
        if !self.kept.get(param).copied().unwrap_or(false) {
            return None;
        }
        let r = self.residual[param];
        Some(if r > T::zero() {
            T::one() / r
        } else {
            T::one() / T::default_epsilon() / T::default_epsilon()
        })
    }

    /// The kept parameters that absorb left-out `param`, largest scaled
    /// coefficient first (at most [`MAX_ABSORBERS`]); empty for a kept
    /// parameter or a column without information.
    pub fn absorbed_by(&self, param: usize) -> heapless::Vec<Absorber<T>, MAX_ABSORBERS> {
        if !self.is_left_out(param) {
            return heapless::Vec::new();
        }
        self.related(param)
    }

    /// The other kept parameters that a kept `param`'s column leans on (its
    /// regression on them, as [`Self::absorbed_by`]), largest scaled
    /// coefficient first; empty for a parameter that is not kept. Read it
    /// with [`Self::inflation`]: with a large inflation, these are the
    /// parameters whose values trade against `param`'s.
    pub fn explained_by(&self, param: usize) -> heapless::Vec<Absorber<T>, MAX_ABSORBERS> {
        if !self.kept.get(param).copied().unwrap_or(false) {
            return heapless::Vec::new();
        }
        self.related(param)
    }

    fn related(&self, param: usize) -> heapless::Vec<Absorber<T>, MAX_ABSORBERS> {
        let mut out: heapless::Vec<Absorber<T>, MAX_ABSORBERS> = heapless::Vec::new();
        if self.scale[param] <= T::zero() {
            return out;
        }
        let n = self.kept.len();
        for k in (0..n).filter(|&k| self.kept[k] && k != param) {
            let b = self.beta[(k, param)];
            if b.abs() < self.absorb_threshold {
                continue;
            }
            let ab = Absorber {
                param: k,
                coefficient: b * self.scale[k] / self.scale[param],
                scaled: b,
            };
            let pos = out
                .iter()
                .position(|x| x.scaled.abs() < ab.scaled.abs())
                .unwrap_or(out.len());
            if pos < MAX_ABSORBERS {
                if out.is_full() {
                    out.pop();
                }
                // Room was made above; cannot fail.
                let _ = out.insert(pos, ab);
            }
        }
        out
    }
}

/// Selects the identifiable subset of the parameters marked in `candidates`
/// (one flag per parameter) from the information matrix `Λ` (eq. 10, full
/// symmetric, e.g. [`super::Accumulator::information`]). See the
/// [module docs](self). Parameters not in `candidates` are ignored (neither
/// kept nor left out).
///
/// # Errors
/// [`Error::Mismatch`] when `candidates` has the wrong length;
/// [`Error::NonFinite`] when `Λ` holds NaN or ±∞.
pub fn identifiability<T: RealField + Copy, D: Dim>(
    lambda: &OMatrix<T, D, D>,
    candidates: &[bool],
    settings: &IdentifiabilitySettings<T>,
) -> Result<Identifiability<T, D>, Error>
where
    DefaultAllocator: Alloc<D>,
{
    identifiability_excluding(lambda, candidates, &[], settings)
}

/// [`identifiability`] with the candidates flagged in `excluded` (empty:
/// none) left out whatever their pivot, with their absorbers: for a caller
/// that tested the columns more accurately than `Λ`, whose pivots carry
/// rounding of about `ε·κ(Λ)` (`calibrate::design`, std).
///
/// # Errors
/// As [`identifiability`]; [`Error::Mismatch`] for a wrong `excluded` length.
pub fn identifiability_excluding<T: RealField + Copy, D: Dim>(
    lambda: &OMatrix<T, D, D>,
    candidates: &[bool],
    excluded: &[bool],
    settings: &IdentifiabilitySettings<T>,
) -> Result<Identifiability<T, D>, Error>
where
    DefaultAllocator: Alloc<D>,
{
    let n = lambda.nrows();
    if candidates.len() != n {
        return Err(Error::Mismatch {
            what: "one candidate flag per parameter",
        });
    }
    if !excluded.is_empty() && excluded.len() != n {
        return Err(Error::Mismatch {
            what: "one excluded flag per parameter",
        });
    }
    if !lambda.iter().all(|v| v.is_finite()) {
        return Err(Error::NonFinite {
            what: "information",
        });
    }
    let Pivoted {
        kept,
        left_out,
        s,
        a,
        dmin,
        dmax,
    } = pivot(lambda, candidates, excluded, settings);
    let dim = lambda.shape_generic().0;
    // Regression of each left-out column on all kept columns: plain
    // Cholesky of the kept block (every positive pivot accepted).
    let l = kept_factor(&a, &kept, T::zero());
    let mut beta = OMatrix::<T, D, D>::zeros_generic(dim, dim);
    let mut residual = OVector::<T, D>::zeros_generic(dim, Const::<1>);
    for d in (0..n).filter(|&d| left_out[d] && s[d] > T::zero()) {
        let rhs = OVector::<T, D>::from_fn_generic(dim, Const::<1>, |i, _| {
            if kept[i] {
                a[(i, d)]
            } else {
                T::zero()
            }
        });
        let mut b = rhs.clone();
        if let Ok(l) = &l {
            solve_lower_in_place(l, &mut b);
            solve_upper_t_in_place(l, &mut b);
        } else {
            b.fill(T::zero());
        }
        residual[d] = (T::one() - dot(&b, &rhs)).max(T::zero());
        beta.set_column(d, &b);
    }
    // Variance inflation of each kept parameter: column d of Λs_KK⁻¹.
    if let Ok(l) = &l {
        for d in (0..n).filter(|&d| kept[d]) {
            let mut x = OVector::<T, D>::zeros_generic(dim, Const::<1>);
            x[d] = T::one();
            solve_lower_in_place(l, &mut x);
            solve_upper_t_in_place(l, &mut x);
            let vif = x[d];
            if vif > T::zero() {
                residual[d] = T::one() / vif;
                for k in (0..n).filter(|&k| kept[k] && k != d) {
                    beta[(k, d)] = -x[k] / vif;
                }
            }
        }
    }
    Ok(Identifiability {
        kept,
        left_out,
        residual,
        beta,
        scale: s,
        absorb_threshold: settings.absorb_threshold,
        rcond: if dmax > T::zero() {
            dmin / dmax
        } else {
            T::zero()
        },
    })
}

/// The pivoted Cholesky of [`identifiability`] alone: which candidates are
/// kept (the rest of [`identifiability`] explains the left-out ones).
struct Pivoted<T: RealField + Copy, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    kept: OVector<bool, D>,
    left_out: OVector<bool, D>,
    s: OVector<T, D>,
    a: OMatrix<T, D, D>,
    dmin: T,
    dmax: T,
}

/// `lambda` finite and `candidates` of its size (checked by the callers).
fn pivot<T: RealField + Copy, D: Dim>(
    lambda: &OMatrix<T, D, D>,
    candidates: &[bool],
    excluded: &[bool],
    settings: &IdentifiabilitySettings<T>,
) -> Pivoted<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    let n = lambda.nrows();
    let dim = lambda.shape_generic().0;
    let flags = || OVector::<bool, D>::from_element_generic(dim, Const::<1>, false);
    let (mut kept, mut left_out, mut open) = (flags(), flags(), flags());
    // Scaling; parameters without information are left out outright.
    let mut s = OVector::<T, D>::zeros_generic(dim, Const::<1>);
    let dmax_info = (0..n)
        .filter(|&i| candidates[i])
        .fold(T::zero(), |m, i| m.max(lambda[(i, i)]));
    let floor = settings.negligible * dmax_info;
    for i in (0..n).filter(|&i| candidates[i]) {
        let d = lambda[(i, i)];
        if d > floor && d > T::zero() {
            s[i] = T::one() / d.sqrt();
            open[i] = true;
        } else {
            left_out[i] = true;
        }
    }
    let a = OMatrix::<T, D, D>::from_fn_generic(dim, dim, |i, j| {
        if open[i] && open[j] {
            lambda[(i, j)] * s[i] * s[j]
        } else {
            T::zero()
        }
    });
    let mut r = a.clone();
    // Pivoted outer-product Cholesky on the open set.
    let (mut dmin, mut dmax) = (T::one(), T::zero());
    loop {
        let pick = match settings.pivoting {
            Pivoting::LayoutOrder => (0..n).find(|&i| open[i]),
            Pivoting::Largest => {
                (0..n)
                    .filter(|&i| open[i])
                    .fold(None, |best: Option<usize>, i| match best {
                        Some(b) if r[(i, i)] <= r[(b, b)] => Some(b),
                        _ => Some(i),
                    })
            }
        };
        let Some(p) = pick else { break };
        open[p] = false;
        let d = r[(p, p)];
        let dependent = excluded.get(p).copied().unwrap_or(false);
        if dependent || d.partial_cmp(&settings.tolerance) != Some(core::cmp::Ordering::Greater) {
            left_out[p] = true;
            continue;
        }
        kept[p] = true;
        dmin = dmin.min(d);
        dmax = dmax.max(d);
        for j in (0..n).filter(|&j| open[j]) {
            let f = r[(p, j)] / d;
            for i in (0..n).filter(|&i| open[i]) {
                let v = r[(i, p)] * f;
                r[(i, j)] -= v;
            }
        }
    }
    verify_kept(&a, &mut kept, &mut left_out, settings.tolerance);
    Pivoted {
        kept,
        left_out,
        s,
        a,
        dmin,
        dmax,
    }
}

/// Which `candidates` are kept, as [`identifiability`] with the default
/// settings decides, without the regressions that explain the left-out
/// ones (the device's in-stream diagnosis needs the flags alone:
/// [`super::screen`]).
///
/// # Errors
/// As [`identifiability`].
pub fn independent<T: RealField + Copy, D: Dim>(
    lambda: &OMatrix<T, D, D>,
    candidates: &[bool],
) -> Result<OVector<bool, D>, Error>
where
    DefaultAllocator: Alloc<D>,
{
    if candidates.len() != lambda.nrows() {
        return Err(Error::Mismatch {
            what: "one candidate flag per parameter",
        });
    }
    if !lambda.iter().all(|v| v.is_finite()) {
        return Err(Error::NonFinite {
            what: "information",
        });
    }
    Ok(pivot(lambda, candidates, &[], &IdentifiabilitySettings::default()).kept)
}

impl<T: RealField + Copy, D: Dim> Accumulator<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    /// Which of all the parameters the accumulated rows can identify, in
    /// layout order, with the one tolerance ([`identifiability`] with the
    /// default settings).
    ///
    /// # Errors
    /// [`Error::NonFinite`] when `Λ` holds NaN or ±∞.
    pub fn identifiable(&self) -> Result<Identifiability<T, D>, Error> {
        let dim = self.dim();
        let all = OVector::<bool, D>::from_element_generic(dim, Const::<1>, true);
        identifiability(
            &self.information(),
            all.as_slice(),
            &IdentifiabilitySettings::default(),
        )
    }
}
