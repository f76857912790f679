//! Diagnosis: where the residual of the identification lives (RMS per equation, the largest
//! residuals), and the discrepancy workflow (`photorobot_core::diagnose`) run step by step in the
//! worker: baseline, candidates scored, discriminating motions run on the bench, effects named
//! and added, the verdict with the residual before and after; then the validation motions planned
//! without and with the effects it added (`photorobot_core::diagnose::validation`), run on the bench.
//! Or the loop of a bench the workbench does not drive: the discriminating motions proposed as a
//! plan to save, the traces recorded from it added, and the diagnosis run again until it is settled.

use crate::state::AppState;
use crate::views::results::equation_of;
use crate::worker::{EffectValidation, BUSY_EFFECT_VALIDATION};
use egui::RichText;
use egui_plot::{Bar, BarChart, GridMark, Legend, Plot, PlotPoint, Text};
use photorobot_core::diagnose::validation::EffectValidationRow;

/// Colour of the figures planned with the calibrated model (as the validation view's "before").
const WITHOUT_COLOR: egui::Color32 = egui::Color32::from_rgb(230, 90, 70);
/// Colour of the figures planned with the extended model (as the validation view's "after").
const WITH_COLOR: egui::Color32 = egui::Color32::from_rgb(70, 190, 100);

/// Draw the diagnosis view.
pub fn ui(ui: &mut egui::Ui, s: &mut AppState) {
    ui.heading("Diagnosis");
    ui.label(
        "Where do the model and the data disagree? A residual above the noise floor means an effect the \
         model lacks (drift, a stage scale or pivot error, …).",
    );
    match s.results.report.as_deref() {
        Some(r) => {
            ui.label(format!(
                "residual {:.2} σ RMS over {} observations (1 = at the noise floor)",
                r.residual_rms_sigma, r.observations
            ));
        }
        None if s.extrinsics == s.worker.nominal.extrinsics => {
            ui.colored_label(
                ui.visuals().warn_fg_color,
                "not identified yet: the diagnosis starts from the design extrinsics. Where the recorded motions cannot refit them (tilts off by a degree, the gap by tens of µm), the error looks like effects: identify first (Wizard) for a diagnosis you can trust. Estimates beyond 20× an effect's typical size are not named.",
            );
        }
        None => {
            ui.label("not identified in this session: the diagnosis starts from the extrinsics in use and refits them");
        }
    }
    refused_calibration(ui, s);
    if s.all_traces().is_empty() {
        ui.label("no recorded trace yet: run the wizard's steps first");
        saved_diagnosis(ui, s);
        return;
    }
    let idle = s.busy.is_none() && s.wizard.running.is_none();
    let (mut start, mut add) = (false, false);
    ui.horizontal(|ui| {
        start = ui
            .add_enabled(idle, egui::Button::new(RichText::new("Run the diagnosis").size(18.0)))
            .on_hover_text(
                "score every effect of the library against the residual, run discriminating motions on the bench \
                 (or propose them), add what is found",
            )
            .clicked();
        ui.checkbox(&mut s.diagnosis.propose_only, "propose the discriminating motions instead of running them")
            .on_hover_text(
                "for a bench this workbench does not drive: save them as a plan, record it there, add the traces",
            );
        add = ui
            .add_enabled(idle, egui::Button::new("Add recorded traces…"))
            .on_hover_text("traces recorded after this session (a proposed plan), on the session's clock")
            .clicked();
        // Beside the other actions, so that it stays in view however long the steps above it.
        if s.diagnosis.proposed_plan.is_some() && ui.button("Save the proposed plan…").clicked() {
            save_proposed_plan(s);
        }
        if s.busy.as_deref() == Some("diagnosing") {
            ui.spinner();
            ui.label("diagnosing…");
        }
    });
    if add {
        let files = s.dialogs.open_traces();
        if !files.is_empty() {
            s.add_recorded_traces(&files);
        }
    }
    egui::ScrollArea::vertical().id_salt("diagnosis").show(ui, |ui| {
        workflow(ui, s);
        proposed_plan(ui, s);
        effect_validation(ui, s);
        saved_diagnosis(ui, s);
        ui.separator();
        residuals(ui, s);
    });
    if start {
        s.diagnose();
    }
}

fn residuals(ui: &mut egui::Ui, s: &AppState) {
    let Some(r) = s.results.report.as_deref() else { return };
    let mut per_eq: Vec<(String, f64, usize)> = Vec::new();
    for (label, unit, res, sigma) in &r.residuals {
        let eq = equation_of(label, unit);
        let z2 = (res / sigma).powi(2);
        match per_eq.iter_mut().find(|e| e.0 == eq) {
            Some(e) => {
                e.1 += z2;
                e.2 += 1;
            }
            None => per_eq.push((eq, z2, 1)),
        }
    }
    ui.label(RichText::new("RMS residual per equation").strong());
    egui::Grid::new("per equation").striped(true).show(ui, |ui| {
        ui.strong("equation");
        ui.strong("RMS (σ)");
        ui.strong("observations");
        ui.end_row();
        for (eq, ss, n) in &per_eq {
            ui.label(eq);
            ui.monospace(format!("{:.2}", (ss / *n as f64).sqrt()));
            ui.monospace(n.to_string());
            ui.end_row();
        }
    });
    let mut worst: Vec<&(String, String, f64, f64)> = r.residuals.iter().collect();
    worst.sort_by(|a, b| (b.2 / b.3).abs().total_cmp(&(a.2 / a.3).abs()));
    ui.label(RichText::new("Largest residuals").strong());
    egui::Grid::new("worst").striped(true).show(ui, |ui| {
        for h in ["measurement", "residual", "σ", "residual / σ"] {
            ui.strong(h);
        }
        ui.end_row();
        for (label, unit, res, sigma) in worst.into_iter().take(10) {
            // Fringe amplitudes are a few µW: shown in µW so the digits mean something.
            let (scale, unit) = if unit == "mW" { (1e3, "µW") } else { (1.0, unit.as_str()) };
            ui.label(label);
            ui.monospace(format!("{:+.3} {unit}", res * scale));
            ui.monospace(format!("{:.3} {unit}", sigma * scale));
            ui.monospace(format!("{:+.2}", res / sigma));
            ui.end_row();
        }
    });
}

fn workflow(ui: &mut egui::Ui, s: &AppState) {
    for (title, summary) in &s.diagnosis.steps {
        ui.label(RichText::new(drawable(title)).strong());
        ui.label(drawable(summary));
    }
    match &s.diagnosis.result {
        None => {}
        Some(Err(e)) => {
            ui.colored_label(ui.visuals().error_fg_color, format!("diagnosis failed: {e}"));
        }
        Some(Ok(d)) => {
            let verdict = match d.verdict {
                photorobot_core::diagnose::Verdict::Named => "named: the model lacked the effects below",
                photorobot_core::diagnose::Verdict::None => "no significant missing effect",
                photorobot_core::diagnose::Verdict::Unexplained => "unexplained structure remains",
            };
            ui.label(RichText::new(format!("Verdict: {verdict}")).size(20.0).strong());
            ui.label(format!(
                "gap-change residual RMS {:.2} nm before, {:.2} nm after ({:.2} σ to {:.2} σ)",
                d.residual_rms_before_nm,
                d.residual_rms_after_nm,
                d.residual_rms_before_sigma,
                d.residual_rms_after_sigma
            ));
            if let Some(line) = d.family_line() {
                ui.label(drawable(&line));
            }
            let effects: Vec<_> = d.effects.iter().chain(&d.partial).collect();
            if !effects.is_empty() {
                egui::Grid::new("effects").striped(true).show(ui, |ui| {
                    for h in ["effect", "estimate", "σ", "F", "absorbed by extrinsics", "cannot be told from"] {
                        ui.strong(h);
                    }
                    ui.end_row();
                    for e in effects {
                        ui.label(drawable(&e.name));
                        ui.monospace(format!("{:.4} {}", e.estimate, e.unit));
                        ui.monospace(e.sigma.map_or("–".into(), |v| format!("{v:.4} {}", e.unit)));
                        ui.monospace(format!("{:.1}", e.score));
                        ui.monospace(format!("{:.1} %", e.absorbed_share * 100.0));
                        ui.label(drawable(&e.ambiguous_with.join(", ")));
                        ui.end_row();
                    }
                });
            }
            if !d.equivalent_to_extrinsics.is_empty() {
                ui.label(drawable(&format!(
                    "equivalent to an extrinsic change: {}",
                    d.equivalent_to_extrinsics.join(", ")
                )));
            }
            if !d.not_detectable.is_empty() {
                ui.label(drawable(&format!(
                    "not detectable at typical size on these data and motions: {}",
                    d.not_detectable.join(", ")
                )));
            }
            cancelling_pairs(ui, &d.cancelling_pairs);
            ruled_out_above(ui, &d.ruled_out_above);
            if !d.discriminating_motions.is_empty() {
                ui.label(drawable(&format!(
                    "discriminating motions {}: {}",
                    if d.discriminating_motions_ran { "run" } else { "designed (not run)" },
                    d.discriminating_motions.join("; ")
                )));
            }
            if !d.need_motions.is_empty() {
                ui.label(drawable(&format!(
                    "the recorded data cannot tell these from an extrinsic change: {}",
                    d.need_motions.join(", ")
                )));
            }
            if d.settled {
                ui.label(RichText::new(SETTLED).strong());
                if let Some(open) = d.pairs_left_open() {
                    ui.label(open);
                }
            }
        }
    }
}

/// Pairs of candidates these data cannot tell apart, folded: the header says how many.
fn cancelling_pairs(ui: &mut egui::Ui, pairs: &[[String; 2]]) {
    if pairs.is_empty() {
        return;
    }
    egui::CollapsingHeader::new(format!(
        "{} pairs these data cannot tell apart (sizes that cancel would show nothing)",
        pairs.len()
    ))
    .id_salt("cancelling pairs")
    .show(ui, |ui| {
        for [a, b] in pairs {
            ui.label(drawable(&format!("{a} ↔ {b}")));
        }
    });
}

/// The header over the candidates named nowhere, each with the size its data rule out.
pub fn bounds_header(count: usize) -> String {
    format!("{count} candidates not named, each smaller than the data would show (|estimate| + 3σ)")
}

/// One bound's line as drawn: [`photorobot_core::diagnose::Bound::describe`].
pub fn bound_line(b: &photorobot_core::diagnose::Bound) -> String {
    drawable(&b.describe())
}

/// Candidates named nowhere, folded: each with the size above which the data would have shown it,
/// so that "not named" is not read as "absent".
fn ruled_out_above(ui: &mut egui::Ui, bounds: &[photorobot_core::diagnose::Bound]) {
    if bounds.is_empty() {
        return;
    }
    egui::CollapsingHeader::new(bounds_header(bounds.len())).id_salt("ruled out above").show(ui, |ui| {
        for b in bounds {
            ui.label(bound_line(b));
        }
    });
}

/// What a settled diagnosis says.
pub const SETTLED: &str =
    "Settled: no discriminating motion that these data lack would tell more of a single candidate \
     (each is named, ruled out at its typical size, equivalent to an extrinsic change, or too small for any motion).";

/// A warning when the calibration the diagnosis starts from was refused or is ambiguous.
fn refused_calibration(ui: &mut egui::Ui, s: &AppState) {
    use photorobot_core::identify::verdict::Verdict;
    let Some(fit) = s.results.report.as_deref().and_then(|r| r.fit.as_ref()) else { return };
    let text = match fit.verdict {
        Verdict::Fits => return,
        Verdict::DoesNotFit => format!(
            "The calibration was refused (residual {:.2} σ, above the {:.2} σ noise allows): the diagnosis starts from its \
             best extrinsics and names what the model lacks; do not use those extrinsics before recalibrating with the \
             named effects.",
            fit.rms_sigma, fit.threshold_sigma
        ),
        Verdict::Ambiguous => "The calibration is ambiguous (branches tie): the diagnosis starts from the chosen branch.".into(),
    };
    ui.colored_label(ui.visuals().warn_fg_color, text);
}

/// The plan the last diagnosis proposed (it ran no motion), with the button that saves it.
fn proposed_plan(ui: &mut egui::Ui, s: &AppState) {
    let Some(plan) = s.diagnosis.proposed_plan.clone() else { return };
    let motions: Vec<&str> = plan.segments.iter().filter(|g| g.is_recorded()).map(|g| g.label()).collect();
    ui.add_space(6.0);
    ui.label(RichText::new("Proposed discriminating motions").size(16.0).strong());
    ui.label(drawable(&format!(
        "{} recorded motions: {}. Save it (Save the proposed plan…), record it on the bench, then add its traces \
         (Add recorded traces…) and run the diagnosis again.",
        motions.len(),
        motions.join("; ")
    )));
}

/// Ask where to save the proposed plan and save it there; the status says what happened.
fn save_proposed_plan(s: &mut AppState) {
    let Some(plan) = s.diagnosis.proposed_plan.clone() else { return };
    if let Some(path) = s.dialogs.save_plan("discriminating-motions.ron") {
        s.status = match plan.save(&path) {
            Ok(()) => format!("saved the proposed plan to {}", path.display()),
            Err(e) => format!("plan not saved: {e}"),
        };
    }
}

/// The names of the effects the diagnosis added (named, then partial), joined.
fn added_effects(s: &AppState) -> Option<String> {
    let Some(Ok(d)) = &s.diagnosis.result else { return None };
    let names: Vec<&str> = d.effects.iter().chain(&d.partial).map(|e| e.name.as_str()).collect();
    (!names.is_empty()).then(|| drawable(&names.join(" + ")))
}

/// A validation motion's name without where it runs (for the chart's axis).
fn short_motion(name: &str) -> &str {
    [" through ", " in the "].iter().fold(name, |n, sep| n.split(sep).next().unwrap_or(n))
}

/// The validation motions planned without and with the effects the diagnosis added: a table and
/// a bar chart of the peak-to-peak cavity variation.
fn effect_validation(ui: &mut egui::Ui, s: &AppState) {
    if !matches!(s.diagnosis.result, Some(Ok(_))) {
        return;
    }
    ui.add_space(8.0);
    ui.label(RichText::new("Validation with and without the added effects").size(16.0).strong());
    let without_name =
        if s.diagnosis.from_calibration { "calibrated model" } else { "design extrinsics (not calibrated)" };
    let with_name = format!("with {}", added_effects(s).unwrap_or_else(|| "the effects".into()));
    let rows = match &s.diagnosis.validation {
        None if s.busy.as_deref() == Some(BUSY_EFFECT_VALIDATION) => {
            ui.horizontal(|ui| {
                ui.spinner();
                ui.label("running the 4 validation motions planned without, then with the added effects…");
            });
            return;
        }
        None => return,
        Some(EffectValidation::NoEffect) => {
            ui.label("no effect was added: there is no extended model to validate (the validation motions are those of the Validation tab)");
            return;
        }
        Some(EffectValidation::Failed(e)) => {
            ui.colored_label(ui.visuals().error_fg_color, format!("validation with the effects failed: {e}"));
            return;
        }
        Some(EffectValidation::Ran { bench, rows }) => {
            ui.label(format!(
                "The validation motions (which must leave the gap unchanged) planned through the inverse model twice: \
                 with the {without_name} and {with_name} (extrinsics refitted with it), run on {bench}, and \
                 measured with the extended model. Figure of merit: FP cavity variation, peak to peak."
            ));
            rows
        }
    };
    validation_table(ui, "effect validation", rows);
    bar_chart(ui, rows, without_name, &with_name);
    ui.label(format!(
        "bars: the {without_name} (left) and the model {with_name} (right), per validation motion; the \
         smaller, the better the model plans motions that must keep the gap"
    ));
}

/// The validation rows without and with the effects, and the notes of the rows that have one.
fn validation_table(ui: &mut egui::Ui, id: &str, rows: &[EffectValidationRow]) {
    let nm = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.1}"));
    egui::Grid::new(id).striped(true).show(ui, |ui| {
        for h in ["motion", "without the effect (nm)", "with the effect (nm)", "improvement (×)"] {
            ui.strong(h);
        }
        ui.end_row();
        for r in rows {
            ui.label(drawable(&r.motion));
            ui.monospace(nm(r.without_effect_nm));
            ui.monospace(nm(r.with_effect_nm));
            ui.monospace(improvement(r).map_or("–".into(), |f| format!("{f:.1}×")));
            ui.end_row();
        }
    });
    for n in rows.iter().filter_map(|r| r.note.as_ref()) {
        ui.colored_label(ui.visuals().warn_fg_color, drawable(n));
    }
}

/// The diagnosis an opened session carries (`session.ron`, written by this view or by
/// `photorobot diagnose`), when no diagnosis was run since: its verdict, the effects it named
/// with their scores, the extended model (the effects' values and the refitted extrinsics) and
/// the validation without and with them. A record, not a result: the steps and the residual
/// plots are not in it; running the diagnosis again replaces it.
fn saved_diagnosis(ui: &mut egui::Ui, s: &AppState) {
    let (None, Some(d)) = (&s.diagnosis.result, &s.diagnosis.loaded_record) else { return };
    ui.add_space(8.0);
    ui.label(RichText::new("Diagnosis saved with this session").size(16.0).strong());
    ui.label(
        "as recorded when the session was saved (running the diagnosis again replaces it; the steps and the \
         discriminating motions' traces are not in the record)",
    );
    ui.label(RichText::new(format!("Verdict: {}", drawable(&d.verdict))).size(18.0).strong());
    if !d.effects.is_empty() {
        egui::Grid::new("saved effects").striped(true).show(ui, |ui| {
            for h in ["effect", "estimate", "σ", "score", "absorbed by extrinsics", "note"] {
                ui.strong(h);
            }
            ui.end_row();
            for e in &d.effects {
                ui.label(drawable(&e.name));
                ui.monospace(format!("{:.4} {}", e.estimate, e.unit));
                ui.monospace(e.sigma.map_or("–".into(), |v| format!("{v:.4} {}", e.unit)));
                ui.monospace(format!("{:.1} ({})", e.score, e.score_kind));
                ui.monospace(e.absorbed_fraction.map_or("–".into(), |f| format!("{:.1} %", f * 100.0)));
                ui.label(drawable(&e.note));
                ui.end_row();
            }
        });
    }
    if !d.model_effects.is_empty() {
        ui.label(RichText::new("Extended model").strong());
        for e in &d.model_effects {
            ui.monospace(drawable(&format!("{e:?}")));
        }
    }
    if let Some(x) = &d.extrinsics {
        let values = x.to_array();
        let text: Vec<String> = photorobot_core::model::extrinsics::PARAMETER_NAMES
            .iter()
            .zip(values)
            .map(|((name, unit), v)| format!("{name} = {v:.4} {unit}"))
            .collect();
        ui.label(format!("extrinsics refitted with them: {}", text.join(", ")));
    }
    if !d.validation.is_empty() {
        ui.label(RichText::new("Validation with and without the added effects (saved)").strong());
        validation_table(ui, "saved effect validation", &d.validation);
        bar_chart(ui, &d.validation, "without the effects", "with the effects");
    }
}

/// Without over with (how many times smaller the variation is with the effect), when both ran.
fn improvement(r: &EffectValidationRow) -> Option<f64> {
    match (r.without_effect_nm, r.with_effect_nm) {
        (Some(a), Some(b)) if b > 0.0 => Some(a / b),
        _ => None,
    }
}

fn bar_chart(ui: &mut egui::Ui, rows: &[EffectValidationRow], without_name: &str, with_name: &str) {
    const WIDTH: f64 = 0.35;
    let series = |name: &str, offset: f64, color: egui::Color32, get: fn(&EffectValidationRow) -> Option<f64>| {
        let bars = rows
            .iter()
            .enumerate()
            .filter_map(|(k, r)| get(r).map(|v| Bar::new(k as f64 + offset, v).width(WIDTH).name(drawable(&r.motion))))
            .collect();
        BarChart::new(name, bars).color(color)
    };
    let labels: Vec<String> = rows.iter().map(|r| drawable(short_motion(&r.motion))).collect();
    let top = rows.iter().flat_map(|r| [r.without_effect_nm, r.with_effect_nm]).flatten().fold(0.0, f64::max);
    Plot::new("effect validation chart")
        .height(260.0)
        .legend(Legend::default().position(egui_plot::Corner::RightTop))
        .x_axis_label("validation motion")
        .y_axis_label("FP cavity variation, peak to peak (nm)")
        .x_grid_spacer(move |input| {
            let n = rows.len();
            (0..n)
                .map(|k| k as f64)
                .filter(|x| input.bounds.0 <= *x && *x <= input.bounds.1)
                .map(|value| GridMark { value, step_size: 1.0 })
                .collect()
        })
        .x_axis_formatter(move |mark, _| {
            let k = mark.value.round();
            if (mark.value - k).abs() < 1e-6 && k >= 0.0 {
                labels.get(k as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        })
        .include_x(-0.6)
        .include_x(rows.len() as f64 - 0.4)
        .include_y(0.0)
        .include_y(top * 1.15)
        .y_axis_min_width(56.0)
        .allow_drag(false)
        .allow_zoom(false)
        .allow_scroll(false)
        .show(ui, |pl| {
            pl.bar_chart(series(without_name, -WIDTH / 2.0, WITHOUT_COLOR, |r| r.without_effect_nm));
            pl.bar_chart(series(with_name, WIDTH / 2.0, WITH_COLOR, |r| r.with_effect_nm));
            // The figures over the bars, so the small ones read too.
            for (k, r) in rows.iter().enumerate() {
                for (offset, v) in [(-WIDTH / 2.0, r.without_effect_nm), (WIDTH / 2.0, r.with_effect_nm)] {
                    if let Some(v) = v {
                        pl.text(
                            Text::new(
                                format!("figure {k} {offset}"),
                                PlotPoint::new(k as f64 + offset, v),
                                format!("{v:.1} nm"),
                            )
                            .name("")
                            .anchor(egui::Align2::CENTER_BOTTOM),
                        );
                    }
                }
            }
        });
}

/// Text from the core with the arrows the UI font lacks written out.
pub fn drawable(text: &str) -> String {
    text.replace('→', "->").replace('←', "<-").replace('↔', "<->")
}

#[cfg(test)]
mod tests {
    use super::*;
    use photorobot_core::diagnose::Bound;

    /// A bound's line is its description, drawable.
    #[test]
    fn a_bound_line_is_its_description() {
        let b = Bound { name: "c".into(), unit: "ppm".into(), estimate: -86.1632, sigma: 126.9992, below: 467.16 };
        assert_eq!(bound_line(&b), "c: -86 ± 127 ppm, below 467 ppm");
    }
}
