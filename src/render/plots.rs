//! The report's figures as SVG (plotters): one drawing code for
//! `--plots DIR` and `DIR/report.html`.
//!
//! - [`residuals`]: the residuals against the variable an effect was traced
//!   by, per axis, before (with the fitted effect) and after (with the
//!   noise band);
//! - [`per_pose`]: every configuration's error before and after
//!   calibration;
//! - [`ecdf`]: the distribution of the error per point, before and after;
//! - [`intervals`]: the parameters' 95 % intervals, one panel per unit.
//!
//! Colours are the Okabe–Ito palette (distinguishable with every common
//! colour-vision deficiency); every axis says its unit; legends sit in a
//! strip above the data, never over it.

use std::collections::BTreeMap;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::calibrate::report::{PlotSeries, Report};

/// One figure of the report: its file name (in `--plots DIR` and
/// `--output DIR`), the SVG and what it shows.
pub struct Figure {
    /// File name.
    pub file: String,
    /// The SVG document.
    pub svg: String,
    /// Caption (plain text).
    pub caption: String,
}

/// `s` as a file-name part: ASCII letters and digits, `_` for the rest.
pub fn slug(s: &str) -> String {
    s.chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect::<String>()
        .trim_matches('_')
        .to_string()
}

/// Every figure of `r`: one per plot series (residuals against the traced
/// variable), numbered in the loop's order (`01_compensator_a2.svg`), then
/// `per_pose.svg`, `error_distribution.svg` and one
/// `parameters_<unit>.svg` per unit; `t975` is the interval's quantile.
///
/// # Errors
/// A figure that cannot be drawn (its name and why).
pub fn figures(r: &Report, t975: f64) -> std::result::Result<Vec<Figure>, String> {
    let fail = |what: &str, e: Box<dyn std::error::Error>| format!("figure '{what}': {e}");
    let noise = noise_um(r);
    let mut out = Vec::new();
    for (i, s) in r.plots.iter().enumerate() {
        out.push(Figure {
            file: format!("{:02}_{}.svg", i + 1, slug(&s.title)),
            svg: residuals(s, noise).map_err(|e| fail(&s.title, e))?,
            caption: format!(
                "{}: residuals per axis against {} before and after the step; the fitted \
                 effect is the change of each residual, the band ±2σ of the final fit's noise \
                 (RMS over configurations: x {:.1}, y {:.1}, z {:.1} µm).",
                s.title, s.variable, noise[0], noise[1], noise[2]
            ),
        });
    }
    out.push(Figure {
        file: "per_pose.svg".into(),
        svg: per_pose(r).map_err(|e| fail("per pose", e))?,
        caption: "Error per configuration before (nominal robot) and after calibration: the \
                  RMS of its points' 3-D errors, log scale."
            .into(),
    });
    out.push(Figure {
        file: "error_distribution.svg".into(),
        svg: ecdf(r).map_err(|e| fail("error distribution", e))?,
        caption: "Distribution of the error per point before and after calibration \
                  (empirical cumulative distribution, log scale)."
            .into(),
    });
    let mut by_unit: BTreeMap<&str, Vec<Interval<'_>>> = BTreeMap::new();
    for p in &r.parameters {
        by_unit.entry(&p.unit).or_default().push(Interval {
            name: &p.name,
            value: p.value,
            half: t975 * p.std,
        });
    }
    for (unit, list) in &by_unit {
        out.push(Figure {
            file: format!("parameters_{}.svg", slug(unit)),
            svg: intervals(unit, list).map_err(|e| fail(unit, e))?,
            caption: format!("Parameters in {unit}: estimate and 95 % interval."),
        });
    }
    Ok(out)
}

/// Okabe–Ito blue: after calibration / residuals.
pub const BLUE: RGBColor = RGBColor(0, 114, 178);
/// Okabe–Ito orange: before calibration / the fitted effect.
pub const ORANGE: RGBColor = RGBColor(230, 159, 0);
/// Okabe–Ito bluish green: the noise band.
pub const GREEN: RGBColor = RGBColor(0, 158, 115);
/// Okabe–Ito vermillion: intervals.
pub const VERMILLION: RGBColor = RGBColor(213, 94, 0);

/// Points drawn per series at most: a larger series is drawn every k-th
/// point (and says so), so that the page stays light at 10⁴ poses.
pub const MAX_POINTS: usize = 2000;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;
type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;

/// How a legend entry is drawn.
#[derive(Clone, Copy)]
enum Mark {
    Dot(RGBColor),
    Cross(RGBColor),
    Band(RGBColor),
    Bar(RGBColor),
    Line(RGBColor),
}

/// A legend strip at the top of `area`; returns the area below it.
fn legend<'a>(area: &Area<'a>, items: &[(&str, Mark)]) -> Result<Area<'a>> {
    let (top, rest) = area.split_vertically(28);
    let font = ("sans-serif", 14).into_font();
    let mut x = 70;
    for (label, mark) in items {
        let (cx, cy) = (x + 6, 14);
        match *mark {
            Mark::Dot(c) => top.draw(&Circle::new((cx, cy), 4, c.filled()))?,
            Mark::Cross(c) => top.draw(&Cross::new((cx, cy), 5, c.stroke_width(2)))?,
            Mark::Band(c) => top.draw(&Rectangle::new(
                [(x, 7), (x + 14, 21)],
                c.mix(0.25).filled(),
            ))?,
            Mark::Bar(c) => top.draw(&Rectangle::new([(x, 7), (x + 14, 21)], c.filled()))?,
            Mark::Line(c) => top.draw(&PathElement::new(
                vec![(x, cy), (x + 14, cy)],
                c.stroke_width(2),
            ))?,
        }
        top.draw(&Text::new(label.to_string(), (x + 20, 6), font.clone()))?;
        x += 30 + 8 * label.chars().count() as i32;
    }
    Ok(rest)
}

/// `(lo, hi)` of the finite values, padded by 5 %.
pub fn bounds(v: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for x in v.filter(|x| x.is_finite()) {
        lo = lo.min(x);
        hi = hi.max(x);
    }
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-9);
    (lo - pad, hi + pad)
}

/// Positive `(lo, hi)` for a log axis (values ≤ 0 ignored).
fn log_bounds(v: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0_f64);
    for x in v.filter(|x| x.is_finite() && *x > 0.0) {
        lo = lo.min(x);
        hi = hi.max(x);
    }
    if !lo.is_finite() {
        return (0.1, 10.0);
    }
    (lo / 1.5, hi * 1.5)
}

/// The x of each point, spread sideways when the variable takes a few
/// discrete values (a joint at a handful of angles), so that the points do
/// not pile on one line: at most ±30 % of the smallest gap, deterministic.
fn spread(x: &[f64]) -> Vec<f64> {
    let mut distinct: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup();
    if distinct.len() < 2 || distinct.len() > 12 || x.len() < 3 * distinct.len() {
        return x.to_vec();
    }
    let gap = distinct
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(f64::INFINITY, f64::min);
    x.iter()
        .enumerate()
        .map(|(i, v)| {
            // The golden-ratio sequence fills [0, 1) evenly.
            let u = (i as f64 * 0.618_033_988_75).fract() - 0.5;
            v + 0.6 * gap * u
        })
        .collect()
}

/// The pooled noise σ per axis \[µm\] of the final fit's rows: the root
/// mean square of the per-configuration σ (eq. 14's input, a point's),
/// and when the rows mix both kinds, of the rows' (a deflection's is `√2`
/// a point's: `Rows::noise_scale`).
pub fn noise_um(r: &Report) -> [f64; 3] {
    let mut s = [0.0; 3];
    if r.noise.is_empty() {
        return s;
    }
    for n in &r.noise {
        for (a, v) in s.iter_mut().enumerate() {
            *v += n.sigma_um[a] * n.sigma_um[a];
        }
    }
    let deflections = r.row_errors.iter().filter(|e| e.deflection).count();
    let rows = r.row_errors.len();
    let mixed = deflections > 0 && deflections < rows;
    let share = if mixed {
        deflections as f64 / rows as f64
    } else {
        0.0
    };
    s.map(|v| (v / r.noise.len() as f64 * (1.0 + share)).sqrt())
}

/// Residuals of `s` against its variable, one row of panels per axis:
/// before (with the fitted effect, before − after) and after (with the
/// final fit's ±2σ noise band `noise`).
pub fn residuals(s: &PlotSeries, noise: [f64; 3]) -> Result<String> {
    let mut buf = String::new();
    let after = !s.after_um.is_empty();
    let cols = if after { 2 } else { 1 };
    {
        let root =
            SVGBackend::with_string(&mut buf, (460 * cols as u32 + 20, 760)).into_drawing_area();
        root.fill(&WHITE)?;
        let n = s.x.len();
        let stride = n.div_ceil(MAX_POINTS).max(1);
        let label = if stride > 1 {
            format!("residual (every {stride}th of {n} points)")
        } else {
            "residual".into()
        };
        let mut items = vec![(label.as_str(), Mark::Dot(BLUE))];
        if after {
            items.push(("fitted effect (before − after)", Mark::Cross(ORANGE)));
            items.push(("±2σ noise (final fit)", Mark::Band(GREEN)));
        }
        let body = legend(&root, &items)?;
        let x = spread(&s.x);
        let (xmin, xmax) = bounds(x.iter().copied());
        let panels = body.split_evenly((3, cols));
        for (k, area) in panels.iter().enumerate() {
            let (axis, col) = (k / cols, k % cols);
            let res = if col == 0 { &s.before_um } else { &s.after_um };
            let fitted: Vec<f64> = if col == 0 && after {
                s.before_um
                    .iter()
                    .zip(&s.after_um)
                    .map(|(b, a)| b[axis] - a[axis])
                    .collect()
            } else {
                Vec::new()
            };
            // Both columns of an axis share its scale.
            let all = s
                .before_um
                .iter()
                .chain(&s.after_um)
                .map(|v| v[axis])
                .chain(fitted.iter().copied())
                .chain([2.0 * noise[axis], -2.0 * noise[axis]]);
            let (ymin, ymax) = bounds(all);
            let name = ["x", "y", "z"][axis];
            let when = if col == 0 { "before" } else { "after" };
            let mut chart = ChartBuilder::on(area)
                .caption(format!("{name}: {when}"), ("sans-serif", 15))
                .margin(8)
                .x_label_area_size(36)
                .y_label_area_size(64)
                .build_cartesian_2d(xmin..xmax, ymin..ymax)?;
            chart
                .configure_mesh()
                .x_desc(s.variable.as_str())
                .y_desc(format!("residual {name} [µm]"))
                .light_line_style(WHITE)
                .draw()?;
            if col == 1 {
                let b = 2.0 * noise[axis];
                chart.draw_series([Rectangle::new(
                    [(xmin, -b), (xmax, b)],
                    GREEN.mix(0.2).filled(),
                )])?;
            }
            chart.draw_series(
                x.iter()
                    .zip(res.iter())
                    .step_by(stride)
                    .map(|(&x, r)| Circle::new((x, r[axis]), 2, BLUE.mix(0.7).filled())),
            )?;
            chart.draw_series(
                x.iter()
                    .zip(&fitted)
                    .step_by(stride)
                    .map(|(&x, &f)| Cross::new((x, f), 3, ORANGE.stroke_width(1))),
            )?;
        }
        root.present()?;
    }
    Ok(buf)
}

/// Per configuration (its id on the axis): the RMS error of its rows
/// before (nominal) and after calibration \[µm, log scale\].
pub fn per_pose(r: &Report) -> Result<String> {
    let mut by: BTreeMap<i64, (f64, f64, usize)> = BTreeMap::new();
    for e in &r.row_errors {
        let v = by.entry(e.config).or_default();
        v.0 += e.nominal_um.norm_squared();
        v.1 += e.final_um.norm_squared();
        v.2 += 1;
    }
    let poses: Vec<(i64, f64, f64)> = by
        .into_iter()
        .map(|(c, (n, f, k))| (c, (n / k as f64).sqrt(), (f / k as f64).sqrt()))
        .collect();
    let (lo, hi) = log_bounds(poses.iter().flat_map(|p| [p.1, p.2]));
    let g = poses.len().max(1) as f64;
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (920, 380)).into_drawing_area();
        root.fill(&WHITE)?;
        let body = legend(
            &root,
            &[
                ("before (nominal robot)", Mark::Bar(ORANGE)),
                ("after (calibrated)", Mark::Bar(BLUE)),
            ],
        )?;
        let mut chart = ChartBuilder::on(&body)
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..g, (lo..hi).log_scale())?;
        let labels: Vec<String> = poses.iter().map(|p| p.0.to_string()).collect();
        chart
            .configure_mesh()
            .x_desc("configuration (config id)")
            .y_desc("error per pose, RMS [µm] (log)")
            .y_labels(5)
            .y_label_formatter(&|v| format!("{v:.0}"))
            .x_labels(poses.len().clamp(2, 20))
            .x_label_formatter(&|x| {
                let i = x.floor() as usize;
                labels.get(i).cloned().unwrap_or_default()
            })
            .light_line_style(WHITE)
            .draw()?;
        for (i, &(_, before, after)) in poses.iter().enumerate() {
            let x = i as f64;
            chart.draw_series([
                Rectangle::new([(x + 0.08, lo), (x + 0.5, before.max(lo))], ORANGE.filled()),
                Rectangle::new([(x + 0.5, lo), (x + 0.92, after.max(lo))], BLUE.filled()),
            ])?;
        }
        root.present()?;
    }
    Ok(buf)
}

/// The empirical distribution of the error per point (the norm of each
/// row's 3-D error) before and after calibration \[µm, log scale\].
pub fn ecdf(r: &Report) -> Result<String> {
    let sorted = |f: &dyn Fn(&crate::calibrate::report::RowError) -> f64| {
        let mut v: Vec<f64> = r.row_errors.iter().map(|e| f(&e)).collect();
        v.sort_by(f64::total_cmp);
        v
    };
    let before = sorted(&|e| e.nominal_um.norm());
    let after = sorted(&|e| e.final_um.norm());
    let (lo, hi) = log_bounds(before.iter().chain(&after).copied());
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (920, 360)).into_drawing_area();
        root.fill(&WHITE)?;
        let body = legend(
            &root,
            &[
                ("before (nominal robot)", Mark::Line(ORANGE)),
                ("after (calibrated)", Mark::Line(BLUE)),
            ],
        )?;
        let mut chart = ChartBuilder::on(&body)
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d((lo..hi).log_scale(), 0.0..1.0)?;
        chart
            .configure_mesh()
            .x_desc("error per point, |Δp| [µm] (log)")
            .x_labels(5)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_desc("fraction of points ≤ error")
            .light_line_style(WHITE)
            .draw()?;
        for (v, c) in [(&before, ORANGE), (&after, BLUE)] {
            let n = v.len() as f64;
            // Every k-th step of a long distribution (the curve is the same
            // to the pixel).
            let stride = v.len().div_ceil(MAX_POINTS).max(1);
            let steps = v.iter().enumerate().step_by(stride).flat_map(|(i, &x)| {
                let x = x.max(lo);
                [(x, i as f64 / n), (x, (i + 1) as f64 / n)]
            });
            chart.draw_series(LineSeries::new(steps, c.stroke_width(2)))?;
        }
        root.present()?;
    }
    Ok(buf)
}

/// One parameter's interval: name, value, half-width, unit.
pub struct Interval<'a> {
    /// Name.
    pub name: &'a str,
    /// Estimate.
    pub value: f64,
    /// Half-width of the 95 % interval.
    pub half: f64,
}

/// The parameters' 95 % intervals, one panel for all parameters of `unit`
/// (parameters of different units share no axis; nothing joins them).
pub fn intervals(unit: &str, p: &[Interval<'_>]) -> Result<String> {
    let (xmin, xmax) = bounds(p.iter().flat_map(|i| [i.value - i.half, i.value + i.half]));
    let (xmin, xmax) = (xmin.min(0.0), xmax.max(0.0));
    let n = p.len().max(1);
    let mut buf = String::new();
    {
        let h = 90 + 22 * n as u32;
        let root = SVGBackend::with_string(&mut buf, (920, h)).into_drawing_area();
        root.fill(&WHITE)?;
        let body = legend(
            &root,
            &[
                ("estimate", Mark::Dot(VERMILLION)),
                ("95 % interval", Mark::Line(VERMILLION)),
            ],
        )?;
        let names: Vec<&str> = p.iter().map(|i| i.name).collect();
        let width = names.iter().map(|s| s.chars().count()).max().unwrap_or(4);
        let mut chart = ChartBuilder::on(&body)
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size((7 * width as u32 + 16).clamp(60, 330))
            .build_cartesian_2d(xmin..xmax, -0.5..(n as f64 - 0.5))?;
        chart
            .configure_mesh()
            .x_desc(format!("value [{unit}]"))
            .y_labels(n)
            .y_label_formatter(&|y| {
                let i = y.round();
                if (y - i).abs() > 1e-6 || i < 0.0 {
                    return String::new();
                }
                // The first parameter at the top.
                let k = n as f64 - 1.0 - i;
                if k < 0.0 {
                    return String::new();
                }
                names
                    .get(k as usize)
                    .map(|s| s.to_string())
                    .unwrap_or_default()
            })
            .light_line_style(WHITE)
            .draw()?;
        chart.draw_series([PathElement::new(
            vec![(0.0, -0.5), (0.0, n as f64 - 0.5)],
            BLACK.mix(0.4),
        )])?;
        for (k, i) in p.iter().enumerate() {
            let y = (n - 1 - k) as f64;
            chart.draw_series([PathElement::new(
                vec![(i.value - i.half, y), (i.value + i.half, y)],
                VERMILLION.stroke_width(2),
            )])?;
            chart.draw_series([Circle::new((i.value, y), 4, VERMILLION.filled())])?;
        }
        root.present()?;
    }
    Ok(buf)
}
