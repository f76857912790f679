//! The report's account of time: each stage's wall time, each plan run's bench time against the
//! plans' timing model with the controllers' waiting and the recorder's reading, and every segment.

use super::escape;
use crate::bench::{RunTiming, TimingTotals};
use crate::calibration::CalibrationReport;
use std::fmt::Write as _;

/// The time section (absent when the report carries no timing).
pub(super) fn timing(h: &mut String, c: &CalibrationReport) {
    let Some(t) = &c.timing else { return };
    h.push_str("<h2>Where the time went</h2>\n");
    if !t.stages.is_empty() {
        h.push_str("<table>\n<tr><th>stage</th><th>wall time (s)</th></tr>\n");
        for s in &t.stages {
            let _ = writeln!(h, "<tr><td>{}</td><td class=\"num\">{:.2}</td></tr>", escape(&s.stage), s.wall_s);
        }
        let total: f64 = t.stages.iter().map(|s| s.wall_s).sum();
        let _ = writeln!(h, "<tr><th>total</th><td class=\"num\">{total:.2}</td></tr>\n</table>");
    }
    if t.segments.is_empty() {
        return;
    }
    h.push_str(
        "<p><i>Planned</i> is the motions' time in the plans' timing model (the stages' speeds and accelerations, \
         settling included); <i>bench</i> the time they took; <i>waiting</i> what the controllers added beyond the \
         planned motion (setting up each segment, reporting its end, checking the arrival); <i>recorder</i> the \
         reading of the data recorder after each motion. On a virtual bench the bench time is the plan's and the wall \
         time the simulation's.</p>\n",
    );
    h.push_str(HEADER);
    for (stage, r) in t.runs() {
        totals_row(h, &format!("{stage}: {}", r.name), &r, false);
    }
    for r in t.stage_totals() {
        totals_row(h, &format!("total {}", r.name), &r, true);
    }
    h.push_str("</table>\n");
    segments(h, t);
}

const HEADER: &str = "<table>\n<tr><th>what</th><th>segments</th><th>planned (s)</th><th>bench (s)</th>\
                      <th>waiting (s)</th><th>recorder (s)</th><th>wall (s)</th></tr>\n";

fn totals_row(h: &mut String, name: &str, r: &TimingTotals, bold: bool) {
    let cell = if bold { "th" } else { "td" };
    let _ = writeln!(
        h,
        "<tr><{cell}>{}</{cell}><td class=\"num\">{}</td><td class=\"num\">{:.2}</td><td class=\"num\">{:.2}</td>\
         <td class=\"num\">{:.2}</td><td class=\"num\">{:.2}</td><td class=\"num\">{:.2}</td></tr>",
        escape(name),
        r.segments,
        r.planned_s,
        r.bench_s,
        r.waiting_s,
        r.recorder_after_s,
        r.wall_s
    );
}

/// Every segment, folded: the bench's own breakdown where it gives one.
fn segments(h: &mut String, t: &RunTiming) {
    let _ = writeln!(
        h,
        "<details><summary>Every segment ({})</summary>\n<table>\n<tr><th>stage</th><th>run</th><th>#</th><th>label</th>\
         <th>planned (s)</th><th>bench (s)</th><th>setup (s)</th><th>motion (s)</th><th>finish (s)</th>\
         <th>recorder (s)</th><th>wall (s)</th></tr>",
        t.segments.len()
    );
    let f = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.3}"));
    for s in &t.segments {
        let b = s.breakdown;
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td>{}</td><td class=\"num\">{:.3}</td>\
             <td class=\"num\">{:.3}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td>\
             <td class=\"num\">{}</td><td class=\"num\">{:.3}</td></tr>",
            escape(&s.stage),
            s.run,
            s.index,
            escape(&s.label),
            s.planned_s,
            s.bench_s,
            f(b.map(|b| b.setup_s)),
            f(b.map(|b| b.motion_s)),
            f(b.map(|b| b.finish_s)),
            f(b.map(|b| b.recorder_s)),
            s.wall_s
        );
    }
    h.push_str("</table>\n</details>\n");
}
