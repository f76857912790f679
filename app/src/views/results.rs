//! Results: the Table II-style table with uncertainties and determined / not determined, the
//! residual plot per equation (measurement kind), the correlation heat map, the condition number
//! and the warnings in words; above them, an error when the validation does not prove the
//! calibration.

use crate::state::AppState;
use egui::{Color32, RichText};
use egui_plot::{Legend, Plot, PlotPoints, Points};
use photorobot_core::calibration::CalibrationReport;
use photorobot_core::identify::verdict::{FitCheck, Verdict};

/// The equation (measurement kind) a residual belongs to, from its unit and trace label: an
/// absolute gap, a fringe amplitude, or the gap change of a motion of joint q1..q6 (the joint
/// named last before the label's `->`).
pub fn equation_of(label: &str, unit: &str) -> String {
    match unit {
        "µm" => return "absolute gap (sweep)".into(),
        "mW" => return "fringe amplitude".into(),
        _ => {}
    }
    if let Some(arrow) = label.find("->") {
        let before = &label.as_bytes()[..arrow];
        if let Some(k) = (0..before.len().saturating_sub(1))
            .rev()
            .find(|&k| before[k] == b'q' && (b'1'..=b'6').contains(&before[k + 1]))
        {
            return format!("dL, q{} moves", before[k + 1] as char);
        }
    }
    let head = label.split(':').next().unwrap_or(label);
    head.split('#').next().unwrap_or(head).trim().to_string()
}

/// A parameter name for display: `beta_et` → `β_et`, `theta_wf` → `θ_wf`.
pub fn display_name(name: &str) -> String {
    name.replace("theta", "θ").replace("beta", "β")
}

/// Draw the results view.
pub fn ui(ui: &mut egui::Ui, s: &mut AppState) {
    let Some(r) = s.results.report.as_deref() else {
        ui.heading("Results");
        ui.label("No identification yet: run the wizard's steps, then Identify.");
        return;
    };
    // A calibration its validation does not confirm is not a success, whatever the fit says.
    super::validation::proof_banner(ui, s);
    egui::ScrollArea::vertical().id_salt("results").show(ui, |ui| report(ui, r));
}

fn report(ui: &mut egui::Ui, r: &CalibrationReport) {
    ui.heading(format!("Identified extrinsics ({:?} mode, {} observations)", r.mode, r.observations));
    ui.label(format!(
        "solver {} ({}); residual {:.2} σ RMS (1 = at the noise floor); {:.1} min of bench time",
        if r.converged { "converged" } else { "did NOT converge" },
        r.termination,
        r.residual_rms_sigma,
        r.measurement_duration_s / 60.0
    ));
    if let Some(fit) = &r.fit {
        if fit.verdict == Verdict::DoesNotFit {
            does_not_fit(ui, fit);
            ui.separator();
            residual_plot(ui, r);
            return;
        }
        if fit.verdict == Verdict::Ambiguous {
            ambiguous(ui, fit);
        }
    }
    egui::Grid::new("parameters").striped(true).num_columns(7).show(ui, |ui| {
        for h in ["parameter", "value", "unit", "σ noise", "σ systematic", "σ total", "determined"] {
            ui.strong(h);
        }
        ui.end_row();
        let sigma = |s: Option<f64>| s.map_or("–".into(), |s| format!("{s:.5}"));
        for p in &r.parameters {
            ui.label(display_name(&p.name));
            if p.determined {
                ui.monospace(format!("{:.5}", p.value));
            } else {
                ui.monospace(format!("({:.3})", p.value));
            }
            ui.label(&p.unit);
            ui.monospace(sigma(p.sigma_noise.or(p.sigma)));
            ui.monospace(sigma(p.sigma_systematic));
            ui.monospace(sigma(p.sigma));
            if p.determined {
                ui.colored_label(Color32::from_rgb(60, 180, 90), "yes");
            } else {
                ui.colored_label(
                    Color32::from_rgb(220, 120, 40),
                    format!("NO: {}", p.reason.as_deref().unwrap_or("not determined by these data")),
                );
            }
            ui.end_row();
        }
    });
    families(ui, r);
    ui.separator();
    let id = &r.identifiability;
    ui.label(RichText::new("Identifiability").strong());
    ui.label(format!("rank {} of {} columns", id.rank, id.parameters.len()));
    if let Some(c) = id.condition_number {
        ui.label(format!(
            "condition number {c:.3e}{}",
            if c > 100.0 { ": above 100, some combinations are poorly determined" } else { "" }
        ));
    }
    if let Some(c) = id.condition_number_determined {
        ui.label(format!("condition number of the determined parameters {c:.3e}"));
    }
    for (a, b, rho) in &id.strong_correlations {
        ui.label(format!("strongly correlated: {a} and {b} (ρ = {rho:+.3})"));
    }
    for c in &id.unobservable {
        ui.label(&c.description);
    }
    for w in &r.warnings {
        ui.colored_label(ui.visuals().warn_fg_color, format!("warning: {w}"));
    }
    ui.separator();
    ui.columns(2, |cols| {
        residual_plot(&mut cols[0], r);
        heat_map(&mut cols[1], r);
    });
}

/// Each family of observations against the model and the others: where the systematic σ comes from.
fn families(ui: &mut egui::Ui, r: &CalibrationReport) {
    let Some(d) = r.model_discrepancy.as_ref().filter(|d| !d.families.is_empty()) else { return };
    ui.label("σ systematic: what noise cannot explain, from families of observations (and traces) that disagree:");
    egui::Grid::new("families").striped(true).num_columns(5).show(ui, |ui| {
        for h in ["family", "observations", "Birge ratio", "scatter beyond noise", "left out"] {
            ui.strong(h);
        }
        ui.end_row();
        for f in &d.families {
            ui.label(f.family.words());
            ui.monospace(f.observations.to_string());
            ui.monospace(format!("{:.2}", f.birge_ratio));
            ui.monospace(format!("{:.3} {}", f.excess_sigma, f.unit));
            let text = format!(
                "χ² {:.1} for {}: {}",
                f.shift_chi2,
                f.shift_dof,
                if f.disagrees { "disagrees" } else { "agrees" }
            );
            if f.disagrees {
                ui.colored_label(ui.visuals().warn_fg_color, text);
            } else {
                ui.label(text);
            }
            ui.end_row();
        }
    });
}

/// A fit the model cannot explain: an error with the residual, the threshold and the worst
/// traces, and no table of numbers.
fn does_not_fit(ui: &mut egui::Ui, fit: &FitCheck) {
    let red = Color32::from_rgb(220, 60, 60);
    ui.label(RichText::new("NOT A CALIBRATION: the model does not fit these data").color(red).strong().size(18.0));
    ui.colored_label(red, &fit.summary);
    ui.label(format!(
        "residual {:.2} σ RMS; noise and the analysis's σ allow at most {:.2} σ",
        fit.rms_sigma, fit.threshold_sigma
    ));
    ui.label(RichText::new("Traces with the largest residual").strong());
    egui::Grid::new("worst traces").striped(true).num_columns(3).show(ui, |ui| {
        for h in ["trace", "residual (σ RMS)", "observations"] {
            ui.strong(h);
        }
        ui.end_row();
        for t in &fit.worst_traces {
            ui.label(&t.label);
            ui.monospace(format!("{:.2}", t.rms_sigma));
            ui.monospace(t.observations.to_string());
            ui.end_row();
        }
    });
    branches(ui, fit);
}

/// Branches that fit equally well: which, and what they disagree on.
fn ambiguous(ui: &mut egui::Ui, fit: &FitCheck) {
    ui.colored_label(ui.visuals().warn_fg_color, RichText::new(&fit.summary).strong());
    branches(ui, fit);
}

fn branches(ui: &mut egui::Ui, fit: &FitCheck) {
    ui.label(
        RichText::new(
            "Starts tried (the identification keeps the lowest cost: χ², plus a charge for each trace \
             a branch skips and each motion its hint led)",
        )
        .strong(),
    );
    egui::Grid::new("branches").striped(true).num_columns(7).show(ui, |ui| {
        for h in ["start", "cost", "χ²", "residual (σ RMS)", "skipped traces", "hint-led motions", ""] {
            ui.strong(h);
        }
        ui.end_row();
        for (k, b) in fit.branches.iter().enumerate() {
            ui.label(&b.start);
            ui.monospace(format!("{:.1}", b.cost()));
            ui.monospace(format!("{:.1}", b.chi2));
            ui.monospace(format!("{:.2}", b.rms_sigma));
            ui.monospace(b.skipped_traces.to_string());
            ui.monospace(b.hint_led_traces.to_string());
            ui.label(fit.standing(k).word());
            ui.end_row();
        }
    });
}

fn residual_plot(ui: &mut egui::Ui, r: &CalibrationReport) {
    ui.label(RichText::new("Residuals per equation (measured − predicted, in σ)").strong());
    let mut groups: Vec<(String, Vec<[f64; 2]>)> = Vec::new();
    for (k, (label, unit, res, sigma)) in r.residuals.iter().enumerate() {
        let eq = equation_of(label, unit);
        let point = [k as f64, res / sigma];
        match groups.iter_mut().find(|g| g.0 == eq) {
            Some(g) => g.1.push(point),
            None => groups.push((eq, vec![point])),
        }
    }
    Plot::new("residuals")
        .height(320.0)
        .legend(Legend::default())
        .x_axis_label("observation")
        .y_axis_label("residual / σ")
        .show(ui, |p| {
            for (name, pts) in groups {
                p.points(Points::new(name, PlotPoints::from(pts)).radius(3.0));
            }
        });
}

fn heat_map(ui: &mut egui::Ui, r: &CalibrationReport) {
    ui.label(RichText::new("Correlation of the estimates").strong());
    let id = &r.identifiability;
    let n = id.correlation.len();
    if n == 0 {
        ui.label("no correlation matrix");
        return;
    }
    let names: Vec<String> = id.parameters.iter().map(|p| display_name(&p.name)).collect();
    let cell = 30.0;
    let margin = 70.0;
    let (rect, _) =
        ui.allocate_exact_size(egui::vec2(margin + cell * n as f32, margin + cell * n as f32), egui::Sense::hover());
    let p = ui.painter();
    let text = ui.visuals().text_color();
    for i in 0..n {
        let name = names.get(i).map_or("?", |s| s.as_str());
        p.text(
            rect.left_top() + egui::vec2(margin - 4.0, margin + cell * (i as f32 + 0.5)),
            egui::Align2::RIGHT_CENTER,
            name,
            egui::FontId::proportional(11.0),
            text,
        );
        p.text(
            rect.left_top() + egui::vec2(margin + cell * (i as f32 + 0.5), margin - 4.0),
            egui::Align2::CENTER_BOTTOM,
            name,
            egui::FontId::proportional(10.0),
            text,
        );
        for j in 0..n {
            let min = rect.left_top() + egui::vec2(margin + cell * j as f32, margin + cell * i as f32);
            let cell_rect = egui::Rect::from_min_size(min, egui::vec2(cell - 1.0, cell - 1.0));
            match id.correlation[i].get(j).copied().flatten() {
                Some(rho) => {
                    let a = (rho.abs().min(1.0) * 255.0) as u8;
                    let color = if rho >= 0.0 {
                        Color32::from_rgb(255, 255 - a, 255 - a)
                    } else {
                        Color32::from_rgb(255 - a, 255 - a, 255)
                    };
                    p.rect_filled(cell_rect, 0.0, color);
                    p.text(
                        cell_rect.center(),
                        egui::Align2::CENTER_CENTER,
                        format!("{rho:.1}"),
                        egui::FontId::proportional(9.0),
                        Color32::BLACK,
                    );
                }
                None => {
                    p.rect_filled(cell_rect, 0.0, Color32::GRAY);
                }
            }
        }
    }
    ui.label("red +1, blue −1, grey: not determined");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn residuals_group_by_the_moving_joint() {
        assert_eq!(equation_of("S1 #1: q1 = -150 µm, X_w (q3) -150 -> +150 µm", "nm"), "dL, q3 moves");
        assert_eq!(equation_of("S2 #4: q4 = 2°, q5 -4 -> +4°", "nm"), "dL, q5 moves");
        assert_eq!(equation_of("S1 #1 sweep before: q1 = -150 µm", "µm"), "absolute gap (sweep)");
        assert_eq!(equation_of("tilt scan #3: amplitude", "mW"), "fringe amplitude");
        assert_eq!(equation_of("extra #2: hold", "nm"), "extra");
        assert_eq!(display_name("theta_wf"), "θ_wf");
    }
}
