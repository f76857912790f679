//! Diagnosis: the entry point of the discrepancy workflow. Until the workflow is wired in, it
//! shows where the residual of the identification lives: the measurements with the largest
//! normalised residuals, and the RMS per equation.

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
    let Some(r) = s.report.as_deref() else {
        ui.label("identify first (wizard)");
        return;
    };
    ui.label(format!(
        "residual {:.2} σ RMS over {} observations (1 = at the noise floor)",
        r.residual_rms_sigma, r.observations
    ));
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
