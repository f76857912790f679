//! The calibration report a technician files: one self-contained HTML file (inline CSS and SVG, no external
//! resource) rendered from a session. Owns the report's layout and its plots (hand-written SVG).
//!
//! Contents: bench, software and session versions; the Table II-style parameter table (value,
//! σ, determined or why not; an undetermined parameter never shows a bare number); the
//! identifiability warnings; the residual of every observation in units of its σ; the
//! validation motions before and after calibration (figures and curves); the diagnosis if one
//! was run; where the calibration's time went (stages, plan runs, segments); the moves of the
//! lamella made with the calibration and their proof; the lab record
//! (who, when, ambient conditions, controllers); the notes and the list of traces.

use crate::calibration::{CalibrationReport, ValidationRow};
use crate::session::{Session, FORMAT_VERSION};
use std::fmt::Write as _;
use svg::{svg_plot, Series};

mod escape;
mod lab;
mod moves;
mod svg;
mod timing;

pub use escape::escape;

const STYLE: &str = "body{font-family:'DejaVu Sans',Arial,sans-serif;max-width:60em;margin:1.5em auto;padding:0 1em;color:#222;line-height:1.4}\
h1{font-size:1.6em;margin-bottom:0.2em}h2{font-size:1.2em;border-bottom:1px solid #ccc;margin-top:1.6em}\
table{border-collapse:collapse;margin:0.6em 0}th,td{border:1px solid #ccc;padding:0.25em 0.6em;text-align:left;vertical-align:top}\
th{background:#f0f0f0}td.num{text-align:right;font-family:'DejaVu Sans Mono',monospace}\
.no{color:#a00;font-weight:bold}.yes{color:#070}.muted{color:#777}.warn{background:#fff4e0;border-left:4px solid #e90;padding:0.3em 0.6em;margin:0.3em 0}\
.plots{display:flex;flex-wrap:wrap;gap:1em}figure{margin:0.5em 0}figcaption{font-size:0.9em;color:#444;max-width:44em}";

/// The whole report as an HTML document.
pub fn render_html(session: &Session) -> String {
    let mut h = String::new();
    let title = match &session.calibration {
        Some(c) => format!("Calibration report: {}", c.bench),
        None => format!("Session report: {}", session.bench.name),
    };
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title><style>{STYLE}</style></head><body>\n<h1>{}</h1>\n",
        escape(&title),
        escape(&title)
    );
    versions(&mut h, session);
    lab::lab_record(&mut h, session);
    match &session.calibration {
        Some(c) => {
            summary(&mut h, c);
            parameter_table(&mut h, c);
            identifiability(&mut h, c);
            residual_plot(&mut h, c);
            validation(&mut h, c);
            timing::timing(&mut h, c);
        }
        None => {
            h.push_str("<p class=\"warn\">No calibration in this session yet: only the measurements are listed.</p>\n")
        }
    }
    diagnosis(&mut h, session);
    moves::moves(&mut h, session);
    notes_and_traces(&mut h, session);
    h.push_str("</body></html>\n");
    h
}

fn versions(h: &mut String, s: &Session) {
    h.push_str("<table>\n");
    let mut row = |k: &str, v: String| {
        let _ = writeln!(h, "<tr><th>{}</th><td>{}</td></tr>", escape(k), escape(&v));
    };
    row("bench", s.bench.name.clone());
    if let Some(p) = &s.bench.preset {
        row("bench preset (model)", p.clone());
    }
    if let Some(seed) = s.bench.seed {
        row("virtual bench seed", seed.to_string());
    }
    row("robot", format!("{} ({} joints)", s.robot.name, s.robot.dof()));
    row("measured with", s.software.clone());
    row("report by", format!("{} (session format {FORMAT_VERSION})", crate::session::software()));
    h.push_str("</table>\n");
}

fn summary(h: &mut String, c: &CalibrationReport) {
    let _ = writeln!(
        h,
        "<h2>Summary</h2>\n<p>Identifier: <b>{}</b> mode. {} observations from {:.1} min of measurement. Solver: {}. \
         Residual RMS {:.2} σ (1 = at the noise floor of the measurements).</p>",
        match c.mode {
            crate::calibration::Mode::Paper => "paper (steps A, B, C)",
            crate::calibration::Mode::Joint => "joint estimate",
        },
        c.observations,
        c.measurement_duration_s / 60.0,
        if c.converged {
            "<span class=\"yes\">converged</span>".to_string()
        } else {
            format!("<span class=\"no\">NOT converged</span> ({})", escape(&c.termination))
        },
        c.residual_rms_sigma
    );
    if let Some(fit) = &c.fit {
        let class = if fit.verdict == crate::identify::verdict::Verdict::Fits { "yes" } else { "no" };
        let _ = writeln!(h, "<p>Fit: <span class=\"{class}\"><b>{}</b></span></p>", escape(&fit.summary));
        if fit.verdict == crate::identify::verdict::Verdict::DoesNotFit {
            let _ = writeln!(h, "<p>Traces with the largest residual:</p>\n<ul>");
            for t in &fit.worst_traces {
                let _ = writeln!(h, "<li>{} ({:.2} σ rms)</li>", escape(&t.label), t.rms_sigma);
            }
            let _ = writeln!(h, "</ul>");
        }
    }
}

/// A number with `digits` significant digits after the decimal point chosen from σ.
fn with_sigma(value: f64, sigma: Option<f64>) -> (String, String) {
    match sigma {
        Some(s) if s > 0.0 && s.is_finite() => {
            let decimals = (1 - s.log10().floor() as i64).clamp(0, 12) as usize;
            (format!("{value:.decimals$}"), format!("{s:.decimals$}"))
        }
        _ => (format!("{value:.6}"), "–".into()),
    }
}

fn parameter_table(h: &mut String, c: &CalibrationReport) {
    h.push_str(
        "<h2>Identified parameters</h2>\n<p>The extrinsic parameters of the paper's Table II: where the fiber and \
         the lamella are. σ is the standard uncertainty (68 %): the noise of the measurements and, in quadrature, a \
         systematic part, what noise cannot explain (independent views of the data that disagree beyond their \
         noise: families of observations, traces). A parameter the measurements do not determine is shown as \
         such, never as a number.</p>\n<table>\n<tr><th>parameter</th><th>what it is</th><th>value</th><th>σ noise</th>\
         <th>σ systematic</th><th>σ total</th><th>unit</th><th>determined</th></tr>\n",
    );
    for p in &c.parameters {
        if p.determined {
            let (v, s) = with_sigma(p.value, p.sigma);
            let digits = |x: Option<f64>| match (x, p.sigma) {
                (Some(x), Some(total)) if total > 0.0 && total.is_finite() => {
                    let decimals = (1 - total.log10().floor() as i64).clamp(0, 12) as usize;
                    format!("{x:.decimals$}")
                }
                _ => "–".into(),
            };
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{}</td><td class=\"num\">{v}</td><td class=\"num\">{}</td><td class=\"num\">{}</td>\
                 <td class=\"num\">{s}</td><td>{}</td><td class=\"yes\">yes</td></tr>",
                escape(&p.name),
                meaning(&p.name),
                digits(p.sigma_noise.or(p.sigma)),
                digits(p.sigma_systematic),
                escape(&p.unit)
            );
        } else {
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{}</td><td class=\"muted\">not determined</td><td class=\"num\">–</td><td class=\"num\">–</td>\
                 <td class=\"num\">–</td><td>{}</td><td><span class=\"no\">no</span>: {}</td></tr>",
                escape(&p.name),
                meaning(&p.name),
                escape(&p.unit),
                escape(p.reason.as_deref().unwrap_or("not determined by these data"))
            );
        }
    }
    h.push_str("</table>\n");
    discrepancy_table(h, c);
}

/// Each family of observations against the model and the others: what the systematic σ comes from.
fn discrepancy_table(h: &mut String, c: &CalibrationReport) {
    let Some(d) = c.model_discrepancy.as_ref().filter(|d| !d.families.is_empty()) else { return };
    h.push_str(
        "<p>Families of observations: each one's residual against its noise (Birge ratio, 1 at the noise floor) \
         and how far the estimate moves when it is left out, against what noise gives (χ², its 99 % quantile \
         decides).</p>\n<table>\n<tr><th>family</th><th>observations</th><th>traces</th><th>Birge ratio</th>\
         <th>scatter beyond noise</th><th>left out: χ² (dof)</th><th>against the others</th></tr>\n",
    );
    for f in &d.families {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{:.2}</td>\
             <td class=\"num\">{:.3} {}</td><td class=\"num\">{:.1} ({})</td><td>{}</td></tr>",
            f.family.words(),
            f.observations,
            f.traces,
            f.birge_ratio,
            f.excess_sigma,
            escape(&f.unit),
            f.shift_chi2,
            f.shift_dof,
            if f.disagrees { "<span class=\"no\">disagrees</span>" } else { "agrees" }
        );
    }
    h.push_str("</table>\n");
}

/// What a parameter of the paper's Table II is, in words (docs/conventions.md).
fn meaning(name: &str) -> &'static str {
    match name {
        "beta_et" => "lamella tilt about the end-effector X axis",
        "theta_et" => "lamella tilt about the end-effector Y axis",
        "beta_wf" => "fiber axis tilt about the world X axis",
        "theta_wf" => "fiber axis tilt about the fiber Z axis",
        "Z_et" => "lamella offset along the end-effector Z axis",
        "x_wf" => "fiber end, world X (across the beam)",
        "y_wf" => "fiber end, world Y (along the beam)",
        "z_wf" => "fiber end, world Z (across the beam)",
        _ => "",
    }
}

fn identifiability(h: &mut String, c: &CalibrationReport) {
    let id = &c.identifiability;
    h.push_str("<h2>Identifiability and warnings</h2>\n<ul>\n");
    let _ = writeln!(h, "<li>rank {} of {} parameters (with detector gains)</li>", id.rank, id.parameters.len());
    if let Some(k) = id.condition_number {
        let _ = writeln!(
            h,
            "<li>condition number {}{}</li>",
            scientific(k),
            if k > 100.0 { " (above 100: some combinations are poorly determined)" } else { "" }
        );
    }
    if let Some(k) = id.condition_number_determined {
        let _ = writeln!(h, "<li>condition number of the determined parameters {}</li>", scientific(k));
    }
    for (a, b, rho) in &id.strong_correlations {
        let _ = writeln!(h, "<li>strongly correlated: {} and {} (ρ = {rho:+.3})</li>", escape(a), escape(b));
    }
    for u in &id.unobservable {
        let _ = writeln!(h, "<li>{}</li>", escape(&u.description));
    }
    h.push_str("</ul>\n");
    for w in &c.warnings {
        let _ = writeln!(h, "<div class=\"warn\">{}</div>", escape(w));
    }
}

/// A number in scientific notation; infinite for an exactly singular matrix.
fn scientific(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3e}")
    } else {
        "∞ (exactly singular)".into()
    }
}

fn residual_plot(h: &mut String, c: &CalibrationReport) {
    h.push_str("<h2>Residuals</h2>\n");
    let colors = [
        ("nm", "#1f77b4", "gap changes (nm)"),
        ("µm", "#d62728", "absolute gaps (µm)"),
        ("mW", "#2ca02c", "fringe amplitudes (mW)"),
    ];
    let mut series: Vec<Series<'_>> = Vec::new();
    for (unit, color, name) in colors {
        let points: Vec<(f64, f64)> = c
            .residuals
            .iter()
            .enumerate()
            .filter(|(_, r)| r.1 == unit && r.3 > 0.0)
            .map(|(k, r)| (k as f64 + 1.0, r.2 / r.3))
            .collect();
        if !points.is_empty() {
            series.push(Series { name, color, points, markers: true });
        }
    }
    let other: Vec<(f64, f64)> = c
        .residuals
        .iter()
        .enumerate()
        .filter(|(_, r)| !colors.iter().any(|c| c.0 == r.1) && r.3 > 0.0)
        .map(|(k, r)| (k as f64 + 1.0, r.2 / r.3))
        .collect();
    if !other.is_empty() {
        series.push(Series { name: "other", color: "#7f7f7f", points: other, markers: true });
    }
    let _ = writeln!(
        h,
        "<figure>{}<figcaption>Measured minus predicted for every observation, divided by its standard uncertainty σ. \
         With a good model most points lie between the dashed lines at ±3 σ; a pattern or many points outside \
         means something the model does not describe (see the diagnosis).</figcaption></figure>",
        svg_plot(
            "Residual per observation",
            "observation number",
            "residual / σ",
            &series,
            &[-3.5, 3.5],
            &[-3.0, 0.0, 3.0]
        )
    );
}

fn validation(h: &mut String, c: &CalibrationReport) {
    h.push_str("<h2>Validation</h2>\n");
    if c.validation_not_run {
        h.push_str(
            "<p class=\"warn\">NOT RUN: the calibration was identified without its validation motions. Run them on the \
             bench (the GUI's Validation view) before relying on it.</p>\n",
        );
    }
    if c.validation_predicted {
        h.push_str(
            "<p class=\"warn\">PREDICTED, not measured: the traces were recorded elsewhere, so the validation motions were run \
             on a virtual bench whose truth is the identified extrinsics. Run them on the real bench to confirm.</p>\n",
        );
    }
    let failures = c.validation_failures();
    if !failures.is_empty() {
        h.push_str(
            "<p class=\"warn\"><b>NOT PROVEN: the validation does not confirm this calibration.</b></p>\n<ul>\n",
        );
        for f in &failures {
            let _ = writeln!(h, "<li class=\"warn\">{}</li>", escape(f));
        }
        h.push_str("</ul>\n");
    } else if !c.validation.is_empty() && !c.validation_predicted {
        h.push_str("<p>Every validation motion is confirmed within its target.</p>\n");
    }
    h.push_str(
        "<p>Each validation motion should leave the Fabry-Perot cavity length |L| unchanged. The figure of merit is the \
         peak-to-peak variation of |L| during the motion, planned with the nominal (design) extrinsics \
         (<i>before</i>) and with the identified ones (<i>after</i>); each is the figure its verdict stands behind. \
         <i>Tracked</i> is the after figure read with the identified extrinsics alone (their fringe prediction as the \
         tracker's hint, their tilt term); <i>model-free</i> reads the same fringes from the signal's own turning \
         points, with the tilt term from the fringe contrast; <i>count</i> is the lower bound the signal's extrema \
         set on the fringes' peak to peak. A motion is <i>confirmed</i> when every such figure agrees, \
         <i>contradicted</i> when one does not. The <i>forecast</i> is what the uncertainty of the identified \
         extrinsics allows the true gap along the motion (95 %): above the target (10 nm for the circle, 20 nm for \
         the rotations) the data do not determine the extrinsics well enough for it.</p>\n<table>\n<tr><th>motion</th>\
         <th>before (nm)</th><th>after (nm)</th><th>tracked (nm)</th><th>model-free (nm)</th><th>count ≥ (nm)</th>\
         <th>verdict</th><th>forecast (nm)</th><th>paper after (nm)</th><th>note</th></tr>\n",
    );
    let f = |x: Option<f64>| x.map_or("–".to_string(), |v| format!("{v:.1}"));
    for v in &c.validation {
        let forecast = c.validation_forecast.iter().find(|x| x.motion == v.motion);
        let forecast_cell = match forecast {
            Some(x) if !x.within_target() => format!("<span class=\"warn\">≤ {:.1}</span>", x.expected_nm),
            Some(x) => format!("≤ {:.1}", x.expected_nm),
            None => "–".to_string(),
        };
        let e = v.after_evidence.as_ref();
        let verdict = match e {
            Some(e) if e.within_target => e.verdict.word().to_string(),
            Some(e) => format!(
                "<span class=\"warn\">{}{}</span>",
                e.verdict.word(),
                if e.verdict == crate::validate::evidence::Verdict::Confirmed { ", above target" } else { "" }
            ),
            None => "–".to_string(),
        };
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td>{verdict}</td><td class=\"num\">{forecast_cell}</td><td class=\"num\">{:.0}</td><td>{}</td></tr>",
            escape(&v.motion),
            f(v.before_nm),
            f(v.after_nm),
            f(e.map(|e| e.tracked_nm)),
            f(e.and_then(|e| e.model_free_nm)),
            f(e.and_then(|e| e.bounds).map(|b| b.lower_nm)),
            v.paper_nm,
            escape(v.note.as_deref().unwrap_or(""))
        );
    }
    h.push_str("</table>\n<div class=\"plots\">\n");
    for v in &c.validation {
        if v.before_curve_nm.is_empty() && v.after_curve_nm.is_empty() {
            continue;
        }
        let _ = writeln!(h, "<figure>{}</figure>", validation_plot(v));
    }
    h.push_str("</div>\n<p class=\"muted\">Before and after share the plot; the after curve is also listed in the table above \
                when it is too small to see at the before curve's scale.</p>\n");
}

fn validation_plot(v: &ValidationRow) -> String {
    let along = |c: &[f64]| -> Vec<(f64, f64)> {
        let n = c.len().max(2) - 1;
        c.iter().enumerate().map(|(i, &y)| (100.0 * i as f64 / n as f64, y)).collect()
    };
    let before = format!("before: {} nm p-p", v.before_nm.map_or("–".into(), |x| format!("{x:.1}")));
    let after = format!("after: {} nm p-p", v.after_nm.map_or("–".into(), |x| format!("{x:.1}")));
    let series = [
        Series { name: &before, color: "#d62728", points: along(&v.before_curve_nm), markers: false },
        Series { name: &after, color: "#1f77b4", points: along(&v.after_curve_nm), markers: false },
    ];
    svg_plot(&v.motion, "progress along the motion (%)", "cavity length change (nm)", &series, &[0.0], &[])
}

fn diagnosis(h: &mut String, s: &Session) {
    h.push_str("<h2>Diagnosis</h2>\n");
    let Some(d) = &s.diagnosis else {
        h.push_str("<p class=\"muted\">No diagnosis was run in this session.</p>\n");
        return;
    };
    let _ = writeln!(h, "<p><b>Verdict:</b> {}</p>", escape(&d.verdict));
    h.push_str("<table>\n<tr><th>effect</th><th>estimate</th><th>σ</th><th>unit</th><th>score</th><th>absorbed by the extrinsics</th><th>note</th></tr>\n");
    for e in &d.effects {
        let (v, sg) = with_sigma(e.estimate, e.sigma);
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td class=\"num\">{v}</td><td class=\"num\">{sg}</td><td>{}</td><td class=\"num\">{:.2} {}</td><td class=\"num\">{}</td><td>{}</td></tr>",
            escape(&e.name),
            escape(&e.unit),
            e.score,
            escape(&e.score_kind),
            e.absorbed_fraction.map_or("–".into(), |f| format!("{:.0} %", 100.0 * f)),
            escape(&e.note)
        );
    }
    h.push_str("</table>\n");
    if d.validation.is_empty() {
        return;
    }
    h.push_str(
        "<h3>Validation with and without the added effects</h3>\n<p>The validation motions planned through \
         the inverse model twice, with the calibrated model and with the added effects (extrinsics refitted \
         with them), both run on the bench. Figure of merit: the Fabry-Perot cavity variation along the \
         motion, peak to peak (it must stay zero).</p>\n<table>\n<tr><th>motion</th><th>without the effects \
         (nm)</th><th>with the effects (nm)</th><th>improvement</th><th>note</th></tr>\n",
    );
    let nm = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.1}"));
    for r in &d.validation {
        let gain = match (r.without_effect_nm, r.with_effect_nm) {
            (Some(a), Some(b)) if b > 0.0 => format!("{:.1}×", a / b),
            _ => "–".to_string(),
        };
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{gain}</td><td>{}</td></tr>",
            escape(&r.motion),
            nm(r.without_effect_nm),
            nm(r.with_effect_nm),
            escape(r.note.as_deref().unwrap_or(""))
        );
    }
    h.push_str("</table>\n");
}

fn notes_and_traces(h: &mut String, s: &Session) {
    if !s.notes.is_empty() {
        let _ = writeln!(h, "<h2>Notes</h2>\n<p>{}</p>", escape(&s.notes).replace('\n', "<br>"));
    }
    let _ = writeln!(
        h,
        "<h2>Measurements</h2>\n<details><summary>{} recorded traces (in the session's traces/ folder)</summary>\n<table>\n<tr><th>file</th><th>label</th><th>kind</th><th>samples</th></tr>",
        s.traces.len()
    );
    for t in &s.traces {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{}{}</td><td>{}</td><td class=\"num\">{}</td></tr>",
            escape(&t.file),
            escape(&t.label),
            if t.complete { "" } else { " <span class=\"no\">(partial, not used)</span>" },
            t.kind,
            t.samples
        );
    }
    h.push_str("</table></details>\n");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_diagnosis_validation_with_and_without_the_effects_is_in_the_report() {
        let dir = tempfile::tempdir().unwrap();
        let mut s = crate::session::tests::sample_session(dir.path());
        let html = render_html(&s);
        assert!(html.contains("Validation with and without the added effects"));
        // the sample row: 310 nm without, 9.5 nm with the pivot
        assert!(html.contains("rotation 6° about X_f through P_r</td><td class=\"num\">310.0</td><td class=\"num\">9.5</td><td class=\"num\">32.6×</td>"), "{html}");
        // no rows: no section
        s.diagnosis.as_mut().unwrap().validation.clear();
        assert!(!render_html(&s).contains("Validation with and without the added effects"));
    }
}
