//! Diagnosis: where the residual of the identification lives (RMS per equation, the largest
//! residuals), and the discrepancy workflow (`photorobot_core::diagnose`) run step by step in the
//! worker: baseline, candidates scored, discriminating motions run on the bench, effects named
//! and added, the verdict with the residual before and after.

use crate::state::AppState;
use crate::views::results::equation_of;
use egui::RichText;

/// Draw the diagnosis view.
pub fn ui(ui: &mut egui::Ui, s: &mut AppState) {
    ui.heading("Diagnosis");
    ui.label(
        "Where do the model and the data disagree? A residual above the noise floor means an effect the \
         model lacks (drift, a stage scale or pivot error, …).",
    );
    match s.report.as_deref() {
        Some(r) => {
            ui.label(format!(
                "residual {:.2} σ RMS over {} observations (1 = at the noise floor)",
                r.residual_rms_sigma, r.observations
            ));
        }
        None => {
            ui.label("not identified yet: the diagnosis starts from the design extrinsics and refits them");
        }
    }
    if s.steps.iter().all(|st| st.traces.is_empty()) {
        ui.label("no recorded trace yet: run the wizard's steps first");
        return;
    }
    let idle = s.busy.is_none() && s.running.is_none();
    let mut start = false;
    ui.horizontal(|ui| {
        start = ui
            .add_enabled(idle, egui::Button::new(RichText::new("Run the diagnosis").size(18.0)))
            .on_hover_text(
                "score every effect of the library against the residual, run discriminating motions on the bench, \
                 add what is found",
            )
            .clicked();
        if s.busy.as_deref() == Some("diagnosing") {
            ui.spinner();
            ui.label("diagnosing…");
        }
    });
    egui::ScrollArea::vertical().id_salt("diagnosis").show(ui, |ui| {
        workflow(ui, s);
        ui.separator();
        residuals(ui, s);
    });
    if start {
        s.diagnose();
    }
}

fn residuals(ui: &mut egui::Ui, s: &AppState) {
    let Some(r) = s.report.as_deref() else { return };
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
    for (title, summary) in &s.diagnosis_steps {
        ui.label(RichText::new(drawable(title)).strong());
        ui.label(drawable(summary));
    }
    match &s.diagnosis {
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
            if !d.discriminating_motions.is_empty() {
                ui.label(drawable(&format!(
                    "discriminating motions {}: {}",
                    if d.discriminating_motions_ran { "run" } else { "designed (not run)" },
                    d.discriminating_motions.join("; ")
                )));
            }
        }
    }
}

/// Text from the core with the arrows the UI font lacks written out.
pub fn drawable(text: &str) -> String {
    text.replace('→', "->").replace('←', "<-").replace('↔', "<->")
}
