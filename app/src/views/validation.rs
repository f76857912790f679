//! Validation: the circle of the tool centre and the three rotations (about X_f, Z_f and the
//! optical axis), planned with the nominal and with the identified extrinsics, run on the bench;
//! or the calibration alone checked on the bench today. Each motion with the figure its verdict
//! stands behind, the figures that do not use the extrinsics under test, and the verdict.

use crate::state::AppState;
use crate::worker::{CheckedMotion, Command, ValidationPair};
use egui::{Color32, RichText};
use egui_plot::{Legend, Line, Plot, PlotPoints};
use photorobot_core::validate::evidence::{Evidence, Verdict};
use photorobot_core::validate::ValidationFigure;

/// Draw the validation view.
pub fn ui(ui: &mut egui::Ui, s: &mut AppState) {
    ui.heading("Validation");
    ui.label(
        "Motions that must leave the cavity length |L| unchanged if the extrinsics are right: a circle of the tool \
         centre in the lamella plane and rotations about the fiber's X and Z axes and about the optical axis. Each \
         figure is proven by measurements that do not use the extrinsics under test: the count of the signal's \
         extrema, its own turning points, the fringe contrast and absolute gaps at stops along the motion.",
    );
    let idle = s.busy.is_none() && s.wizard.running.is_none();
    let can = s.results.report.is_some();
    if !can {
        ui.label("identify first (wizard), or open a session");
    }
    ui.horizontal(|ui| {
        if ui.add_enabled(can && idle, egui::Button::new(RichText::new("Run validation").size(18.0))).clicked() {
            s.worker.send(Command::Validate { identified: s.extrinsics });
            s.results.validation = None;
        }
        let check = egui::Button::new(RichText::new("Check the calibration on the bench").size(18.0));
        if ui
            .add_enabled(can && idle, check)
            .on_hover_text(
                "the four motions planned with these extrinsics, without recalibrating: has the bench drifted?",
            )
            .clicked()
        {
            s.worker.send(Command::Check { extrinsics: s.extrinsics });
            s.results.check = None;
        }
    });
    if s.busy.as_deref() == Some(crate::worker::BUSY_VALIDATING) {
        ui.horizontal(|ui| {
            ui.spinner();
            ui.label("running the validation motions and their stops");
        });
    }
    proof_banner(ui, s);
    egui::ScrollArea::vertical().id_salt("validation").show(ui, |ui| {
        if let Some(check) = &s.results.check {
            ui.separator();
            checked_table(ui, check);
        }
        if let Some(pairs) = &s.results.validation {
            ui.separator();
            before_after(ui, pairs);
        }
    });
}

/// Red when the latest validation does not prove the calibration, with one line per motion; a
/// green line when it does.
pub fn proof_banner(ui: &mut egui::Ui, s: &AppState) {
    if s.results.check.is_none() && s.results.validation.is_none() && s.results.report.is_none() {
        return;
    }
    let ran = s.results.check.is_some()
        || s.results.validation.is_some()
        || s.results.report.as_ref().is_some_and(|r| !r.validation.is_empty() && !r.validation_predicted);
    if !ran {
        return;
    }
    let failures = s.results.validation_failures();
    if failures.is_empty() {
        ui.colored_label(Color32::from_rgb(60, 180, 90), "Validation: every motion confirmed within its target.");
        return;
    }
    let red = Color32::from_rgb(220, 60, 60);
    ui.label(RichText::new("NOT PROVEN: the validation does not confirm this calibration").color(red).strong());
    for f in failures {
        ui.colored_label(red, f);
    }
}

fn verdict_label(ui: &mut egui::Ui, e: &Evidence) {
    let (color, word) = match (e.verdict, e.within_target) {
        (Verdict::Confirmed, true) => (Color32::from_rgb(60, 180, 90), "confirmed".to_string()),
        (Verdict::Confirmed, false) => (Color32::from_rgb(220, 120, 40), "confirmed, above target".to_string()),
        (Verdict::Unconfirmed, _) => (Color32::from_rgb(220, 120, 40), "unconfirmed".to_string()),
        (Verdict::Contradicted, _) => (Color32::from_rgb(220, 60, 60), "contradicted".to_string()),
    };
    ui.colored_label(color, word);
}

fn nm(x: Option<f64>) -> String {
    x.map_or("–".into(), |v| format!("{v:.1} nm"))
}

/// The check of the calibration: one row per motion, then what disagrees.
fn checked_table(ui: &mut egui::Ui, check: &[CheckedMotion]) {
    ui.label(RichText::new("Check of the calibration on the bench (no recalibration)").strong());
    egui::Grid::new("check table").striped(true).show(ui, |ui| {
        for h in ["motion", "measured", "target", "tracked", "model-free", "count ≥", "sweeps", "verdict"] {
            ui.strong(h);
        }
        ui.end_row();
        for c in check {
            ui.label(c.motion.name());
            match &c.figure {
                Ok(f) => {
                    let e = &f.evidence;
                    ui.monospace(nm(Some(e.measured_nm)));
                    ui.monospace(format!("{:.0} nm", e.target_nm));
                    ui.monospace(nm(Some(e.tracked_nm)));
                    ui.monospace(e.model_free_words().map_or("–".into(), |w| format!("{w} nm")));
                    ui.monospace(nm(e.bounds.map(|b| b.lower_nm)));
                    ui.monospace(nm(e.sweep_spread_nm));
                    verdict_label(ui, e);
                }
                Err(e) => {
                    ui.colored_label(Color32::from_rgb(220, 60, 60), format!("failed: {e}"));
                }
            }
            ui.end_row();
        }
    });
    disagreements(ui, check.iter().filter_map(|c| c.figure.as_ref().ok()));
}

/// The comparisons that disagree, and what is missing, per motion not confirmed.
fn disagreements<'a>(ui: &mut egui::Ui, figures: impl Iterator<Item = &'a ValidationFigure>) {
    for f in figures.filter(|f| !f.evidence.within_target) {
        ui.label(RichText::new(format!("{}: {}", f.motion.name(), f.evidence.verdict.word())).strong());
        for c in f.evidence.checks.iter().filter(|c| !c.agrees) {
            ui.colored_label(Color32::from_rgb(220, 60, 60), format!("{}: {}", c.name, c.detail));
        }
        for n in &f.evidence.notes {
            ui.label(n);
        }
    }
}

/// Before and after calibration: the figures, the after motion's model-free figure beside the
/// tracked one and its verdict, then the curves.
fn before_after(ui: &mut egui::Ui, pairs: &[ValidationPair]) {
    let fmt = |f: &Result<ValidationFigure, String>| match f {
        Ok(f) => format!("{:.1} nm", f.evidence.measured_nm),
        Err(e) => format!("failed: {e}"),
    };
    ui.label(RichText::new("Before and after calibration").strong());
    egui::Grid::new("validation table").striped(true).show(ui, |ui| {
        for h in
            ["motion", "before (nominal)", "after (identified)", "tracked", "model-free", "verdict", "paper (after)"]
        {
            ui.strong(h);
        }
        ui.end_row();
        for p in pairs {
            ui.label(p.motion.name());
            ui.monospace(fmt(&p.before));
            ui.monospace(fmt(&p.after));
            match &p.after {
                Ok(a) => {
                    ui.monospace(nm(Some(a.evidence.tracked_nm)));
                    ui.monospace(a.evidence.model_free_words().map_or("–".into(), |w| format!("{w} nm")));
                    verdict_label(ui, &a.evidence);
                }
                Err(_) => {
                    for _ in 0..3 {
                        ui.label("–");
                    }
                }
            }
            ui.monospace(format!("{:.0} nm", p.motion.paper_after_nm()));
            ui.end_row();
        }
    });
    disagreements(ui, pairs.iter().filter_map(|p| p.after.as_ref().ok()));
    ui.label("cavity variation along each motion (nm), before and after; note the different scales");
    for p in pairs {
        ui.label(RichText::new(p.motion.name()).strong());
        ui.columns(2, |cols| {
            for (col, (f, name, color)) in cols.iter_mut().zip([
                (&p.before, "before", Color32::from_rgb(230, 90, 70)),
                (&p.after, "after", Color32::from_rgb(70, 190, 100)),
            ]) {
                if let Ok(f) = f {
                    curve(col, p, f, name, color);
                }
            }
        });
    }
}

fn curve(ui: &mut egui::Ui, p: &ValidationPair, f: &ValidationFigure, name: &str, color: Color32) {
    let n = f.variation_nm.len().max(1);
    let step = (n / 2000).max(1);
    let pts: Vec<[f64; 2]> =
        f.variation_nm.iter().enumerate().step_by(step).map(|(k, v)| [k as f64 / n as f64 * 100.0, *v]).collect();
    Plot::new((p.motion.name(), name))
        .height(150.0)
        .legend(Legend::default())
        .x_axis_label("% of the motion")
        .y_axis_label("ΔL (nm)")
        .show(ui, |pl| {
            pl.line(
                Line::new(format!("{name}: {:.1} nm p-p tracked", f.peak_to_peak_nm), PlotPoints::from(pts))
                    .color(color),
            );
        });
}
