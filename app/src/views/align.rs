//! Pre-alignment: a large live gauge of reflected power and fringe visibility that guides the
//! technician's manual positioning of the fiber (or the lamella tilt) until the signal is good
//! enough to calibrate, with the thresholds stated (`photorobot_core::measure::alignment`).

use crate::state::AppState;
use egui::{Color32, RichText};
use photorobot_core::measure::alignment::{MIN_FRINGE_SNR, MIN_VISIBILITY};
use std::sync::atomic::Ordering;

fn gauge(ui: &mut egui::Ui, label: &str, value: f64, full_scale: f64, threshold: Option<f64>, text: String) {
    ui.label(RichText::new(label).size(18.0));
    let (row, _) = ui.allocate_exact_size(egui::vec2(ui.available_width().min(900.0), 44.0), egui::Sense::hover());
    let rect = egui::Rect::from_min_size(row.min, egui::vec2(row.width() - 180.0, row.height()));
    let p = ui.painter();
    p.rect_filled(rect, 4.0, ui.visuals().extreme_bg_color);
    let f = (value / full_scale).clamp(0.0, 1.0) as f32;
    let ok = threshold.is_none_or(|t| value >= t);
    let color = if ok { Color32::from_rgb(60, 180, 90) } else { Color32::from_rgb(220, 120, 40) };
    let mut filled = rect;
    filled.set_width(rect.width() * f);
    p.rect_filled(filled, 4.0, color);
    if let Some(t) = threshold {
        let x = rect.left() + rect.width() * (t / full_scale).clamp(0.0, 1.0) as f32;
        p.line_segment([egui::pos2(x, rect.top()), egui::pos2(x, rect.bottom())], (3.0, ui.visuals().text_color()));
    }
    p.text(
        egui::pos2(rect.right() + 16.0, rect.center().y),
        egui::Align2::LEFT_CENTER,
        text,
        egui::FontId::proportional(24.0),
        ui.visuals().strong_text_color(),
    );
}

/// Draw the pre-alignment view.
pub fn ui(ui: &mut egui::Ui, s: &mut AppState) {
    ui.heading("Pre-alignment");
    ui.label(
        "Position the fiber by hand in front of the lamella until the gauges turn green. The live signal \
         dithers the lamella along the beam so the fringes show; the power gauge is scaled to the best \
         power seen since the start.",
    );
    let live_on = s.worker.live.load(Ordering::Relaxed);
    if !live_on && ui.button(RichText::new("Start live signal").size(18.0)).clicked() {
        s.worker.set_live(true);
    }
    ui.label(format!(
        "Thresholds: fringe visibility ≥ {MIN_VISIBILITY}, fringe amplitude ≥ {MIN_FRINGE_SNR}× the noise σ \
         (what the phase tracker needs for nanometre dL)."
    ));
    ui.add_space(10.0);
    let Some(q) = s.live.quality else {
        ui.label(RichText::new("no signal yet: start the live signal").size(20.0));
        return;
    };
    let best = s.live.trace.range_min_max(0, s.live.trace.len()).1.max(1e-12);
    gauge(ui, "reflected power", q.mean, best, None, format!("{:.4} mW", q.mean));
    ui.add_space(8.0);
    gauge(ui, "fringe visibility", q.visibility, 1.0, Some(MIN_VISIBILITY), format!("{:.3}", q.visibility));
    ui.add_space(8.0);
    gauge(
        ui,
        "fringe amplitude / noise",
        q.fringe_snr.min(1e6),
        (4.0 * MIN_FRINGE_SNR).max(q.fringe_snr.min(1e6)),
        Some(MIN_FRINGE_SNR),
        format!("{:.0}×", q.fringe_snr),
    );
    ui.add_space(12.0);
    let (text, color) = if q.ready {
        ("READY TO CALIBRATE", Color32::from_rgb(60, 180, 90))
    } else {
        ("NOT READY", Color32::from_rgb(220, 120, 40))
    };
    ui.label(RichText::new(text).size(30.0).strong().color(color));
    ui.label(RichText::new(q.advice()).size(16.0));
}
