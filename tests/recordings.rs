//! Diagnosis from recordings alone, as a user runs it: the CLI called with arguments, the
//! session diagnosed without a bench, and the traces of a proposed plan added to the session
//! (`diagnose --add`) and diagnosed again.

use photorobot_app::cli::run;
use serde_json::Value;
use std::path::Path;

/// Run `photorobot` with `args`: whether it succeeded, and what it printed (then the error).
pub fn cli(args: &[&str]) -> (bool, String) {
    let mut out = Vec::new();
    let r = run(args.iter().copied(), &mut out);
    let mut text = String::from_utf8_lossy(&out).into_owned();
    if let Err(e) = &r {
        text += &format!("\nerror: {e}");
    }
    (r.is_ok(), text)
}

/// `photorobot diagnose SESSION --bench none --json`, its outcome printed in brief.
pub fn diagnose_without_bench(session: &Path) -> Value {
    diagnose_adding(session, None)
}

/// `photorobot diagnose SESSION [--add FOLDER] --bench none --json`: the traces of `added` (a
/// proposed plan recorded on the bench) joined to the session first; the outcome printed in brief.
pub fn diagnose_adding(session: &Path, added: Option<&Path>) -> Value {
    let mut args = vec!["photorobot", "diagnose", session.to_str().unwrap(), "--bench", "none", "--json"];
    if let Some(a) = added {
        args.extend(["--add", a.to_str().unwrap()]);
    }
    let (ok, text) = cli(&args);
    assert!(ok, "diagnose: {text}");
    let v: Value = serde_json::from_str(&text).unwrap();
    eprintln!(
        "  verdict {}, residual {:.2} → {:.2}σ, effects {}, need motions {}, proposed {}, settled {}",
        v["verdict"],
        v["residual_rms_before_sigma"].as_f64().unwrap_or(f64::NAN),
        v["residual_rms_after_sigma"].as_f64().unwrap_or(f64::NAN),
        v["effects"],
        v["need_motions"],
        v["proposed_plan_file"],
        v["settled"]
    );
    v
}

/// The first named effect is one of `names`, within 3σ of `value` (its magnitude when `abs`).
pub fn assert_named(v: &Value, names: &[&str], value: f64, abs: bool) {
    assert_eq!(v["verdict"], "named", "{v}");
    let first = &v["effects"][0];
    let name = first["name"].as_str().unwrap();
    assert!(names.contains(&name), "{name}: {v}");
    let (mut est, sigma) = (first["estimate"].as_f64().unwrap(), first["sigma"].as_f64().unwrap());
    if abs {
        est = est.abs();
    }
    assert!((est - value).abs() <= 3.0 * sigma, "{name} = {est} ± {sigma}, hidden {value}");
}

/// Another simulator's recordings ([`crate::independent`]) of the lab motions with `hidden`,
/// calibrated (`calibrate --bench table2-ideal --traces`; a refused fit still writes its best
/// extrinsics) and diagnosed without a bench; then, if motions were proposed, those recorded by
/// the same simulator later on the same clock, added, and the diagnosis run again.
/// (first, second)
pub fn independent_calibrate_and_diagnose(hidden: crate::independent::Hidden, seed: u64) -> (Value, Option<Value>) {
    let mut passes = independent_loop(hidden, seed, 2).into_iter();
    let first = passes.next().expect("a first pass");
    (first, passes.next())
}

/// [`independent_calibrate_and_diagnose`], the loop a technician follows: each proposed plan
/// recorded (pass k by the simulator seeded `seed + 100·(k − 1)`, a minute after the last
/// recording), added and diagnosed again, until no plan is proposed or after `max_passes`
/// diagnoses. Every pass's result, in order.
pub fn independent_loop(hidden: crate::independent::Hidden, seed: u64, max_passes: usize) -> Vec<Value> {
    let optics = crate::independent::Recorder::new(seed).optics;
    independent_loop_with(&optics, hidden, seed, max_passes)
}

/// [`independent_loop`] with the simulator's `optics` (its multi-beam model by default; the
/// two-beam model is farther from ours).
pub fn independent_loop_with(
    optics: &crate::independent::OpticsModel,
    hidden: crate::independent::Hidden,
    seed: u64,
    max_passes: usize,
) -> Vec<Value> {
    let dir = tempfile::tempdir().unwrap();
    independent_loop_in(dir.path(), optics, hidden, seed, max_passes)
}

/// The lab motions recorded by `recorder` into `dir/recorded` and calibrated from them alone
/// (`calibrate --bench table2-ideal --traces … --out dir/session --json`; a refused fit still
/// writes its best extrinsics): the recordings' end on their clock (s) and what calibrate
/// printed, then its error if it refused.
pub fn calibrate_lab_records(recorder: &crate::independent::Recorder, dir: &Path) -> (f64, String) {
    let (traces, session) = (dir.join("recorded"), dir.join("session"));
    let (_, end_s) = recorder.write_folder(&crate::independent::lab_records(), &traces).unwrap();
    let (t, s) = (traces.to_str().unwrap(), session.to_str().unwrap());
    let (_, text) = cli(&["photorobot", "calibrate", "--bench", "table2-ideal", "--traces", t, "--out", s, "--json"]);
    (end_s, text)
}

/// [`independent_loop_with`] in the folder `dir`, which keeps the recordings (`recorded/`,
/// `proposed-K/`) and the session (`session/`) for a later look.
pub fn independent_loop_in(
    dir: &Path,
    optics: &crate::independent::OpticsModel,
    hidden: crate::independent::Hidden,
    seed: u64,
    max_passes: usize,
) -> Vec<Value> {
    use crate::independent::{records_of, Recorder};
    let mut recorder = Recorder::new(seed);
    recorder.hidden = hidden;
    recorder.optics = optics.clone();
    let (mut end_s, text) = calibrate_lab_records(&recorder, dir);
    let session = dir.join("session");
    assert!(session.join("extrinsics.ron").exists(), "calibrate wrote no extrinsics: {text}");
    let mut passes = vec![diagnose_without_bench(&session)];
    for pass in 1..max_passes as u64 {
        let Some(file) = passes.last().and_then(|v| v["proposed_plan_file"].as_str().map(String::from)) else {
            break;
        };
        let plan = photorobot_core::plan::Plan::load(Path::new(&file)).unwrap();
        let mut later = Recorder::new(seed + 100 * pass);
        later.hidden = hidden;
        later.optics = optics.clone();
        later.start_clock_s = end_s + 60.0;
        let added = dir.join(format!("proposed-{pass}"));
        end_s = later.write_folder(&records_of(&plan), &added).unwrap().1;
        passes.push(diagnose_adding(&session, Some(&added)));
    }
    passes
}
