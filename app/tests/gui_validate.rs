//! GUI test of checking a calibration on the bench without recalibrating (egui_kittest,
//! headless): a session calibrated by `photorobot calibrate` is opened, the Validation view's
//! button runs the four motions with the proof of each, then the same with extrinsics moved off
//! the identified ones on purpose, which the view refuses. With PHOTOROBOT_SCREENSHOTS=1 the
//! view is written to screenshots/.

mod common;

use common::*;
use egui_kittest::kittest::Queryable;
use photorobot_app::dialogs::ScriptedDialogs;
use photorobot_app::gui::{Pending, Tab, Workbench};
use photorobot_app::settings::Settings;
use photorobot_core::validate::evidence::Verdict;
use photorobot_core::validate::ValidationMotion;
use std::time::Duration;

/// Calibrate table2-ideal with the designed plan into `out` through the CLI, as a user does.
fn calibrate(out: &std::path::Path) {
    let argv = ["photorobot", "calibrate", "--bench", "table2-ideal", "--seed", "7", "--plan", "optimised"];
    let mut argv: Vec<String> = argv.iter().map(|s| s.to_string()).collect();
    argv.extend(["--no-validation".into(), "--out".into(), out.display().to_string()]);
    let mut sink = Vec::new();
    photorobot_app::cli::run(argv, &mut sink).unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&sink)));
}

/// Open the session, press "Check the calibration on the bench": four motions, each with its
/// verdict and figures, every one confirmed within target with the identified extrinsics; with
/// β_wf moved by 1° the check says NOT PROVEN and names the motions.
#[test]
fn an_opened_session_is_checked_on_the_bench_and_a_wrong_calibration_refused() {
    let dir = tempfile::tempdir().unwrap();
    let session = dir.path().join("session");
    calibrate(&session);
    let wb = Workbench::new(Settings::default(), Box::new(ScriptedDialogs::default()), Box::new(|| {}));
    let mut h = harness(wb.expect("the embedded virtual bench starts"));
    h.state_mut().request(Pending::Open(session.clone()));
    h.run_steps(3);
    assert!(h.state().state.results.report.is_some(), "the opened session carries its calibration");
    open(&mut h, Tab::Validation);
    h.get_by_label("Check the calibration on the bench").click();
    wait_until(&mut h, "the check", Duration::from_secs(300), |w| w.state.results.check.is_some());
    h.run_steps(3);
    let check = h.state().state.results.check.clone().unwrap();
    assert_eq!(check.iter().map(|c| c.motion).collect::<Vec<_>>(), ValidationMotion::ALL.to_vec());
    h.get_by_label("Check of the calibration on the bench (no recalibration)");
    for c in &check {
        let e = &c.figure.as_ref().unwrap_or_else(|e| panic!("{}: {e}", c.motion.name())).evidence;
        eprintln!("{}: {}", c.motion.name(), e.summary());
        assert!(e.count.is_some() && e.bounds.is_some(), "{}: the model-free count is shown", c.motion.name());
        assert_eq!(e.verdict, Verdict::Confirmed, "{}: {}", c.motion.name(), e.summary());
        assert!(e.within_target, "{}: {}", c.motion.name(), e.summary());
    }
    h.get_by_label("Validation: every motion confirmed within its target.");
    screenshot(&mut h, "validation-check");

    let mut wrong = h.state().state.extrinsics;
    wrong.beta_wf_deg += 1.0;
    h.state_mut().state.extrinsics = wrong;
    h.get_by_label("Check the calibration on the bench").click();
    wait_until(&mut h, "the check of the wrong extrinsics", Duration::from_secs(300), |w| {
        w.state.results.check.is_some()
    });
    h.run_steps(3);
    let check = h.state().state.results.check.clone().unwrap();
    assert!(check.iter().any(|c| c.figure.as_ref().map_or(true, |f| !f.evidence.within_target)));
    h.get_by_label("NOT PROVEN: the validation does not confirm this calibration");
    screenshot(&mut h, "validation-check-refused");
}
