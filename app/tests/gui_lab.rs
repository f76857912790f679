//! GUI test of the "Lab record and notes" window: typing an operator and a note, recording the
//! ambient temperature, and saving puts them into session.ron; the window shows the record.

mod common;

use common::*;
use egui::accesskit::Role;
use egui_kittest::kittest::Queryable;
use photorobot_app::dialogs::ScriptedDialogs;
use photorobot_app::gui::Workbench;
use photorobot_app::settings::Settings;
use std::time::Duration;

#[test]
fn the_lab_record_and_notes_typed_in_are_saved_with_the_session() {
    let app = Workbench::new(Settings::default(), Box::new(ScriptedDialogs::default()), Box::new(|| {}))
        .expect("the embedded virtual bench starts");
    let mut h = harness(app);
    h.run_steps(2);
    h.get_by_label("File").click();
    h.run_steps(2);
    h.get_by_label("Lab record and notes…").click();
    h.run_steps(3);
    h.get_by_label("set when recording starts");
    assert!(!h.state().state.session.dirty);

    let operator = h.get_by_role_and_label(Role::TextInput, "operator");
    operator.focus();
    h.run_steps(1);
    h.get_by_role_and_label(Role::TextInput, "operator").type_text("Ada Lovelace");
    h.run_steps(2);
    assert_eq!(h.state().state.session.lab.operator.as_deref(), Some("Ada Lovelace"));
    assert!(h.state().state.session.dirty, "editing the lab record marks the session unsaved");

    // Record the temperature: the checkbox beside it gives the typical value, kept in range.
    h.get_by_role_and_label(Role::CheckBox, "temperature").click();
    h.run_steps(2);
    assert_eq!(h.state().state.session.lab.ambient_temperature_c, Some(20.0));

    h.get_by_role_and_label(Role::MultilineTextInput, "Notes").focus();
    h.run_steps(1);
    h.get_by_role_and_label(Role::MultilineTextInput, "Notes").type_text("fiber cleaved again");
    h.run_steps(2);
    assert_eq!(h.state().state.session.notes, "fiber cleaved again");

    // Recording starts: the time and the bench's identification are recorded by themselves.
    h.state_mut().state.run_step(0);
    h.state_mut().state.cancel();
    wait_until(&mut h, "the cancelled step", Duration::from_secs(60), |w| w.state.wizard.running.is_none());
    let lab = h.state().state.session.lab.clone();
    let at = lab.measured_at_utc.clone().expect("stamped when the step started");
    assert!(at.ends_with('Z') && at.len() == 20, "{at}");
    assert_eq!(lab.controllers.len(), 1);
    assert!(lab.controllers[0].identification.contains("virtual bench table2-ideal"), "{:?}", lab.controllers);
    h.get_by_label(&at);
    screenshot(&mut h, "lab-record");

    let root = tempfile::tempdir().unwrap();
    let session = save_as_and_load(&mut h, &root.path().join("lab-session"));
    assert_eq!(session.lab.operator.as_deref(), Some("Ada Lovelace"));
    assert_eq!(session.lab.ambient_temperature_c, Some(20.0));
    assert_eq!(session.lab.pressure_hpa, None);
    assert_eq!(session.notes, "fiber cleaved again");
    assert_eq!(session.lab.measured_at_utc.as_deref(), Some(at.as_str()));
    assert_eq!(session.lab.controllers, lab.controllers);
    let text = std::fs::read_to_string(root.path().join("lab-session/session.ron")).unwrap();
    assert!(text.contains("Ada Lovelace") && text.contains("fiber cleaved again"));
}
