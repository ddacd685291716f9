//! The engine's leave-one-configuration-out prediction error
//! ([`Engine::heldout`]): OLS in closed form ([`crate::calibrate::fit::heldout`]),
//! a fit with weights fixed in advance (the instrument's σ) — or re-estimated
//! on more configurations than `Policy::heldout_refit_groups`, held — by a
//! downdate of its sums per configuration
//! ([`crate::calibrate::fit::moments::FixedFolds`]), other weighted fits
//! from the moments per configuration and axis (their weights refitted),
//! refits where those cannot.

use nalgebra::Vector3;

use crate::calibrate::engine::{Engine, Fitted};
use crate::calibrate::fit::heldout::{ols_heldout, HeldOut, OlsHeldOut, WINDOW_ROWS};
use crate::calibrate::fit::moments::DesignMoments;
use crate::calibrate::fit::residuals::SquareSum;
use crate::calibrate::fit::Weighting;
use crate::calibrate::fit::{fit, fit_moments, Method};
use crate::calibrate::settings::CalibrationError;
use crate::error::Error;
use crate::estimate::robust_weights;

impl Engine<'_> {
    /// Leave-one-configuration-out prediction RMS \[µm\] of `fitted`: each
    /// configuration's points predicted by a fit (same method, same
    /// linearisation) without it — without a pose's orientation too
    /// ([`crate::calibrate::rows::Rows::fold`]). Parameters the other
    /// configurations cannot identify are held at zero (their error then
    /// shows in the prediction).
    ///
    /// # Errors
    /// [`CalibrationError::Core`] from the estimator.
    pub fn heldout(&mut self, fitted: &Fitted) -> Result<Option<f64>, CalibrationError> {
        if !self.heldout || self.rows.configs.len() < 2 {
            return Ok(None);
        }
        self.restore(fitted)?;
        let d = self.design(&fitted.params)?;
        let cols: Vec<usize> = (0..fitted.params.len()).collect();
        // The held-out residuals' squares summed in row order as they come
        // (their [`rms_um`], without a vector of them all).
        let mut res = SquareSum::default();
        (self.progress)(&format!(
            "held-out RMS: {} fits, one without each configuration",
            self.rows.error_groups()
        ));
        // OLS: the closed form of `heldout` (exact at one linearisation);
        // a group no other can replace, and weighted fits, are refitted.
        let Some(by) = d.group_rows() else {
            return Ok(None);
        };
        let ols = self.fit_settings.method == Method::Ols;
        // A pose's fold leaves out two groups (its points' and its
        // orientations'): OLS then downdates the unit-weight sums of both
        // (`FixedFolds` at weight 1), not the one group's closed form.
        // (So do a configuration's plane contacts and distances beside its
        // points.)
        let poses = self.rows.orientation_groups > 0 || self.rows.scalar_groups > 0;
        let fast = (ols && !poses)
            .then(|| ols_heldout(&d, &cols, fitted.information.as_ref()))
            .flatten();
        // Its residuals a window of groups (`WINDOW_ROWS` rows) at a time.
        let mut window: Option<HeldOut> = None;
        // Weighted fits: each fold from the moments per configuration and
        // axis, built once (`moments`); a fold that leaves a parameter
        // unidentified is refitted from the rows below.
        let moments = (!ols || poses).then(|| DesignMoments::new(&d, &cols));
        // The folds from the moments are independent: on worker threads
        // (`parallel`; bit for bit the serial loop's), unless the problem
        // is too small for threads to pay.
        let groups = self.rows.configs.len();
        // The points' configurations: a pose's orientation (a group of its
        // own, after them) is not predicted here, in µm, nor a plane
        // contact or a distance beside points (in data of those alone,
        // their groups: `Rows::error_groups`).
        let points = self.rows.error_groups();
        let settings = self.fit_settings;
        // Residuals in metres again ([`Rows::unscaled`]).
        let rows = &self.rows;
        // Weights fixed in advance (the instrument's σ, one weighted fit):
        // each fold by a downdate of the sums (`FixedFolds`), not a fit.
        let instrument = d.instrument_sigma.as_deref();
        // Weights re-estimated (IRLS, eq. 14) on more configurations than
        // `Policy::heldout_refit_groups`: each fold at the whole fit's
        // weights, held (the configuration left out moves the others' σ
        // only through the estimate: a second-order change).
        let held = (self.fit_settings.method != Method::Ols
            && groups > self.policy.heldout_refit_groups
            && fitted.fit.weights.len() == groups)
            .then(|| fitted.fit.weights.clone());
        let fixed_weights: Option<Vec<Vector3<f64>>> = if ols {
            poses.then(|| vec![Vector3::repeat(1.0); groups])
        } else {
            instrument
                .filter(|_| settings.weighting == Weighting::Instrument)
                .and_then(|sigma| {
                    let mut w = vec![Vector3::zeros(); sigma.len()];
                    robust_weights(sigma, &settings.weight, &mut w).ok()?;
                    Some(w)
                })
                .or(held)
        };
        let fixed = match (&moments, &fixed_weights) {
            (Some(m), Some(w)) => m.fixed_folds(w).ok(),
            _ => None,
        };
        let folds: Vec<Option<Vec<Vector3<f64>>>> = match (&moments, &fixed) {
            (Some(_), Some(f)) => {
                let small = groups * cols.len() * cols.len() * cols.len() < 200_000;
                let threads = if small { 1 } else { crate::parallel::threads() };
                crate::parallel::map(points, threads, |g| {
                    let x = f.estimate(&rows.fold(g)).ok()?;
                    Some(
                        by.of(g)
                            .iter()
                            .map(|&i| rows.unscaled(i, d.residual(&cols, x.as_slice(), i)))
                            .collect(),
                    )
                })
            }
            (Some(m), None) => {
                let small = groups * groups * cols.len() * cols.len() < 20_000;
                let threads = if small { 1 } else { crate::parallel::threads() };
                crate::parallel::map(points, threads, |g| {
                    // An error is left to the refit below, which decides as
                    // before (a column dropped, no held-out error, or the
                    // error).
                    let out = fit_moments(m, &d, &cols, &rows.fold(g), &settings).ok()?;
                    Some(
                        by.of(g)
                            .iter()
                            .map(|&i| rows.unscaled(i, d.residual(&cols, &out.x, i)))
                            .collect(),
                    )
                })
            }
            (None, _) => Vec::new(),
        };
        for g in 0..points {
            if let Some(f) = &fast {
                if window.as_ref().is_none_or(|w| g >= w.first + w.ok.len()) {
                    window = Some(f.groups(&by, OlsHeldOut::window(&by, g, WINDOW_ROWS)));
                }
            }
            if let Some(r) = window.as_ref().and_then(|w| w.of(&by, g)) {
                for (&i, &r) in by.of(g).iter().zip(r) {
                    res.extend(&[self.rows.unscaled(i, r)]);
                }
                continue;
            }
            if let Some(r) = folds.get(g).and_then(Option::as_ref) {
                res.extend(r);
                continue;
            }
            let mut use_cols = cols.clone();
            let out = loop {
                match fit(&d, &use_cols, &self.rows.fold(g), &self.fit_settings) {
                    Ok(f) => break Some(f),
                    Err(Error::NotIdentifiable { column, .. }) if column < use_cols.len() => {
                        use_cols.remove(column);
                    }
                    Err(Error::TooFewEquations { .. }) => break None,
                    Err(e) => return Err(CalibrationError::Core("held-out fit", e)),
                }
            };
            let Some(out) = out else { return Ok(None) };
            for &i in by.of(g).iter() {
                res.extend(&[self.rows.unscaled(i, d.residual(&use_cols, &out.x, i))]);
            }
        }
        self.restore(fitted)?;
        Ok(Some(res.rms_um()))
    }

    /// `f` with its held-out RMS.
    ///
    /// # Errors
    /// As [`Engine::heldout`].
    pub fn with_heldout(&mut self, mut f: Fitted) -> Result<Fitted, CalibrationError> {
        f.heldout_rms_um = self.heldout(&f)?;
        Ok(f)
    }
}
