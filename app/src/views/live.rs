//! Live view: the scrolling irradiance trace from the bench (min/max-per-pixel decimation over
//! the visible range), the fringe count with its direction, dL, the model's absolute gap and the
//! fringe visibility. Pause freezes the view for pan and zoom while the buffer keeps filling.

use crate::state::AppState;
use crate::views::{decimated_line, or_dash};
use egui::RichText;
use egui_plot::Plot;
use photorobot_core::measure::live_count::LiveCounter;
use std::sync::atomic::Ordering;

/// Draw the live view.
pub fn ui(ui: &mut egui::Ui, s: &mut AppState) {
    let n_air = s.worker.nominal.n_air;
    let live_on = s.worker.live.load(Ordering::Relaxed);
    ui.horizontal(|ui| {
        let label = if live_on { "Stop live signal" } else { "Start live signal" };
        if ui.button(label).on_hover_text("dither the lamella ±0.8 µm along the beam and stream the signal").clicked()
        {
            s.worker.set_live(!live_on);
        }
        let pause = if s.live.paused { "Resume scrolling (Space)" } else { "Pause (Space)" };
        if ui.button(pause).clicked() {
            s.live.paused = !s.live.paused;
        }
        if ui.button("Reset count").clicked() {
            s.live.counter = LiveCounter::default();
        }
        ui.label("window");
        ui.add(egui::DragValue::new(&mut s.settings.live_window_s).range(0.1..=600.0).suffix(" s"));
    });
    ui.separator();
    let c = &s.live.counter;
    let arrow = match c.direction {
        1 => "gap opening (+)",
        -1 => "gap closing (−)",
        _ => "no motion yet",
    };
    ui.horizontal(|ui| {
        ui.label(RichText::new(format!("{:+.1} fringes", c.steps as f64 / 2.0)).size(40.0).strong())
            .on_hover_text("one fringe = λ/(2n) of gap change; counted extrema / 2");
        ui.label(RichText::new(arrow).size(22.0));
        ui.add_space(30.0);
        ui.vertical(|ui| {
            ui.label(RichText::new(format!("dL = {:+.1} nm", s.live.dl_nm(n_air))).size(22.0))
                .on_hover_text("counted extrema × λ/(4n); the phase tracker refines it after each motion");
            ui.label(RichText::new(format!("gap (model) = {}", or_dash(s.live.gap_um, 3, "µm"))).size(18.0));
        });
        ui.add_space(30.0);
        ui.vertical(|ui| {
            let q = s.live.quality;
            ui.label(RichText::new(format!("visibility = {}", or_dash(q.map(|q| q.visibility), 3, ""))).size(18.0));
            ui.label(format!("mean power = {}", or_dash(q.map(|q| q.mean), 4, "mW")));
            ui.label(format!("λ = {:.3} nm, {} samples", s.live.wavelength_nm, s.live.trace.len()));
        });
    });
    let window = s.settings.live_window_s;
    let paused = s.live.paused;
    let d = &s.live.trace;
    let last_t = d.times().last().copied().unwrap_or(0.0);
    Plot::new("live trace")
        .x_axis_label("bench time (s)")
        .y_axis_label("irradiance (mW)")
        .allow_drag(paused)
        .allow_zoom(paused)
        .allow_scroll(paused)
        .show(ui, |p| {
            if !paused {
                p.set_plot_bounds_x(last_t - window..=last_t);
                let t = d.times();
                let i = t.partition_point(|&x| x < last_t - window);
                if i < d.len() {
                    let (mn, mx) = d.range_min_max(i, d.len());
                    let pad = 0.05 * (mx - mn).max(1e-6);
                    p.set_plot_bounds_y(mn - pad..=mx + pad);
                }
            }
            decimated_line(p, "irradiance", d, egui::Color32::from_rgb(80, 170, 255));
        });
}
