//! The message panel: every status and error message of the session, with its time, newest
//! last, errors in red; toggled from the status bar ("Messages (N)"). Drawing only; the list is
//! [`crate::messages::Messages`] in the state.

use crate::messages::{clock_utc, Level};
use crate::state::AppState;

/// The status bar's toggle: "Messages (N)", red when some are errors and the panel is closed.
pub fn toggle(ui: &mut egui::Ui, state: &mut AppState) {
    let m = &mut state.messages;
    let label = format!("Messages ({})", m.list.len());
    // Red while closed with errors listed (on the selected button's fill red would not read).
    let text = if m.errors() > 0 && !m.open {
        egui::RichText::new(label).color(ui.visuals().error_fg_color)
    } else {
        label.into()
    };
    if ui.selectable_label(m.open, text).on_hover_text("Every status and error message, with its time").clicked() {
        m.open = !m.open;
    }
}

/// The panel, above the status bar, when open: newest at the bottom, scrolled to it.
pub fn panel(ui: &mut egui::Ui, state: &mut AppState) {
    if !state.messages.open {
        return;
    }
    egui::Panel::bottom("messages").resizable(true).default_size(140.0).show(ui, |ui| {
        ui.horizontal(|ui| {
            ui.strong("Messages");
            ui.label(format!("{} (UTC), newest last", state.messages.list.len()));
            if ui.button("Clear").clicked() {
                state.messages.list.clear();
            }
            if ui.button("Close").clicked() {
                state.messages.open = false;
            }
        });
        ui.separator();
        egui::ScrollArea::vertical().stick_to_bottom(true).auto_shrink([false, false]).show(ui, |ui| {
            for m in &state.messages.list {
                // Long messages (a file's whole complaint) wrap instead of running off the panel.
                ui.horizontal_wrapped(|ui| {
                    ui.monospace(clock_utc(m.time_s));
                    match m.level {
                        Level::Info => ui.label(&m.text),
                        Level::Error => ui.colored_label(ui.visuals().error_fg_color, format!("error: {}", m.text)),
                    };
                });
            }
        });
    });
}
