//! The closed loop on the device (issue 17): fit the model by iterative
//! WLS over a stream of deflections, then in **one more pass** accumulate the
//! cross-products of the model's columns and of every candidate effect's
//! (`robcal::estimate::screen::Augmented`) and the pure error of the
//! repetitions (`PureError`), test every candidate from them with the
//! host's rule (nested F test, Bonferroni over the candidates tried, share
//! of the lack of fit), add the most significant one whose estimate is
//! physical, refit, and repeat. No row is stored: memory is
//! `O((N+K)² + G)`.
//!
//! Generic over the scalar (f32 on the device, f64 in the host test that
//! compares it with `robcal calibrate --linear`,
//! `host-tests/tests/device_diagnosis.rs`) and over the data ([`Data`]: the
//! firmware's flash table, or a measurement file on the host).
//!
//! What the device does not do that the host does (documented, not
//! hidden): the leave-one-configuration-out check (an effect is added on
//! the host only if the held-out RMS drops: `G` refits per candidate), the
//! identifiability pruning of the extended model (`extended` on the host;
//! the device's candidate columns are already independent of the model by
//! the test), and the geometric effects (absolute rows, Gauss–Newton): see
//! `robcal::model::effect`.

use nalgebra::{Const, RealField, SMatrix, Vector3};
use robcal::estimate::screen::{Augmented, LackOfFit, PureError, Rule};
use robcal::estimate::{group_dof, group_sigma, leverage, NestedTest, Noise, Solution};
use robcal::model::effect::{inadmissible, joint_bins, stream_candidates, Effect, JointBins};
use robcal::model::{Layout, Marker, Param, Sample};
use robcal::robot::{joint_torques, Frames, PointLoad};
use robcal::{Accumulator, Block, Chain, Error, IrlsSettings, Reweightable};

/// Joints of the arm.
pub const J: usize = 6;
/// Model columns at most, and the size of one test's sub-problem (the
/// model and the candidate's informative columns): the KR-270's naive
/// model has 5 (+ 4 compensator bins), with the compensator 9, with the
/// backlash 10 (+ 1). One size for both: one copy of the solver in flash,
/// and f32 matrices of 484 bytes on the stack. A larger problem is refused
/// (`Error::Mismatch`), never truncated.
pub const NMAX: usize = 11;
/// The model's dimension.
pub type Dm = Const<NMAX>;
/// Columns of the augmented pass: the model's and every candidate's.
pub const P: usize = 32;
/// `P (P + 1) / 2`.
pub const L: usize = P * (P + 1) / 2;
/// Candidates at most.
pub const K: usize = 24;
/// One test's sub-problem: the model and one candidate ([`NMAX`]).
pub const S: usize = NMAX;
/// Angle bins of a joint at most (a compensator has 2 to 8).
pub const BINS: usize = 8;
/// Configurations at most.
pub const GMAX: usize = 16;
/// Cells (configuration × marker) at most.
pub const CELLS: usize = 3 * GMAX;
/// Effects added at most (`robcal::calibrate::Policy::max_effects` is 8;
/// the device's model capacity allows fewer).
pub const MAX_EFFECTS: usize = 3;
/// `Policy::max_drift_mm_per_h`.
pub const MAX_DRIFT_MM_PER_H: f64 = 5.0;

/// One measured deflection: its configuration (the group of the weights),
/// marker, time between the unloaded and the loaded measurement, and `Δp`.
#[derive(Clone, Copy, Debug)]
pub struct Meas<T: RealField + Copy> {
    /// Configuration index.
    pub group: usize,
    /// Marker index.
    pub marker: u8,
    /// `t_loaded − t_unloaded` \[s\] (0 without time).
    pub dt_s: T,
    /// Loaded − unloaded position \[m\].
    pub dp: Vector3<T>,
}

/// What the loop needs of a data set: the robot, its configurations (angles
/// and load), the markers, and a stream of the deflections (sorted by
/// configuration, so that the rows of a configuration are computed once).
pub trait Data<T: RealField + Copy> {
    /// The arm.
    fn chain(&self) -> &Chain<T, J>;
    /// Number of configurations.
    fn groups(&self) -> usize;
    /// Joint angles of configuration `g` \[rad\].
    fn q(&self, g: usize) -> [T; J];
    /// The load of configuration `g`.
    fn load(&self, g: usize) -> PointLoad<T>;
    /// Marker `m`.
    fn marker(&self, m: u8) -> Option<Marker<T>>;
    /// Whether the measurements carry time (a drift candidate).
    fn time(&self) -> bool;
    /// Every deflection, in order (a `dyn` callback: one copy of the loop
    /// in flash, not one per caller).
    fn for_each(&self, f: &mut dyn FnMut(&Meas<T>) -> Result<(), Error>) -> Result<(), Error>;
}

/// The rows of a configuration: frames, the load's torques and wrench.
struct Config<T: RealField + Copy> {
    g: usize,
    frames: Frames<T, J>,
    tau: [T; J],
    wrench: robcal::robot::Wrench<T>,
}

/// The rows of configuration `g` into `cached` (`None` on error). Not
/// inlined: the kinematics' temporaries are on the stack only while it runs.
#[inline(never)]
fn config<T: RealField + Copy, D: Data<T>>(
    data: &D,
    g: usize,
    cached: &mut Option<Config<T>>,
) -> Result<(), Error> {
    let q = data.q(g);
    // The frames computed into the cache itself (no copy of them here).
    *cached = None;
    let c = cached.insert(Config {
        g,
        frames: data.chain().frames(&q)?,
        tau: [T::zero(); J],
        wrench: robcal::robot::Wrench {
            force_n: Vector3::zeros(),
            point_m: Vector3::zeros(),
            moment_nm: Vector3::zeros(),
        },
    });
    c.wrench = data.load(g).wrench(&c.frames);
    let done = joint_torques(&c.frames, &c.wrench, &mut c.tau);
    if done.is_err() {
        *cached = None;
    }
    done
}

/// What [`stream`] hands each deflection to: the measurement and its rows.
type RowSink<'a, T, const C: usize> =
    dyn FnMut(&Meas<T>, &SMatrix<T, 3, C>) -> Result<(), Error> + 'a;

/// Streams every deflection with its rows `B` for `layout` (columns past it
/// zero). The load centre of mass's column is first order about the joint
/// law the rows are linearised at; as the host's first-order model
/// (`--linear`), the device linearises at the nominal robot (no
/// compliance), where that column is zero: the host never tries
/// `load_com` there, nor does the device (a host inconsistency, reported
/// in issue 17: with the fitted compliances it would be tested).
#[inline(never)]
fn stream<T: RealField + Copy, D: Data<T>, const C: usize>(
    data: &D,
    layout: &Layout<C>,
    f: &mut RowSink<'_, T, C>,
) -> Result<(), Error> {
    let mut cached: Option<Config<T>> = None;
    let mut b = SMatrix::<T, 3, C>::zeros();
    data.for_each(&mut |m| {
        if cached.as_ref().map(|c| c.g) != Some(m.group) {
            config(data, m.group, &mut cached)?;
        }
        let c = cached.as_ref().ok_or(Error::Mismatch { what: "no rows" })?;
        let marker = data.marker(m.marker).ok_or(Error::OutOfRange {
            what: "marker",
            index: usize::from(m.marker),
            len: 0,
        })?;
        let sample = Sample {
            dt_s: m.dt_s,
            ..Sample::deflection(
                &c.frames,
                c.frames.point_m(&marker.xyz_m),
                m.marker,
                &c.tau,
                Some(c.wrench),
            )
        };
        layout.fill(&sample, &mut b)?;
        f(m, &b)
    })
}

/// The model as a streaming [`Reweightable`] source (as the firmware's
/// KR-270 source, at the model's columns).
struct ModelSource<'a, T: RealField + Copy, D: Data<T>> {
    data: &'a D,
    layout: &'a Layout<NMAX>,
    scalar: core::marker::PhantomData<T>,
}

impl<T: RealField + Copy, D: Data<T>> Reweightable<T, Dm> for ModelSource<'_, T, D> {
    fn group_count(&self) -> usize {
        self.data.groups()
    }

    fn weighted(
        &self,
        weights: &[Vector3<T>],
        noise: Option<Noise<'_, T>>,
    ) -> Result<Accumulator<T, Dm>, Error> {
        let g = self.data.groups();
        if weights.len() != g || noise.is_some_and(|n| !n.fits(g)) {
            return Err(Error::Mismatch {
                what: "one weight (and sigma) per group",
            });
        }
        let mut acc = Accumulator::new();
        stream(self.data, self.layout, &mut |m, b| {
            let w = weights[m.group];
            let mut block = Block::new(*b, m.dp).with_weights(w);
            if let Some(n) = noise {
                block = block.with_sigma(n.sigma(m.group, &w));
            }
            acc.update(&block)
        })?;
        Ok(acc)
    }

    fn residual_sigma_into(
        &self,
        fit: &Solution<T, Dm>,
        weights: &[Vector3<T>],
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
    ) -> Result<(), Error> {
        let g = self.data.groups();
        if sigma.len() != g || dof.len() != g || weights.len() != g || g > GMAX {
            return Err(Error::Mismatch {
                what: "one sigma and one weight per group",
            });
        }
        let mut rss = [Vector3::<T>::zeros(); GMAX];
        let mut h = [Vector3::<T>::zeros(); GMAX];
        let mut rows = [0usize; GMAX];
        stream(self.data, self.layout, &mut |m, b| {
            let r = m.dp - b * fit.x;
            rss[m.group] += r.component_mul(&r);
            for a in 0..3 {
                h[m.group][a] += leverage(&fit.lambda_inv, |c| b[(a, c)], weights[m.group][a]);
            }
            rows[m.group] += 1;
            Ok(())
        })?;
        for i in 0..g {
            sigma[i] = Vector3::from_fn(|a, _| group_sigma(rss[i][a], rows[i], h[i][a]));
            dof[i] = Vector3::from_fn(|a, _| group_dof(rows[i], h[i][a]));
        }
        Ok(())
    }
}

/// A fitted model: its layout, estimate (reported units), weights and RMS.
#[derive(Clone, Debug)]
pub struct Fitted<T: RealField + Copy> {
    /// The model's columns.
    pub layout: Layout<NMAX>,
    /// The estimate, one per column.
    pub x: [T; NMAX],
    /// Weights per configuration and axis (eq. 14) of the final fit.
    pub weights: [Vector3<T>; GMAX],
    /// RMS of the position residuals \[µm\] (as the host's `rms_um`).
    pub rms_um: f64,
    /// IRLS iterations.
    pub iterations: usize,
}

impl<T: RealField + Copy> Fitted<T> {
    /// No model yet (a buffer for [`fit`]).
    fn empty() -> Self {
        Self {
            layout: Layout::new(),
            x: [T::zero(); NMAX],
            weights: [Vector3::zeros(); GMAX],
            rms_um: 0.0,
            iterations: 0,
        }
    }
}

fn to_f64<T: RealField + Copy>(v: T) -> f64 {
    nalgebra::try_convert::<T, f64>(v).unwrap_or(f64::NAN)
}

/// The OLS start's estimate (`Reweightable::fit_ols`). Not inlined: its fit
/// is not on the stack during the reweighted ones.
#[inline(never)]
fn ols<T: RealField + Copy, D: Data<T>>(
    src: &ModelSource<'_, T, D>,
    active: &[bool],
    weights: &mut [Vector3<T>],
    sigma: &mut [Vector3<T>],
    dof: &mut [Vector3<T>],
) -> Result<SMatrix<T, NMAX, 1>, Error> {
    match &src.fit_ols(active, weights, sigma, dof) {
        Ok(f) => Ok(f.solution.x),
        Err(e) => Err(*e),
    }
}

/// One reweighted fit (`Reweightable::fit_reweighted`): its estimate into
/// `x`, and the largest move of a parameter from the previous `x` in its
/// standard deviations (`Reweightable::fit_irls`'s convergence test). Not
/// inlined, as [`ols`].
#[inline(never)]
fn reweighted<T: RealField + Copy, D: Data<T>>(
    src: &ModelSource<'_, T, D>,
    settings: &IrlsSettings<T>,
    active: &[bool],
    weights: &mut [Vector3<T>],
    sigma: &mut [Vector3<T>],
    dof: &mut [Vector3<T>],
    x: &mut SMatrix<T, NMAX, 1>,
) -> Result<T, Error> {
    let next = src.fit_reweighted(&settings.weight, active, weights, sigma, dof);
    let f = match &next {
        Ok(f) => f,
        Err(e) => return Err(*e),
    };
    let std = f.std();
    let mut change = T::zero();
    for i in 0..active.len() {
        if active[i] && std[i] > T::zero() {
            change = change.max((f.solution.x[i] - x[i]).abs() / std[i]);
        }
    }
    *x = f.solution.x;
    Ok(change)
}

/// Iterative WLS of `layout` over the stream, to convergence, and the RMS
/// of its residuals (one more pass), into `out` (unchanged on error). Not
/// inlined: its frame stays out of the loop's.
#[inline(never)]
fn fit<T: RealField + Copy, D: Data<T>>(
    data: &D,
    layout: &Layout<NMAX>,
    settings: &IrlsSettings<T>,
    out: &mut Fitted<T>,
) -> Result<(), Error> {
    let g = data.groups();
    if g > GMAX {
        return Err(Error::CapacityExceeded {
            what: "configurations",
            capacity: GMAX,
        });
    }
    let src = ModelSource {
        data,
        layout,
        scalar: core::marker::PhantomData,
    };
    let mut weights = [Vector3::zeros(); GMAX];
    let mut sigma = [Vector3::zeros(); GMAX];
    let mut dof = [Vector3::zeros(); GMAX];
    let mut active = [false; NMAX];
    active[..layout.len()].fill(true);
    // `Reweightable::fit_irls` step for step (the same fits, the same
    // convergence test), with one fit on the stack instead of two: the
    // previous estimate is all the test needs of the previous fit, and
    // each fit lives in the frame of the helper that made it ([`ols`],
    // [`reweighted`]).
    if settings.max_iterations == 0 {
        return Err(Error::OutOfRange {
            what: "max_iterations",
            index: 0,
            len: 0,
        });
    }
    let mut x = ols(
        &src,
        &active,
        &mut weights[..g],
        &mut sigma[..g],
        &mut dof[..g],
    )?;
    let mut iterations = 0;
    for k in 1..=settings.max_iterations {
        let change = reweighted(
            &src,
            settings,
            &active,
            &mut weights[..g],
            &mut sigma[..g],
            &mut dof[..g],
            &mut x,
        )?;
        iterations = k;
        if change < settings.tolerance {
            break;
        }
    }
    let (mut ss, mut rows) = (0.0f64, 0usize);
    stream(data, layout, &mut |m, b| {
        let r = m.dp - b * x;
        ss += to_f64(r.norm_squared());
        rows += 1;
        Ok(())
    })?;
    out.layout = layout.clone();
    out.x.copy_from_slice(x.as_slice());
    out.weights = weights;
    out.rms_um = if rows == 0 {
        0.0
    } else {
        libm::sqrt(ss / rows as f64) * 1e6
    };
    out.iterations = iterations;
    Ok(())
}

/// One effect added.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Step {
    /// The effect.
    pub effect: Effect,
    /// Its joint.
    pub joint: Option<u8>,
    /// Its test.
    pub test: NestedTest,
    /// Candidates tested in its round (the Bonferroni count).
    pub tried: usize,
    /// RMS before and after \[µm\].
    pub rms_um: (f64, f64),
}

/// What the loop found.
#[derive(Clone, Debug)]
pub struct Outcome<T: RealField + Copy> {
    /// The declared model's fit.
    pub declared_rms_um: f64,
    /// The effects added, in order.
    pub steps: heapless::Vec<Step, MAX_EFFECTS>,
    /// The final fit.
    pub last: Fitted<T>,
    /// Candidates tested in the first round.
    pub first_tried: usize,
    /// The first round's lack of fit.
    pub first_lof: Option<LackOfFit>,
}

/// Column indices of a bit mask.
fn indices(mask: u64, out: &mut [usize; 64]) -> usize {
    let mut n = 0;
    for i in 0..64 {
        if mask & (1u64 << i) != 0 {
            out[n] = i;
            n += 1;
        }
    }
    n
}

/// One candidate's test, compactly: what ranks and selects it (the
/// round's [`Round`] holds what all tests share: the model's weighted RSS
/// and the equations).
#[derive(Clone, Copy)]
struct Tested {
    /// Index into [`Round::cands`].
    cand: u8,
    /// Its columns tested (`NestedTest::dof_num`).
    q: u8,
    delta_rss: f64,
    f: f64,
    p_value: f64,
}

/// What one round's screening leaves to the loop: the augmented layout,
/// the candidates, their tests (most significant first) and the lack of
/// fit. Owned by the loop and filled in place (no returned copies); the
/// sums themselves live only in [`screen`].
struct Round {
    aug: Layout<P>,
    cands: heapless::Vec<robcal::model::effect::StreamCandidate, K>,
    tests: heapless::Vec<Tested, K>,
    /// Every test's `rss_before` (the model's weighted RSS).
    rss_before: f64,
    /// Every test's `dof_num + dof_den` (equations minus the model's columns).
    dof: usize,
    lof: Option<LackOfFit>,
}

impl Round {
    /// The full test of `t` (`Augmented::test_fitted`'s, field for field).
    fn test(&self, t: &Tested) -> NestedTest {
        let q = usize::from(t.q);
        NestedTest {
            delta_rss: t.delta_rss,
            rss_before: self.rss_before,
            f: t.f,
            dof_num: q,
            dof_den: self.dof - q,
            p_value: t.p_value,
        }
    }

    /// Orders the tests as `screen::rank_tests` (by p-value, then by F,
    /// largest first; stable).
    fn rank(&mut self) {
        let before = |a: &Tested, b: &Tested| match a.p_value.total_cmp(&b.p_value) {
            core::cmp::Ordering::Less => true,
            core::cmp::Ordering::Equal => b.f.total_cmp(&a.f) == core::cmp::Ordering::Less,
            core::cmp::Ordering::Greater => false,
        };
        let t = &mut self.tests;
        for i in 1..t.len() {
            let mut j = i;
            while j > 0 && before(&t[j], &t[j - 1]) {
                t.swap(j, j - 1);
                j -= 1;
            }
        }
    }
}

/// The sums of one screening pass (`Augmented`, `PureError`): built in
/// place by [`screen`], dropped when it returns.
struct Sums<T: RealField + Copy> {
    aug: Augmented<T, P, L>,
    pure: PureError<T, CELLS>,
}

/// The candidates of the model `layout` into `round` (their layout after
/// the model's columns). Not inlined: the returned copies stay in its frame.
#[inline(never)]
fn candidates<T: RealField + Copy, D: Data<T>>(
    data: &D,
    layout: &Layout<NMAX>,
    bins: &[JointBins<BINS>; J],
    round: &mut Round,
) -> Result<(), Error> {
    let n = layout.len();
    let mut model = [Param::Compliance { joint: 0 }; NMAX];
    for (m, c) in model.iter_mut().zip(layout.columns()) {
        *m = c.param;
    }
    (round.aug, round.cands) =
        stream_candidates::<T, J, P, K, BINS>(data.chain(), &model[..n], bins, data.time())?;
    Ok(())
}

/// The screening of one round on `cur`: one pass over the stream, every
/// candidate tested (the model factored once), into `round`. Not inlined:
/// its sums are on the stack only while it runs, not during the fits.
#[inline(never)]
fn screen<T: RealField + Copy, D: Data<T>>(
    data: &D,
    cur: &Fitted<T>,
    bins: &[JointBins<BINS>; J],
    round: &mut Round,
) -> Result<(), Error> {
    let n = cur.layout.len();
    candidates(data, &cur.layout, bins, round)?;
    round.tests.clear();
    round.lof = None;
    let mut sums = Sums {
        aug: Augmented::<T, P, L>::new()?,
        pure: PureError::<T, CELLS>::new(),
    };
    // The model fit's residuals `r = Δp − B_A X̂_A` in place of `Δp`: every
    // test is the same (`r` differs from `Δp` by a combination of the
    // model's columns), and the scores `B_Cᵀ W² r` are summed directly
    // instead of as a difference of large sums (in f32 that moved F by
    // 1 %). The model's columns are the layout's first `n`.
    let mut x = SMatrix::<T, P, 1>::zeros();
    x.as_mut_slice()[..n].copy_from_slice(&cur.x[..n]);
    stream(data, &round.aug, &mut |m, b| {
        let r = m.dp - b * x;
        sums.aug.update(b, &r, &cur.weights[m.group])?;
        sums.pure.update(m.group as u16, u16::from(m.marker), &m.dp)
    })?;
    test_all(&sums, cur, data.groups(), round)
}

/// Every candidate of `round` tested from the sums (the model factored
/// once), ranked, and the lack of fit. Not inlined: its frame is not on
/// the stack during the stream.
#[inline(never)]
fn test_all<T: RealField + Copy>(
    sums: &Sums<T>,
    cur: &Fitted<T>,
    groups: usize,
    round: &mut Round,
) -> Result<(), Error> {
    let n = cur.layout.len();
    let model_cols: [usize; NMAX] = core::array::from_fn(|i| i);
    // The model's fit at these weights, once for every candidate and for
    // the lack of fit (its weighted RSS).
    let fit = sums.aug.solve_model(&model_cols[..n], Const::<S>);
    let fit = match &fit {
        Ok(f) => f,
        Err(e) => return Err(*e),
    };
    let wrss = to_f64(fit.wrss);
    round.rss_before = wrss;
    round.dof = sums.aug.equations().saturating_sub(n);
    let mut cols = [0usize; 64];
    for (i, c) in round.cands.iter().enumerate() {
        let q = indices(c.test, &mut cols);
        let r = sums
            .aug
            .test_fitted(&model_cols[..n], fit, &cols[..q], Const::<S>)?;
        if let Some(t) = r {
            // Within capacity: one test per candidate (K ≤ 255, q ≤ 64).
            let _ = round.tests.push(Tested {
                cand: i as u8,
                q: t.dof_num as u8,
                delta_rss: t.delta_rss,
                f: t.f,
                p_value: t.p_value,
            });
        }
    }
    round.rank();
    round.lof = sums.pure.lack_of_fit(wrss, &cur.weights[..groups], n);
    Ok(())
}

/// The model with a candidate added (the host's `extended`, without its
/// identifiability pruning): its parameters where the ones it replaces
/// were, else at the end. Not inlined: its buffers are not under the fit.
#[inline(never)]
fn extended(
    model: &Layout<NMAX>,
    aug: &Layout<P>,
    c: &robcal::model::effect::StreamCandidate,
    chain: &Chain<impl RealField + Copy, J>,
) -> Result<Layout<NMAX>, Error> {
    let col = |i: usize| aug.columns()[i].param;
    let removed = |p: &Param| aug.index_of(p).is_some_and(|i| c.remove & (1u64 << i) != 0);
    let params = model.columns();
    let at = params
        .iter()
        .position(|p| removed(&p.param))
        .unwrap_or(params.len());
    let mut out = Layout::new();
    for p in params[..at].iter().filter(|p| !removed(&p.param)) {
        out.push(chain, p.param)?;
    }
    let mut idx = [0usize; 64];
    let na = indices(c.add, &mut idx);
    for &i in &idx[..na] {
        if model.index_of(&col(i)).is_none() {
            out.push(chain, col(i))?;
        }
    }
    for p in params[at..].iter().filter(|p| !removed(&p.param)) {
        out.push(chain, p.param)?;
    }
    Ok(out)
}

/// Whether the estimate of the parameters `c` adds to `next` is physical
/// (`effect::inadmissible`).
#[inline(never)]
fn physical<T: RealField + Copy>(
    next: &Fitted<T>,
    aug: &Layout<P>,
    c: &robcal::model::effect::StreamCandidate,
) -> bool {
    let mut params = [Param::Compliance { joint: 0 }; NMAX];
    let mut x = [0.0; NMAX];
    for (i, col) in next.layout.columns().iter().enumerate() {
        params[i] = col.param;
        x[i] = to_f64(next.x[i]);
    }
    let mut idx = [0usize; 64];
    let na = indices(c.add, &mut idx);
    let added = idx[..na].iter().map(|&i| &aug.columns()[i].param);
    let m = next.layout.len();
    inadmissible(&params[..m], &x[..m], added, MAX_DRIFT_MM_PER_H).is_none()
}

/// The model `cur` with candidate `c` added and refitted: when the fit
/// identifies it and its estimate is physical, it replaces `cur` and the
/// RMS before and after are returned. Not inlined: the new fit is on the
/// stack only while it runs (not during the screening).
#[inline(never)]
fn admissible<T: RealField + Copy, D: Data<T>>(
    data: &D,
    cur: &mut Fitted<T>,
    aug: &Layout<P>,
    c: &robcal::model::effect::StreamCandidate,
    settings: &IrlsSettings<T>,
) -> Result<Option<(f64, f64)>, Error> {
    let mut next = Fitted::empty();
    let next_layout = extended(&cur.layout, aug, c, data.chain());
    let next_layout = match &next_layout {
        Ok(l) => l,
        Err(e) => return Err(*e),
    };
    match fit(data, next_layout, settings, &mut next) {
        Ok(()) => {}
        Err(Error::NotIdentifiable { .. } | Error::TooFewEquations { .. }) => return Ok(None),
        Err(e) => return Err(e),
    }
    if !physical(&next, aug, c) {
        return Ok(None);
    }
    let rms = (cur.rms_um, next.rms_um);
    *cur = next;
    Ok(Some(rms))
}

/// Each joint's angle bins from the configurations (`g ≤ GMAX`). Not
/// inlined: its frame is not under the fit's.
#[inline(never)]
fn angle_bins<T: RealField + Copy, D: Data<T>>(
    data: &D,
    bins: &mut [JointBins<BINS>; J],
) -> Result<(), Error> {
    let g = data.groups().min(GMAX);
    let mut angles = [T::zero(); GMAX];
    for (j, b) in bins.iter_mut().enumerate() {
        for (i, a) in angles[..g].iter_mut().enumerate() {
            *a = data.q(i)[j];
        }
        *b = joint_bins(&angles[..g])?;
    }
    Ok(())
}

/// The declared model's fit into `out`, and each joint's angle bins from
/// the configurations into `bins`. Not inlined: its buffers are not on
/// the stack during the rounds.
#[inline(never)]
fn declared<T: RealField + Copy, D: Data<T>>(
    data: &D,
    model: &[Param],
    settings: &IrlsSettings<T>,
    bins: &mut [JointBins<BINS>; J],
    out: &mut Fitted<T>,
) -> Result<(), Error> {
    let g = data.groups();
    if g > GMAX {
        return Err(Error::CapacityExceeded {
            what: "configurations",
            capacity: GMAX,
        });
    }
    angle_bins(data, bins)?;
    let mut layout = Layout::new();
    for p in model {
        layout.push(data.chain(), *p)?;
    }
    fit(data, &layout, settings, out)
}

/// The closed loop: the declared `model`, then rounds of screening until
/// no candidate passes the `rule` with a physical estimate (or
/// [`MAX_EFFECTS`]). `log` gets each step as it is taken.
///
/// # Errors
/// From the fits and the screening.
pub fn run<T: RealField + Copy, D: Data<T>>(
    data: &D,
    model: &[Param],
    settings: &IrlsSettings<T>,
    rule: &Rule,
    mut log: impl FnMut(&Step),
) -> Result<Outcome<T>, Error> {
    let mut bins: [JointBins<BINS>; J] = core::array::from_fn(|_| JointBins {
        angles_urad: heapless::Vec::new(),
        compensator_ok: false,
    });
    // `out.last` is the current fit.
    let mut out = Outcome {
        declared_rms_um: 0.0,
        steps: heapless::Vec::new(),
        last: Fitted::empty(),
        first_tried: 0,
        first_lof: None,
    };
    declared(data, model, settings, &mut bins, &mut out.last)?;
    out.declared_rms_um = out.last.rms_um;
    let mut round = Round {
        aug: Layout::new(),
        cands: heapless::Vec::new(),
        tests: heapless::Vec::new(),
        rss_before: 0.0,
        dof: 0,
        lof: None,
    };
    for r in 0.. {
        screen(data, &out.last, &bins, &mut round)?;
        let lof = round.lof;
        if r == 0 {
            out.first_lof = lof;
            out.first_tried = round.tests.len();
        }
        let tried = round.tests.len();
        if out.steps.is_full() {
            break;
        }
        let mut step = None;
        for t in &round.tests {
            let test = round.test(t);
            if !rule.eligible(&test, tried, lof.as_ref()) {
                continue;
            }
            let c = &round.cands[usize::from(t.cand)];
            if let Some(rms_um) = admissible(data, &mut out.last, &round.aug, c, settings)? {
                step = Some(Step {
                    effect: c.effect,
                    joint: c.joint,
                    test,
                    tried,
                    rms_um,
                });
                break;
            }
        }
        let Some(step) = step else { break };
        log(&step);
        let _ = out.steps.push(step);
    }
    Ok(out)
}
