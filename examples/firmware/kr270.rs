//! The paper's KR-270 experiment (section 5) as the firmware runs it: the
//! robot as a constant, the 270 measured deflections from a compact table in
//! flash (`kr270_table.rs`, generated on the host by
//! `examples/firmware_table.rs` from `data/kr270/measurements.csv`), the
//! identification rows computed on the device, and a [`Reweightable`] source
//! that streams the table on every pass of the iterative WLS.
//!
//! Its fits are its own ([`Kr270::sweep`]): the table is read
//! configuration by configuration, the rows of a configuration computed
//! once per pass, and each marker's six repetitions taken together (same
//! rows: their `Σ Δp` and scatter, exact from the table's integers, see
//! [`Group`]). A configuration's residual σ needs only its own rows, so one
//! pass per fit gives the residual σ, the sandwich's middle term and the
//! next fit's `Λ`, `η` (eq. 14 weights from that σ); `η` is summed about
//! the previous estimate, which keeps f32 rounding below the iteration's
//! 1e-3 σ tolerance ([`Information`]).
//!
//! Memory is `O(N² + G)` and does not grow with the number of measurements:
//! the next fit's statistics (`Λ`, `η`, its weights: ~0.6 KB in f32), the σ
//! and weights per configuration and axis, and the three marker blocks of
//! the configuration being streamed. The rows are recomputed from the joint
//! angles on every pass (one forward kinematics and one set of load torques
//! per configuration, half of a pass), which trades `O(measurements)` RAM
//! (270 × 3 × 9 scalars, 29 KB in f32) or `O(G)` RAM (45 cached blocks,
//! 4.9 KB) for time.
//!
//! Generic over the scalar: the firmware runs it in f32; the host runs the
//! same code in f64 and compares it with [`robcal::GroupedStats`]
//! (`host-tests/tests/firmware_kr270.rs`).
//!
//! Units: the estimate in µrad/(N·m) (the layout's unit), `Δp` and σ in m.

use core::cell::Cell;
use nalgebra::{
    Const, Isometry3, RealField, SMatrix, SVector, Translation3, UnitQuaternion, Vector3,
};

use robcal::estimate::{
    group_dof, group_sigma, leverage, pool_small_groups, robust_weights, Noise, RobustWeight,
    Solution,
};
use robcal::model::{Layout, Marker, Sample};
use robcal::robot::{joint_torques, PointLoad};
use robcal::{Accumulator, Block, Chain, Error, Fit, IrlsSettings, Joint, JointKind, Reweightable};

// The generated data: `Q_CDEG`, `LOAD_DKG`, `KEYS`, `DP_NM`, `DP_QUANTUM_M`
// and the host's reference result `HOST_*`.
include!("kr270_table.rs");

/// Parameters: k21…k25, k3, k4, k5, k6 (`robcal_paper::kr270::PARAM_NAMES`).
pub const N: usize = robcal_paper::kr270::PARAMS;
/// The parameters as a nalgebra dimension.
pub type Dn = Const<N>;
/// Groups: the 15 configurations of Table 2.
pub const G: usize = robcal_paper::kr270::CONFIGS;
/// Movable joints.
pub const J: usize = 6;

/// One measured deflection (loaded − unloaded position of one marker, one
/// repetition), decoded from the table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Deflection {
    /// Configuration index 0…14 (the CSV's `config` − 1): the group.
    pub config: u8,
    /// Marker index 0…2 (the CSV's `marker` − 1).
    pub marker: u8,
    /// `Δp` (x, y, z, base frame) in units of [`DP_QUANTUM_M`] (1 nm).
    pub dp: [i32; 3],
}

/// The deflections of the table, in table order.
pub fn deflections() -> impl Iterator<Item = Deflection> {
    KEYS.iter().zip(DP_NM.iter()).map(|(&k, &dp)| Deflection {
        config: k >> 2,
        marker: k & 3,
        dp,
    })
}

/// The KR 270 R2700 ultra of `data/kr270/kr270.urdf`, written out: joint
/// origins \[m\] (all rpy 0), axes, and the `tool0` tip (flange turned by
/// 1.5707963 rad about y, the URDF's number). The host test checks it
/// against the URDF reader's chain.
pub fn chain<T: RealField + Copy>() -> Result<Chain<T, J>, Error> {
    // (origin xyz [m], axis), base to tip.
    const JOINTS: [([f64; 3], [f64; 3]); J] = [
        ([0.0, 0.0, 0.675], [0.0, 0.0, -1.0]),
        ([0.350, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ([1.150, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ([1.200, 0.0, -0.041], [-1.0, 0.0, 0.0]),
        ([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ([0.240, 0.0, 0.0], [-1.0, 0.0, 0.0]),
    ];
    // The URDF's literal, not π/2: the chain must be the URDF's to rounding.
    #[allow(clippy::approx_constant)]
    const TOOL0_PITCH_RAD: f64 = 1.570_796_3;
    let v = |a: [f64; 3]| Vector3::new(c(a[0]), c(a[1]), c(a[2]));
    let mut chain = Chain::new();
    for (xyz, axis) in JOINTS {
        let joint = Joint::from_urdf(v(xyz), Vector3::zeros(), v(axis), JointKind::Revolute)
            .ok_or(Error::NonFinite { what: "joint axis" })?;
        chain.push(joint)?;
    }
    chain.set_tip(Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_euler_angles(T::zero(), c(TOOL0_PITCH_RAD), T::zero()),
    ));
    Ok(chain)
}

/// The paper's layout: k21…k25 (A2's compliance by angle, one per q2 group
/// of Table 2), then k3…k6.
pub fn layout<T: RealField + Copy>(chain: &Chain<T, J>) -> Result<Layout<N>, Error> {
    robcal_paper::kr270::layout(chain)
}

fn c<T: RealField + Copy>(x: f64) -> T {
    nalgebra::convert(x)
}

/// Joint angles of configuration `g` \[rad\].
pub fn q_rad<T: RealField + Copy>(g: usize) -> [T; J] {
    Q_CDEG[g].map(|cdeg| c::<T>(f64::from(cdeg) * 0.01) * T::pi() / c(180.0))
}

/// `Δp` of a deflection \[m\]: the count of nanometres times the quantum
/// in `T`. The table's counts are below 2²⁴ (checked by the generator,
/// `examples/firmware_table.rs`), so they are exact in f32 as in f64 and
/// the product is the only rounding: in f64 the same value as
/// `f64::from(count) * 1e-9`; in f32 no soft-float f64 arithmetic on the
/// device (through f64 it cost ~400 instructions per deflection on the
/// Cortex-M4F).
pub fn dp_m<T: RealField + Copy>(d: &Deflection) -> Vector3<T> {
    let quantum: T = c(DP_QUANTUM_M);
    // `f64::from(v as f32)`: exact for |v| < 2²⁴, and `as f32` back is the
    // identity, which the compiler folds: no f64 arithmetic in f32.
    Vector3::from_fn(|a, _| c::<T>(f64::from(d.dp[a] as f32)) * quantum)
}

/// The experiment as a streaming [`Reweightable`] source over the flash
/// table.
///
/// Its fits ([`Reweightable::fit_weighted`], [`Reweightable::fit_reweighted`])
/// are its own (see [`Group`]): per configuration and marker, not per
/// deflection; `η` relative to the previous estimate; and the sandwich's
/// pass of one fit also accumulates `Λ` and `η` of the next (`pending`).
pub struct Kr270<T: RealField + Copy> {
    chain: Chain<T, J>,
    layout: Layout<N>,
    markers: [Marker<T>; 3],
    com_m: Vector3<T>,
    gravity_mps2: Vector3<T>,
    /// Eq. 14 of the firmware's settings: the next fit's weights, which
    /// the sandwich pass of a fit prepares `Λ` and `η` for.
    weight: RobustWeight<T>,
    /// Whether the sandwich pass also accumulates the next fit's `Λ` and
    /// `η` (`false`: every fit streams its own; the same numbers, bit for
    /// bit, one pass more per fit — the host test's reference).
    fuse: bool,
    /// The last fit's estimate: the reference `x₀` of the next reweighted
    /// fit's `η`.
    x_last: Cell<SVector<T, N>>,
    /// The next fit's `Λ`, `η`, prepared by the last fit's sandwich pass.
    pending: Cell<Option<Pending<T>>>,
    /// Passes over the table so far (host build: the tests count them).
    #[cfg(not(target_os = "none"))]
    passes: Cell<usize>,
}

/// `Λ` and `η` for weights not yet asked for (see [`Kr270`]).
#[derive(Clone, Copy)]
struct Pending<T: RealField + Copy> {
    weights: [Vector3<T>; G],
    x_ref: SVector<T, N>,
    info: Information<T>,
}

/// The repetitions of one marker at one configuration, from the table:
/// how many, `Σ Δp` and `Σ Δp²` per axis in quanta (exact integers).
#[derive(Clone, Copy, Default)]
struct Reps {
    n: u32,
    sum: [i64; 3],
    sq: [i64; 3],
}

impl Reps {
    fn add(&mut self, dp: &[i32; 3]) {
        self.n += 1;
        for ((s, q), &v) in self.sum.iter_mut().zip(&mut self.sq).zip(dp) {
            let v = i64::from(v);
            *s += v;
            *q += v * v;
        }
    }
}

/// What a pass does with the groups of one configuration
/// ([`Kr270::stream_groups`]).
pub type GroupSink<'a, T> = dyn FnMut(&[Group<T>]) -> Result<(), Error> + 'a;

/// One configuration and marker with its repetitions: the rows `B` are the
/// same for all of them, so every sum of the fit takes them together. The
/// data enter as `Σ Δp` and the scatter about their mean, both computed
/// from the table's integers exactly and rounded once: the residuals' sum
/// of squares is `scatter + (Σ Δp − n B x)² / n` per axis, with no
/// difference of large sums.
pub struct Group<T: RealField + Copy> {
    /// The configuration.
    pub g: usize,
    /// Rows `B` of the marker at the configuration.
    pub b: SMatrix<T, 3, N>,
    /// Repetitions.
    pub count: usize,
    /// `n` in `T`.
    pub n: T,
    /// `Σ Δp` per axis \[m\].
    pub sum: Vector3<T>,
    /// `Σ (Δp − mean)²` per axis \[m²\].
    pub scatter: Vector3<T>,
}

impl<T: RealField + Copy> Group<T> {
    /// `Σ_k (Δp_k − B x)` of axis `a`.
    fn residual_sum(&self, a: usize, x: &SVector<T, N>) -> T {
        let mut bx = T::zero();
        // Column-major 3 × N: row `a` is every third element from `a`.
        for (b, x) in self.b.as_slice().iter().skip(a).step_by(3).zip(x.iter()) {
            bx += *b * *x;
        }
        self.sum[a] - self.n * bx
    }
}

/// `Λ = Σ n w² bbᵀ`, `η = Σ w² b Σ(Δp − b x₀)`,
/// `Σ w² (Δp − b x₀)²` and the rows of positive weight, relative to a
/// reference `x₀`: `Λ (x − x₀) = η`. With `x₀` near the solution `η` is a
/// sum of residuals, not of deflections 20–100 times their size, and its
/// f32 rounding no longer decides when the iteration stops.
#[derive(Clone, Copy)]
pub struct Information<T: RealField + Copy> {
    /// `Λ` (both triangles).
    pub lambda: SMatrix<T, N, N>,
    /// `η` about `x₀`.
    pub eta: SVector<T, N>,
    /// `Σ w² (Δp − b x₀)²`.
    pub yy: T,
    /// Rows of positive weight.
    pub equations: usize,
}

impl<T: RealField + Copy> Default for Information<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: RealField + Copy> Information<T> {
    /// Nothing accumulated.
    pub fn new() -> Self {
        Self {
            lambda: SMatrix::zeros(),
            eta: SVector::zeros(),
            yy: T::zero(),
            equations: 0,
        }
    }

    /// Adds a configuration and marker with weights `w` (checked by the
    /// caller: finite, ≥ 0) about `x_ref`.
    fn add(&mut self, grp: &Group<T>, w: &Vector3<T>, x_ref: &SVector<T, N>) {
        let mut k = [T::zero(); 3];
        for a in 0..3 {
            let w2 = w[a] * w[a];
            if w2 == T::zero() {
                continue;
            }
            let r = grp.residual_sum(a, x_ref);
            let wr = w2 * r;
            for (e, &b) in self.eta.iter_mut().zip(grp.b.row(a).iter()) {
                *e += b * wr;
            }
            self.yy += w2 * (grp.scatter[a] + r * r / grp.n);
            self.equations += grp.count;
            k[a] = grp.n * w2;
        }
        add_upper3(&mut self.lambda, &grp.b, &k);
    }

    /// Whether every checked sum is finite (the diagonal bounds the rest).
    fn is_finite(&self) -> bool {
        self.yy.is_finite()
            && (0..N).all(|i| self.lambda[(i, i)].is_finite() && self.eta[i].is_finite())
    }
}

/// `u += Σ_a k_a b_a b_aᵀ`: the upper triangle column by column (the three
/// rows' terms summed first), mirrored to the lower one.
fn add_upper3<T: RealField + Copy>(u: &mut SMatrix<T, N, N>, b: &SMatrix<T, 3, N>, k: &[T; 3]) {
    for j in 0..N {
        let c = [k[0] * b[(0, j)], k[1] * b[(1, j)], k[2] * b[(2, j)]];
        for i in 0..=j {
            u[(i, j)] += c[0] * b[(0, i)] + c[1] * b[(1, i)] + c[2] * b[(2, i)];
            u[(j, i)] = u[(i, j)];
        }
    }
}

impl<T: RealField + Copy> Kr270<T> {
    /// The robot, the layout, the tool (markers and load centre of mass,
    /// `robcal::kr270`) and gravity. Not inlined: its temporaries stay out
    /// of the caller's stack frame.
    #[inline(never)]
    pub fn new() -> Result<Self, Error> {
        let chain = chain()?;
        let layout = layout(&chain)?;
        let v = |a: [f64; 3]| Vector3::new(c(a[0]), c(a[1]), c(a[2]));
        let markers = core::array::from_fn(|i| Marker {
            index: i as u8,
            xyz_m: v(robcal_paper::kr270::MARKERS_M[i]),
        });
        Ok(Self {
            chain,
            layout,
            markers,
            com_m: v(robcal_paper::kr270::LOAD_COM_M),
            gravity_mps2: v([0.0, 0.0, -9.80665]),
            weight: settings()?.weight,
            fuse: true,
            x_last: Cell::new(SVector::zeros()),
            pending: Cell::new(None),
            #[cfg(not(target_os = "none"))]
            passes: Cell::new(0),
        })
    }

    /// Passes over the table so far ([`Kr270::stream_groups`]).
    #[cfg(not(target_os = "none"))]
    #[allow(dead_code)] // host-tests/tests/firmware_kr270.rs
    pub fn passes(&self) -> usize {
        self.passes.get()
    }

    /// The same source whose fits do not prepare the next fit's `Λ` and
    /// `η` in their sandwich pass (the unfused reference of the host test).
    #[cfg(not(target_os = "none"))]
    #[allow(dead_code)] // host-tests/tests/firmware_kr270.rs
    pub fn unfused(mut self) -> Self {
        self.fuse = false;
        self
    }

    /// The layout.
    pub fn layout(&self) -> &Layout<N> {
        &self.layout
    }

    /// Rows `B` (eq. 3) of the three markers at configuration `g` under its
    /// load: one forward kinematics, one set of joint torques.
    pub fn config_blocks(&self, g: usize) -> Result<[SMatrix<T, 3, N>; 3], Error> {
        let q = q_rad::<T>(g);
        let frames = self.chain.frames(&q)?;
        let load = PointLoad {
            mass_kg: c::<T>(f64::from(LOAD_DKG[g]) * 0.1),
            com_m: self.com_m,
            gravity_mps2: self.gravity_mps2,
        };
        let mut tau = [T::zero(); J];
        let wrench = load.wrench(&frames);
        joint_torques(&frames, &wrench, &mut tau)?;
        let mut blocks = [SMatrix::zeros(); 3];
        for (b, m) in blocks.iter_mut().zip(&self.markers) {
            let point = frames.point_m(&m.xyz_m);
            let sample = Sample::deflection(&frames, point, m.index, &tau, Some(wrench));
            self.layout.fill(&sample, b)?;
        }
        Ok(blocks)
    }

    /// Streams every deflection of the table, in table order, to `f` as
    /// (group, `B`, `Δp`). The rows of a configuration are computed once per
    /// run of consecutive deflections of that configuration (the table is
    /// sorted by configuration, so once per pass).
    pub fn stream(
        &self,
        mut f: impl FnMut(usize, &SMatrix<T, 3, N>, &Vector3<T>) -> Result<(), Error>,
    ) -> Result<(), Error> {
        let mut cached = usize::MAX;
        let mut blocks = [SMatrix::zeros(); 3];
        for d in deflections() {
            let g = usize::from(d.config);
            if g != cached {
                blocks = self.config_blocks(g)?;
                cached = g;
            }
            let b = blocks.get(usize::from(d.marker)).ok_or(Error::OutOfRange {
                what: "marker",
                index: usize::from(d.marker),
                len: 3,
            })?;
            f(g, b, &dp_m(&d))?;
        }
        Ok(())
    }
}

impl<T: RealField + Copy> Kr270<T> {
    /// Streams the table configuration by configuration: its rows once,
    /// and each marker's repetitions together as one [`Group`] (`f` gets
    /// the configuration's groups). The table must be sorted by
    /// configuration (the generator sorts it): a configuration that comes
    /// back is an error.
    // `dyn`: one copy of the loop and the rows for every pass (flash).
    pub fn stream_groups(&self, f: &mut GroupSink<'_, T>) -> Result<(), Error> {
        #[cfg(not(target_os = "none"))]
        self.passes.set(self.passes.get() + 1);
        let mut current = None;
        let mut seen = 0u32;
        let mut reps = [Reps::default(); 3];
        for (&key, dp) in KEYS.iter().zip(DP_NM.iter()) {
            let g = usize::from(key >> 2);
            if current != Some(g) {
                if let Some(c) = current {
                    self.flush(c, &reps, f)?;
                }
                if g >= G || seen & (1 << g) != 0 {
                    return Err(Error::Mismatch {
                        what: "table not sorted by configuration",
                    });
                }
                seen |= 1 << g;
                current = Some(g);
                reps = [Reps::default(); 3];
            }
            let m = usize::from(key & 3);
            reps.get_mut(m)
                .ok_or(Error::OutOfRange {
                    what: "marker",
                    index: m,
                    len: 3,
                })?
                .add(dp);
        }
        match current {
            Some(c) => self.flush(c, &reps, f),
            None => Ok(()),
        }
    }

    /// The groups of configuration `g` to `f`.
    fn flush(&self, g: usize, reps: &[Reps; 3], f: &mut GroupSink<'_, T>) -> Result<(), Error> {
        let blocks = self.config_blocks(g)?;
        let q: T = c(DP_QUANTUM_M);
        let mut groups: heapless::Vec<Group<T>, 3> = heapless::Vec::new();
        for (b, r) in blocks.iter().zip(reps) {
            if r.n == 0 {
                continue;
            }
            let (count, nt) = (i64::from(r.n), c::<T>(f64::from(r.n)));
            let (mut sum, mut scatter) = (Vector3::zeros(), Vector3::zeros());
            for a in 0..3 {
                // n Σ Δp² − (Σ Δp)² = n Σ (Δp − mean)², exact (for this
                // table ≤ 5e15 < 2⁵³, so exact in f64 too).
                let s = r.sum[a];
                let d = count
                    .checked_mul(r.sq[a])
                    .zip(s.checked_mul(s))
                    .and_then(|(a, b)| a.checked_sub(b))
                    .ok_or(Error::NonFinite { what: "overflow" })?;
                sum[a] = c::<T>(s as f64) * q;
                scatter[a] = c::<T>(d as f64) * q * q / nt;
            }
            // At most three markers: never full.
            let _ = groups.push(Group {
                g,
                b: *b,
                count: r.n as usize,
                n: nt,
                sum,
                scatter,
            });
        }
        f(&groups)
    }

    /// One pass over the table for the fit `sweep.fit` made with `weights`
    /// (`estimated`: eq. 14 weights from these data), configuration by
    /// configuration:
    ///
    /// - with `sweep.fit`, the residual σ of each configuration and axis
    ///   and its degrees of freedom, written to `sigma` and `dof` (as
    ///   [`Reweightable::residual_sigma_into`], from [`Group`]s; not
    ///   pooled); without, `sigma` and `dof` are read;
    /// - with `sweep.middle`, the sandwich's middle term `M = Σ n w⁴ σ²
    ///   bbᵀ` (σ of [`Noise::sigma`]);
    /// - with `sweep.next`, the next fit's eq. 14 weights and its `Λ`, `η`
    ///   about `x₀` (the sums of [`Kr270::information`]).
    ///
    /// A configuration's σ depends on its own rows only, so its `M` and
    /// next `Λ`, `η` terms are added as soon as its residuals are summed:
    /// one pass per fit instead of three, unless σ must be pooled
    /// ([`pool_small_groups`], which needs every σ first: then the caller
    /// sweeps again without `fit`). Returns whether `next` holds the next
    /// fit's statistics (not when a σ gives no weight: the next fit
    /// reports it).
    ///
    /// # Errors
    /// [`Error::Mismatch`] without one entry per group; bad weights or σ;
    /// overflow; the rows.
    pub fn sweep(
        &self,
        weights: &[Vector3<T>],
        estimated: bool,
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
        sweep: Sweep<'_, T>,
    ) -> Result<bool, Error> {
        check_weights(weights)?;
        if sigma.len() != G || dof.len() != G {
            return Err(Error::Mismatch {
                what: "one sigma and one weight per group",
            });
        }
        let Sweep {
            fit,
            mut middle,
            mut next,
        } = sweep;
        if fit.is_some() {
            // Configurations without rows.
            sigma.fill(Vector3::zeros());
            dof.fill(Vector3::zeros());
        }
        let mut next_ok = next.is_some();
        self.stream_groups(&mut |groups| {
            let Some(g) = groups.first().map(|grp| grp.g) else {
                return Ok(());
            };
            if let Some(fit) = fit {
                let (mut rss, mut h, mut rows) = (Vector3::<T>::zeros(), Vector3::<T>::zeros(), 0);
                for grp in groups {
                    for a in 0..3 {
                        let r = grp.residual_sum(a, &fit.x);
                        rss[a] += grp.scatter[a] + r * r / grp.n;
                        h[a] += grp.n * leverage(&fit.lambda_inv, |k| grp.b[(a, k)], weights[g][a]);
                    }
                    rows += grp.count;
                }
                for a in 0..3 {
                    sigma[g][a] = group_sigma(rss[a], rows, h[a]);
                    dof[g][a] = group_dof(rows, h[a]);
                }
            }
            let w = &weights[g];
            if let Some(m) = middle.as_deref_mut() {
                // `Noise::sigma` itself, on this configuration alone.
                let noise = Noise {
                    sigma: core::slice::from_ref(&sigma[g]),
                    estimated_from: estimated.then_some(core::slice::from_ref(&dof[g])),
                };
                // A σ that is not finite makes `M` not finite: an error
                // below.
                let s = noise.sigma(0, w);
                for grp in groups {
                    let mut k = [T::zero(); 3];
                    for a in 0..3 {
                        let w2 = w[a] * w[a];
                        k[a] = grp.n * (w2 * w2 * s[a] * s[a]);
                    }
                    add_upper3(m, &grp.b, &k);
                }
            }
            if let Some((weight, next_w, x_ref, info)) = next.as_mut() {
                if let Some(weight) = weight {
                    // As `robust_weights`, on this configuration alone.
                    for a in 0..3 {
                        match weight.weight(sigma[g][a]) {
                            Ok(v) => next_w[g][a] = v,
                            Err(_) => next_ok = false,
                        }
                    }
                }
                if next_ok {
                    for grp in groups {
                        info.add(grp, &next_w[g], x_ref);
                    }
                }
            }
            Ok(())
        })?;
        if let Some(m) = middle {
            finite((0..N).all(|i| m[(i, i)].is_finite()))?;
        }
        if let Some((_, _, _, info)) = next {
            next_ok = next_ok && info.is_finite();
        }
        Ok(next_ok)
    }

    /// Whether the fits fuse their passes (always on the device).
    fn fused(&self) -> bool {
        cfg!(target_os = "none") || self.fuse
    }

    /// The fit behind [`Reweightable::fit_weighted`] (`estimated = false`,
    /// `η` about zero) and [`Reweightable::fit_reweighted`] (`true`, about
    /// the last fit's estimate; `weight` gives the next fit's weights).
    fn fit_grouped(
        &self,
        weights: &[Vector3<T>],
        active: &[bool],
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
        estimated: bool,
        weight: &RobustWeight<T>,
    ) -> Result<Fit<T, Dn>, Error> {
        if weights.len() != G {
            return Err(Error::Mismatch {
                what: "one weight (and sigma) per group",
            });
        }
        // Inactive parameters are held at zero: so is their reference.
        let mut x_ref = SVector::<T, N>::zeros();
        if estimated {
            for ((r, &x), &on) in x_ref.iter_mut().zip(self.x_last.get().iter()).zip(active) {
                if on {
                    *r = x;
                }
            }
        }
        let info = match self.pending.take() {
            Some(p) if p.weights[..] == *weights && p.x_ref == x_ref => p.info,
            _ => {
                // `Λ` and `η` alone: a sweep with given weights.
                let mut w = [Vector3::zeros(); G];
                for (w, v) in w.iter_mut().zip(weights) {
                    *w = *v;
                }
                let mut info = Information::new();
                let next = Some((None, &mut w, &x_ref, &mut info));
                let ok = self.sweep(
                    weights,
                    false,
                    sigma,
                    dof,
                    Sweep {
                        fit: None,
                        middle: None,
                        next,
                    },
                )?;
                finite(ok)?;
                info
            }
        };
        // As `Accumulator::solve_active`.
        let parameters = active.iter().filter(|a| **a).count();
        if active.len() == N && info.equations < parameters {
            return Err(Error::TooFewEquations {
                equations: info.equations,
                parameters,
            });
        }
        let mut solution = Solution::new(&info.lambda, &info.eta, info.yy, info.equations, active)?;
        // Zero where inactive in both.
        solution.x += x_ref;
        let x = solution.x;
        let fused = self.fused();
        let mut next_w = [Vector3::zeros(); G];
        let (mut middle, mut next, mut next_ok);
        // First the sweep with the residuals; a second one without, for M
        // (and the next Λ, η) from pooled σ, or when not fused.
        let mut fit = Some(&solution);
        loop {
            middle = SMatrix::<T, N, N>::zeros();
            next = Information::new();
            next_ok = self.sweep(
                weights,
                estimated,
                sigma,
                dof,
                Sweep {
                    fit,
                    middle: (fused || fit.is_none()).then_some(&mut middle),
                    next: fused.then_some((Some(weight), &mut next_w, &x, &mut next)),
                },
            )?;
            if fit.is_none() {
                break;
            }
            let small: T = nalgebra::convert(robcal::estimate::POOL_BELOW_DOF);
            let pooled = dof
                .iter()
                .any(|d| d.iter().any(|&v| v > T::zero() && v < small));
            pool_small_groups(sigma, dof);
            if fused && !pooled {
                break;
            }
            fit = None;
        }
        let covariance = solution.cov_sandwich(&middle);
        self.x_last.set(x);
        if next_ok {
            self.pending.set(Some(Pending {
                weights: next_w,
                x_ref: x,
                info: next,
            }));
        }
        Ok(Fit {
            solution,
            covariance,
            iterations: 0,
            converged: false,
        })
    }
}

/// What one [`Kr270::sweep`] computes besides the residual σ.
pub struct Sweep<'a, T: RealField + Copy> {
    /// The fit whose residual σ the sweep computes (`None`: σ is given).
    pub fit: Option<&'a Solution<T, Dn>>,
    /// The sandwich's middle term, added to.
    pub middle: Option<&'a mut SMatrix<T, N, N>>,
    /// `Λ`, `η` for the next fit: eq. 14 (`None`: the weights are given,
    /// and not checked: the fit gives a copy of the checked `weights`),
    /// the weights (written, or given), `x₀`, the sums.
    #[allow(clippy::type_complexity)]
    pub next: Option<(
        Option<&'a RobustWeight<T>>,
        &'a mut [Vector3<T>; G],
        &'a SVector<T, N>,
        &'a mut Information<T>,
    )>,
}

fn check_weights<T: RealField + Copy>(weights: &[Vector3<T>]) -> Result<(), Error> {
    if weights.len() != G {
        return Err(Error::Mismatch {
            what: "one weight (and sigma) per group",
        });
    }
    // The checks of the core's `add_moments`, on the first bad weight.
    let bad = |v: &&T| !(v.is_finite() && **v >= T::zero());
    match weights.iter().flat_map(|w| w.iter()).find(bad) {
        None => Ok(()),
        Some(v) if v.is_finite() => Err(Error::NotPositive { what: "weight" }),
        Some(_) => Err(Error::NonFinite { what: "weight" }),
    }
}

fn finite(ok: bool) -> Result<(), Error> {
    if ok {
        Ok(())
    } else {
        Err(Error::NonFinite { what: "overflow" })
    }
}

impl<T: RealField + Copy> Reweightable<T, Dn> for Kr270<T> {
    fn group_count(&self) -> usize {
        G
    }

    /// One pass over the table: every deflection is one [`Block`] with the
    /// weight (and σ) of its configuration and axis, streamed into a fresh
    /// accumulator. (The generic path, for the host's comparisons: this
    /// source's own fits use [`Kr270::sweep`].)
    fn weighted(
        &self,
        weights: &[Vector3<T>],
        noise: Option<Noise<'_, T>>,
    ) -> Result<Accumulator<T, Dn>, Error> {
        if weights.len() != G || noise.is_some_and(|n| !n.fits(G)) {
            return Err(Error::Mismatch {
                what: "one weight (and sigma) per group",
            });
        }
        let mut acc = Accumulator::new();
        self.stream(|g, b, dp| {
            let mut block = Block::new(*b, *dp).with_weights(weights[g]);
            if let Some(n) = noise {
                block = block.with_sigma(n.sigma(g, &weights[g]));
            }
            acc.update(&block)
        })?;
        Ok(acc)
    }

    /// One pass over the table: the residuals `Δp − B x` directly (no
    /// difference of large sums) and each row's leverage `w² bᵀ Λ⁻¹ b`; σ
    /// per configuration and axis with its own degrees of freedom, as
    /// [`robcal::GroupedStats::residual_sigma_into`].
    fn residual_sigma_into(
        &self,
        fit: &Solution<T, Dn>,
        weights: &[Vector3<T>],
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
    ) -> Result<(), Error> {
        if sigma.len() != G || dof.len() != G || weights.len() != G {
            return Err(Error::Mismatch {
                what: "one sigma and one weight per group",
            });
        }
        let mut rss = [Vector3::<T>::zeros(); G];
        let mut h = [Vector3::<T>::zeros(); G];
        let mut rows = [0usize; G];
        self.stream(|g, b, dp| {
            let r = dp - b * fit.x;
            rss[g] += r.component_mul(&r);
            for a in 0..3 {
                h[g][a] += leverage(&fit.lambda_inv, |k| b[(a, k)], weights[g][a]);
            }
            rows[g] += 1;
            Ok(())
        })?;
        for g in 0..G {
            sigma[g] = Vector3::from_fn(|a, _| group_sigma(rss[g][a], rows[g], h[g][a]));
            dof[g] = Vector3::from_fn(|a, _| group_dof(rows[g], h[g][a]));
        }
        Ok(())
    }

    /// The grouped fit ([`Kr270::fit_grouped`]), `η` about zero.
    fn fit_weighted(
        &self,
        weights: &[Vector3<T>],
        active: &[bool],
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
    ) -> Result<Fit<T, Dn>, Error> {
        self.fit_grouped(weights, active, sigma, dof, false, &self.weight)
    }

    /// The grouped fit ([`Kr270::fit_grouped`]) with eq. 14's weights,
    /// `η` about the last fit's estimate.
    fn fit_reweighted(
        &self,
        weight: &RobustWeight<T>,
        active: &[bool],
        weights: &mut [Vector3<T>],
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
    ) -> Result<Fit<T, Dn>, Error> {
        robust_weights(sigma, weight, weights)?;
        self.fit_grouped(weights, active, sigma, dof, true, weight)
    }
}

/// History kept by the firmware's fit (OLS start + iterations; the fit goes
/// on when it is full).
#[cfg_attr(not(target_os = "none"), allow(dead_code))]
pub const HISTORY: usize = 10;

/// The firmware's settings: eq. 14 with σ0 and λ of `setup.toml`, stop at a
/// change below 1e-3 σ (as the host), at most 100 iterations.
pub fn settings<T: RealField + Copy>() -> Result<IrlsSettings<T>, Error> {
    Ok(IrlsSettings::new(RobustWeight::new(
        c(SIGMA0_M),
        c(LAMBDA),
    )?))
}

/// Check 1: every estimate within this many of the host's standard
/// deviations of the host's f64 estimate (from the CSV). Measured: at most
/// 1.8e-4 σ (k3), the same on the Cortex-M4F and the Cortex-M3, 1.6e-4 σ
/// on x86-64 in f32 (whose `sin_cos` is the system's): f32 rounding of the
/// rows (forward kinematics in f32, relative
/// ~1e-7), of the accumulated sums and of the solve, against standard
/// deviations of 2e-3 … 1e-2 of the estimates; the table's quantisation
/// adds 2e-5 σ (`QUANTISATION_SIGMAS`). (2.5e-3 σ, k22, while `η` was
/// summed about zero and every deflection on its own, [`Information`].)
pub const TOL_X_SIGMAS: f64 = 0.01;
/// Check 2: every standard deviation within this relative distance of the
/// host's (measured: at most 3.3e-6, k21, on the devices; 2.2e-5 before).
pub const TOL_SD_REL: f64 = 1e-3;

/// The outcome of the checks for one parameter.
#[derive(Clone, Copy, Debug)]
pub struct ParamCheck {
    /// `x̂` on this target \[µrad/(N·m)\].
    pub x: f64,
    /// Its standard deviation.
    pub sd: f64,
    /// `|x̂ − x̂_host| / σ_host`.
    pub x_sigmas: f64,
    /// `|σ / σ_host − 1|`.
    pub sd_rel: f64,
}

/// What the checks need of a fit (small: the firmware keeps only this
/// once the fit is done).
#[derive(Clone, Copy, Debug)]
pub struct Estimate<T: RealField + Copy> {
    /// `X̂` \[µrad/(N·m)\].
    pub x: SVector<T, N>,
    /// Its standard deviations (sandwich, eq. 11).
    pub sd: SVector<T, N>,
    /// WLS iterations after the OLS start.
    pub iterations: usize,
    /// Whether the iteration converged.
    pub converged: bool,
}

impl<T: RealField + Copy> From<&Fit<T, Dn>> for Estimate<T> {
    fn from(fit: &Fit<T, Dn>) -> Self {
        Self {
            x: fit.solution.x,
            sd: fit.std(),
            iterations: fit.iterations,
            converged: fit.converged,
        }
    }
}

/// Compares an estimate with the host's (`expected` is normally
/// [`HOST_X`]): converged, and checks 1 and 2 for every parameter.
pub fn check<T: RealField + Copy>(
    est: &Estimate<T>,
    expected: &[f64; N],
) -> ([ParamCheck; N], bool) {
    let params: [ParamCheck; N] = core::array::from_fn(|i| {
        let x: f64 = to_f64(est.x[i]);
        let s: f64 = to_f64(est.sd[i]);
        ParamCheck {
            x,
            sd: s,
            x_sigmas: libm::fabs(x - expected[i]) / HOST_SD[i],
            sd_rel: libm::fabs(s / HOST_SD[i] - 1.0),
        }
    });
    let pass = est.converged
        && params
            .iter()
            .all(|p| p.x_sigmas <= TOL_X_SIGMAS && p.sd_rel <= TOL_SD_REL);
    (params, pass)
}

fn to_f64<T: RealField + Copy>(x: T) -> f64 {
    // `RealField` has no lossless cast to f64; every scalar robcal runs on
    // (f32, f64) converts exactly through `SubsetOf`.
    nalgebra::try_convert::<T, f64>(x).unwrap_or(f64::NAN)
}

/// The same rows in grouped sufficient statistics (host comparison: the
/// streaming source and [`robcal::GroupedStats`] must agree to rounding).
#[cfg(not(target_os = "none"))]
pub fn grouped<T: RealField + Copy>(
    source: &Kr270<T>,
) -> Result<robcal::GroupedStats<T, Dn, G>, Error> {
    let mut stats = robcal::GroupedStats::new();
    source.stream(|g, b, dp| stats.update(g as i32, b, dp))?;
    Ok(stats)
}

/// The configuration whose taught point the device compensates for (the
/// paper's configuration 1).
pub const COMPENSATE_CONFIG: usize = 0;
/// The payload of the compensation \[kg\] (at the tool's centre of mass).
pub const COMPENSATE_LOAD_KG: f64 = 270.0;

/// The device's compensation problem (issue 14): the point marker 1 has
/// at configuration [`COMPENSATE_CONFIG`] without load (taught) is the
/// target; with [`COMPENSATE_LOAD_KG`] on the tool the robot sags; the
/// compensated command puts the marker back on it. The joint law: A2's
/// compliance of the configuration's q2 group (k21…k25), then k3…k6, of a
/// calibrated estimate.
pub struct Compensation<T: RealField + Copy> {
    chain: Chain<T, J>,
    tool: Vector3<T>,
    /// The target \[m, base frame\].
    pub target: Vector3<T>,
    /// The taught command \[rad\].
    pub q: [T; J],
    loading: robcal::robot::Loading<T>,
    law: robcal::robot::Compliances<T, J>,
}

impl<T: RealField + Copy> Compensation<T> {
    /// The problem for the estimate `x` (µrad/(N·m)).
    ///
    /// # Errors
    /// From the chain and the forward kinematics.
    #[inline(never)]
    pub fn new(x: &SVector<T, N>) -> Result<Self, Error> {
        let chain = chain::<T>()?;
        let v = |a: [f64; 3]| Vector3::new(c(a[0]), c(a[1]), c(a[2]));
        let tool = v(robcal_paper::kr270::MARKERS_M[0]);
        let g = COMPENSATE_CONFIG;
        let q = q_rad::<T>(g);
        let target = chain.frames(&q)?.point_m(&tool);
        let group = robcal_paper::kr270::q2_group(robcal_paper::kr270::CONFIGURATIONS_DEG[g][1])
            .ok_or(Error::Mismatch {
                what: "configuration not in a q2 group",
            })?;
        let micro: T = c(1e-6);
        Ok(Self {
            chain,
            tool,
            target,
            q,
            loading: robcal::robot::Loading {
                load: Some(PointLoad {
                    mass_kg: c(COMPENSATE_LOAD_KG),
                    com_m: v(robcal_paper::kr270::LOAD_COM_M),
                    gravity_mps2: v([0.0, 0.0, -9.80665]),
                }),
                own_weight_mps2: None,
            },
            law: robcal::robot::Compliances {
                k: [T::zero(), x[group], x[5], x[6], x[7], x[8]].map(|k| k * micro),
            },
        })
    }

    /// The compensated command, from the taught one.
    ///
    /// # Errors
    /// From [`robcal::robot::compensate`].
    #[inline(never)]
    pub fn solve(
        &self,
        settings: &robcal::robot::CompensateSettings<T>,
    ) -> Result<robcal::robot::Compensation<T, J>, Error> {
        let law = self.law;
        robcal::robot::compensate(
            &self.chain,
            &self.tool,
            &self.target,
            &self.q,
            &self.loading,
            |_| law,
            settings,
        )
    }

    /// How far the loaded robot commanded to `q` misses the target \[m\],
    /// by its own equilibrium solve.
    ///
    /// # Errors
    /// From the equilibrium.
    #[inline(never)]
    pub fn miss_m(
        &self,
        q: &[T],
        settings: &robcal::robot::EquilibriumSettings<T>,
    ) -> Result<T, Error> {
        let eq = robcal::robot::equilibrium(&self.chain, q, q, &self.loading, &self.law, settings)?;
        Ok((eq.frames.point_m(&self.tool) - self.target).norm())
    }
}

/// The compensation settings of the device (f32): stop within 2 µm, the
/// equilibrium to 1e-6 rad (f32 rounds a joint value at ~2e-7 rad).
pub fn compensate_settings<T: RealField + Copy>() -> robcal::robot::CompensateSettings<T> {
    robcal::robot::CompensateSettings {
        tolerance_m: c(2e-6),
        max_iterations: 10,
        max_step: c(0.1),
        equilibrium: robcal::robot::EquilibriumSettings {
            tolerance: c(1e-6),
            max_iterations: 20,
        },
    }
}

/// The device's compensation must end within [`compensate_settings`]'
/// tolerance, confirmed by a separate equilibrium at the command, in at most
/// this many steps.
pub const COMPENSATE_MAX_STEPS: usize = 5;
