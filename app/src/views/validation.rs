//! Validation: the circle of the tool centre and the three rotations (about X_f, Z_f and the
//! optical axis), planned with the nominal and with the identified extrinsics, run on the bench;
//! the cavity-length variation before and after beside the paper's figures.

use crate::state::AppState;
use crate::worker::Command;
use egui::RichText;
use egui_plot::{Legend, Line, Plot, PlotPoints};
use photorobot_core::validate::ValidationFigure;

/// Draw the validation view.
pub fn ui(ui: &mut egui::Ui, s: &mut AppState) {
    ui.heading("Validation");
    ui.label(
        "Motions that must leave the gap unchanged if the extrinsics are right: a circle of the tool centre \
         in the lamella plane and rotations about the fiber's X and Z axes and about the optical axis. Each \
         is planned twice, with the design (nominal) extrinsics and with the identified ones, run on the \
         bench and measured by phase tracking.",
    );
    let idle = s.busy.is_none() && s.wizard.running.is_none();
    let can = s.results.report.is_some();
    if !can {
        ui.label("identify first (wizard)");
    }
    if ui.add_enabled(can && idle, egui::Button::new(RichText::new("Run validation").size(18.0))).clicked() {
        s.worker.send(Command::Validate { identified: s.extrinsics });
        s.results.validation = None;
    }
    if s.busy.as_deref() == Some("validating") {
        ui.horizontal(|ui| {
            ui.spinner();
            ui.label("running 4 motions × (before, after)");
        });
    }
    let Some(pairs) = &s.results.validation else { return };
    ui.separator();
    let fmt = |f: &Result<ValidationFigure, String>| match f {
        Ok(f) => format!("{:.1} nm", f.peak_to_peak_nm),
        Err(e) => format!("failed: {e}"),
    };
    egui::Grid::new("validation table").striped(true).show(ui, |ui| {
        for h in ["motion", "before (nominal)", "after (identified)", "paper (after)"] {
            ui.strong(h);
        }
        ui.end_row();
        for p in pairs {
            ui.label(p.motion.name());
            ui.monospace(fmt(&p.before));
            ui.monospace(fmt(&p.after));
            ui.monospace(format!("{:.0} nm", p.motion.paper_after_nm()));
            ui.end_row();
        }
    });
    ui.label("cavity variation along each motion (nm), before and after; note the different scales");
    egui::ScrollArea::vertical().id_salt("validation plots").show(ui, |ui| {
        for p in pairs {
            ui.label(RichText::new(p.motion.name()).strong());
            ui.columns(2, |cols| {
                for (col, (f, name, color)) in cols.iter_mut().zip([
                    (&p.before, "before", egui::Color32::from_rgb(230, 90, 70)),
                    (&p.after, "after", egui::Color32::from_rgb(70, 190, 100)),
                ]) {
                    if let Ok(f) = f {
                        let n = f.variation_nm.len().max(1);
                        let step = (n / 2000).max(1);
                        let pts: Vec<[f64; 2]> = f
                            .variation_nm
                            .iter()
                            .enumerate()
                            .step_by(step)
                            .map(|(k, v)| [k as f64 / n as f64 * 100.0, *v])
                            .collect();
                        Plot::new((p.motion.name(), name))
                            .height(150.0)
                            .legend(Legend::default())
                            .x_axis_label("% of the motion")
                            .y_axis_label("ΔL (nm)")
                            .show(col, |pl| {
                                pl.line(
                                    Line::new(
                                        format!("{name}: {:.1} nm p-p", f.peak_to_peak_nm),
                                        PlotPoints::from(pts),
                                    )
                                    .color(color),
                                );
                            });
                    }
                }
            });
        }
    });
}
