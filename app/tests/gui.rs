//! GUI tests (egui_kittest, headless): drive the workbench on the virtual bench and check what it
//! shows by accessible labels. With PHOTOROBOT_SCREENSHOTS=1 every view is also written to
//! screenshots/ (rendered on Mesa llvmpipe): `PHOTOROBOT_SCREENSHOTS=1 cargo test -p photorobot --test gui`.

mod common;

use common::*;
use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use photorobot_app::dialogs::ScriptedDialogs;
use photorobot_app::gui::{App, Tab, Workbench};
use photorobot_app::settings::Settings;
use photorobot_app::state::StepState;
use photorobot_app::worker::EffectValidation;
use std::time::{Duration, Instant};

fn workbench(settings: Settings, dialogs: ScriptedDialogs) -> Workbench {
    Workbench::new(settings, Box::new(dialogs), Box::new(|| {})).expect("the embedded virtual bench starts")
}

#[test]
fn robot_view_shows_the_frames_and_selecting_a_node_highlights_it() {
    let mut h = harness(workbench(Settings::default(), ScriptedDialogs::default()));
    open(&mut h, Tab::Robot);
    // Before calibration the view uses the design extrinsics: the lamella 900 µm from the fiber.
    h.get_by_label_contains("L = -900.000 µm");
    h.get_by_label_contains("P_r (world) = (100.000, 0.000, 100.000) µm");
    for frame in ["world", "link 6 (q6)", "end effector", "fiber", "tool (lamella)", "reflection point P_r"] {
        assert!(h.query_all_by_label_contains(frame).next().is_some(), "frame {frame} is not shown");
    }
    h.get_by_label("fiber").click();
    h.run_steps(2);
    h.get_by_label("selected: fiber");
    // Orbit: a drag on the scene turns the camera; reset brings it back.
    let before = h.state().state.robot_view.camera;
    let centre = h.get_by_label("Reset view").rect().center() + egui::vec2(300.0, 300.0);
    h.drag_at(centre);
    h.hover_at(centre + egui::vec2(60.0, 20.0));
    h.drop_at(centre + egui::vec2(60.0, 20.0));
    h.run_steps(2);
    assert_ne!(h.state().state.robot_view.camera, before, "dragging the scene orbits the camera");
    screenshot(&mut h, "robot");
    h.get_by_label("Reset view").click();
    h.run_steps(2);
    assert_eq!(h.state().state.robot_view.camera, before);
    // Jog: the bench moves and the readouts follow.
    h.state_mut().state.robot_view.jog_target = [10.0, -20.0, 30.0, 1.0, -2.0, 3.0];
    h.get_by_label("Move to targets").click();
    wait_until(&mut h, "the jog", Duration::from_secs(30), |w| (w.state.q_display[0] - 10.0).abs() < 1e-9);
    let chain = photorobot_core::model::kinematics::Chain::femto_6dof();
    let q = chain.description().q_from_display(&[10.0, -20.0, 30.0, 1.0, -2.0, 3.0]);
    let cavity =
        photorobot_core::model::extrinsics::Extrinsics::nominal_design().cavity(&chain.end_effector(&q)).unwrap();
    h.get_by_label_contains(&format!("L = {:.3} µm", cavity.length_um));
    h.get_by_label_contains("q1 = 10.000 µm");
    h.get_by_label("Home (all joints 0)").click();
    wait_until(&mut h, "homing", Duration::from_secs(30), |w| w.state.q_display == [0.0; 6]);
    h.get_by_label_contains("L = -900.000 µm");
}

#[test]
fn live_view_streams_counts_fringes_and_the_gauge_says_ready() {
    let mut h = harness(workbench(Settings::default(), ScriptedDialogs::default()));
    open(&mut h, Tab::Live);
    h.get_by_label("Start live signal").click();
    // Real time: a dither half-cycle (2 µm along the beam, about 5 extrema) lasts about a second.
    let start = Instant::now();
    let (mut most, mut saw_down) = (0i64, false);
    while !(most >= 4 && saw_down) {
        h.run_steps(1);
        let c = &h.state().state.live.counter;
        most = most.max(c.steps.abs());
        saw_down |= c.direction == -1 && most >= 4;
        assert!(start.elapsed() < Duration::from_secs(60), "no fringes counted: most {most}");
        std::thread::sleep(Duration::from_millis(20));
    }
    h.run_steps(2);
    let steps = h.state().state.live.counter.steps;
    h.get_by_label_contains(&format!("{:+.1} fringes", steps as f64 / 2.0));
    assert!(h.query_by_label_contains("gap opening").is_some() || h.query_by_label_contains("gap closing").is_some());
    let gap = h.state().state.live.gap_um.expect("the model gap is shown");
    assert!((gap - 900.0).abs() < 2.5, "the design gap, dithered by 2 µm: {gap}");
    h.get_by_label_contains(&format!("gap (model) = {gap:.3} µm"));
    h.get_by_label_contains("visibility = 0.");
    // Space pauses the scrolling view (the buffer keeps filling).
    h.key_press(egui::Key::Space);
    h.run_steps(2);
    assert!(h.state().state.live.paused);
    h.get_by_label("Resume scrolling (Space)");
    screenshot(&mut h, "live");
    open(&mut h, Tab::Align);
    h.get_by_label_contains("fringe visibility ≥ 0.05");
    h.get_by_label("READY TO CALIBRATE");
    screenshot(&mut h, "align");
    h.state_mut().state.worker.live.store(false, std::sync::atomic::Ordering::Relaxed);
}

/// The whole calibration by hand: every wizard step, identification, results, validation,
/// trace inspection and the diagnosis entry point, on the virtual bench as fast as it runs.
#[test]
fn wizard_runs_every_step_identifies_and_validates() {
    let dir = tempfile::tempdir().unwrap();
    let exported = dir.path().join("exported.csv");
    let dialogs = ScriptedDialogs { opens: vec![], saves: vec![Some(exported.clone())], folders: vec![] };
    let mut h = harness(workbench(Settings::default(), dialogs));
    h.state_mut().state.session.dir = Some(dir.path().join("session"));
    open(&mut h, Tab::Wizard);
    h.get_by_label_contains("Strategy 1: translations");
    h.get_by_label("Identify"); // present, disabled until the steps ran
                                // F5 runs the next step; a button runs the others.
    h.key_press(egui::Key::F5);
    wait_until(&mut h, "strategy 1", Duration::from_secs(300), |w| w.state.wizard.steps[0].state == StepState::Done);
    let step = &h.state().state.wizard.steps[0];
    let recorded = step.plan.segments.iter().filter(|g| g.is_recorded()).count();
    assert_eq!(step.traces.len(), recorded, "one trace per recorded segment");
    h.get_by_label_contains(&format!("done: {recorded} traces"));
    h.get_by_label("Run step 2 (F5)").click();
    h.run_steps(2);
    screenshot(&mut h, "wizard-running");
    wait_until(&mut h, "strategy 2", Duration::from_secs(300), |w| w.state.wizard.steps[1].state == StepState::Done);
    h.get_by_label("Run step 3 (F5)").click();
    wait_until(&mut h, "the extra measurements", Duration::from_secs(300), |w| {
        w.state.wizard.steps[2].state == StepState::Done
    });
    h.get_by_label("Redo step 1");
    click_in_view(&mut h, "Identify");
    wait_until(&mut h, "the identification", Duration::from_secs(600), |w| {
        w.state.results.report.is_some() || w.state.results.identify_error.is_some()
    });
    assert!(h.state().state.results.identify_error.is_none(), "{:?}", h.state().state.results.identify_error);
    screenshot(&mut h, "wizard");

    open(&mut h, Tab::Results);
    h.get_by_label_contains("Identified extrinsics (Joint mode");
    for name in ["β_et", "θ_et", "β_wf", "θ_wf", "x_wf", "z_wf", "Z_et", "y_wf"] {
        assert!(h.query_all_by_label(name).next().is_some(), "row {name} missing");
    }
    let report = h.state().state.results.report.clone().unwrap();
    let determined = report.parameters.iter().filter(|p| p.determined).count();
    assert_eq!(h.query_all_by_label("yes").count(), determined);
    assert!(determined >= 6, "{determined} parameters determined");
    assert!(h.query_all_by_label_contains("condition number").next().is_some());
    h.get_by_label_contains("Residuals per equation");
    h.get_by_label_contains("Correlation of the estimates");
    screenshot(&mut h, "results");

    open(&mut h, Tab::Validation);
    h.get_by_label("Run validation").click();
    wait_until(&mut h, "the validation", Duration::from_secs(600), |w| w.state.results.validation.is_some());
    let pairs = h.state().state.results.validation.clone().unwrap();
    let shown = |h: &Harness<'_, Workbench>, text: &str| h.query_all_by_label(text).next().is_some();
    for p in &pairs {
        assert!(shown(&h, p.motion.name()), "{}", p.motion.name());
        let (b, a) = (p.before.as_ref().unwrap(), p.after.as_ref().unwrap());
        eprintln!(
            "{}: before {:.1} nm ({}), after {:.1} nm ({})",
            p.motion.name(),
            b.evidence.measured_nm,
            b.evidence.verdict.word(),
            a.evidence.measured_nm,
            a.evidence.verdict.word()
        );
        // Each figure the one its verdict stands behind.
        assert!(shown(&h, &format!("{:.1} nm", b.evidence.measured_nm)), "{:?}", b.evidence);
        assert!(shown(&h, &format!("{:.1} nm", a.evidence.measured_nm)), "{:?}", a.evidence);
        assert!(shown(&h, &format!("{:.0} nm", p.motion.paper_after_nm())), "{}", p.motion.name());
        // Calibration pays off on the circle (the paper's headline motion).
        if p.motion.name().contains("circle") {
            assert!(a.evidence.measured_nm < 0.1 * b.evidence.measured_nm, "{:?} {:?}", a.evidence, b.evidence);
        }
    }
    screenshot(&mut h, "validation");

    // The first trace is the sweep before strategy 1's first move, the second that move.
    open(&mut h, Tab::Traces);
    wait_until(&mut h, "the sweep analysis", Duration::from_secs(120), |w| w.state.analyses.contains_key(&0));
    h.get_by_label_contains("absolute gap = ");
    h.state_mut().inspector.selected = 1;
    h.run_steps(1);
    wait_until(&mut h, "the motion analysis", Duration::from_secs(120), |w| w.state.analyses.contains_key(&1));
    h.get_by_label_contains("(phase tracking); extremum counting");
    screenshot(&mut h, "traces");
    h.get_by_label("Export CSV…").click();
    h.run_steps(2);
    let back = photorobot_core::trace::Trace::read_csv(&exported).expect("the exported trace reads back");
    assert_eq!(back.irradiance, h.state().state.wizard.steps[0].traces[1].irradiance);

    open(&mut h, Tab::Diagnosis);
    h.get_by_label("Largest residuals");
    h.get_by_label("RMS residual per equation");
    screenshot(&mut h, "diagnosis");
}

#[test]
fn sessions_autosave_save_open_recover_and_export_through_the_file_menu() {
    let tmp = tempfile::tempdir().unwrap();
    let (work, saved, report) = (tmp.path().join("work"), tmp.path().join("saved"), tmp.path().join("report.html"));
    let dialogs =
        ScriptedDialogs { opens: vec![], saves: vec![Some(report.clone())], folders: vec![Some(saved.clone())] };
    let mut h = harness(workbench(Settings::default(), dialogs));
    h.state_mut().state.session.dir = Some(work.clone());
    open(&mut h, Tab::Wizard);
    h.get_by_label("Run step 2 (F5)").click();
    wait_until(&mut h, "strategy 2 and its autosave", Duration::from_secs(300), |w| {
        w.state.wizard.steps[1].state == StepState::Done
            && w.state.session.saving == 0
            && w.state.status.starts_with("autosaved")
    });
    let recorded = h.state().state.wizard.steps[1].traces.clone();
    // Autosaved after the step: a crash now would lose nothing.
    assert_eq!(photorobot_app::session_io::recoverable(&work), Some(recorded.len()));
    h.get_by_label_contains("(unsaved)");
    // Save as: the folder dialog, then session.ron there.
    h.get_by_label("File").click();
    h.run_steps(2);
    h.get_by_label("Save as…").click();
    wait_until(&mut h, "the save", Duration::from_secs(60), |w| w.state.session.saving == 0);
    assert!(saved.join("session.ron").is_file(), "{}", h.state().state.status);
    assert!(h.query_by_label_contains("(unsaved)").is_none());
    assert_eq!(h.state().state.settings.recent[0], saved.display().to_string());
    // Export the report.
    h.get_by_label("File").click();
    h.run_steps(2);
    h.get_by_label("Export report…").click();
    h.run_steps(2);
    let html = std::fs::read_to_string(&report).expect("the report is written");
    assert!(html.contains("<html") && html.contains("virtual bench table2-ideal"), "{}", &html[..html.len().min(300)]);
    // New (nothing unsaved: no prompt), then open the saved folder again: the same traces.
    h.state_mut().request(photorobot_app::gui::Pending::New);
    h.run_steps(2);
    assert!(h.state().state.wizard.steps[1].traces.is_empty());
    h.state_mut().request(photorobot_app::gui::Pending::Open(saved.clone()));
    h.run_steps(2);
    assert_eq!(h.state().state.wizard.steps[1].state, StepState::Done);
    assert_eq!(h.state().state.wizard.steps[1].traces, recorded);
    // The work folder has only an autosave: opening it offers recovery.
    h.state_mut().request(photorobot_app::gui::Pending::Open(work.clone()));
    h.run_steps(2);
    h.get_by_label_contains("holds an autosave with");
    h.get_by_label("Recover the autosave").click();
    h.run_steps(2);
    assert_eq!(h.state().state.wizard.steps[1].traces, recorded);
    assert!(h.state().state.session.dirty, "a recovered session still needs a save");
    // Unsaved changes: New asks first; Discard goes ahead.
    h.state_mut().request(photorobot_app::gui::Pending::New);
    h.run_steps(2);
    h.get_by_label_contains("not saved");
    h.get_by_label("Discard").click();
    h.run_steps(2);
    assert!(h.state().state.wizard.steps[1].traces.is_empty() && !h.state().state.session.dirty);
}

/// A virtual bench whose goniometer pivots sit 150-200 µm off the model's: no extrinsics explain
/// its rotations. Written as a preset file in `dir`.
fn off_pivot_preset(dir: &std::path::Path) -> String {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/benches/table2-ideal.ron"))
        .unwrap()
        .replace("name: \"table2-ideal\"", "name: \"off-pivot\"")
        .replacen(
            "effects: [],",
            "effects: [PivotOffset(joint: \"q4\", offset_world_um: (0.0, 200.0, 150.0)), \
             PivotOffset(joint: \"q5\", offset_world_um: (150.0, 200.0, 0.0))],",
            1,
        );
    assert!(text.contains("PivotOffset"));
    let path = dir.join("off-pivot.ron");
    std::fs::write(&path, text).unwrap();
    path.display().to_string()
}

/// The technician sees before step 1 that the bench has no tunable laser and what skipping the
/// sweeps costs (forecast on a pilot run of the plans); the step runs without its sweeps.
#[test]
fn wizard_says_before_step_1_what_a_bench_without_a_tunable_laser_costs() {
    let dir = tempfile::tempdir().unwrap();
    let settings = Settings { preset: fixed_laser_preset(dir.path()), ..Settings::default() };
    let mut h = harness(workbench(settings, ScriptedDialogs::default()));
    open(&mut h, Tab::Wizard);
    h.get_by_label("No tunable laser on this bench");
    let sweeps: usize = h.state().state.identifier_plans().iter().map(|p| p.sweeps()).sum();
    assert!(sweeps > 0);
    h.get_by_label_contains(&format!("leave their {sweeps} wavelength sweeps out"));
    wait_until(&mut h, "the sweep-cost forecast", Duration::from_secs(600), |w| w.state.sweep_forecast.ready());
    h.run_steps(3);
    let cost = h.state_mut().state.sweep_cost_forecast().cloned().unwrap().unwrap();
    assert!(!cost.is_free(), "{cost:?}");
    for sentence in cost.sentences() {
        h.get_by_label(&format!("• {sentence}"));
    }
    assert!(!cost.signed_by_sweeps.is_empty(), "strategy 1 signs its translations with sweeps: {cost:?}");
    screenshot(&mut h, "wizard-no-tunable-laser");
    // Step 1 runs its translations without the sweeps.
    h.get_by_label("Run step 1 (F5)").click();
    wait_until(&mut h, "strategy 1", Duration::from_secs(300), |w| w.state.wizard.steps[0].state == StepState::Done);
    let step = &h.state().state.wizard.steps[0];
    assert!(step.traces.iter().all(|t| !photorobot_core::trace::is_sweep(t)));
    assert_eq!(step.traces.len(), step.plan.recorded_moves());
    // The session keeps the plans as they ran, and each trace names its segment of them.
    let session = save_as_and_load(&mut h, &dir.path().join("session"));
    assert!(session.plans.iter().all(|p| p.sweeps() == 0), "the plans as this bench runs them");
    let of_step_1: Vec<_> = session.traces.iter().filter(|r| r.step.is_some_and(|(p, _)| p == 0)).collect();
    assert_eq!(of_step_1.len(), session.plans[0].recorded_moves());
    for r in of_step_1 {
        let (p, segment) = r.step.unwrap();
        assert_eq!(session.plans[p].segments[segment].label(), r.label, "trace `{}`", r.label);
    }
}

/// Identify on a bench the model cannot fit: the Results view shows an error, the residual
/// against its threshold and the worst traces, and no table of numbers.
#[test]
fn results_view_refuses_a_fit_the_model_cannot_explain() {
    let dir = tempfile::tempdir().unwrap();
    let settings = Settings { preset: off_pivot_preset(dir.path()), ..Settings::default() };
    let dialogs = ScriptedDialogs { opens: vec![], saves: vec![], folders: vec![] };
    let mut h = harness(workbench(settings, dialogs));
    h.state_mut().state.session.dir = Some(dir.path().join("session"));
    open(&mut h, Tab::Wizard);
    for step in 0..3 {
        h.get_by_label(&format!("Run step {} (F5)", step + 1)).click();
        wait_until(&mut h, "a step", Duration::from_secs(300), |w| w.state.wizard.steps[step].state == StepState::Done);
    }
    click_in_view(&mut h, "Identify");
    wait_until(&mut h, "the identification", Duration::from_secs(600), |w| {
        w.state.results.report.is_some() || w.state.results.identify_error.is_some()
    });
    let report = h.state().state.results.report.clone().expect("a report, even of a failed fit");
    let fit = report.fit.clone().expect("the verdict");
    assert_eq!(fit.verdict, photorobot_core::identify::verdict::Verdict::DoesNotFit, "{}", fit.summary);
    open(&mut h, Tab::Results);
    h.get_by_label_contains("NOT A CALIBRATION");
    h.get_by_label_contains("Traces with the largest residual");
    h.get_by_label(&fit.worst_traces[0].label);
    assert!(h.query_all_by_label("yes").next().is_none(), "no parameter shown as determined");
    assert!(h.query_all_by_label("β_et").next().is_none(), "no table of numbers");
    // Each start tried says how it stands: a start that ended in the kept branch is that
    // branch, not a worse one.
    h.get_by_label("chosen");
    let standing = |k: usize| fit.standing(k).word();
    let shown = |h: &Harness<'_, Workbench>, word: &str| h.query_all_by_label(word).count();
    for word in ["same branch", "worse"] {
        let expected = (0..fit.branches.len()).filter(|&k| standing(k) == word).count();
        assert_eq!(shown(&h, word), expected, "{word}: {:?}", fit.branches);
    }
    screenshot(&mut h, "results-does-not-fit");
    // The kept branch found again from one more start.
    let mut again = report.clone();
    let listed = &mut again.fit.as_mut().unwrap().branches;
    listed.push(photorobot_core::identify::verdict::BranchSummary {
        start: "one more start".into(),
        ..listed[0].clone()
    });
    h.state_mut().state.results.report = Some(again.clone());
    h.run_steps(2);
    assert_eq!(shown(&h, "same branch"), 1 + (0..fit.branches.len()).filter(|&k| standing(k) == "same branch").count());
    // A distinct branch with the lower χ², charged for nine motions its hint led: listed worse,
    // with its counts and the cost that ranks it.
    let listed = &mut again.fit.as_mut().unwrap().branches;
    let mut charged = listed[0].clone();
    charged.start = "a charged start".into();
    charged.extrinsics.theta_et_deg += 3.0;
    charged.chi2 = 0.5 * listed[0].chi2;
    charged.hint_led_traces = 9;
    let cost = format!("{:.1}", charged.cost());
    listed.push(charged);
    h.state_mut().state.results.report = Some(again);
    h.run_steps(2);
    assert_eq!(shown(&h, "worse"), 1 + (0..fit.branches.len()).filter(|&k| standing(k) == "worse").count());
    h.get_by_label("a charged start");
    h.get_by_label(&cost);
    assert!(h.query_all_by_label("9").next().is_some(), "the hint-led count");
}

/// The discrepancy workflow from the GUI on strategy 2's traces: every step is shown, then the
/// verdict with the residual before and after.
#[test]
fn diagnosis_view_runs_the_workflow_step_by_step() {
    let tmp = tempfile::tempdir().unwrap();
    let mut h = harness(workbench(Settings::default(), ScriptedDialogs::default()));
    h.state_mut().state.session.dir = Some(tmp.path().join("session"));
    open(&mut h, Tab::Diagnosis);
    h.get_by_label_contains("no recorded trace yet");
    open(&mut h, Tab::Wizard);
    h.get_by_label("Run step 2 (F5)").click();
    wait_until(&mut h, "strategy 2", Duration::from_secs(300), |w| w.state.wizard.steps[1].state == StepState::Done);
    open(&mut h, Tab::Diagnosis);
    // Not identified: the view warns that the design extrinsics' errors can look like effects.
    h.get_by_label_contains("not identified yet: the diagnosis starts from the design extrinsics.");
    h.get_by_label("Run the diagnosis").click();
    wait_until(&mut h, "the diagnosis", Duration::from_secs(600), |w| w.state.diagnosis.result.is_some());
    let result = h.state().state.diagnosis.result.clone().unwrap().expect("the diagnosis runs");
    assert!(h.state().state.diagnosis.steps.len() >= 3, "{:?}", h.state().state.diagnosis.steps);
    h.get_by_label("1. replay: baseline fit of the extrinsics");
    h.get_by_label_contains("Verdict: ");
    h.get_by_label_contains(&format!(
        "{:.2} nm before, {:.2} nm after",
        result.residual_rms_before_nm, result.residual_rms_after_nm
    ));
    // The validation with and without the effects follows; with none added, one line says so.
    wait_until(&mut h, "the validation with the effects", Duration::from_secs(600), |w| {
        w.state.diagnosis.validation.is_some()
    });
    if result.effects.is_empty() && result.partial.is_empty() {
        assert_eq!(h.state().state.diagnosis.validation, Some(EffectValidation::NoEffect));
        h.get_by_label_contains("no effect was added: there is no extended model to validate");
    } else {
        h.get_by_label("without the effect (nm)");
    }
    // What the data could not have seen at typical size.
    assert!(!result.not_detectable.is_empty(), "a strategy-2 session cannot see every effect at typical size");
    h.get_by_label(&format!(
        "not detectable at typical size on these data and motions: {}",
        result.not_detectable.join(", ")
    ));
    screenshot(&mut h, "diagnosis-workflow");
    // Saved with the session.
    let saved = tmp.path().join("saved");
    let session = save_as_and_load(&mut h, &saved);
    let record = session.diagnosis.expect("the diagnosis is in the session");
    assert!(record.verdict.contains(&format!("{:.2} nm before", result.residual_rms_before_nm)), "{}", record.verdict);
    assert_eq!(record.effects.len(), result.effects.len() + result.partial.len());
}

/// On a bench with a hidden joint-4 pivot offset (assets/benches/hidden-pivot.ron): strategy 2's
/// rotations and the extra measurements, the calibrated extrinsics set to the bench's truth (as
/// `tests/cli_diagnose.rs` does; a full joint calibration takes 2 min here and its extrinsics
/// absorb most of the pivot on the validation rotations), then the diagnosis names the pivot and
/// the worker runs the validation motions planned without and with it; the view shows the
/// figures, the rotation about X_f improves more than tenfold, and the rows are saved with the
/// session.
#[test]
fn diagnosis_view_validates_with_and_without_the_named_effect() {
    let t0 = Instant::now();
    let tmp = tempfile::tempdir().unwrap();
    let mut h = record_strategy_2_on_the_hidden_pivot_bench(tmp.path(), t0);
    let result = diagnose_and_validate(&mut h, t0);
    let first = first_effect_in_the_pivot_class(&result);
    let rows = validation_rows(&h);
    check_the_validation_table(&mut h, &rows, first);
    h.get_by_label_contains("bars: the calibrated model (left)").scroll_to_me();
    h.run_steps(6);
    screenshot(&mut h, "diagnosis-validation");
    let saved = tmp.path().join("saved");
    let record = check_the_saved_record(&mut h, &saved, &rows, &result);
    check_the_reopened_record(&mut h, &saved, &record, &rows, first);
    check_a_second_save_keeps_the_record(&mut h, &tmp.path().join("again"), &rows);
    eprintln!("total {:.1} s", t0.elapsed().as_secs_f64());
}

/// Whether some widget carries exactly `text` as its label.
fn label_shown(h: &Harness<'_, Workbench>, text: &str) -> bool {
    h.query_all_by_label(text).next().is_some()
}

/// The workbench on the hidden-pivot bench after the wizard's steps 2 and 3, with the
/// extrinsics set to the bench's truth; the session lives under `tmp`.
fn record_strategy_2_on_the_hidden_pivot_bench(tmp: &std::path::Path, t0: Instant) -> Harness<'static, Workbench> {
    let settings = Settings { preset: "hidden-pivot".into(), ..Settings::default() };
    let mut h = harness(workbench(settings, ScriptedDialogs::default()));
    h.state_mut().state.session.dir = Some(tmp.join("session"));
    open(&mut h, Tab::Wizard);
    h.get_by_label("Run step 2 (F5)").click();
    wait_until(&mut h, "strategy 2", Duration::from_secs(300), |w| w.state.wizard.steps[1].state == StepState::Done);
    h.get_by_label("Run step 3 (F5)").click();
    wait_until(&mut h, "the extra measurements", Duration::from_secs(300), |w| {
        w.state.wizard.steps[2].state == StepState::Done
    });
    h.state_mut().state.extrinsics = photorobot_core::bench::BenchPreset::resolve("hidden-pivot").unwrap().truth;
    eprintln!("strategy 2 recorded after {:.1} s", t0.elapsed().as_secs_f64());
    h
}

/// Runs the diagnosis from its view and waits for the worker's validation that follows it;
/// returns the diagnosis result (its steps and effects are logged).
fn diagnose_and_validate(
    h: &mut Harness<'_, Workbench>,
    t0: Instant,
) -> Box<photorobot_core::diagnose::DiagnosisResult> {
    open(h, Tab::Diagnosis);
    h.get_by_label("Run the diagnosis").click();
    wait_until(h, "the diagnosis", Duration::from_secs(600), |w| w.state.diagnosis.result.is_some());
    let result = h.state().state.diagnosis.result.clone().unwrap().expect("the diagnosis runs");
    // The validation comes after the verdict, from the worker.
    wait_until(h, "the validation with the effect", Duration::from_secs(600), |w| {
        w.state.diagnosis.validation.is_some()
    });
    eprintln!("diagnosed and validated after {:.1} s", t0.elapsed().as_secs_f64());
    for (title, summary) in &h.state().state.diagnosis.steps {
        eprintln!("{title}\n{summary}");
    }
    for e in result.effects.iter().chain(&result.partial) {
        eprintln!("{:?}: {} = {:.3} {}", result.verdict, e.name, e.estimate, e.unit);
    }
    result
}

/// The first effect the diagnosis added, asserted to be one of the pivot offsets that explain
/// the hidden joint-4 pivot.
fn first_effect_in_the_pivot_class(
    result: &photorobot_core::diagnose::DiagnosisResult,
) -> &photorobot_core::diagnose::NamedEffect {
    let first = result.effects.iter().chain(&result.partial).next().expect("an effect added");
    let class = [
        "pivot offset q4 along Z_w",
        "pivot offset q6 along Z_w",
        "pivot offset q5 along X_w",
        "pivot offset q6 along X_w",
    ];
    assert!(class.contains(&first.name.as_str()), "{}", first.name);
    first
}

/// The rows of the validation the worker ran (it must have run).
fn validation_rows(h: &Harness<'_, Workbench>) -> Vec<photorobot_core::diagnose::validation::EffectValidationRow> {
    let Some(EffectValidation::Ran { rows, .. }) = h.state().state.diagnosis.validation.clone() else {
        panic!("{:?}", h.state().state.diagnosis.validation)
    };
    rows
}

/// The view's validation table: four motions, each with its figures or the reason one is
/// missing; the rotation about X_f improves more than tenfold, the others are not worse.
fn check_the_validation_table(
    h: &mut Harness<'_, Workbench>,
    rows: &[photorobot_core::diagnose::validation::EffectValidationRow],
    first: &photorobot_core::diagnose::NamedEffect,
) {
    assert_eq!(rows.len(), 4, "{rows:?}");
    h.get_by_label("Validation with and without the added effects");
    h.get_by_label_contains(&format!("with the calibrated model and with {}", first.name));
    for h_ in ["without the effect (nm)", "with the effect (nm)", "improvement (×)"] {
        h.get_by_label(h_);
    }
    let mut rotations = 0;
    for r in rows {
        assert!(label_shown(h, &r.motion), "{}", r.motion);
        let (Some(without), Some(with)) = (r.without_effect_nm, r.with_effect_nm) else {
            // A motion the IGM or the bench refused: a dash in the table and why, below it.
            eprintln!(
                "{}: {:?} nm without, {:?} nm with: {:?}",
                r.motion, r.without_effect_nm, r.with_effect_nm, r.note
            );
            let note = r.note.as_deref().expect("a missing figure says why");
            assert!(label_shown(h, note), "{note}");
            assert!(!r.motion.starts_with("rotation 6°"), "{r:?}");
            continue;
        };
        eprintln!("{}: {without:.1} nm without the effect, {with:.1} nm with it", r.motion);
        assert!(label_shown(h, &format!("{without:.1}")), "{r:?}");
        assert!(label_shown(h, &format!("{with:.1}")), "{r:?}");
        assert!(label_shown(h, &format!("{:.1}×", without / with)), "{r:?}");
        // The hidden pivot of joint 4 (the goniometer turning about X_w) moves P_r along the beam
        // by about 20 µm × 3° in the rotation about X_f: the model with the effect plans it so
        // that the cavity barely moves. The other motions barely use joint 4: not worse with the
        // effect than without, beyond the tracking floor.
        if r.motion.starts_with("rotation 6° about X_f") {
            rotations += 1;
            assert!(with * 10.0 < without, "{}: {without} → {with} nm", r.motion);
        } else {
            assert!(with <= without.max(50.0), "{}: {without} → {with} nm", r.motion);
        }
    }
    assert_eq!(rotations, 1);
}

/// Saves the session to `saved` (as `photorobot diagnose` saves it) and checks the diagnosis
/// record it holds: the validation rows, the model's effects and the extrinsics.
fn check_the_saved_record(
    h: &mut Harness<'_, Workbench>,
    saved: &std::path::Path,
    rows: &[photorobot_core::diagnose::validation::EffectValidationRow],
    result: &photorobot_core::diagnose::DiagnosisResult,
) -> photorobot_core::session::DiagnosisRecord {
    let session = save_as_and_load(h, saved);
    let record = session.diagnosis.expect("the diagnosis is in the session");
    assert_eq!(record.validation, rows);
    assert_eq!(record.model_effects, h.state().state.diagnosis.effects);
    assert!(!record.model_effects.is_empty());
    assert_eq!(record.extrinsics, Some(result.extrinsics));
    record
}

/// New forgets the diagnosis; opening the saved session brings back its record (not a result
/// to draw), which the Diagnosis view shows: the verdict, the effect, the validation figures.
fn check_the_reopened_record(
    h: &mut Harness<'_, Workbench>,
    saved: &std::path::Path,
    record: &photorobot_core::session::DiagnosisRecord,
    rows: &[photorobot_core::diagnose::validation::EffectValidationRow],
    first: &photorobot_core::diagnose::NamedEffect,
) {
    h.state_mut().request(photorobot_app::gui::Pending::New);
    h.run_steps(2);
    assert!(h.state().state.diagnosis.result.is_none() && h.state().state.diagnosis.validation.is_none());
    h.get_by_label_contains("no recorded trace yet");
    h.state_mut().request(photorobot_app::gui::Pending::Open(saved.to_path_buf()));
    h.run_steps(2);
    assert!(h.state().state.diagnosis.result.is_none(), "a session's record is not a result to draw");
    open(h, Tab::Diagnosis);
    h.get_by_label("Diagnosis saved with this session");
    h.get_by_label_contains(&format!("Verdict: {}", record.verdict));
    h.get_by_label(&first.name);
    h.get_by_label(&format!("{:.4} {}", first.estimate, first.unit));
    for e in &record.model_effects {
        h.get_by_label(&format!("{e:?}"));
    }
    h.get_by_label_contains("extrinsics refitted with them: beta_et = ");
    h.get_by_label("Validation with and without the added effects (saved)");
    for r in rows {
        if let (Some(without), Some(with)) = (r.without_effect_nm, r.with_effect_nm) {
            assert!(label_shown(h, &format!("{without:.1}")), "{r:?}");
            assert!(label_shown(h, &format!("{with:.1}")), "{r:?}");
        }
    }
    h.get_by_label("Diagnosis saved with this session").scroll_to_me();
    h.run_steps(6);
    screenshot(h, "diagnosis-saved");
}

/// Saving the reopened session elsewhere (`again`) keeps its diagnosis record.
fn check_a_second_save_keeps_the_record(
    h: &mut Harness<'_, Workbench>,
    again: &std::path::Path,
    rows: &[photorobot_core::diagnose::validation::EffectValidationRow],
) {
    h.state_mut().state.dialogs =
        Box::new(ScriptedDialogs { folders: vec![Some(again.to_path_buf())], ..Default::default() });
    h.state_mut().save(true);
    wait_until(h, "the second save", Duration::from_secs(60), |w| w.state.session.saving == 0);
    let kept = photorobot_core::session::Session::load(again).expect("loads").diagnosis.expect("the record is kept");
    assert_eq!(kept.validation, rows);
}

#[test]
fn cancelling_a_step_keeps_what_was_recorded_and_imports_go_through_the_dialog() {
    let dir = tempfile::tempdir().unwrap();
    // Real time: the step is still running when Esc arrives.
    let settings = Settings { speed: 1.0, ..Settings::default() };
    let mut h = harness(workbench(settings, ScriptedDialogs::default()));
    h.state_mut().state.session.dir = Some(dir.path().join("session"));
    open(&mut h, Tab::Wizard);
    h.get_by_label("Run step 1 (F5)").click();
    wait_until(&mut h, "the first recorded samples", Duration::from_secs(60), |w| w.state.live.trace.len() > 500);
    h.get_by_label("Cancel (Esc)");
    h.key_press(egui::Key::Escape);
    wait_until(&mut h, "the cancel", Duration::from_secs(60), |w| w.state.wizard.running.is_none());
    let step = &h.state().state.wizard.steps[0];
    assert!(matches!(step.state, StepState::Stopped(_)), "{:?}", step.state);
    assert!(!step.traces.is_empty() && !step.traces[0].is_empty(), "the partial trace is kept");
    h.get_by_label_contains("stopped: ");
    assert!(step.resume.is_some(), "a step stopped by the technician can be resumed");
    h.get_by_label("Resume or redo step 1 (F5)");
    // Import: the trace recorded so far, written to a file and opened through the dialog.
    let path = dir.path().join("partial.csv");
    step.traces[0].write_csv(&path).unwrap();
    h.state_mut().state.dialogs = Box::new(ScriptedDialogs { opens: vec![vec![path.clone()]], ..Default::default() });
    open(&mut h, Tab::Traces);
    h.get_by_label("Import CSV traces…").click();
    // The status line also takes the autosave's messages, which can land in any frame: wait
    // for the import's own message rather than reading it after a fixed number of frames.
    let imported = format!("imported {}", path.display());
    wait_until(&mut h, "the import message", Duration::from_secs(10), |w| w.state.status == imported);
    assert_eq!(h.state().state.imported.len(), 1);
    // A bad file is refused with a message naming it; nothing is added.
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "t_s,q1_um\n0,1\n").unwrap();
    h.state_mut().state.dialogs = Box::new(ScriptedDialogs { opens: vec![vec![bad.clone()]], ..Default::default() });
    h.get_by_label("Import CSV traces…").click();
    // the refusal names the file
    wait_until(&mut h, "the refusal naming bad.csv", Duration::from_secs(10), |w| {
        w.state.status.starts_with("import refused: ") && w.state.status.contains("bad.csv")
    });
    assert_eq!(h.state().state.imported.len(), 1);
}

#[test]
fn settings_persist_between_runs_and_the_theme_toggles() {
    let mut h = harness(workbench(Settings::default(), ScriptedDialogs::default()));
    assert!(h.state().state.settings.dark);
    h.get_by_label("Light theme").click();
    h.run_steps(3);
    assert!(!h.state().state.settings.dark);
    h.get_by_label("Dark theme");
    let mean_brightness = |h: &mut Harness<'_, Workbench>| {
        let image = h.render().unwrap();
        image.pixels().map(|p| (p.0[0] as f64 + p.0[1] as f64 + p.0[2] as f64) / 3.0).sum::<f64>()
            / (image.width() * image.height()) as f64
    };
    let light = mean_brightness(&mut h);
    assert!(light > 180.0, "the light theme is light: mean brightness {light}");
    screenshot(&mut h, "light-theme");
    h.get_by_label("Dark theme").click();
    h.run_steps(3);
    assert!(mean_brightness(&mut h) < 80.0, "the dark theme is dark");
    h.get_by_label("Light theme").click();
    h.run_steps(3);
    // Settings… is in the File menu; its window edits the seed and the theme among others.
    h.get_by_label("File").click();
    h.run_steps(2);
    h.get_by_label("Settings…").click();
    h.run_steps(3);
    h.get_by_label("random seed");
    h.get_by_label("live window");
    screenshot(&mut h, "settings");
    h.state_mut().state.settings.seed = 42;
    let mut app = App { workbench: h.into_state() };
    let mut storage = MemoryStorage::default();
    eframe::App::save(&mut app, &mut storage);
    let back: Settings = eframe::get_value(&storage, eframe::APP_KEY).expect("settings were saved");
    assert_eq!(back, app.workbench.state.settings);
    assert!(!back.dark && back.seed == 42);
}

#[test]
fn a_save_that_fails_keeps_the_session_unsaved_and_the_window_asks_again() {
    let tmp = tempfile::tempdir().unwrap();
    let csv = tmp.path().join("trace.csv");
    std::fs::write(
        &csv,
        "t_s,q1_um,q2_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,irradiance\n\
         0,0,0,0,0,0,0,1550,0.5\n0.001,0.1,0,0,0,0,0,1550,0.6\n",
    )
    .unwrap();
    // A folder under a regular file cannot be created, even by root.
    let blocker = tmp.path().join("a-file");
    std::fs::write(&blocker, "not a folder").unwrap();
    let (unwritable, good) = (blocker.join("session"), tmp.path().join("saved"));
    let dialogs = ScriptedDialogs {
        opens: vec![vec![csv.clone()]],
        saves: vec![],
        folders: vec![Some(unwritable.clone()), Some(good.clone())],
    };
    let mut h = harness(workbench(Settings::default(), dialogs));
    open(&mut h, Tab::Traces);
    h.get_by_label("Import CSV traces…").click();
    wait_until(&mut h, "the import", Duration::from_secs(10), |w| w.state.imported.len() == 1);
    assert!(h.state().state.session.dirty);
    // Closing asks; Save picks a folder that cannot be written.
    h.state_mut().request(photorobot_app::gui::Pending::Quit);
    h.run_steps(2);
    h.get_by_label("Save").click();
    wait_until(&mut h, "the failed save", Duration::from_secs(60), |w| {
        w.state.session.saving == 0 && w.pending.is_some()
    });
    let state = &h.state().state;
    assert!(state.session.dirty, "a failed save leaves the session unsaved");
    assert!(!h.state().quit, "a failed save does not close the window");
    assert!(state.status.starts_with("NOT saved"), "{}", state.status);
    assert!(
        state.session.save_error.as_deref().is_some_and(|e| e.contains("a-file")),
        "{:?}",
        state.session.save_error
    );
    assert!(!unwritable.join("session.ron").exists());
    // The prompt is back, with the error; Save again goes to a folder that can be written.
    h.get_by_label_contains("The last save failed");
    screenshot(&mut h, "save-failed");
    h.get_by_label("Save").click();
    wait_until(&mut h, "the second save and the close", Duration::from_secs(60), |w| w.quit);
    let state = &h.state().state;
    assert!(!state.session.dirty && state.session.save_error.is_none());
    assert!(good.join("session.ron").is_file());
    assert_eq!(state.session.dir.as_deref(), Some(good.as_path()));
}

/// `photorobot ARGS…` in this process (its output discarded); panics with the error.
fn cli(args: &[&str]) {
    photorobot_app::cli::run(args.iter().copied(), &mut Vec::new()).unwrap_or_else(|e| panic!("{args:?}: {e}"));
}

/// The CSV files of `dir`, in name order.
fn csv_files(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut files: Vec<_> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
    files.retain(|f| f.extension().is_some_and(|x| x == "csv"));
    files.sort();
    files
}

/// Click "Run the diagnosis" and wait until the worker is idle again (the diagnosis, its
/// proposed plan and the validation that follows).
fn diagnose_to_the_end(h: &mut Harness<'_, Workbench>) -> photorobot_core::diagnose::DiagnosisResult {
    h.get_by_label("Run the diagnosis").click();
    wait_until(h, "the diagnosis", Duration::from_secs(600), |w| w.state.diagnosis.validation.is_some());
    *h.state().state.diagnosis.result.clone().unwrap().expect("the diagnosis runs")
}

/// For a bench the workbench does not drive: a session calibrated by `photorobot calibrate` is
/// opened, the diagnosis proposes its discriminating motions instead of running them, the plan
/// is saved, recorded on the bench (`photorobot simulate --after`), its traces added on the
/// session's clock, and the second pass proposes none of the motions already recorded.
#[test]
fn diagnosis_view_proposes_saves_and_adds_the_discriminating_motions() {
    let tmp = tempfile::tempdir().unwrap();
    let session = tmp.path().join("session");
    let s = session.to_str().unwrap();
    cli(&["photorobot", "calibrate", "--bench", "table2-ideal", "--plan", "optimised", "--seed", "3", "--out", s]);
    let mut h = harness(workbench(Settings::default(), ScriptedDialogs::default()));
    h.state_mut().request(photorobot_app::gui::Pending::Open(session.clone()));
    h.run_steps(3);
    let recorded = h.state().state.all_traces().len();
    assert!(recorded > 0 && h.state().state.results.report.is_some(), "the calibrated session is open");
    open(&mut h, Tab::Diagnosis);
    h.get_by_label("propose the discriminating motions instead of running them").click();
    h.run_steps(2);
    assert!(h.state().state.diagnosis.propose_only);
    let result = diagnose_to_the_end(&mut h);
    assert!(!result.discriminating_motions_ran);
    let proposed = h.state().state.diagnosis.proposed_plan.clone().expect("the calibration leaves motions to propose");
    let labels: Vec<String> =
        proposed.segments.iter().filter(|g| g.is_recorded()).map(|g| g.label().to_string()).collect();
    assert_eq!(labels, result.discriminating_motions, "the plan holds the designed motions");
    h.get_by_label("Proposed discriminating motions").scroll_to_me();
    h.run_steps(4);
    screenshot(&mut h, "diagnosis-proposed");
    // Saved through the plan dialog, recorded on the bench, added back.
    let saved = tmp.path().join("proposed.ron");
    h.state_mut().state.dialogs = Box::new(ScriptedDialogs { saves: vec![Some(saved.clone())], ..Default::default() });
    h.get_by_label("Save the proposed plan…").click();
    h.run_steps(2);
    assert_eq!(h.state().state.status, format!("saved the proposed plan to {}", saved.display()));
    assert_eq!(photorobot_core::plan::Plan::load(&saved).expect("the saved plan loads"), proposed);
    let later_dir = tmp.path().join("later");
    let (p, o) = (saved.to_str().unwrap(), later_dir.to_str().unwrap());
    cli(&["photorobot", "simulate", "--bench", "table2-ideal", "--plan", p, "--seed", "4", "--after", s, "--out", o]);
    let later = csv_files(&later_dir);
    assert_eq!(later.len(), labels.len());
    let session_end = h.state().state.all_traces().iter().filter_map(|t| t.t_s.last().copied()).fold(0.0, f64::max);
    h.state_mut().state.dialogs = Box::new(ScriptedDialogs { opens: vec![later.clone()], ..Default::default() });
    h.get_by_label("Add recorded traces…").click();
    h.run_steps(2);
    let status = h.state().state.status.clone();
    assert!(status.starts_with(&format!("added {} recorded traces", later.len())), "{status}");
    let traces = h.state().state.all_traces();
    assert_eq!(traces.len(), recorded + later.len());
    // The added traces continue the session's clock: each starts after the session ended.
    assert!(traces[recorded..].iter().all(|t| t.t_s[0] > session_end), "the added traces start after {session_end} s");
    // The second pass knows those motions: it proposes none of them again.
    let again = diagnose_to_the_end(&mut h);
    for m in &again.discriminating_motions {
        assert!(!labels.contains(m), "{m} was recorded and is proposed again");
    }
    assert!(again.effects.is_empty(), "a clean bench: nothing named ({:?})", again.effects);
    // Each family's residual, as the result gives it.
    let families = again.family_line().expect("the result has its families");
    assert!(again.residual_by_family.len() >= 3, "{:?}", again.residual_by_family);
    for f in &again.residual_by_family {
        assert!(families.contains(&format!("{} {:.2}σ → {:.2}σ", f.family.words(), f.before_sigma, f.after_sigma)));
    }
    h.get_by_label(&photorobot_app::views::diagnosis::drawable(&families));
    if again.settled {
        h.get_by_label(photorobot_app::views::diagnosis::SETTLED).scroll_to_me();
    } else {
        h.get_by_label_contains("Verdict: ").scroll_to_me();
    }
    h.run_steps(2);
    screenshot(&mut h, "diagnosis-added");
    // The pairs these data cannot tell apart, folded under a header that counts them; opened,
    // one line each. The designed plan's few motions leave several open.
    let pairs = again.cancelling_pairs.clone();
    assert!(!pairs.is_empty(), "the designed plan's motions leave pairs open");
    if again.settled {
        let open = again.pairs_left_open().expect("a settled result with pairs says they are left open");
        assert!(open.contains("from recordings alone"), "{open}");
        h.get_by_label(open);
    }
    let header = format!("{} pairs these data cannot tell apart (sizes that cancel would show nothing)", pairs.len());
    h.get_by_label(&header).scroll_to_me();
    h.run_steps(2);
    h.get_by_label(&header).click_accesskit();
    h.run_steps(6);
    let line = |[a, b]: &[String; 2]| photorobot_app::views::diagnosis::drawable(&format!("{a} ↔ {b}"));
    for p in &pairs {
        h.get_by_label(&line(p));
    }
    h.get_by_label(&line(&pairs[0])).scroll_to_me();
    h.run_steps(2);
    screenshot(&mut h, "diagnosis-pairs");
    // Every candidate named nowhere, folded with the size its data rule out.
    use photorobot_app::views::diagnosis::{bound_line, bounds_header};
    let bounds = again.ruled_out_above.clone();
    assert!(!bounds.is_empty(), "a clean bench leaves candidates not named");
    h.get_by_label(&bounds_header(bounds.len())).scroll_to_me();
    h.run_steps(2);
    h.get_by_label(&bounds_header(bounds.len())).click_accesskit();
    h.run_steps(6);
    for b in &bounds {
        assert!(b.below >= b.estimate.abs() + 3.0 * b.sigma - 1e-12, "{b:?}");
        h.get_by_label(&bound_line(b));
    }
    h.get_by_label(&bound_line(&bounds[0])).scroll_to_me();
    h.run_steps(2);
    screenshot(&mut h, "diagnosis-bounds");
}
