//! The "Lab record and notes" window (File menu): who measures, the ambient conditions read in the
//! lab (each optional, kept within the ranges the session accepts), when recording started and the
//! bench's identification (both set by themselves), and the session's notes. Every edit marks the
//! session unsaved.

use crate::state::AppState;
use egui::{DragValue, TextEdit, Ui};
use photorobot_core::session::{HUMIDITY_RANGE_PERCENT, PRESSURE_RANGE_HPA, TEMPERATURE_RANGE_C};

/// Whether the window is open, kept in egui's memory.
fn open_id() -> egui::Id {
    egui::Id::unique("lab record window open")
}

/// Open the window.
pub fn open(ctx: &egui::Context) {
    ctx.data_mut(|d| d.insert_temp(open_id(), true));
}

/// The window, when open.
pub fn window(ctx: &egui::Context, state: &mut AppState) {
    let mut is_open = ctx.data(|d| d.get_temp::<bool>(open_id()).unwrap_or(false));
    if !is_open {
        return;
    }
    egui::Window::new("Lab record and notes")
        .open(&mut is_open)
        .default_width(420.0)
        .default_pos([60.0, 70.0])
        .show(ctx, |ui| ui_section(ui, state));
    ctx.data_mut(|d| d.insert_temp(open_id(), is_open));
}

/// An optional quantity: a checkbox named after it (ticked: recorded) and its value, kept within `range`.
fn optional_value(
    ui: &mut Ui,
    label: &str,
    value: &mut Option<f64>,
    range: std::ops::RangeInclusive<f64>,
    typical: f64,
    unit: &str,
) -> bool {
    let mut changed = false;
    let mut recorded = value.is_some();
    if ui.checkbox(&mut recorded, label).on_hover_text(format!("record the {label}")).changed() {
        *value = recorded.then_some(typical);
        changed = true;
    }
    match value {
        Some(v) => {
            changed |= ui.add(DragValue::new(v).range(range).speed(0.1).suffix(format!(" {unit}"))).changed();
        }
        None => {
            ui.weak("not recorded");
        }
    }
    ui.end_row();
    changed
}

/// The record's fields and the notes.
pub fn ui_section(ui: &mut Ui, state: &mut AppState) {
    let mut changed = false;
    let lab = &mut state.session.lab;
    ui.heading("Lab record");
    egui::Grid::new("lab record").num_columns(2).spacing([12.0, 6.0]).show(ui, |ui| {
        ui.label("measured at (UTC)");
        ui.label(lab.measured_at_utc.as_deref().unwrap_or("set when recording starts"));
        ui.end_row();
        let operator_label = ui.label("operator");
        let mut operator = lab.operator.clone().unwrap_or_default();
        let r = ui
            .add(TextEdit::singleline(&mut operator).hint_text("name").desired_width(240.0))
            .labelled_by(operator_label.id);
        if r.changed() {
            lab.operator = (!operator.trim().is_empty()).then_some(operator);
            changed = true;
        }
        ui.end_row();
        changed |= optional_value(ui, "temperature", &mut lab.ambient_temperature_c, TEMPERATURE_RANGE_C, 20.0, "°C");
        changed |= optional_value(ui, "pressure", &mut lab.pressure_hpa, PRESSURE_RANGE_HPA, 1013.25, "hPa");
        changed |= optional_value(
            ui,
            "relative humidity",
            &mut lab.relative_humidity_percent,
            HUMIDITY_RANGE_PERCENT,
            50.0,
            "%",
        );
        ui.label("controllers");
        ui.vertical(|ui| {
            if lab.controllers.is_empty() {
                ui.weak("identified when recording starts");
            }
            for c in &lab.controllers {
                ui.label(format!("{}: {}", c.name, c.identification));
            }
        });
        ui.end_row();
    });
    ui.weak("The model's air index comes from the bench preset; these readings are recorded beside it in the report.");
    ui.separator();
    let notes_label = ui.heading("Notes");
    let r = ui
        .add(
            TextEdit::multiline(&mut state.session.notes)
                .hint_text("what was done, what was seen")
                .desired_rows(6)
                .desired_width(f32::INFINITY),
        )
        .labelled_by(notes_label.id);
    changed |= r.changed();
    if changed {
        state.session.mark_dirty();
    }
}
