//! `DIR/report.html`: one self-contained page (no script, no external
//! file; the figures are inline SVG) that an engineer reads first and can
//! forward. Sections, each an `id` the browser check looks for:
//! `job`, `summary`, `loop`, `parameters`, `correlations`,
//! `identifiability`, `validation`, `warnings`, `figures`.
//!
//! Every number is the report's ([`Report`]); the page adds only what
//! follows from them by a stated formula: the 95 % interval
//! `x ± t₀.₉₇₅(ν) σ` with `ν = 3·rows − parameters` (Student t, statrs),
//! `t = x / σ`, and the correlations `ρᵢⱼ = Σᵢⱼ / √(Σᵢᵢ Σⱼⱼ)` of the
//! sandwich covariance (eq. 8, 11), flagged at `|ρ| ≥` [`FLAG_CORRELATION`].

use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::Path;

use statrs::distribution::{ContinuousCDF, StudentsT};

use crate::calibrate::report::Report;
use crate::io::job::Job;

use crate::render::plots;

/// Pairs of parameters whose estimates correlate at least this much are
/// listed under "correlations" (their values trade against each other).
pub const FLAG_CORRELATION: f64 = 0.9;

/// What the page says about the job besides the report.
pub struct JobInfo<'a> {
    /// The job (setup and robot).
    pub job: &'a Job,
    /// `--data`.
    pub data: &'a Path,
    /// `--validate`.
    pub validate: Option<&'a Path>,
    /// The run's λ of eq. 14.
    pub lambda: f64,
}

/// Text with `& < > "` escaped for HTML.
pub fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            c => o.push(c),
        }
    }
    o
}

/// A number with 4 significant digits (fixed or scientific as suits).
fn g(v: f64) -> String {
    if !v.is_finite() {
        return "n/a".into();
    }
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{v:.3e}")
    } else {
        let digits = if a == 0.0 {
            1
        } else {
            (3 - a.log10().floor() as i32).clamp(0, 6) as usize
        };
        format!("{v:.digits$}")
    }
}

fn um(v: Option<f64>) -> String {
    v.map_or_else(|| "n/a".into(), |v| format!("{v:.1}"))
}

const STYLE: &str =
    "body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1000px;padding:0 1.5em;\
color:#222;line-height:1.4}h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;\
padding-bottom:.2em;margin-top:1.8em}table{border-collapse:collapse;margin:.6em 0}\
td,th{padding:.25em .7em;border-bottom:1px solid #e4e4e4;text-align:left;vertical-align:top}\
table.num td+td,table.num th+th{text-align:right;white-space:nowrap}th{background:#f4f4f4}\
.big{font-size:1.3em}.warn{color:#a04000}.ok{color:#006045}figure{margin:1em 0}\
figcaption{color:#555;font-size:.9em}code{background:#f4f4f4;padding:0 .2em}\
svg{max-width:100%;height:auto}";

/// The page, with the figures of [`plots::figures`].
pub fn page(r: &Report, info: &JobInfo<'_>, figs: &[plots::Figure]) -> String {
    let mut h = String::new();
    let robot = &info.job.robot;
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>robcal calibration report: {}</title><style>{STYLE}</style></head><body>\n\
         <h1>Calibration report: {}</h1>\n",
        esc(&robot.name),
        esc(&robot.name)
    );
    job(&mut h, r, info);
    summary(&mut h, r);
    closed_loop(&mut h, r);
    parameters(&mut h, r);
    correlations(&mut h, r);
    identifiability(&mut h, r);
    validation(&mut h, r, info);
    warnings(&mut h, r);
    figures(&mut h, figs);
    h.push_str(
        "<p><small>Written by robcal calibrate; the same numbers are in \
         <code>model.json</code>.</small></p></body></html>\n",
    );
    h
}

fn job(h: &mut String, r: &Report, info: &JobInfo<'_>) {
    let j = info.job;
    let robot = &j.robot;
    let s = &j.setup;
    let _ = write!(
        h,
        "<section id=\"job\"><h2>The job</h2><table>\
         <tr><td>robot</td><td>{} (<code>{}</code>), chain {} → {}, {} joints: {}</td></tr>\
         <tr><td>setup</td><td><code>{}</code>, {} marker(s){}</td></tr>\
         <tr><td>data</td><td><code>{}</code>: {} rows ({} equations), {} configurations</td></tr>\
         <tr><td>method</td><td>{} (λ = {} of eq. 14), {} deflection model, {} iterations, {}, \
         {} Gauss–Newton relinearisation(s)</td></tr>",
        esc(&robot.name),
        esc(&robot.file.display().to_string()),
        esc(&robot.base_link),
        esc(&robot.tip_link),
        robot.joint_names.len(),
        esc(&robot.joint_names.join(", ")),
        esc(&j.setup_path.display().to_string()),
        s.markers.len(),
        s.load
            .as_ref()
            .map_or_else(String::new, |_| ", a payload ([load])".into()),
        esc(&info.data.display().to_string()),
        r.rows,
        r.equations,
        r.configurations,
        r.method,
        g(info.lambda),
        r.deflection_model,
        r.iterations,
        if r.converged {
            "<span class=\"ok\">converged</span>"
        } else {
            "<span class=\"warn\">NOT converged</span>"
        },
        r.relinearisations,
    );
    let _ = write!(
        h,
        "<tr><td>weights</td><td>{}: {}</td></tr>",
        r.weights,
        esc(crate::calibrate::report::weights_line(r.weights))
    );
    h.push_str("</table></section>\n");
}

fn summary(h: &mut String, r: &Report) {
    let after = r.final_error();
    let (mean, max) = (after.mean_um, after.max_um);
    let _ = write!(
        h,
        "<section id=\"summary\"><h2>Error before and after</h2>\
         <p class=\"big\">Nominal robot: RMS <b>{:.1} µm</b> → calibrated: RMS <b>{:.1} µm</b> \
         (held-out {} µm)</p><table class=\"num\"><tr><th></th><th>RMS [µm]</th><th>mean [µm]</th>\
         <th>max [µm]</th></tr>\
         <tr><td>before calibration (nominal robot)</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td></tr>\
         <tr><td>after calibration (final model)</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td></tr>\
         </table><p>Per point, the norm of the 3-D position error over the calibration data \
         (a deflection row: the measured deflection before, its residual after). Held-out: \
         each configuration predicted by the model fitted without it.</p>",
        r.nominal.rms_um,
        r.rms_um,
        um(r.heldout_rms_um),
        r.nominal.rms_um,
        r.nominal.mean_um,
        r.nominal.max_um,
        r.rms_um,
        mean,
        max
    );
    if let Some(o) = &r.orientation {
        // The measured poses' orientations, apart.
        let _ = write!(
            h,
            "<table class=\"num\"><tr><th>orientation of {} poses</th><th>RMS [µrad]</th>\
             <th>mean [µrad]</th><th>max [µrad]</th></tr>\
             <tr><td>before calibration (nominal robot)</td><td>{:.1}</td><td></td><td></td></tr>\
             <tr><td>after calibration (final model)</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td></tr>\
             </table><p>Per pose, the angle of the rotation left between the measured and the \
             predicted frame (<code>rx, ry, rz</code>); the points' errors above leave them out.</p>",
            o.poses, o.nominal_rms_urad, o.rms_urad, o.mean_urad, o.max_urad
        );
        if !o.identified.is_empty() {
            let names: Vec<String> = o.identified.iter().map(|n| esc(n)).collect();
            let _ = write!(
                h,
                "<p>The orientations determine {}, which the points alone leave out.</p>",
                names.join(", ")
            );
        }
    }
    h.push_str("</section>");
}

fn closed_loop(h: &mut String, r: &Report) {
    h.push_str(
        "<section id=\"loop\"><h2>The closed loop</h2><table><tr><th>step</th><th>added</th>\
         <th>F</th><th>p</th><th>tried</th><th>RMS [µm]</th><th>held-out RMS [µm]</th></tr>",
    );
    let _ = write!(
        h,
        "<tr><td>nominal</td><td>(no parameter identified)</td><td></td><td></td><td></td>\
         <td>{:.1}</td><td></td></tr><tr><td>declared model</td><td></td><td>{}</td><td>{}</td>\
         <td></td><td>{:.1}</td><td>{}</td></tr>",
        r.nominal.rms_um,
        r.declared_structure
            .as_ref()
            .map_or(String::new(), |d| format!(
                "{:.2} (lack of fit)",
                d.statistic
            )),
        r.declared_structure
            .as_ref()
            .map_or(String::new(), |d| format!("{:.2e}", d.p_value)),
        r.declared_rms_um,
        um(r.declared_heldout_rms_um)
    );
    for (i, s) in r.effects.iter().enumerate() {
        let on = match (&s.joint, s.marker) {
            (Some(j), _) => format!(" on {j}"),
            (None, Some(m)) => format!(" on marker {m}"),
            _ => String::new(),
        };
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}{}</td><td>{:.1}</td><td style=\"white-space:nowrap\">{:.2e}</td><td>{}</td>\
             <td style=\"white-space:nowrap\">{:.1} → {:.1}</td>\
             <td style=\"white-space:nowrap\">{} → {}</td></tr>",
            i + 1,
            s.effect,
            esc(&on),
            s.f,
            s.p_value,
            s.tried,
            s.rms_um_before,
            s.rms_um_after,
            um(s.heldout_rms_um_before),
            um(s.heldout_rms_um_after)
        );
    }
    h.push_str("</table>");
    if r.effects.is_empty() {
        h.push_str("<p>No effect added.</p>");
    }
    match (&r.unexplained, &r.lack_of_fit) {
        (Some(u), _) => {
            let _ = write!(
                h,
                "<p class=\"warn\">Structure left unexplained: the residuals follow {} most \
                 (lack-of-fit F = {:.2}, p = {:.2e}); no effect of the library explains it.</p>",
                esc(&u.variable),
                u.statistic,
                u.p_value
            );
        }
        (None, Some(l)) => {
            let _ = write!(
                h,
                "<p>Lack of fit of the final model (repetitions as pure error): F = {:.2}, \
                 p = {:.2e}{}.</p>",
                l.f,
                l.p_value,
                if l.p_value < 0.01 {
                    ""
                } else {
                    ": no structure left beyond the noise"
                }
            );
        }
        (None, None) => h.push_str("<p>Lack of fit: not testable (no repetitions).</p>"),
    }
    h.push_str(
        "<p>Each step adds the effect of the library that explains the residuals best \
         (nested F test, Bonferroni over the candidates tried, α = 0.01) when it also \
         lowers the held-out RMS.</p>",
    );
    if !r.notes.is_empty() {
        h.push_str("<p>What the run decided on its own:</p><ul>");
        for n in &r.notes {
            let _ = write!(h, "<li>{}</li>", esc(n));
        }
        h.push_str("</ul>");
    }
    h.push_str("</section>\n");
}

/// `(ν, t₀.₉₇₅(ν))`: the residual degrees of freedom of the fit (the
/// equations less the parameters) and Student's quantile.
pub fn t975(r: &Report) -> (usize, f64) {
    let nu = r.equations.saturating_sub(r.parameters.len()).max(1);
    let t = StudentsT::new(0.0, 1.0, nu as f64).map_or(1.959_964, |t| t.inverse_cdf(0.975));
    (nu, t)
}

fn parameters(h: &mut String, r: &Report) {
    let (nu, t975) = t975(r);
    let _ = write!(
        h,
        "<section id=\"parameters\"><h2>Final parameters</h2><table class=\"num\"><tr><th>parameter</th>\
         <th>value</th><th>σ (1 sd)</th><th>95 % interval</th><th>unit</th><th>t = value/σ</th>\
         <th></th></tr>"
    );
    for p in &r.parameters {
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>[{}, {}]</td><td>{}</td><td>{:.1}</td>\
             <td>{}</td></tr>",
            esc(&p.name),
            g(p.value),
            g(p.std),
            g(p.value - t975 * p.std),
            g(p.value + t975 * p.std),
            esc(&p.unit),
            p.value / p.std,
            if p.determined { "" } else { "within 2σ of 0" }
        );
    }
    let _ = write!(
        h,
        "</table><p>σ from the sandwich covariance (eq. 8, 11); 95 % interval = value ± \
         t<sub>0.975</sub>(ν) σ with ν = {} equations − {} parameters = {nu}, \
         t<sub>0.975</sub> = {t975:.4}.</p></section>",
        r.equations,
        r.parameters.len()
    );
}

fn correlations(h: &mut String, r: &Report) {
    let c = &r.covariance;
    let mut pairs = Vec::new();
    for i in 0..c.nrows() {
        for k in i + 1..c.ncols() {
            let rho = c[(i, k)] / (c[(i, i)] * c[(k, k)]).sqrt();
            if rho.abs() >= FLAG_CORRELATION {
                pairs.push((rho, i, k));
            }
        }
    }
    pairs.sort_by(|a, b| b.0.abs().total_cmp(&a.0.abs()));
    let _ = write!(
        h,
        "<section id=\"correlations\"><h2>Correlated estimates</h2><p>Pairs with \
         |ρ| ≥ {FLAG_CORRELATION}: {}.</p>",
        pairs.len()
    );
    if !pairs.is_empty() {
        h.push_str("<table><tr><th>parameter</th><th>with</th><th>ρ</th></tr>");
        for (rho, i, k) in pairs.iter().take(30) {
            let _ = write!(
                h,
                "<tr><td>{}</td><td>{}</td><td>{rho:+.3}</td></tr>",
                esc(&r.parameters[*i].name),
                esc(&r.parameters[*k].name)
            );
        }
        h.push_str("</table>");
        if pairs.len() > 30 {
            let _ = write!(
                h,
                "<p>… and {} more (model.json has the covariance).</p>",
                pairs.len() - 30
            );
        }
    }
    if !r.near_dependent.is_empty() {
        h.push_str(
            "<p class=\"warn\">Poorly determined (variance inflation; their values trade \
             against the ones named):</p><ul>",
        );
        for n in &r.near_dependent {
            let _ = write!(h, "<li>{}</li>", esc(&n.line()));
        }
        h.push_str("</ul>");
    }
    h.push_str("</section>\n");
}

fn identifiability(h: &mut String, r: &Report) {
    h.push_str("<section id=\"identifiability\"><h2>Identifiability</h2>");
    if r.left_out.is_empty() {
        h.push_str("<p>Every declared parameter is identifiable from these data.</p>");
    } else {
        let _ = write!(
            h,
            "<p>{} declared parameter(s) left out: the data cannot tell them from kept ones, \
             which absorb them (coefficient: change of the kept one per unit of the left-out \
             one).</p><table><tr><th>left out</th><th>absorbed by</th></tr>",
            r.left_out.len()
        );
        for l in &r.left_out {
            let by: Vec<String> = l
                .absorbed_by
                .iter()
                .map(|a| format!("{} ({:.3} {})", esc(&a.name), a.coefficient, esc(&a.unit)))
                .collect();
            let by = if by.is_empty() {
                "no information in these data".to_string()
            } else {
                by.join(", ")
            };
            let _ = write!(h, "<tr><td>{}</td><td>{by}</td></tr>", esc(&l.name));
        }
        h.push_str("</table>");
    }
    h.push_str("</section>\n");
}

fn validation(h: &mut String, r: &Report, info: &JobInfo<'_>) {
    h.push_str("<section id=\"validation\"><h2>Validation</h2>");
    match (&r.validation, info.validate) {
        (Some(v), Some(file)) => {
            let _ = write!(
                h,
                "<p>The final model, not re-estimated, on <code>{}</code>: {} points, RMS \
                 <b>{:.4} mm</b>.</p><table class=\"num\"><tr><th>marker</th><th>mean [mm]</th><th>RMS [mm]</th>\
                 <th>max [mm]</th></tr>",
                esc(&file.display().to_string()),
                v.points,
                v.rms_mm
            );
            let rows: BTreeMap<&String, ()> = v.per_marker_rms_mm.keys().map(|k| (k, ())).collect();
            for m in rows.keys() {
                let get = |t: &BTreeMap<String, f64>| {
                    t.get(*m).map_or("n/a".into(), |x| format!("{x:.4}"))
                };
                let _ = write!(
                    h,
                    "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                    esc(m),
                    get(&v.per_marker_mean_mm),
                    get(&v.per_marker_rms_mm),
                    get(&v.per_marker_max_mm)
                );
            }
            h.push_str("</table>");
            if let Some(g) = &v.reregistration {
                let _ = write!(
                    h,
                    "<p>{}As measured, RMS {:.4} mm; with the file's measurement frame re-fitted \
                     (the model held fixed), RMS {:.4} mm: the frame moved {:.3} mm and turned \
                     {:.3} mrad.</p>",
                    if v.reregistered {
                        "The table is after re-registration (<code>--reregister</code>). "
                    } else {
                        ""
                    },
                    v.as_measured_rms_mm,
                    g.rms_mm,
                    g.shift_mm(),
                    g.turn_mrad()
                );
            }
            if v.interpolated_points > 0 {
                let _ = write!(
                    h,
                    "<p>{} of {} points at angles between the calibrated ones (compensator \
                     table interpolated linearly, held at its ends).</p>",
                    v.interpolated_points, v.points
                );
            }
        }
        _ => h.push_str(
            "<p>Not run: <code>--validate V.csv</code> evaluates the final model on \
             measurements it was not fitted to.</p>",
        ),
    }
    h.push_str("</section>\n");
}

fn warnings(h: &mut String, r: &Report) {
    h.push_str("<section id=\"warnings\"><h2>Warnings</h2>");
    if let Some(why) = &r.failure {
        let _ = write!(
            h,
            "<p class=\"warn\"><strong>Not a calibration:</strong> {}</p>",
            esc(why)
        );
    }
    if r.warnings.is_empty() {
        h.push_str("<p class=\"ok\">None.</p>");
    } else {
        h.push_str("<ul>");
        for w in &r.warnings {
            let _ = write!(h, "<li class=\"warn\">{}</li>", esc(w));
        }
        h.push_str("</ul>");
    }
    h.push_str("</section>\n");
}

fn figure(h: &mut String, svg: &str, caption: &str) {
    // The SVG's own XML declaration is not allowed inside HTML.
    let svg = svg.trim_start();
    let svg = if svg.starts_with("<?xml") {
        svg.split_once("?>").map_or(svg, |(_, rest)| rest)
    } else {
        svg
    };
    let _ = write!(
        h,
        "<figure>{svg}<figcaption>{caption}</figcaption></figure>"
    );
}

fn figures(h: &mut String, figures: &[plots::Figure]) {
    h.push_str("<section id=\"figures\"><h2>Figures</h2>");
    for f in figures {
        figure(h, &f.svg, &esc(&f.caption));
    }
    h.push_str("</section>\n");
}
