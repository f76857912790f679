//! The report's lab record: when, by whom and in what air the session was measured, beside the
//! ambient conditions the model's air index was computed from, and the controllers' identification.

use super::escape;
use crate::model::air::air_index_ciddor;
use crate::session::Session;
use std::fmt::Write as _;

/// A value with its unit, or "not recorded".
fn value(v: Option<f64>, decimals: usize, unit: &str) -> String {
    v.map_or("not recorded".to_string(), |v| format!("{v:.decimals$} {unit}"))
}

/// The lab record's section (always present: "not recorded" says the field was left empty).
pub(super) fn lab_record(h: &mut String, s: &Session) {
    let lab = &s.lab;
    h.push_str("<h2>Lab record</h2>\n<table>\n");
    let mut row = |k: &str, v: &str| {
        let _ = writeln!(h, "<tr><th>{}</th><td>{}</td></tr>", escape(k), escape(v));
    };
    row("measured at (UTC)", lab.measured_at_utc.as_deref().unwrap_or("not recorded"));
    row("operator", lab.operator.as_deref().unwrap_or("not recorded"));
    h.push_str("</table>\n");
    // The model's air index comes from the bench preset's ambient conditions; the lab's readings
    // are shown beside them so that a difference is seen, not silently applied.
    let model = s.bench.description.as_ref().map(|p| (p.ambient, air_index_ciddor(p.laser.wavelength_nm, &p.ambient)));
    h.push_str("<table>\n<tr><th></th><th>measured in the lab</th><th>model (bench preset, sets n_air)</th></tr>\n");
    let rows = [
        ("temperature", lab.ambient_temperature_c, model.as_ref().map(|m| m.0.temperature_c), 2, "°C"),
        ("pressure", lab.pressure_hpa, model.as_ref().map(|m| m.0.pressure_hpa), 2, "hPa"),
        (
            "relative humidity",
            lab.relative_humidity_percent,
            model.as_ref().map(|m| m.0.relative_humidity_percent),
            1,
            "%",
        ),
    ];
    for (name, measured, modelled, decimals, unit) in rows {
        let modelled = modelled.map_or("–".to_string(), |v| format!("{v:.decimals$} {unit}"));
        let _ = writeln!(
            h,
            "<tr><th>{name}</th><td class=\"num\">{}</td><td class=\"num\">{}</td></tr>",
            escape(&value(measured, decimals, unit)),
            escape(&modelled)
        );
    }
    let n_air = match &model {
        Some((_, Ok(n))) => format!("{n:.9}"),
        Some((_, Err(e))) => format!("not computable: {e}"),
        None => "–".into(),
    };
    let _ = writeln!(
        h,
        "<tr><th>n_air</th><td class=\"muted\">not used</td><td class=\"num\">{}</td></tr>\n</table>",
        escape(&n_air)
    );
    if !lab.controllers.is_empty() {
        h.push_str("<table>\n<tr><th>controller</th><th>identification</th></tr>\n");
        for c in &lab.controllers {
            let _ = writeln!(h, "<tr><td>{}</td><td>{}</td></tr>", escape(&c.name), escape(&c.identification));
        }
        h.push_str("</table>\n");
    }
}

#[cfg(test)]
mod tests {
    use crate::session::{BenchInfo, ControllerIdentity, Session};

    #[test]
    fn the_report_shows_the_lab_record_beside_the_models_ambient() {
        let preset = crate::bench::BenchPreset::resolve("table2-ideal").unwrap();
        let info = BenchInfo { name: "bench".into(), preset: None, description: Some(preset.clone()), seed: None };
        let mut s = Session::new(info, preset.robot_description().unwrap());
        s.lab.operator = Some("A. <Tech>".into());
        s.lab.ambient_temperature_c = Some(22.4);
        s.lab.pressure_hpa = Some(987.6);
        s.lab.measured_at_utc = Some("2026-11-27T16:49:50Z".into());
        s.lab.controllers = vec![ControllerIdentity { name: "pi".into(), identification: "E-712 (emulated)".into() }];
        let h = super::super::render_html(&s);
        for want in [
            "Lab record",
            "A. &lt;Tech&gt;",
            "22.40 °C",
            "987.60 hPa",
            "2026-11-27T16:49:50Z",
            "E-712 (emulated)",
            "n_air",
        ] {
            assert!(h.contains(want), "{want} missing");
        }
        // Humidity was not recorded; the model's is shown beside it.
        let model_rh = format!("{:.1} %", preset.ambient.relative_humidity_percent);
        assert!(h.contains("not recorded") && h.contains(&model_rh));
    }
}
