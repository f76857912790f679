//! GUI tests of the session folder's integrity (egui_kittest, headless): every recorded segment
//! autosaved while the step runs, a step redone after a save leaving the saved session loadable,
//! a folder open in another photorobot refused with the reason, the untitled session a crash
//! left offered for recovery at start, and a step a crash interrupted resumed from the autosave
//! (on a bench that runs the plan it ran).

mod common;

use common::*;
use egui_kittest::kittest::Queryable;
use photorobot_app::dialogs::ScriptedDialogs;
use photorobot_app::gui::{Pending, Tab, Workbench};
use photorobot_app::settings::Settings;
use photorobot_app::state::StepState;
use photorobot_core::session::{BenchInfo, FolderLock, Session, SessionWriter};
use photorobot_core::trace::{Trace, TraceMeta};
use std::time::Duration;

fn workbench(settings: Settings, dialogs: ScriptedDialogs) -> Workbench {
    Workbench::new(settings, Box::new(dialogs), Box::new(|| {})).expect("the embedded virtual bench starts")
}

fn trace(label: &str, phase: f64) -> Trace {
    let mut t = Trace::new(TraceMeta { label: label.into(), ..TraceMeta::default() });
    for i in 0..50 {
        let x = f64::from(i);
        t.push_sample(x * 1e-3, [x * 0.1, 0.0, -3.0, 0.0, 0.0, 0.0], 1560.0, 0.5 + 0.1 * (x * 0.3 + phase).sin());
    }
    t
}

fn labels(session: &Session, dir: &std::path::Path) -> Vec<String> {
    session.load_traces(dir).unwrap().into_iter().map(|t| t.meta.label).collect()
}

#[test]
fn every_recorded_segment_is_autosaved_while_the_step_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("session");
    let settings = Settings { speed: 20.0, ..Settings::default() };
    let mut h = harness(workbench(settings, ScriptedDialogs::default()));
    h.state_mut().state.session.dir = Some(dir.clone());
    open(&mut h, Tab::Wizard);
    h.get_by_label("Run step 1 (F5)").click();
    wait_until(&mut h, "a segment autosaved while the step runs", Duration::from_secs(120), |w| {
        w.state.wizard.running.is_some() && photorobot_app::session_io::recoverable(&dir).is_some_and(|n| n >= 1)
    });
    // Stopped: what was recorded stays, in the window and in the autosave.
    h.key_press(egui::Key::Escape);
    wait_until(&mut h, "the stop and its autosave", Duration::from_secs(60), |w| {
        w.state.wizard.running.is_none() && w.state.session.saving == 0
    });
    let step = &h.state().state.wizard.steps[0];
    assert!(matches!(step.state, StepState::Stopped(_)), "{:?}", step.state);
    // A stop mid-segment leaves one partial trace after the whole ones; a stop between two
    // segments leaves none.
    let whole = step.resume.as_ref().expect("a stopped step resumes").whole_traces;
    assert!(whole >= 1 && (whole..=whole + 1).contains(&step.traces.len()), "{whole} of {}", step.traces.len());
    let recovered = Session::recover(&dir).unwrap();
    assert_eq!(recovered.load_traces(&dir).unwrap().len(), whole, "every whole trace, no partial one");
    assert_eq!(recovered.traces.len(), step.traces.len(), "the partial one kept beside them, marked incomplete");
}

#[test]
fn a_step_redone_after_a_save_leaves_the_saved_session_loadable() {
    let tmp = tempfile::tempdir().unwrap();
    let saved = tmp.path().join("saved");
    let mut h = harness(workbench(Settings::default(), ScriptedDialogs::default()));
    let set_step = |h: &mut egui_kittest::Harness<'_, Workbench>, traces: Vec<Trace>| {
        let state = &mut h.state_mut().state;
        state.wizard.steps[1].traces = traces;
        state.wizard.steps[1].state = StepState::Done;
        state.session.mark_dirty();
    };
    set_step(&mut h, vec![trace("first run A", 0.0), trace("first run B", 1.0)]);
    save_as_and_load(&mut h, &saved);
    // Redone: new traces, autosaved into the same folder.
    set_step(&mut h, vec![trace("redo A", 2.0), trace("redo B", 3.0)]);
    h.state_mut().state.save_in_background(saved.clone(), true);
    wait_until(&mut h, "the autosave", Duration::from_secs(60), |w| w.state.session.saving == 0);
    assert!(h.state().state.status.starts_with("autosaved"), "{}", h.state().state.status);
    let on_disk = Session::load(&saved).unwrap();
    assert_eq!(labels(&on_disk, &saved), ["first run A", "first run B"], "session.ron loads, every CRC good");
    assert_eq!(labels(&Session::recover(&saved).unwrap(), &saved), ["redo A", "redo B"]);
    // Saved again: the redo is the session, and the first run's files are gone.
    h.state_mut().save(false);
    wait_until(&mut h, "the save", Duration::from_secs(60), |w| w.state.session.saving == 0);
    assert_eq!(labels(&Session::load(&saved).unwrap(), &saved), ["redo A", "redo B"]);
    assert_eq!(std::fs::read_dir(saved.join("traces")).unwrap().count(), 2);
}

#[test]
fn a_folder_open_in_another_photorobot_is_refused_with_the_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("busy");
    let mut h = harness(workbench(Settings::default(), ScriptedDialogs::default()));
    h.state_mut().state.wizard.steps[1].traces = vec![trace("a", 0.0)];
    h.state_mut().state.wizard.steps[1].state = StepState::Done;
    save_as_and_load(&mut h, &dir);
    h.state_mut().request(Pending::New);
    h.run_steps(2);
    // Another program holds it now.
    let _held = FolderLock::acquire(&dir).unwrap();
    h.state_mut().request(Pending::Open(dir.clone()));
    h.run_steps(3);
    let expected = format!("{}: the session folder is open in another photorobot (process", dir.display());
    // In the window that says so, and in the status bar.
    assert_eq!(h.query_all_by_label_contains(&expected).count(), 2);
    screenshot(&mut h, "session-folder-locked");
    assert!(h.state().state.wizard.steps[1].traces.is_empty(), "nothing was opened");
    h.get_by_label("OK").click();
    h.run_steps(2);
    assert_eq!(h.query_all_by_label_contains(&expected).count(), 1, "the window is closed");
    // Saving into it is refused too, and the session saved there is left as it was.
    h.state_mut().state.wizard.steps[1].traces = vec![trace("b", 1.0)];
    h.state_mut().state.save_in_background(dir.clone(), false);
    wait_until(&mut h, "the refused save", Duration::from_secs(60), |w| w.state.session.saving == 0);
    assert!(h.state().state.status.contains(&expected), "{}", h.state().state.status);
    assert_eq!(labels(&Session::load(&dir).unwrap(), &dir), ["a"]);
}

#[test]
fn at_start_the_untitled_session_a_crash_left_is_offered_for_recovery() {
    let tmp = tempfile::tempdir().unwrap();
    let base = tmp.path();
    let mut h = harness(workbench(Settings::default(), ScriptedDialogs::default()));
    let plans: Vec<_> = h.state().state.wizard.steps.iter().map(|s| s.plan.clone()).collect();
    let robot = h.state().state.chain.description().clone();
    let write = |name: &str, traces: &[Trace], save: bool| {
        let info = BenchInfo { name: "virtual bench".into(), preset: None, description: None, seed: None };
        let mut session = Session::new(info, robot.clone());
        session.plans = plans.clone();
        let mut w = SessionWriter::new(&base.join(name), session);
        w.set_traces(traces.iter().enumerate().map(|(k, t)| (t, Some((1, k)), true))).unwrap();
        if save { w.save() } else { w.autosave() }.unwrap();
        std::thread::sleep(Duration::from_millis(20)); // distinct modification times
    };
    write("untitled-100-1", &[trace("older", 0.0)], false);
    write("untitled-200-1", &[trace("crashed A", 0.0), trace("crashed B", 1.0)], false);
    write("untitled-300-1", &[trace("saved", 0.0)], true);
    write("untitled-400-1", &[trace("open elsewhere", 0.0)], false);
    let _elsewhere = FolderLock::acquire(&base.join("untitled-400-1")).unwrap();
    h.state_mut().state.session.untitled_base = base.to_path_buf();
    h.state_mut().offer_untitled_recovery();
    h.run_steps(3);
    h.get_by_label_contains("untitled-200-1 holds an autosave with 2 traces");
    assert!(h.query_by_label("Open the saved session").is_none(), "an untitled session has none");
    screenshot(&mut h, "recover-untitled-session");
    h.get_by_label("Recover the autosave").click();
    h.run_steps(3);
    let state = &h.state().state;
    let recovered: Vec<&str> = state.wizard.steps[1].traces.iter().map(|t| t.meta.label.as_str()).collect();
    assert_eq!(recovered, ["crashed A", "crashed B"]);
    assert!(state.session.dirty, "a recovered session still needs a save");
    assert_eq!(state.session.dir.as_deref(), Some(base.join("untitled-200-1").as_path()));
}

/// A crash while a step runs: the autosave keeps where the step stood, and the recovered session
/// resumes the step from there: its whole traces kept, the rest measured, one trace per recorded
/// segment of its plan in the end, in order.
#[test]
fn a_step_a_crash_interrupted_resumes_from_the_autosave() {
    let tmp = tempfile::tempdir().unwrap();
    let settings = || Settings { speed: 20.0, ..Settings::default() };
    let mut h = harness(workbench(settings(), ScriptedDialogs::default()));
    h.state_mut().state.session.untitled_base = tmp.path().to_path_buf();
    open(&mut h, Tab::Wizard);
    h.get_by_label("Run step 1 (F5)").click();
    wait_until(&mut h, "two segments autosaved while the step runs", Duration::from_secs(120), |w| {
        let dir = w.state.session.dir.as_deref();
        w.state.wizard.running.is_some()
            && dir.and_then(photorobot_app::session_io::recoverable).is_some_and(|n| n >= 2)
    });
    // The crash: the workbench goes without a save; what is on disk is the last autosave.
    drop(h);
    let mut h = harness(workbench(settings(), ScriptedDialogs::default()));
    recover_untitled(&mut h, tmp.path());
    let step = &h.state().state.wizard.steps[0];
    assert!(matches!(&step.state, StepState::Stopped(e) if e.contains("recovered")), "{:?}", step.state);
    let resume = step.resume.expect("the autosave says where the step stood");
    assert!(resume.whole_traces >= 2 && resume.whole_traces == step.traces.len(), "{resume:?}");
    let whole: Vec<Trace> = step.traces.clone();
    open(&mut h, Tab::Wizard);
    h.get_by_label("Resume or redo step 1 (F5)").click();
    // The question opens the frame after the click and shows the frame after its sizing pass.
    h.run_steps(3);
    h.get_by_label_contains(&format!("Resume keeps its {} whole trace", resume.whole_traces));
    screenshot(&mut h, "resume-recovered-step");
    h.state_mut().state.settings.speed = 0.0;
    h.get_by_label("Resume").click();
    resumed_step_1_ends_whole(&mut h, &whole);
}

/// A step's resume point counts the segments of the plan its bench ran: a recovered session
/// offers Resume on a bench that runs the same plan, and only Redo on one that runs another (here
/// a bench without a tunable laser, whose steps leave their sweeps out).
#[test]
fn a_recovered_step_resumes_only_where_its_plan_runs_the_same() {
    let tmp = tempfile::tempdir().unwrap();
    let fixed = fixed_laser_preset(tmp.path());
    for (preset, resumable) in [("table2-ideal".to_string(), true), (fixed, false)] {
        let base = tempfile::tempdir().unwrap();
        let settings = Settings { preset, ..Settings::default() };
        let mut h = harness(workbench(settings, ScriptedDialogs::default()));
        // A session a tunable bench was measuring: step 1's first two recorded segments done.
        let plans: Vec<_> = h.state().state.wizard.steps.iter().map(|s| s.plan.clone()).collect();
        let recorded: Vec<usize> =
            plans[0].segments.iter().enumerate().filter(|(_, g)| g.is_recorded()).map(|(i, _)| i).take(2).collect();
        let info = BenchInfo { name: "virtual bench".into(), preset: None, description: None, seed: None };
        let mut session = Session::new(info, h.state().state.chain.description().clone());
        session.plans = plans;
        session.progress = Some(photorobot_core::session::Progress {
            plan: 0,
            next_segment: recorded[1] + 1,
            plan_start_display: [0.0; 6],
        });
        let dir = base.path().join("untitled-100-1");
        let mut w = SessionWriter::new(&dir, session);
        let traces = [trace("first", 0.0), trace("second", 1.0)];
        w.set_traces(traces.iter().zip(&recorded).map(|(t, &k)| (t, Some((0, k)), true))).unwrap();
        w.autosave().unwrap();
        recover_untitled(&mut h, base.path());
        let step = &h.state().state.wizard.steps[0];
        assert_eq!(step.traces.len(), 2);
        assert!(matches!(&step.state, StepState::Stopped(e) if e.contains("recovered")), "{:?}", step.state);
        assert_eq!(step.resume.is_some(), resumable, "tunable laser: {}", h.state().state.worker.tunable_laser);
        if let Some(r) = step.resume {
            assert_eq!((r.whole_traces, r.progress.next_segment), (2, recorded[1] + 1));
        }
    }
}
