//! Position: place the lamella where the technician asks (gap, tilt, lateral offset, rotation
//! about the beam) with the session's calibration: the target fields, the joints and path the
//! move is planned with, Go (stoppable like every motion), and each move's proof and verdict.

use crate::state::AppState;
use egui::{Color32, RichText};
use egui_plot::{Line, Plot, PlotPoints};
use photorobot_core::position::{MovePlan, MoveRecord, Target, Verdict};

/// Draw the Position view: the target and its planned move on the left, the last move and the
/// session's moves on the right.
pub fn ui(ui: &mut egui::Ui, s: &mut AppState) {
    ui.heading("Position the lamella");
    let placement = s.placement();
    match &placement {
        Ok(p) => ui.label(format!(
            "Planned with {}: the identified extrinsics and their uncertainty{}.",
            p.source,
            if p.play.iter().any(|w| *w != 0.0) { ", the stages' play compensated" } else { "" }
        )),
        Err(e) => ui.colored_label(ui.visuals().warn_fg_color, format!("No move yet: {e}.")),
    };
    ui.separator();
    ui.columns(2, |cols| {
        egui::ScrollArea::vertical().id_salt("position target").show(&mut cols[0], |ui| {
            target_fields(ui, s);
            ui.separator();
            let planned_ok = preview(ui, s);
            go(ui, s, planned_ok && placement.is_ok());
        });
        egui::ScrollArea::vertical().id_salt("position moves").show(&mut cols[1], |ui| {
            match s.position.moves.last() {
                Some(r) => result(ui, r),
                None => {
                    ui.label("No move yet in this session.");
                }
            }
            if !s.position.moves.is_empty() {
                ui.separator();
                history(ui, &s.position.moves);
            }
        });
    });
}

/// Go, and what runs.
fn go(ui: &mut egui::Ui, s: &mut AppState, ready: bool) {
    let idle = s.busy.is_none() && s.wizard.running.is_none();
    ui.horizontal(|ui| {
        let go = egui::Button::new(RichText::new("Go (F5)").size(18.0));
        if ui.add_enabled(idle && ready, go).clicked() {
            s.go_position();
        }
        if s.moving() == Some(crate::motion::Motion::Position) {
            ui.spinner();
            ui.label("moving, then measuring the gap: the red Stop (or Esc) stops it");
        }
    });
    if let Some(e) = &s.position.refused {
        ui.colored_label(ui.visuals().error_fg_color, format!("refused, nothing moved: {e}"));
    }
}

/// The target's fields, each with its unit.
fn target_fields(ui: &mut egui::Ui, s: &mut AppState) {
    let t = &mut s.position.target;
    ui.label(RichText::new("Target, in the fiber's frame").size(16.0).strong());
    egui::Grid::new("target").num_columns(3).show(ui, |ui| {
        ui.label("gap along the beam");
        ui.add(egui::DragValue::new(&mut t.gap_um).speed(0.1).max_decimals(4).suffix(" µm"));
        ui.label("|L|: fiber end to lamella");
        ui.end_row();
        ui.label("tilt β, θ");
        ui.horizontal(|ui| {
            ui.add(egui::DragValue::new(&mut t.tilt_deg[0]).speed(0.01).max_decimals(4).suffix(" °"));
            ui.add(egui::DragValue::new(&mut t.tilt_deg[1]).speed(0.01).max_decimals(4).suffix(" °"));
        });
        ui.label("normal vs beam; 0, 0: parallel to the fiber end").on_hover_text(
            "the lamella normal against the beam, about X_f then Z_f; 0, 0 is parallel to the fiber's end face",
        );
        ui.end_row();
        ui.label("lateral x, z");
        ui.horizontal(|ui| {
            ui.add(egui::DragValue::new(&mut t.lateral_um[0]).speed(0.5).max_decimals(3).suffix(" µm"));
            ui.add(egui::DragValue::new(&mut t.lateral_um[1]).speed(0.5).max_decimals(3).suffix(" µm"));
        });
        ui.label("lamella origin from the beam");
        ui.end_row();
        ui.label("rotation about the beam");
        ui.add(egui::DragValue::new(&mut t.rotation_deg).speed(0.1).max_decimals(3).suffix(" °"));
        ui.label("about the beam, through P_r");
        ui.end_row();
    });
    ui.checkbox(&mut s.position.keep_gap, "keep the gap on the way").on_hover_text(
        "the gap is held at the larger of start and end while the rest moves, then changed along the beam",
    );
    ui.checkbox(&mut s.position.measure_tilt, "measure the tilt at the end").on_hover_text(
        "two ±3° rotations about X_f and Z_f through P_r read the tilt from the fringe contrast (about 20 s of \
         bench time); the gap is read at that tilt, so its proof uses no extrinsics. Off: read at the requested tilt",
    );
}

/// The move planned from where the bench stands: joints, path, forecast and proof; whether Go
/// may run it.
fn preview(ui: &mut egui::Ui, s: &mut AppState) -> bool {
    let q = s.q_display;
    match s.position_preview() {
        None => false,
        Some(Err(e)) => {
            ui.colored_label(ui.visuals().error_fg_color, format!("Refused: {e}"));
            false
        }
        Some(Ok(plan)) => {
            planned(ui, plan, &q);
            true
        }
    }
}

fn planned(ui: &mut egui::Ui, plan: &MovePlan, from: &[f64; 6]) {
    ui.label(RichText::new("Planned move").size(16.0).strong());
    let end = plan.path.end();
    egui::Grid::new("joints").num_columns(7).striped(true).show(ui, |ui| {
        ui.label("");
        for name in ["q1", "q2", "q3", "q4", "q5", "q6"] {
            ui.label(name);
        }
        ui.end_row();
        for (row, q) in [("now", from), ("predicted at the target", &end)] {
            ui.label(row);
            for (j, v) in q.iter().enumerate() {
                ui.monospace(if j < 3 { format!("{v:.3} µm") } else { format!("{v:.4}°") });
            }
            ui.end_row();
        }
    });
    let proof = match &plan.proof {
        photorobot_core::position::ProofKind::Sweep => "a wavelength sweep at the target (absolute gap)".to_string(),
        photorobot_core::position::ProofKind::Fringes(r) => format!("the fringes along the path from {}", r.source),
        photorobot_core::position::ProofKind::None(why) => why.clone(),
    };
    let tilt = if plan.measure_tilt {
        ", read at the tilt the contrast measures there (two ±3° rotations)"
    } else {
        ", read at the requested tilt"
    };
    ui.label(format!("path: {} waypoints; the gap proven by {proof}{tilt}", plan.path.joints.len() - 1));
    match &plan.forecast {
        Some(f) => ui.label(format!(
            "forecast σ at the target: gap {:.2} nm, tilt ({:.5}°, {:.5}°), lateral ({:.4}, {:.4}) µm, rotation {:.5}°",
            f.gap_sigma_nm,
            f.tilt_sigma_deg[0],
            f.tilt_sigma_deg[1],
            f.lateral_sigma_um[0],
            f.lateral_sigma_um[1],
            f.rotation_sigma_deg
        )),
        None => ui.label("no forecast: the extrinsics are taken as exact"),
    };
    match (plan.path.targets.first(), plan.path.targets.last()) {
        (Some(a), Some(b)) if !same_place(a, b) => path_plots(ui, plan),
        _ => {
            ui.label("the lamella is at the target already");
        }
    }
}

/// Two targets the same to round-off (1 pm, 1 µ°): a move from one to the other has no path.
fn same_place(a: &Target, b: &Target) -> bool {
    let (pa, pb) = (
        [a.gap_um, a.tilt_deg[0], a.tilt_deg[1], a.lateral_um[0], a.lateral_um[1], a.rotation_deg],
        [b.gap_um, b.tilt_deg[0], b.tilt_deg[1], b.lateral_um[0], b.lateral_um[1], b.rotation_deg],
    );
    pa.iter().zip(&pb).all(|(x, y)| (x - y).abs() < 1e-6)
}

/// The path in task space: the gap along the waypoints, and the lamella across the beam.
fn path_plots(ui: &mut egui::Ui, plan: &MovePlan) {
    let t = &plan.path.targets;
    let gap: Vec<[f64; 2]> = t.iter().enumerate().map(|(k, p)| [k as f64, p.gap_um]).collect();
    let lateral: Vec<[f64; 2]> = t.iter().map(|p| [p.lateral_um[0], p.lateral_um[1]]).collect();
    // A path that keeps the gap or the lateral position would give the plot no extent along that
    // axis (egui_plot refuses such bounds): each plot spans at least a little around the start.
    let (g0, l0) = (gap[0][1], lateral[0]);
    ui.columns(2, |cols| {
        Plot::new("path gap")
            .height(150.0)
            .x_axis_label("waypoint")
            .y_axis_label("gap (µm)")
            .include_y(g0 - 0.01)
            .include_y(g0 + 0.01)
            .show(&mut cols[0], |p| {
                p.line(Line::new("gap", PlotPoints::from(gap)));
            });
        Plot::new("path lateral")
            .height(150.0)
            .data_aspect(1.0)
            .include_x(l0[0] - 1.0)
            .include_x(l0[0] + 1.0)
            .include_y(l0[1] - 1.0)
            .include_y(l0[1] + 1.0)
            .x_axis_label("x along X_f (µm)")
            .y_axis_label("z along Z_f (µm)")
            .show(&mut cols[1], |p| {
                p.line(Line::new("lamella origin from the beam", PlotPoints::from(lateral)));
            });
    });
}

/// The colour of a verdict.
fn verdict_color(v: Verdict) -> Color32 {
    match v {
        Verdict::Confirmed => Color32::from_rgb(40, 160, 70),
        Verdict::Off | Verdict::Failed => Color32::from_rgb(210, 60, 50),
        Verdict::Unconfirmed | Verdict::Stopped => Color32::from_rgb(220, 150, 30),
    }
}

/// The last move: verdict, measured gap against the request, the bound and what the model alone set.
fn result(ui: &mut egui::Ui, r: &MoveRecord) {
    ui.horizontal(|ui| {
        ui.label(RichText::new("Last move:").size(16.0).strong());
        ui.label(RichText::new(r.verdict.word().to_uppercase()).size(20.0).strong().color(verdict_color(r.verdict)));
    });
    ui.label(format!("requested {}", r.requested.describe()));
    if let Some(m) = &r.measurement {
        ui.label(format!("measured gap {:.4} µm ± {:.2} nm, by {}", m.gap_um, m.sigma_nm, m.method));
    }
    if let Some(t) = &r.tilt {
        ui.label(t.describe());
    }
    ui.label(&r.note);
    if let Some(a) = &r.achieved {
        ui.label(format!("reached, by the model at the joints read back: {}", a.model.describe()));
    }
    ui.label(RichText::new(&r.model_only).italics());
}

/// Every move of the session.
fn history(ui: &mut egui::Ui, moves: &[MoveRecord]) {
    ui.label(RichText::new(format!("Moves in this session ({})", moves.len())).size(16.0).strong());
    egui::Grid::new("moves").num_columns(7).striped(true).show(ui, |ui| {
        for h in ["#", "requested gap", "measured gap", "error", "bound", "tilt (contrast)", "verdict"] {
            ui.label(RichText::new(h).strong());
        }
        ui.end_row();
        for (k, r) in moves.iter().enumerate() {
            ui.label(format!("{}", k + 1));
            ui.monospace(format!("{:.4} µm", r.requested.gap_um));
            ui.monospace(r.measurement.as_ref().map_or("–".into(), |m| format!("{:.4} µm", m.gap_um)));
            ui.monospace(r.gap_error_nm.map_or("–".into(), |e| format!("{e:+.2} nm")));
            ui.monospace(r.bound_nm.map_or("–".into(), |b| format!("±{b:.2} nm")));
            ui.monospace(r.tilt.map_or("–".into(), |t| format!("{:.4} ± {:.4}°", t.tilt_deg, t.sigma_deg)));
            ui.colored_label(verdict_color(r.verdict), r.verdict.word());
            ui.end_row();
        }
    });
}
