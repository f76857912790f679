//! The report's plots: hand-written SVG with axes, ticks, guides, series and a legend.

use super::escape::escape;
use std::fmt::Write as _;

/// One data series of a plot.
pub(super) struct Series<'a> {
    pub(super) name: &'a str,
    pub(super) color: &'a str,
    pub(super) points: Vec<(f64, f64)>,
    /// Draw as markers instead of a line.
    pub(super) markers: bool,
}

/// A "nice" tick step for a range: 1, 2 or 5 × 10ⁿ giving about `count` ticks.
fn tick_step(range: f64, count: f64) -> f64 {
    let raw = (range / count).max(f64::MIN_POSITIVE);
    let mag = 10f64.powf(raw.log10().floor());
    let r = raw / mag;
    mag * if r < 1.5 {
        1.0
    } else if r < 3.5 {
        2.0
    } else if r < 7.5 {
        5.0
    } else {
        10.0
    }
}

/// A tick's value with as many decimals as its step needs.
fn tick_label(v: f64, step: f64) -> String {
    let decimals = (-step.log10().floor()).clamp(0.0, 9.0) as usize;
    format!("{v:.decimals$}")
}

/// Size and margins of the plot (px), the data ranges the axes show and their tick steps.
struct Frame {
    w: f64,
    hgt: f64,
    left: f64,
    right: f64,
    top: f64,
    bottom: f64,
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
    xstep: f64,
    ystep: f64,
}

impl Frame {
    /// The frame of the finite points of `series`, the y range widened to `y_include` and
    /// rounded out to whole y ticks.
    fn of(series: &[Series<'_>], y_include: &[f64]) -> Self {
        let (w, hgt) = (640.0, 300.0);
        let (left, right, top, bottom) = (70.0, 16.0, 34.0, 46.0);
        let all = series.iter().flat_map(|s| s.points.iter()).filter(|p| p.0.is_finite() && p.1.is_finite());
        let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
        for &(x, y) in all {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        for &y in y_include {
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if !x0.is_finite() {
            (x0, x1, y0, y1) = (0.0, 1.0, -1.0, 1.0);
        }
        if x1 - x0 <= 0.0 {
            x1 = x0 + 1.0;
        }
        if y1 - y0 <= 0.0 {
            let pad = y0.abs().max(1.0) * 0.1;
            (y0, y1) = (y0 - pad, y1 + pad);
        }
        let ystep = tick_step(y1 - y0, 5.0);
        let (y0, y1) = ((y0 / ystep).floor() * ystep, (y1 / ystep).ceil() * ystep);
        let xstep = tick_step(x1 - x0, 6.0);
        Self { w, hgt, left, right, top, bottom, x0, x1, y0, y1, xstep, ystep }
    }

    /// Horizontal position (px) of `x`.
    fn px(&self, x: f64) -> f64 {
        self.left + (x - self.x0) / (self.x1 - self.x0) * (self.w - self.left - self.right)
    }

    /// Vertical position (px) of `y`.
    fn py(&self, y: f64) -> f64 {
        self.top + (self.y1 - y) / (self.y1 - self.y0) * (self.hgt - self.top - self.bottom)
    }
}

/// An SVG plot with axes, ticks, labels and a legend; y range from the data (and `y_include`).
pub(super) fn svg_plot(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series<'_>],
    y_include: &[f64],
    guides: &[f64],
) -> String {
    let frame = Frame::of(series, y_include);
    let mut s = String::new();
    write_canvas(&mut s, &frame, title);
    write_y_grid(&mut s, &frame);
    write_x_grid(&mut s, &frame);
    write_guides(&mut s, &frame, guides);
    write_axes(&mut s, &frame, x_label, y_label);
    for (k, sr) in series.iter().enumerate() {
        write_series(&mut s, &frame, sr);
        write_legend_entry(&mut s, &frame, k, sr);
    }
    s.push_str("</svg>");
    s
}

/// The opening tag, the white background and the title.
fn write_canvas(s: &mut String, frame: &Frame, title: &str) {
    let (w, hgt, left) = (frame.w, frame.hgt, frame.left);
    let _ = write!(
        s,
        "<svg width=\"{w}\" height=\"{hgt}\" viewBox=\"0 0 {w} {hgt}\" font-family=\"DejaVu Sans, Arial, sans-serif\" font-size=\"11\">\
         <rect width=\"{w}\" height=\"{hgt}\" fill=\"white\"/>\
         <text x=\"{}\" y=\"18\" font-size=\"13\" font-weight=\"bold\">{}</text>",
        left,
        escape(title)
    );
}

/// Horizontal grid lines with their y tick labels.
fn write_y_grid(s: &mut String, frame: &Frame) {
    let (w, left, right) = (frame.w, frame.left, frame.right);
    let (y1, ystep) = (frame.y1, frame.ystep);
    let mut y = frame.y0;
    while y <= y1 + ystep * 1e-6 {
        let v = frame.py(y);
        let _ = write!(
            s,
            "<line x1=\"{left}\" y1=\"{v:.1}\" x2=\"{:.1}\" y2=\"{v:.1}\" stroke=\"#e4e4e4\"/><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{}</text>",
            w - right,
            left - 5.0,
            v + 4.0,
            tick_label(y, ystep)
        );
        y += ystep;
    }
}

/// Vertical grid lines with their x tick labels.
fn write_x_grid(s: &mut String, frame: &Frame) {
    let (hgt, top, bottom) = (frame.hgt, frame.top, frame.bottom);
    let (x1, xstep) = (frame.x1, frame.xstep);
    let mut x = (frame.x0 / xstep).ceil() * xstep;
    while x <= x1 + xstep * 1e-6 {
        let v = frame.px(x);
        let _ = write!(
            s,
            "<line x1=\"{v:.1}\" y1=\"{top}\" x2=\"{v:.1}\" y2=\"{:.1}\" stroke=\"#f0f0f0\"/><text x=\"{v:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
            hgt - bottom,
            hgt - bottom + 15.0,
            tick_label(x, xstep)
        );
        x += xstep;
    }
}

/// Dashed horizontal guides at the values of `guides` inside the y range.
fn write_guides(s: &mut String, frame: &Frame, guides: &[f64]) {
    let (w, left, right) = (frame.w, frame.left, frame.right);
    for &g in guides {
        if g >= frame.y0 && g <= frame.y1 {
            let v = frame.py(g);
            let _ = write!(
                s,
                "<line x1=\"{left}\" y1=\"{v:.1}\" x2=\"{:.1}\" y2=\"{v:.1}\" stroke=\"#999\" stroke-dasharray=\"4 3\"/>",
                w - right
            );
        }
    }
}

/// The plot area's border and the axis labels.
fn write_axes(s: &mut String, frame: &Frame, x_label: &str, y_label: &str) {
    let (w, hgt, left, right, top, bottom) = (frame.w, frame.hgt, frame.left, frame.right, frame.top, frame.bottom);
    let _ = write!(
        s,
        "<rect x=\"{left}\" y=\"{top}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"none\" stroke=\"#444\"/>\
         <text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>\
         <text transform=\"translate(14 {:.1}) rotate(-90)\" text-anchor=\"middle\">{}</text>",
        w - left - right,
        hgt - top - bottom,
        (left + w - right) / 2.0,
        hgt - 8.0,
        escape(x_label),
        (top + hgt - bottom) / 2.0,
        escape(y_label)
    );
}

/// The finite points of one series, as markers or a line.
fn write_series(s: &mut String, frame: &Frame, sr: &Series<'_>) {
    let pts = sr.points.iter().filter(|p| p.0.is_finite() && p.1.is_finite());
    if sr.markers {
        for &(x, y) in pts {
            let _ = write!(
                s,
                "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"2.2\" fill=\"{}\"/>",
                frame.px(x),
                frame.py(y),
                sr.color
            );
        }
    } else {
        let coords: Vec<String> = pts.map(|&(x, y)| format!("{:.1},{:.1}", frame.px(x), frame.py(y))).collect();
        let _ = write!(
            s,
            "<polyline fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\" points=\"{}\"/>",
            sr.color,
            coords.join(" ")
        );
    }
}

/// The legend entry of series number `k`, top right.
fn write_legend_entry(s: &mut String, frame: &Frame, k: usize, sr: &Series<'_>) {
    let ly = frame.top + 14.0 + 14.0 * k as f64;
    let lx = frame.w - frame.right - 190.0;
    let _ = write!(
        s,
        "<rect x=\"{lx:.1}\" y=\"{:.1}\" width=\"10\" height=\"10\" fill=\"{}\"/><text x=\"{:.1}\" y=\"{ly:.1}\">{}</text>",
        ly - 9.0,
        sr.color,
        lx + 14.0,
        escape(sr.name)
    );
}
