//! GUI tests of the quick calibration and the Position view (egui_kittest, headless): the
//! wizard's plan choice with what each costs, the designed plan measured and identified, then
//! moves of the lamella: a confirmed one (checked against the bench's hidden truth), a target out
//! of reach refused with nothing moved, a move stopped, and random targets over the workspace.
//! With PHOTOROBOT_SCREENSHOTS=1 the views are written to screenshots/.

mod common;

use common::*;
use egui_kittest::kittest::Queryable;
use photorobot_app::dialogs::ScriptedDialogs;
use photorobot_app::gui::{Tab, Workbench};
use photorobot_app::settings::Settings;
use photorobot_app::state::StepState;
use photorobot_core::bench::BenchPreset;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::position::{Target, TaskFrame, Verdict};
use rand::{Rng, SeedableRng};
use std::time::Duration;

fn workbench() -> Workbench {
    let wb = Workbench::new(Settings::default(), Box::new(ScriptedDialogs::default()), Box::new(|| {}));
    wb.expect("the embedded virtual bench starts")
}

/// The true gap (µm) and tilt (°) at joints `q` on table2-ideal (its hidden truth).
fn truth_at(q: &[f64; 6]) -> Target {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let m = PhaseModel::of_preset(&preset, preset.truth).unwrap();
    TaskFrame::at(&m, &m.extrinsics, q).unwrap().target_at(&m, q).unwrap()
}

/// The designed plan chosen in the wizard (its bench time beside the paper's), measured with F5
/// and identified; in the Position view a target's joints and path are planned as it is typed, Go
/// places the lamella and the sweep at the end confirms it: the true gap within 10 nm and within
/// the bound. A target out of reach is refused and Go stays disabled; a move stopped with Esc is
/// recorded as stopped.
#[test]
fn the_quick_calibration_then_a_confirmed_move_in_the_position_view() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = harness(workbench());
    h.state_mut().state.session.dir = Some(dir.path().join("session"));
    open(&mut h, Tab::Wizard);
    h.get_by_label_contains("The paper's strategies 1 and 2 and the extra measurements: 13.0 min of bench time");
    h.get_by_label_contains("The designed plan (shipped, designed for table2-ideal): 0.44 min of bench time").click();
    h.run_steps(3);
    assert!(h.state().state.wizard.quick);
    screenshot(&mut h, "wizard-plan-choice");
    h.key_press(egui::Key::F5);
    wait_until(&mut h, "the designed plan", Duration::from_secs(300), |w| {
        w.state.wizard.steps.iter().any(|s| s.designed && s.state == StepState::Done)
    });
    assert!(
        h.state().state.wizard.steps.iter().all(|s| s.designed || s.traces.is_empty()),
        "only the designed step ran"
    );
    // Below the steps, out of view: clicked the way a screen reader does.
    h.get_by_label("Identify").click_accesskit();
    wait_until(&mut h, "the identification", Duration::from_secs(300), |w| {
        w.state.results.report.is_some() || w.state.results.identify_error.is_some()
    });
    assert!(h.state().state.results.identify_error.is_none(), "{:?}", h.state().state.results.identify_error);

    open(&mut h, Tab::Position);
    let target = Target { gap_um: 860.0, tilt_deg: [0.5, -0.3], lateral_um: [-60.0, -80.0], rotation_deg: 5.0 };
    h.state_mut().state.position.target = target;
    h.run_steps(3);
    h.get_by_label("predicted at the target");
    h.get_by_label_contains("the gap proven by a wavelength sweep at the target");
    h.get_by_label("Go (F5)").click();
    wait_until(&mut h, "the move", Duration::from_secs(120), |w| !w.state.position.moves.is_empty());
    let r = h.state().state.position.moves[0].clone();
    assert_eq!(r.verdict, Verdict::Confirmed, "{}", r.note);
    h.get_by_label("CONFIRMED");
    h.get_by_label_contains("measured gap 860.0");
    h.get_by_label_contains("tilt from the fringe contrast: ");
    let truth = truth_at(&r.joints_end.to_array());
    let t = r.tilt.expect("the tilt measured at the end pose");
    h.get_by_label(&format!("{:.4} ± {:.4}°", t.tilt_deg, t.sigma_deg));
    assert!((t.tilt_deg - truth.tilt_angle_rad().to_degrees()).abs() <= 3.0 * t.sigma_deg, "{t:?} vs {truth:?}");
    let error_nm = (truth.gap_um - target.gap_um) * 1e3;
    eprintln!(
        "true gap error {error_nm:+.2} nm, measured {:+.2} nm ± bound {:.2} nm",
        r.gap_error_nm.unwrap(),
        r.bound_nm.unwrap()
    );
    assert!(error_nm.abs() <= 10.0 && error_nm.abs() <= r.bound_nm.unwrap(), "true gap error {error_nm} nm");
    assert_eq!(h.state().state.q_display, r.joints_end.to_array(), "the bench stands at the target");
    // The next target typed: its path planned beside the confirmed move.
    h.state_mut().state.position.target = Target { gap_um: 900.0, lateral_um: [-110.0, -40.0], ..target };
    h.state_mut().state.position.keep_gap = true;
    h.run_steps(3);
    h.get_by_label("CONFIRMED");
    screenshot(&mut h, "position");

    // Out of reach: refused as it is typed, Go disabled, nothing moves.
    h.state_mut().state.position.target.gap_um = 50.0;
    h.run_steps(3);
    h.get_by_label_contains("Refused: target gap 50.0000 µm");
    h.get_by_label_contains("joint q2");
    h.get_by_label("Go (F5)").click();
    h.run_steps(5);
    assert_eq!(h.state().state.position.moves.len(), 1, "nothing ran");
    assert_eq!(h.state().state.q_display, r.joints_end.to_array(), "nothing moved");

    // A move stopped with Esc: at real time it lasts seconds; it is recorded as stopped.
    let speed = h.state().state.settings.speed;
    h.state_mut().state.settings.speed = 1.0;
    h.state_mut().state.position.target = Target { gap_um: 960.0, ..target };
    h.run_steps(3);
    h.key_press(egui::Key::F5);
    wait_until(&mut h, "the move to start", Duration::from_secs(30), |w| w.state.busy.is_some());
    std::thread::sleep(Duration::from_millis(300));
    h.get_by_label("Stop (Esc)");
    h.key_press(egui::Key::Escape);
    wait_until(&mut h, "the stop", Duration::from_secs(30), |w| w.state.position.moves.len() == 2);
    assert_eq!(h.state().state.position.moves[1].verdict, Verdict::Stopped);
    h.get_by_label("STOPPED");

    // Random targets over the workspace, each typed and placed with Go from where the last one
    // left the lamella: every target the view does not refuse is confirmed by its sweep, the
    // true gap within 10 nm and within the bound shown.
    h.state_mut().state.settings.speed = speed;
    let mut rng = rand::rngs::StdRng::seed_from_u64(23);
    let (mut placed, mut typed) = (0, 0);
    while placed < 4 {
        typed += 1;
        assert!(typed <= 20, "{placed} of {typed} random targets planned");
        let target = Target {
            gap_um: rng.random_range(780.0..1020.0),
            tilt_deg: [rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0)],
            lateral_um: [rng.random_range(-200.0..20.0), rng.random_range(-200.0..20.0)],
            rotation_deg: rng.random_range(-20.0..20.0),
        };
        h.state_mut().state.position.target = target;
        h.state_mut().state.position.keep_gap = false;
        h.run_steps(3);
        if matches!(&h.state().state.position.preview, Some((_, Err(_)))) {
            continue;
        }
        // The last one with the tilt measurement unticked: read at the requested tilt, and said.
        if placed == 3 {
            h.get_by_label("measure the tilt at the end").click();
            h.run_steps(3);
            assert!(!h.state().state.position.measure_tilt);
            h.get_by_label_contains("read at the requested tilt");
        }
        let before = h.state().state.position.moves.len();
        h.get_by_label("Go (F5)").click();
        wait_until(&mut h, "a random move", Duration::from_secs(120), |w| w.state.position.moves.len() > before);
        let r = h.state().state.position.moves[before].clone();
        assert_eq!(r.verdict, Verdict::Confirmed, "{target:?}: {}", r.note);
        assert_eq!(r.tilt.is_none(), placed == 3, "{}", r.note);
        let error_nm = (truth_at(&r.joints_end.to_array()).gap_um - target.gap_um) * 1e3;
        eprintln!("{target:?}: true gap error {error_nm:+.2} nm, bound {:.2} nm", r.bound_nm.unwrap());
        assert!(error_nm.abs() <= 10.0 && error_nm.abs() <= r.bound_nm.unwrap(), "{target:?}: {error_nm} nm");
        placed += 1;
    }
}

/// "Design a plan for this bench" runs the experiment design for the preset at hand and makes its
/// plan the designed step's, with its bench time and predicted σ shown.
#[test]
fn the_wizard_designs_a_plan_for_the_bench_at_hand() {
    let mut h = harness(workbench());
    open(&mut h, Tab::Wizard);
    h.get_by_label("Design a plan for this bench (table2-ideal)").click();
    h.run_steps(2);
    h.get_by_label_contains("designing: a pilot run of the candidate motions");
    wait_until(&mut h, "the design", Duration::from_secs(600), |w| w.state.wizard.design.result.is_some());
    let (preset, d) = h.state().state.wizard.design.result.clone().unwrap();
    let d = d.expect("a design");
    assert_eq!(preset, "table2-ideal");
    h.get_by_label_contains(&format!(
        "Designed for table2-ideal: {} motions, {:.2} min",
        d.chosen.len(),
        d.total_s / 60.0
    ));
    h.get_by_label_contains("The designed plan (designed here for table2-ideal)");
    let step = h.state().state.wizard.steps.iter().find(|s| s.designed).unwrap().plan.clone();
    assert_eq!(step, d.plan, "the designed step measures the plan designed here");
    assert!(d.targets.iter().all(|t| t.predicted_sigma <= t.required_sigma), "{:?}", d.targets);
}
