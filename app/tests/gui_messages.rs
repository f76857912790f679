//! GUI test of the message panel (egui_kittest, headless): successive status and error messages
//! are all listed with their time, not overwritten; the status bar's "Messages (N)" toggles it.

mod common;

use common::*;
use egui_kittest::kittest::Queryable;
use photorobot_app::dialogs::ScriptedDialogs;
use photorobot_app::gui::{Tab, Workbench};
use photorobot_app::messages::Level;
use photorobot_app::settings::Settings;
use std::time::Duration;

#[test]
fn successive_messages_are_all_listed_with_errors_marked() {
    let tmp = tempfile::tempdir().unwrap();
    let good = tmp.path().join("trace.csv");
    std::fs::write(
        &good,
        "t_s,q1_um,q2_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,irradiance\n\
         0,0,0,0,0,0,0,1550,0.5\n0.001,0.1,0,0,0,0,0,1550,0.6\n",
    )
    .unwrap();
    let bad = tmp.path().join("broken.csv");
    std::fs::write(&bad, "t_s,irradiance\n0,zero\n").unwrap();
    let dialogs =
        ScriptedDialogs { opens: vec![vec![good.clone()], vec![bad.clone()]], saves: vec![], folders: vec![] };
    let workbench = Workbench::new(Settings::default(), Box::new(dialogs), Box::new(|| {})).unwrap();
    let mut h = harness(workbench);
    open(&mut h, Tab::Traces);
    h.get_by_label("Import CSV traces…").click();
    wait_until(&mut h, "the import", Duration::from_secs(10), |w| w.state.imported.len() == 1);
    h.get_by_label("Import CSV traces…").click();
    wait_until(&mut h, "the refused import", Duration::from_secs(10), |w| w.state.status.starts_with("import refused"));
    // The status bar shows only the latest; the panel lists both, the refusal as an error.
    assert!(h.query_all_by_label_contains("imported ").next().is_none(), "the panel is closed");
    h.get_by_label("Messages (2)").click();
    h.run_steps(3);
    h.get_by_label_contains(&format!("imported {}", good.display()));
    h.get_by_label_contains("error: import refused");
    let list = &h.state().state.messages.list;
    assert_eq!(list.iter().map(|m| m.level).collect::<Vec<_>>(), [Level::Info, Level::Error]);
    assert!(list[0].time_s <= list[1].time_s && list[0].time_s > 1.0e9, "times are wall-clock, in order");
    // Away from the toggle, so the screenshot shows it unhovered.
    h.hover_at(egui::pos2(700.0, 300.0));
    h.run_steps(2);
    screenshot(&mut h, "messages");
    h.get_by_label("Close").click();
    h.run_steps(3);
    assert!(!h.state().state.messages.open);
}
