//! The report's moves of the lamella: each target requested, the gap measured without the
//! extrinsics, its error against the bound the forecast and the measurement allow, the verdict.

use super::escape;
use crate::position::{MoveRecord, Verdict, MODEL_ONLY};
use crate::session::Session;
use std::fmt::Write as _;

/// The moves' section (absent when the session made none).
pub(super) fn moves(h: &mut String, s: &Session) {
    if s.moves.is_empty() {
        return;
    }
    let confirmed = s.moves.iter().filter(|m| m.verdict == Verdict::Confirmed).count();
    let _ = writeln!(
        h,
        "<h2>Moves of the lamella</h2>\n<p>{} moves with the calibration, {confirmed} confirmed. Each gap is \
         measured without the extrinsics (a wavelength sweep at the end pose, or the fringes along the path from a \
         pose a sweep measured); a move is confirmed when the measured gap is within 3σ of the request, σ the \
         forecast's and the measurement's together. {}.</p>",
        s.moves.len(),
        escape(MODEL_ONLY)
    );
    h.push_str(
        "<table>\n<tr><th>#</th><th>label</th><th>requested</th><th>measured gap (µm)</th><th>error (nm)</th>\
         <th>bound (nm)</th><th>forecast σ gap (nm)</th><th>verdict</th><th>measured by</th></tr>\n",
    );
    for (k, m) in s.moves.iter().enumerate() {
        row(h, k, m);
    }
    h.push_str("</table>\n");
}

fn row(h: &mut String, k: usize, m: &MoveRecord) {
    let num = |v: Option<f64>, d: usize| v.map_or("–".to_string(), |v| format!("{v:.d$}"));
    let class = match m.verdict {
        Verdict::Confirmed => "yes",
        Verdict::Off | Verdict::Failed => "no",
        _ => "muted",
    };
    let _ = writeln!(
        h,
        "<tr><td>{}</td><td>{}</td><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td>\
         <td class=\"num\">{}</td><td class=\"{class}\">{}</td><td>{}</td></tr>",
        k + 1,
        escape(&m.label),
        escape(&m.requested.describe()),
        num(m.measurement.as_ref().map(|x| x.gap_um), 4),
        num(m.gap_error_nm, 2),
        num(m.bound_nm, 2),
        num(m.forecast.map(|f| f.gap_sigma_nm), 2),
        m.verdict.word(),
        escape(m.measurement.as_ref().map_or(m.note.as_str(), |x| x.method.as_str())),
    );
}
