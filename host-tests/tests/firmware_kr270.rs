//! The firmware's KR-270 experiment (`examples/firmware/kr270.rs`) on the
//! host: its hand-written chain against the URDF, its flash table against
//! the CSV, its streaming `Reweightable` source against `GroupedStats` on
//! the same rows, and its f32 and f64 fits against the host reference the
//! table carries (`robcal::calibrate` on the CSV, `examples/firmware_table.rs`).

use crate::kr270;

use std::path::Path;

use kr270::{Dn, Kr270, G, N};
use nalgebra::{RealField, Vector3};
use robcal::io::Job;
use robcal::{Fit, Iteration, Reweightable};

fn job() -> (Job, robcal::io::Measurements) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/kr270");
    let job = Job::load(root.join("setup.toml")).unwrap();
    let data = job
        .read_measurements(root.join("measurements.csv"))
        .unwrap();
    (job, data)
}

/// The iterative WLS and its residual σ per configuration.
fn irls<T: RealField + Copy, R: Reweightable<T, Dn>>(src: &R) -> (Fit<T, Dn>, Vec<Vector3<T>>) {
    let mut w = vec![Vector3::zeros(); G];
    let mut s = vec![Vector3::zeros(); G];
    let mut n = vec![Vector3::zeros(); G];
    let fit = src
        .fit_irls(
            &kr270::settings().unwrap(),
            &[true; N],
            &mut w,
            &mut s,
            &mut n,
            |_| {},
        )
        .unwrap();
    (fit, s)
}

#[test]
fn chain_constant_matches_the_urdf() {
    let (job, _) = job();
    let urdf = &job.robot.chain;
    let ours = kr270::chain::<f64>().unwrap();
    assert_eq!(urdf.dof(), 6);
    for g in 0..G {
        let q = kr270::q_rad::<f64>(g);
        let a = urdf.frames(&q).unwrap();
        let b = ours.frames(&q).unwrap();
        for (ja, jb) in a.joints().iter().zip(b.joints()) {
            assert!((ja.origin_m() - jb.origin_m()).norm() < 1e-12);
            assert!((ja.axis.into_inner() - jb.axis.into_inner()).norm() < 1e-12);
        }
        // Marker positions through the tip transform.
        for m in robcal_paper::kr270::MARKERS_M {
            let m = nalgebra::Vector3::from(m);
            assert!((a.point_m(&m) - b.point_m(&m)).norm() < 1e-12);
        }
    }
}

#[test]
fn flash_table_holds_the_csv() {
    let (job, data) = job();
    // The table is sorted by configuration, file order within one.
    let mut csv: Vec<_> = data.deflections.iter().collect();
    csv.sort_by_key(|d| d.config);
    let table: Vec<_> = kr270::deflections().collect();
    assert_eq!(table.len(), csv.len());
    assert_eq!(table.len(), 270);
    for (t, d) in table.iter().zip(&csv) {
        assert_eq!(i64::from(t.config) + 1, d.config);
        let marker = &job.setup.markers[usize::from(t.marker)];
        assert_eq!(marker.id, d.marker);
        let q = kr270::q_rad::<f64>(usize::from(t.config));
        for (a, b) in q.iter().zip(&d.q) {
            // 0.01° steps, exact up to the CSV's degree→radian rounding.
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        let load = f64::from(kr270::LOAD_DKG[usize::from(t.config)]) * 0.1;
        assert!((load - d.load_kg).abs() < 1e-9);
        let dp = kr270::dp_m::<f64>(t);
        for a in 0..3 {
            // Quantisation: at most half a nanometre.
            assert!((dp[a] - d.dp_m[a]).abs() <= 0.5e-9 + 1e-15);
        }
    }
}

/// The streaming source and `GroupedStats` fed with the same rows give the
/// same iterative WLS to rounding (f64): same iterations, estimates within
/// 1e-9 σ, standard deviations within 1e-9 relative.
#[test]
fn streaming_source_equals_grouped_stats() {
    let src = Kr270::<f64>::new().unwrap();
    let grouped = kr270::grouped(&src).unwrap();
    assert_eq!(grouped.equations(), 810);
    let (a, sigma_a) = irls(&src);
    let (b, sigma_b) = irls(&grouped);
    assert!(a.converged && b.converged);
    assert_eq!(a.iterations, b.iterations);
    let (sa, sb) = (a.std(), b.std());
    for i in 0..N {
        assert!((a.solution.x[i] - b.solution.x[i]).abs() <= 1e-9 * sb[i]);
        assert!((sa[i] / sb[i] - 1.0).abs() <= 1e-9);
    }
    for (x, y) in sigma_a.iter().zip(&sigma_b) {
        assert!((x - y).norm() <= 1e-9 * y.norm());
    }
}

/// Against the reference in the table (f64 from the CSV): the f64 stream
/// differs only by the table's quantisation (measured 1.8e-5 σ), the f32
/// stream — what the firmware computes — within the firmware's tolerance.
#[test]
fn fits_match_the_host_reference() {
    let (f64fit, _) = irls(&Kr270::<f64>::new().unwrap());
    let e64 = kr270::Estimate::from(&f64fit);
    let (p64, ok64) = kr270::check(&e64, &kr270::HOST_X);
    assert!(ok64);
    assert_eq!(f64fit.iterations, kr270::HOST_ITERATIONS);
    for p in &p64 {
        assert!(p.x_sigmas < 1e-4, "{p:?}");
        assert!(p.sd_rel < 1e-4, "{p:?}");
    }
    let (f32fit, _) = irls(&Kr270::<f32>::new().unwrap());
    let (p32, ok32) = kr270::check(&(&f32fit).into(), &kr270::HOST_X);
    assert!(ok32, "{p32:?}");
}

/// The firmware's fits share passes (one sweep per fit: residual σ,
/// sandwich, next `Λ`, `η`); without that (`unfused`: σ, then `M`, then the
/// next fit's `Λ`, `η`, three passes) every number is the same bit for bit,
/// in f64 and in f32: the same sums in the same order. The unfused path is
/// also the one taken when σ must be pooled.
#[test]
fn fused_passes_equal_unfused_bit_for_bit() {
    type Run<T> = (Fit<T, Dn>, Vec<Vector3<T>>, Vec<Iteration<T, Dn>>);
    fn run<T: RealField + Copy>(src: &Kr270<T>) -> Run<T> {
        let mut w = vec![Vector3::zeros(); G];
        let mut s = vec![Vector3::zeros(); G];
        let mut n = vec![Vector3::zeros(); G];
        let mut history = Vec::new();
        let fit = src
            .fit_irls(
                &kr270::settings().unwrap(),
                &[true; N],
                &mut w,
                &mut s,
                &mut n,
                |it| history.push(*it),
            )
            .unwrap();
        (fit, s, history)
    }
    fn check<T: RealField + Copy>() {
        let (a, b) = (
            Kr270::<T>::new().unwrap(),
            Kr270::<T>::new().unwrap().unfused(),
        );
        let (fused, unfused) = (run(&a), run(&b));
        assert!(fused.0.converged);
        let fits = kr270::HOST_ITERATIONS + 1;
        assert_eq!(fused.2.len(), fits);
        assert!(fused == unfused);
        // OLS: Λ and η, then one sweep; every WLS step one sweep. Unfused:
        // three passes per fit.
        assert_eq!(a.passes(), fits + 1);
        assert_eq!(b.passes(), 3 * fits);
    }
    check::<f64>();
    check::<f32>();
}

/// `η` is summed about the last estimate: a fit with fewer parameters
/// after one with all of them must not keep the dropped ones in its
/// reference (they are held at zero). Against `GroupedStats`, f64.
#[test]
fn reweighted_fit_with_fewer_parameters() {
    fn run<R: Reweightable<f64, Dn>>(r: &R) -> Fit<f64, Dn> {
        let weight = kr270::settings::<f64>().unwrap().weight;
        let mut w = vec![Vector3::zeros(); G];
        let mut s = vec![Vector3::zeros(); G];
        let mut n = vec![Vector3::zeros(); G];
        r.fit_ols(&[true; N], &mut w, &mut s, &mut n).unwrap();
        let mut active = [true; N];
        active[N - 1] = false;
        r.fit_reweighted(&weight, &active, &mut w, &mut s, &mut n)
            .unwrap()
    }
    let src = Kr270::<f64>::new().unwrap();
    let (a, b) = (run(&src), run(&kr270::grouped(&src).unwrap()));
    assert_eq!(a.solution.x[N - 1], 0.0);
    let sd = b.std();
    for i in 0..N - 1 {
        assert!((a.solution.x[i] - b.solution.x[i]).abs() <= 1e-9 * sd[i]);
    }
}

/// f32 rounding no longer decides when the iteration stops: the f32 fit
/// takes the f64 fit's iterations (it took 7, then 12, while `η` was summed
/// about zero from every deflection on its own).
#[test]
fn f32_converges_as_f64() {
    let (f32fit, _) = irls(&Kr270::<f32>::new().unwrap());
    assert!(f32fit.converged);
    assert_eq!(f32fit.iterations, kr270::HOST_ITERATIONS);
}

/// The mismatch self-test's shift (one σ of k21) fails the check.
#[test]
fn check_rejects_a_one_sigma_shift() {
    let (fit, _) = irls(&Kr270::<f64>::new().unwrap());
    let mut x = kr270::HOST_X;
    x[0] += kr270::HOST_SD[0];
    assert!(!kr270::check(&(&fit).into(), &x).1);
}
