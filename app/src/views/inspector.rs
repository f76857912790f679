//! Trace inspector: any recorded or imported trace, zoomable, with the detected extrema, the
//! tracked dL and the motion hint overlaid and the turning points of the motion marked; import
//! and export of CSV traces through the file dialogs.

use crate::decimate::Decimator;
use crate::state::AppState;
use crate::views::decimated_line;
use crate::worker::Command;
use egui::{Color32, RichText};
use egui_plot::{Legend, Line, MarkerShape, Plot, PlotPoints, Points, VLine};
use photorobot_core::measure::live_count::turning_points;
use photorobot_core::measure::{Measurement, MotionMeasurement};
use photorobot_core::trace::Trace;

/// Plot points (x, y).
type Series = Vec<[f64; 2]>;

/// Which trace is shown, and its plot data (rebuilt when the selection changes).
#[derive(Debug, Default)]
pub struct Inspector {
    /// Index in [`AppState::all_traces`].
    pub selected: usize,
    shown: Option<usize>,
    irradiance: Decimator,
}

/// Draw the inspector.
pub fn ui(ui: &mut egui::Ui, s: &mut AppState, ins: &mut Inspector) {
    ui.horizontal(|ui| {
        ui.heading("Trace inspector");
        if ui.button("Import CSV traces…").clicked() {
            import_traces(s);
        }
    });
    let labels: Vec<String> = s.all_traces().iter().map(|t| t.meta.label.clone()).collect();
    if labels.is_empty() {
        ui.label("No trace yet: run a wizard step or import CSV traces.");
        return;
    }
    ins.selected = ins.selected.min(labels.len() - 1);
    if trace_selector(ui, ins, &labels) {
        export_selected(s, ins.selected);
    }
    if ins.shown != Some(ins.selected) && !show_selected(s, ins) {
        return;
    }
    let Some(t) = s.trace(ins.selected) else { return };
    ui.label(format!(
        "{} samples over {:.3} s; bench {}; {}",
        t.len(),
        t.t_s.last().unwrap_or(&0.0) - t.t_s.first().unwrap_or(&0.0),
        t.meta.bench,
        t.meta.notes
    ));
    let analysis = s.analyses.get(&ins.selected);
    analysis_summary(ui, analysis);
    let motion = match analysis {
        Some(Ok(m)) => match m.as_ref() {
            Measurement::Motion(m) => Some(m),
            Measurement::Sweep(_) => None,
        },
        _ => None,
    };
    plots(ui, t, motion, &ins.irradiance);
}

/// Import the CSV traces the file dialog picks; the status says what happened.
fn import_traces(s: &mut AppState) {
    for path in s.dialogs.open_traces() {
        match Trace::read_csv(&path) {
            Ok(t) => {
                s.status = format!("imported {}", path.display());
                s.imported.push(t);
                s.session.mark_dirty();
            }
            Err(e) => s.status = format!("import refused: {e}"),
        }
    }
}

/// The trace chooser and the export button; true when export was clicked.
fn trace_selector(ui: &mut egui::Ui, ins: &mut Inspector, labels: &[String]) -> bool {
    let mut export = false;
    ui.horizontal(|ui| {
        egui::ComboBox::from_label("trace")
            .width(420.0)
            .selected_text(format!("{}: {}", ins.selected + 1, labels[ins.selected]))
            .show_ui(ui, |ui| {
                for (k, label) in labels.iter().enumerate() {
                    ui.selectable_value(&mut ins.selected, k, format!("{}: {label}", k + 1));
                }
            });
        export = ui.button("Export CSV…").clicked();
    });
    export
}

/// Write trace `index` where the save dialog says; the status says what happened.
fn export_selected(s: &mut AppState, index: usize) {
    let name = format!("trace-{:03}.csv", index + 1);
    if let Some(path) = s.dialogs.save_trace(&name) {
        let result = s.trace(index).map(|t| t.write_csv(&path));
        s.status = match result {
            Some(Ok(())) => format!("saved {}", path.display()),
            Some(Err(e)) => format!("not saved: {e}"),
            None => "not saved: no trace".into(),
        };
    }
}

/// Load the selected trace into the plot and ask the worker to analyse it when no analysis is
/// there yet; false when there is no such trace.
fn show_selected(s: &mut AppState, ins: &mut Inspector) -> bool {
    let Some(t) = s.trace(ins.selected) else { return false };
    ins.irradiance.clear();
    ins.irradiance.extend(&t.t_s, &t.irradiance);
    ins.shown = Some(ins.selected);
    if !s.analyses.contains_key(&ins.selected) {
        s.worker.send(Command::Analyse { index: ins.selected, trace: Box::new(t.clone()), extrinsics: s.extrinsics });
    }
    true
}

/// One line: the analysis' result, a spinner while it runs, or why it failed.
fn analysis_summary(ui: &mut egui::Ui, analysis: Option<&Result<Box<Measurement>, String>>) {
    match analysis {
        None => {
            ui.horizontal(|ui| {
                ui.spinner();
                ui.label("analysing…");
            });
        }
        Some(Err(e)) => {
            ui.colored_label(ui.visuals().error_fg_color, format!("analysis failed: {e}"));
        }
        Some(Ok(m)) => {
            match m.as_ref() {
                Measurement::Motion(m) => {
                    ui.label(
                        RichText::new(format!(
                    "dL = {:+.2} ± {:.2} nm (phase tracking); extremum counting {:+} steps = {:+.1} nm ± {:.0} nm",
                    m.track.total_dl_nm, m.track.sigma_total_nm, m.count.count, m.count.dl_nm, m.count.resolution_nm
                ))
                        .size(16.0),
                    );
                }
                Measurement::Sweep(sw) => {
                    ui.label(
                        RichText::new(format!(
                            "absolute gap = {:.4} ± {:.4} µm (sweep fit)",
                            sw.gap.gap_um, sw.gap.sigma_um
                        ))
                        .size(16.0),
                    );
                }
            }
        }
    }
}

/// The irradiance with the extrema and turning points; under it, for a motion, the tracked dL
/// and the motion hint, the two plots' time axes linked.
fn plots(ui: &mut egui::Ui, t: &Trace, motion: Option<&MotionMeasurement>, irradiance: &Decimator) {
    let extrema: Series = motion.map_or(vec![], |m| {
        m.count.extrema.iter().filter(|e| e.index < t.len()).map(|e| [t.t_s[e.index], t.irradiance[e.index]]).collect()
    });
    let turning: Vec<f64> =
        motion.map_or(vec![], |m| turning_points(&m.hint_nm).into_iter().map(|i| t.t_s[i]).collect());
    let thin = |v: &[f64]| -> Series {
        v.iter().enumerate().step_by((t.len() / 4000).max(1)).map(|(i, v)| [t.t_s[i], *v]).collect()
    };
    let dl: Option<(Series, Series)> = motion.map(|m| (thin(&m.track.dl_nm), thin(&m.hint_nm)));
    let height = if dl.is_some() { ui.available_height() * 0.55 } else { ui.available_height() };
    let link = egui::Id::unique("inspector x link");
    Plot::new("inspector irradiance")
        .height(height)
        .legend(Legend::default())
        .link_axis(link, [true, false])
        .x_axis_label("bench time (s)")
        .y_axis_label("irradiance (mW)")
        .show(ui, |p| {
            decimated_line(p, "irradiance", irradiance, Color32::from_rgb(80, 170, 255));
            p.points(
                Points::new("extrema", PlotPoints::from(extrema))
                    .shape(MarkerShape::Circle)
                    .radius(3.5)
                    .color(Color32::from_rgb(255, 200, 40)),
            );
            for x in &turning {
                p.vline(VLine::new("turning point", *x).color(Color32::from_rgb(220, 80, 220)));
            }
        });
    if let Some((track, hint)) = dl {
        Plot::new("inspector dl")
            .legend(Legend::default())
            .link_axis(link, [true, false])
            .x_axis_label("bench time (s)")
            .y_axis_label("dL (nm)")
            .show(ui, |p| {
                p.line(Line::new("dL, phase tracking", PlotPoints::from(track)).color(Color32::from_rgb(70, 190, 100)));
                p.line(Line::new("motion hint (model)", PlotPoints::from(hint)).color(Color32::GRAY));
                for x in &turning {
                    p.vline(VLine::new("turning point", *x).color(Color32::from_rgb(220, 80, 220)));
                }
            });
    }
}
