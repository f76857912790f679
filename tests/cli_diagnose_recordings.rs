//! Diagnosis from recordings alone, through the path users run: a random plan (motions nobody
//! designed for the diagnosis) recorded with `photorobot simulate` on a virtual bench that hides
//! one effect, `photorobot calibrate --traces`, then `photorobot diagnose <session> --bench none
//! --json`. Without a bench the diagnosis names what the traces show, and writes the motions that
//! would tell the rest apart as a plan file; those are recorded on the same bench (`simulate
//! --plan` that file `--after` the session), added to the session (`diagnose --add`), and the
//! diagnosis runs again.

use photorobot_app::cli::diagnose::PROPOSED_PLAN_FILE;
use photorobot_core::bench::BenchPreset;
use photorobot_core::files::save_ron;
use photorobot_core::model::effects::Effect;
use photorobot_core::plan::random::{random_plan, Family};
use photorobot_core::plan::{Plan, Segment};
use photorobot_core::session::Session;
use photorobot_e2e::recordings::{assert_named, cli, diagnose_adding, diagnose_without_bench as diagnose};
use serde_json::Value;
use std::path::Path;

fn simulate(bench: &str, plan: &Path, seed: u64, out: &Path, after: Option<&Path>) {
    let seed = seed.to_string();
    let (p, o) = (plan.to_str().unwrap(), out.to_str().unwrap());
    let mut args = vec!["photorobot", "simulate", "--bench", bench, "--plan", p, "--seed", &seed, "--out", o];
    if let Some(a) = after {
        args.extend(["--after", a.to_str().unwrap()]);
    }
    let (ok, text) = cli(&args);
    assert!(ok, "simulate: {text}");
}

/// What the recordings alone gave, then what they gave with the proposed motions added (when
/// the first diagnosis proposed any).
struct Outcome {
    first: Value,
    second: Option<Value>,
}

/// table2-ideal hiding `effects`; random plan `plan_seed` of `family` recorded on it (seed 5),
/// calibrated from its traces, diagnosed without a bench; the proposal recorded and added.
fn from_recordings(effects: Vec<Effect>, family: Family, plan_seed: u64) -> Outcome {
    let mut preset = BenchPreset::resolve("table2-ideal").unwrap();
    preset.name = "recordings bench".into();
    preset.effects = effects;
    let dir = tempfile::tempdir().unwrap();
    let bench_file = dir.path().join("bench.ron");
    save_ron(&bench_file, &preset).unwrap();
    let bench = bench_file.to_str().unwrap();
    let plan_file = dir.path().join("plan.ron");
    random_plan(family, plan_seed).save(&plan_file).unwrap();
    let traces = dir.path().join("recorded");
    simulate(bench, &plan_file, 5, &traces, None);
    let session = dir.path().join("session");
    let (t, s) = (traces.to_str().unwrap(), session.to_str().unwrap());
    // The calibration may refuse the fit (the hidden effect is not in its model): the session
    // keeps its traces and best extrinsics either way, and the diagnosis starts from them.
    let (_, text) = cli(&["photorobot", "calibrate", "--bench", "table2-ideal", "--traces", t, "--out", s, "--json"]);
    assert!(session.join("extrinsics.ron").exists(), "calibrate wrote no extrinsics: {text}");
    let first = diagnose(&session);
    let proposal = session.join(PROPOSED_PLAN_FILE);
    let second = first["proposed_plan_file"].is_string().then(|| {
        assert!(proposal.exists(), "{}", first["proposed_plan_file"]);
        assert_eq!(first["settled"], false, "motions proposed: not settled");
        let plan = Plan::load(&proposal).unwrap();
        assert_analysable(&plan, &preset);
        let before = Session::load(&session).unwrap();
        let added = dir.path().join("proposed");
        simulate(bench, &proposal, 6, &added, Some(&session));
        let second = diagnose_adding(&session, Some(&added));
        assert_added(&session, &before, &added, &second);
        assert_second_pass(&session, &proposal, &plan, &second);
        second
    });
    Outcome { first, second }
}

/// Every recorded motion of a proposed plan moves the gap of the true bench by at least 1.5
/// fringes (its fringes can be analysed) without turning back inside it.
fn assert_analysable(plan: &Plan, preset: &BenchPreset) {
    use photorobot_core::diagnose::fit::Predictor;
    use photorobot_core::diagnose::motions::{gap_turns, too_short, turn_templates, DesignedMotion, MotionKind};
    use photorobot_core::model::phase::PhaseModel;
    let truth = PhaseModel::of_preset(preset, preset.truth).unwrap();
    let mut at = [0.0; 6];
    for seg in &plan.segments {
        let Segment::Move { to, record, label, through: false } = seg else { continue };
        let next = [to.q1_um, to.q2_um, to.q3_um, to.q4_deg, to.q5_deg, to.q6_deg];
        let next: [f64; 6] = std::array::from_fn(|j| next[j].unwrap_or(at[j]));
        if *record && !label.ends_with("(arrive)") {
            let m = DesignedMotion {
                label: label.clone(),
                kind: MotionKind::Move { from_display: at, to_display: next },
                free_start: false,
            };
            let t = turn_templates(&m);
            let dl = Predictor::new(&truth, &t).unwrap().predict(&preset.truth, &preset.effects, &[], &t).unwrap();
            assert!(!too_short(&dl) && !gap_turns(&dl), "{label}: the gap moves {:.0} nm at its end", dl[dl.len() - 1]);
        }
        at = next;
    }
}

/// The traces of `added` joined the session: referenced by session.ron after the ones it had, their
/// files there, on the session's clock (`simulate --after` started them after its end: no shift).
fn assert_added(session: &Path, before: &Session, added: &Path, v: &Value) {
    let after = Session::load(session).unwrap();
    let count = std::fs::read_dir(added).unwrap().count();
    assert_eq!(after.traces.len(), before.traces.len() + count, "{:?}", v["added_traces"]);
    assert_eq!(&after.traces[..before.traces.len()], &before.traces[..], "the earlier references kept");
    for r in &after.traces {
        assert!(session.join(&r.file).is_file(), "{} referenced and on disk", r.file);
    }
    assert_eq!(v["added_traces"][0]["clock_shift_s"], 0.0, "{}", v["added_traces"]);
    let traces = after.load_traces(session).unwrap();
    let end = |ts: &[photorobot_core::trace::Trace]| ts.iter().map(|t| t.t_s[t.len() - 1]).fold(0.0, f64::max);
    let (old, new) = traces.split_at(before.traces.len());
    assert!(new.iter().all(|t| t.t_s[0] > end(old)), "the added traces come after the session's on its clock");
}

/// A second pass proposes no motion the session holds already: either it is settled (no new
/// plan file) or its plan goes to a new file and the first one stays as it was.
fn assert_second_pass(session: &Path, first_file: &Path, first: &Plan, v: &Value) {
    assert_eq!(&Plan::load(first_file).unwrap(), first, "the first proposal is kept");
    match v["proposed_plan_file"].as_str() {
        None => assert_eq!(v["settled"], true, "no motion proposed: settled ({})", v["need_motions"]),
        Some(f) => {
            assert_ne!(Path::new(f), first_file, "a new plan file");
            let recorded: Vec<String> =
                Session::load(session).unwrap().traces.iter().map(|t| t.label.clone()).collect();
            for seg in Plan::load(Path::new(f)).unwrap().segments.iter().filter(|s| s.is_recorded()) {
                assert!(!recorded.contains(&seg.label().to_string()), "{} proposed again", seg.label());
            }
        }
    }
}

/// The named result: from the recordings alone, or once the proposed motions were added.
fn finally(o: &Outcome) -> &Value {
    o.second.as_ref().unwrap_or(&o.first)
}

#[test]
fn recordings_of_a_clean_bench_name_nothing() {
    let o = from_recordings(vec![], Family::PaperOneSweep, 3);
    assert_eq!(o.first["verdict"], "none", "{}", o.first);
    assert_eq!(o.first["effects"].as_array().map(Vec::len), Some(0));
    if let Some(v) = &o.second {
        assert_eq!(v["verdict"], "none", "with the proposed motions: {v}");
    }
}

#[test]
fn recordings_with_a_hidden_joint_zero_offset_name_it() {
    let o =
        from_recordings(vec![Effect::JointZeroOffset { joint: "q4".into(), offset: 0.05 }], Family::PaperOneSweep, 4);
    assert_named(finally(&o), &["joint zero offset q4"], 0.05, false);
}

#[test]
fn recordings_with_a_hidden_pivot_offset_name_it() {
    let o = from_recordings(
        vec![Effect::PivotOffset { joint: "q4".into(), offset_world_um: [0.0, 0.0, 20.0] }],
        Family::RotationsOnly,
        5,
    );
    let class = [
        "pivot offset q4 along Z_w",
        "pivot offset q6 along Z_w",
        "pivot offset q5 along X_w",
        "pivot offset q6 along X_w",
    ];
    // The rotations alone show it (measured: q4 along Z_w, 20.4 ± 3.4 µm).
    assert_named(&o.first, &class, 20.0, true);
    // With the proposed motions the pivot's σ shrinks sevenfold, and its equivalents, nearly
    // degenerate on every motion, share it: measured q4 along Z_w 17.9 ± 0.5 µm and q5 along
    // X_w 1.6 ± 0.4 µm. The first stays the hidden one, within 15 % of its size.
    let v = o.second.as_ref().expect("motions proposed for the candidates the data absorb");
    assert_eq!(v["verdict"], "named", "{v}");
    let first = &v["effects"][0];
    assert!(class.contains(&first["name"].as_str().unwrap()), "{v}");
    let est = first["estimate"].as_f64().unwrap().abs();
    assert!((est - 20.0).abs() <= 3.0, "{} = {est} µm", first["name"]);
}

#[test]
fn recordings_with_a_hidden_stage_axis_tilt_name_it() {
    let o =
        from_recordings(vec![Effect::AxisTilt { joint: "q3".into(), tilt_mrad: [0.0, 1.0] }], Family::OtherOffsets, 6);
    assert_named(finally(&o), &["axis tilt q3 toward link y"], 1.0, false);
}
