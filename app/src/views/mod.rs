//! The workbench's views, one module per view, each a function over the shared [`AppState`]
//! (drawing only; commands go to the worker).
//!
//! [`AppState`]: crate::state::AppState

pub mod align;
pub mod connection;
pub mod diagnosis;
pub mod frames;
pub mod inspector;
pub mod lab;
pub mod live;
pub mod messages;
pub mod position;
pub mod results;
pub mod robot;
pub mod validation;
pub mod wizard;

use crate::decimate::Decimator;
use egui_plot::{Line, PlotPoints, PlotUi};

/// Draw `d` decimated to the plot's visible x range and pixel width.
pub fn decimated_line(plot_ui: &mut PlotUi<'_>, name: &str, d: &Decimator, color: egui::Color32) {
    let b = plot_ui.plot_bounds();
    let columns = plot_ui.transform().frame().width().max(1.0) as usize;
    let pts = d.decimate(b.min()[0], b.max()[0], columns);
    plot_ui.line(Line::new(name, PlotPoints::from(pts)).color(color));
}

/// A number with its unit, or a dash.
pub fn or_dash(v: Option<f64>, decimals: usize, unit: &str) -> String {
    v.map_or("–".to_string(), |v| format!("{v:.decimals$} {unit}"))
}
