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
//! taken, but later parameters can still lean on it, so the pivots alone
//! do not bound the VIF of a kept parameter by `1/tolerance` (7e6 was seen
//! with layout-order pivoting on a random arm): the next paragraph.
//!
//! **The criterion as stated**: every kept parameter's `1 − R²` on *all*
//! the other kept ones (`1/VIF`) exceeds the tolerance. The greedy pivots
//! meet it as a rule, not always: a column a small angle off an exact
//! dependency passes its pivot (`1 − R²` ≈ sin² of the angle, 1e-4 at 10
//! mrad) and a later column closes the dependency, so the kept set holds a
//! near-null direction (a calibrated robot as the nominal one: its
//! misaligned axes turn the nominal robot's exact dependencies into such
//! near ones; VIF 5e12 and σ of 300 m on TIAGo with the tolerance, a set
//! as well determined as the first calibration's with it ×100). When the
//! kept set breaks the criterion, the pivots are taken again with the
//! tolerance raised tenfold ([`ESCALATION`]), up to
//! [`MAX_ESCALATED_TOLERANCE`], and the first set that meets it is kept;
//! when none does, the first set is (its inflated parameters are then
//! reported by the caller). Sets that meet it at once are untouched.
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
use kept::{kept_factor, verify_kept, within_inflation};

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
    let (mut left_out, mut open) = (flags(), flags());
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
    // The greedy pivots with the tolerance, raised tenfold while the set
    // they keep breaks the criterion as stated (see the module docs); when
    // no raised tolerance meets it, the first set, as the pivots chose it.
    let pass = |tolerance: T| greedy(&a, &open, &left_out, excluded, settings.pivoting, tolerance);
    let first = pass(settings.tolerance);
    let mut raised = None;
    if !within_inflation(&a, &first.kept, settings.tolerance) {
        let (ten, most) = (
            nalgebra::convert::<f64, T>(ESCALATION),
            nalgebra::convert::<f64, T>(MAX_ESCALATED_TOLERANCE),
        );
        let mut tolerance = settings.tolerance * ten;
        while tolerance <= most {
            let g = pass(tolerance);
            if within_inflation(&a, &g.kept, settings.tolerance) {
                raised = Some(g);
                break;
            }
            tolerance *= ten;
        }
    }
    let mut g = raised.unwrap_or(first);
    verify_kept(&a, &mut g.kept, &mut g.left_out, settings.tolerance);
    Pivoted {
        kept: g.kept,
        left_out: g.left_out,
        s,
        a,
        dmin: g.dmin,
        dmax: g.dmax,
    }
}

/// Each raise of the greedy pivots' tolerance ([`identifiability`]'s
/// module docs): tenfold.
pub const ESCALATION: f64 = 10.0;

/// The greedy pivots' tolerance is raised at most to this `1 − R²` (a
/// column 99 % explained by the kept ones before it). 1e-2.
pub const MAX_ESCALATED_TOLERANCE: f64 = 1e-2;

/// The kept set of one pass of the greedy pivots.
struct Greedy<T: RealField + Copy, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    kept: OVector<bool, D>,
    left_out: OVector<bool, D>,
    dmin: T,
    dmax: T,
}

/// Pivoted outer-product Cholesky of the scaled `a` on the `open` set
/// (`left_out`: the candidates already left out, without information): a
/// column is kept when its pivot exceeds `tolerance` and `excluded` does
/// not flag it.
fn greedy<T: RealField + Copy, D: Dim>(
    a: &OMatrix<T, D, D>,
    open: &OVector<bool, D>,
    left_out: &OVector<bool, D>,
    excluded: &[bool],
    pivoting: Pivoting,
    tolerance: T,
) -> Greedy<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    let n = a.nrows();
    let mut open = open.clone();
    let mut left_out = left_out.clone();
    let mut kept = OVector::<bool, D>::from_element_generic(a.shape_generic().0, Const::<1>, false);
    let mut r = a.clone();
    let (mut dmin, mut dmax) = (T::one(), T::zero());
    loop {
        let pick = match pivoting {
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
        if dependent || d.partial_cmp(&tolerance) != Some(core::cmp::Ordering::Greater) {
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
    Greedy {
        kept,
        left_out,
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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3x4, Matrix4};

    /// Columns `e0`, `e0 + ε e1`, `e1 + ε e2`, `e2` (ε = 3e-3): the second
    /// passes its pivot (ε² = 9e-6) and the third (≈ ε²) too, but the second
    /// is then `ε·(third)` short of the first, to `ε²`: a VIF of ~1e10.
    /// With the tolerance ×10 the second is left out and the fourth kept:
    /// the same rank, every VIF near 1.
    fn near_chain() -> Matrix4<f64> {
        let e = 3e-3;
        let c = Matrix3x4::new(1.0, 1.0, 0.0, 0.0, 0.0, e, 1.0, 0.0, 0.0, 0.0, e, 1.0);
        c.transpose() * c
    }

    #[test]
    fn a_near_null_set_is_taken_again_with_a_raised_tolerance() {
        let lambda = near_chain();
        let tol = independence_tolerance::<f64>();
        // The greedy pivots alone, on the scaled Λ, keep the first three,
        // and that set breaks the criterion as stated.
        let d = lambda.diagonal().map(|v| 1.0 / v.sqrt());
        let a = Matrix4::from_fn(|i, j| lambda[(i, j)] * d[i] * d[j]);
        let all = OVector::<bool, Const<4>>::from_element(true);
        let none = OVector::<bool, Const<4>>::from_element(false);
        let g = greedy(&a, &all, &none, &[], Pivoting::LayoutOrder, tol);
        assert_eq!(g.kept.as_slice(), &[true, true, true, false]);
        assert!(!within_inflation(&a, &g.kept, tol));
        // The test keeps the same rank, well determined.
        let id = identifiability(&lambda, &[true; 4], &IdentifiabilitySettings::default()).unwrap();
        assert_eq!(id.kept.as_slice(), &[true, false, true, true]);
        assert!(id.is_left_out(1));
        for i in [0, 2, 3] {
            let vif = id.inflation(i).unwrap();
            assert!(vif < 2.0, "parameter {i}: VIF {vif}");
        }
    }
}
