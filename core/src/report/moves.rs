//! The report's moves of the lamella: each target requested, the gap measured without the
//! extrinsics, its error against the bound the forecast and the measurement allow, the verdict.

use super::escape;
use crate::position::{MoveRecord, Verdict, MODEL_ONLY, MODEL_ONLY_TILT_MEASURED};
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
        escape(if s.moves.iter().any(|m| m.tilt.is_some()) { MODEL_ONLY_TILT_MEASURED } else { MODEL_ONLY })
    );
    h.push_str(
        "<table>\n<tr><th>#</th><th>label</th><th>requested</th><th>measured gap (µm)</th><th>error (nm)</th>\
         <th>bound (nm)</th><th>forecast σ gap (nm)</th><th>tilt from the contrast (°)</th><th>verdict</th>\
         <th>measured by</th></tr>\n",
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
         <td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"{class}\">{}</td><td>{}</td></tr>",
        k + 1,
        escape(&m.label),
        escape(&m.requested.describe()),
        num(m.measurement.as_ref().map(|x| x.gap_um), 4),
        num(m.gap_error_nm, 2),
        num(m.bound_nm, 2),
        num(m.forecast.map(|f| f.gap_sigma_nm), 2),
        m.tilt.map_or("–".to_string(), |t| format!(
            "{:.4} ± {:.4} (model {:.4})",
            t.tilt_deg, t.sigma_deg, t.model_deg
        )),
        m.verdict.word(),
        escape(m.measurement.as_ref().map_or(m.note.as_str(), |x| x.method.as_str())),
    );
}

#[cfg(test)]
mod tests {
    use crate::position::{
        Achieved, GapMeasurement, Joints, MoveRecord, PoseForecast, Target, TiltMeasurement, Verdict, MODEL_ONLY,
    };
    use crate::session::Session;

    fn a_move(verdict: Verdict, error_nm: f64) -> MoveRecord {
        let target = Target { gap_um: 870.0, tilt_deg: [0.5, -0.25], lateral_um: [-80.0, -90.0], rotation_deg: 5.0 };
        MoveRecord {
            label: "place".into(),
            recipe: Some(("glue".into(), 1)),
            started_utc: Some("2026-11-29T08:00:00Z".into()),
            extrinsics_source: "session s".into(),
            requested: target,
            keep_gap: true,
            joints_start: Joints::from([0.0; 6]),
            joints_end: Joints::from([10.0, 28.8, -20.0, 0.5, -0.25, 5.0]),
            waypoints: 12,
            forecast: Some(PoseForecast {
                gap_sigma_nm: 3.2,
                tilt_sigma_deg: [0.002, 0.003],
                lateral_sigma_um: [0.05, 0.04],
                rotation_sigma_deg: 0.01,
            }),
            measurement: Some(GapMeasurement {
                method: "wavelength sweep at the end pose".into(),
                gap_um: 870.0 + error_nm * 1e-3,
                sigma_nm: 0.1,
            }),
            tilt: None,
            achieved: Some(Achieved { gap_um: Some(870.0 + error_nm * 1e-3), gap_sigma_nm: Some(0.1), model: target }),
            gap_error_nm: Some(error_nm),
            bound_nm: Some(9.6),
            model_only: MODEL_ONLY.into(),
            verdict,
            note: "measured".into(),
            bench_time_s: 5.5,
        }
    }

    /// The moves survive a save and a load, show in the report with their verdicts, and a
    /// session written before moves existed (no `moves` field) loads with none.
    #[test]
    fn moves_round_trip_through_the_session_and_show_in_the_report() {
        let dir = tempfile::tempdir().unwrap();
        let mut s = crate::session::tests::sample_session(dir.path());
        assert!(!super::super::render_html(&s).contains("Moves of the lamella"), "no moves: no section");
        s.moves = vec![a_move(Verdict::Confirmed, -0.3), a_move(Verdict::Off, 1204.5)];
        s.moves[0].tilt = Some(TiltMeasurement {
            tilt_deg: 0.559,
            sigma_deg: 0.004,
            components_deg: [0.5, -0.25],
            components_sigma_deg: [0.003, 0.003],
            model_deg: 0.5591,
            bench_time_s: 7.5,
        });
        s.save(dir.path()).unwrap();
        let back = Session::load(dir.path()).unwrap();
        assert_eq!(back.moves, s.moves);
        let html = super::super::render_html(&back);
        assert!(
            html.contains("Moves of the lamella") && html.contains("2 moves with the calibration, 1 confirmed"),
            "{html}"
        );
        assert!(html.contains("<td class=\"num\">1204.50</td><td class=\"num\">9.60</td>"), "{html}");
        assert!(html.contains("<td class=\"num\">0.5590 ± 0.0040 (model 0.5591)</td>"), "{html}");
        assert!(html.contains("the tilt is measured from the fringe contrast"), "{html}");
        assert!(html.contains("<td class=\"no\">off</td>") && html.contains("<td class=\"yes\">confirmed</td>"));
        let text = std::fs::read_to_string(crate::session::session_path(dir.path())).unwrap();
        let start = text.find("    moves: [").expect("the moves field");
        let end = start + text[start..].find("\n    ],\n").unwrap() + "\n    ],\n".len();
        let old = format!("{}{}", &text[..start], &text[end..]);
        assert!(!old.contains("moves:"));
        let older = Session::from_ron_str(&old, std::path::Path::new("old.ron")).unwrap();
        assert!(older.moves.is_empty());
    }
}
