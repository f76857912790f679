//! End to end, through the path users run: a short calibration-like session measured on the
//! virtual bench with a hidden pivot offset (assets/benches/hidden-pivot.ron) or another hidden
//! effect by `photorobot calibrate --bench B --plan P --seed 5 --out D`, then `photorobot diagnose D
//! --json`: the workflow starts from the calibration's extrinsics (a refused fit's best ones when
//! the hidden effect keeps the model from fitting), runs its discriminating motions on that bench
//! and names the hidden effect from the traces.

use photorobot_core::bench::BenchPreset;
use photorobot_core::files::save_ron;
use photorobot_e2e::session_plan;

/// `photorobot calibrate --bench BENCH --plan <session_plan> --seed 5 --out dir/session --json`
/// (the session is written whether or not the model fits), then `photorobot diagnose dir/session
/// [extra] --json`; writes the JSON to the file `$dump_var` names, if set, and prints the verdict
/// and the effects.
fn record_and_diagnose(bench: &str, dir: &std::path::Path, extra: &[&str], dump_var: &str) -> serde_json::Value {
    let t0 = std::time::Instant::now();
    let plan = dir.join("session-plan.ron");
    session_plan().save(&plan).unwrap();
    let session = dir.join("session");
    let (p, s) = (plan.to_str().unwrap(), session.to_str().unwrap());
    let mut out = Vec::new();
    let calibrated = photorobot_app::cli::run(
        ["photorobot", "calibrate", "--bench", bench, "--plan", p, "--seed", "5", "--out", s, "--json"],
        &mut out,
    );
    eprintln!("calibration: {}", calibrated.as_ref().map_or_else(|e| e.to_string(), |_| "fits".into()));
    assert!(session.join("extrinsics.ron").exists(), "calibrate wrote no session: {calibrated:?}");
    let mut out = Vec::new();
    let mut args = vec!["photorobot", "diagnose", s];
    args.extend_from_slice(extra);
    args.push("--json");
    photorobot_app::cli::run(args, &mut out).unwrap();
    let v: serde_json::Value = serde_json::from_slice(&out).unwrap();
    if let Ok(p) = std::env::var(dump_var) {
        std::fs::write(p, &out).unwrap();
    }
    eprintln!(
        "verdict {}, rms {} → {} nm ({} → {} σ), {:.1} s",
        v["verdict"],
        v["residual_rms_before_nm"],
        v["residual_rms_after_nm"],
        v["residual_rms_before_sigma"],
        v["residual_rms_after_sigma"],
        t0.elapsed().as_secs_f64()
    );
    for e in v["effects"].as_array().unwrap() {
        eprintln!("  {} = {} ± {} {}", e["name"], e["estimate"], e["sigma"], e["unit"]);
    }
    v
}

/// table2-ideal with `effects` hidden, saved as a bench file that the diagnosis runs its
/// discriminating motions on; the session recorded on it and diagnosed.
fn diagnose_hidden(
    name: &str,
    effects: Vec<photorobot_core::model::effects::Effect>,
    dump_var: &str,
) -> serde_json::Value {
    let mut preset = BenchPreset::resolve("table2-ideal").unwrap();
    preset.name = name.into();
    preset.effects = effects;
    let dir = tempfile::tempdir().unwrap();
    let bench_file = dir.path().join("bench.ron");
    save_ron(&bench_file, &preset).unwrap();
    let bench = bench_file.to_str().unwrap();
    record_and_diagnose(bench, dir.path(), &["--bench", bench], dump_var)
}

#[test]
fn diagnose_names_the_hidden_pivot_from_virtual_bench_traces() {
    let dir = tempfile::tempdir().unwrap();
    let v = record_and_diagnose("hidden-pivot", dir.path(), &[], "DIAGNOSE_DUMP");
    assert_eq!(v["discriminating_motions_ran"], true);
    // The first effect named: the joint-4 pivot along Z_w or one of its equivalents (a pivot of
    // joint 6 along Z_w or X_w, or of joint 5 along X_w, with the beam shifted), of its size.
    // (The workflow may add one of them and remove it again when another explains it better:
    // q6 along X_w added first, −17.8 µm, then q6 along Z_w, after which q6 along X_w refits
    // to −1.2 ± 1.2 µm and is removed.)
    let first = &v["effects"][0];
    let name = first["name"].as_str().unwrap();
    let class = [
        "pivot offset q4 along Z_w",
        "pivot offset q6 along Z_w",
        "pivot offset q5 along X_w",
        "pivot offset q6 along X_w",
    ];
    assert!(class.contains(&name), "{name}");
    let est = first["estimate"].as_f64().unwrap();
    assert!((est.abs() - 20.0).abs() < 5.0, "{name} = {est} µm");
    // And nothing else: without the re-analysis tracked with the model's fringe shape, a
    // spurious joint scale error q1 of ~500 ppm followed the pivot here: the data-estimated
    // fringe shape left the q4 rotation at q1 = 150 µm 7-9.5 nm off.
    let names: Vec<&str> = v["effects"].as_array().unwrap().iter().map(|e| e["name"].as_str().unwrap()).collect();
    assert_eq!(names, [name], "only the pivot");
    // The residual falls by more than a factor of 5 (the verdict itself is not asserted: the
    // absolute gaps of the virtual bench's sweeps keep a few-σ residual that the model lacks).
    let (before, after) = (v["residual_rms_before_nm"].as_f64().unwrap(), v["residual_rms_after_nm"].as_f64().unwrap());
    assert!(after * 5.0 < before, "{before} → {after} nm");
    // The extended model in use: the validation motions planned through the IGM with the effect
    // leave the cavity nearly unchanged where the model without it does not (the hidden pivot
    // moves P_r along the beam by about 20 µm × 3° in the 6° rotations).
    let rows = v["validation"].as_array().expect("validation rows");
    assert_eq!(rows.len(), 4, "{rows:?}");
    for r in rows {
        let (without, with) = (r["without_effect_nm"].as_f64().unwrap(), r["with_effect_nm"].as_f64().unwrap());
        eprintln!("{}: {without:.1} nm without the effect, {with:.1} nm with it", r["motion"]);
        // A rotation in which joint 4 turns moves P_r with the hidden pivot; with the fiber
        // angles fixed by the fringe amplitudes of the rotations, the rotation about Z_f (joint 4
        // barely turns) already keeps the cavity within 15 nm without the effect.
        if r["motion"].as_str().unwrap().starts_with("rotation 6°") && without > 100.0 {
            // Which of the equivalent pivots is named, and the figures, depend on the
            // discriminating motions the workflow designs: with the q4 pivot itself named, 3036 →
            // 19.9 nm about X_f and 3694 → 26.2 nm about Z_f; with the q6 pivot along Z_w, 2830 →
            // 18.1 and 3642 → 32.2 nm (seed 5). About Z_f, where joint 4 barely turns, the
            // figure can stay under 100 nm without the effect, and is then not asserted.
            // "Without" is the final extrinsics without the effects and moves with what was
            // named; more than 20× and a few tens of nm left.
            assert!(with * 20.0 < without && with < 40.0, "{}: {without} → {with} nm", r["motion"]);
        } else {
            assert!(with <= without.max(50.0), "{}: {without} → {with} nm", r["motion"]);
        }
    }
}

/// A hidden reversal error (1 µm of play on the X stage, its typical size) from
/// traces: the recorded motions each go one way, and their tracking takes the start phase from
/// the motion, so the calibration data cannot see the play; the workflow runs its reversal
/// motions, tracked with the start phase from the samples, and names it.
#[test]
fn diagnose_names_a_hidden_reversal_error_from_virtual_bench_traces() {
    use photorobot_core::model::effects::Effect;
    let v = diagnose_hidden(
        "hidden-reversal",
        vec![Effect::ReversalError { joint: "q3".into(), step: 1.0 }],
        "DIAGNOSE_DUMP_REVERSAL",
    );
    assert_eq!(v["discriminating_motions_ran"], true);
    let first = &v["effects"][0];
    assert_eq!(first["name"], "reversal error q3", "{v}");
    // Nothing else: the absolute gaps keep their first extraction when the traces are
    // analysed again. Re-extracted with fitted extrinsics whose fiber angles are off by degrees,
    // they move by 0.2 µm, and a spurious q2 scale of −4393 ± 282 ppm takes that up.
    assert_eq!(v["effects"].as_array().unwrap().len(), 1, "{v}");
    // Measured (seed 5): 1.0047 ± 0.0113 µm; residual 3.43σ → 0.13σ. The fringe amplitudes of
    // the rotations hold the fit's fiber angles: left free, they wander by degrees and the
    // estimate falls 3.5σ low.
    // The README states these figures: the estimate within its σ of them, σ and the residual
    // after within 2×, the residual before within a tenth.
    let (est, sigma) = (first["estimate"].as_f64().unwrap(), first["sigma"].as_f64().unwrap());
    assert!((est - 1.0).abs() < 3.0 * sigma && (est - 1.0).abs() < 0.1, "{est} ± {sigma} µm");
    assert!((est - 1.0047).abs() <= 0.0113 && (0.5..=2.0).contains(&(sigma / 0.0113)), "{est} ± {sigma} µm");
    let after = v["residual_rms_after_sigma"].as_f64().unwrap();
    let before = v["residual_rms_before_sigma"].as_f64().unwrap();
    assert!(after <= 0.26, "residual {after}σ after, the README states 0.13σ");
    assert!((before / 3.43 - 1.0).abs() <= 0.1, "residual {before}σ before, the README states 3.43σ");
}

/// Thermal drift at its typical rate (0.5 nm/s) hidden. The session's motions see it only
/// as a few nm per motion; the pool's dwell (arrive at a pose, wait 30 s, leave) sees 15 nm
/// across the pause, from the fringe phases at the end of the arrival and the start of the
/// departure. A still trace could not be tracked (its motion hint never changes), so the
/// drift was misnamed (a q4 zero offset of −0.0045°) before.
#[test]
fn diagnose_names_a_hidden_thermal_drift_from_virtual_bench_traces() {
    use photorobot_core::model::effects::Effect;
    let v = diagnose_hidden(
        "hidden-drift",
        vec![Effect::ThermalDrift { nm_per_s: 0.5, nm_per_s2: 0.0 }],
        "DIAGNOSE_DUMP_DRIFT",
    );
    assert_eq!(v["discriminating_motions_ran"], true);
    assert_eq!(v["verdict"], "named", "{v}");
    let first = &v["effects"][0];
    assert_eq!(first["name"], "thermal drift rate", "{v}");
    // Measured (seed 5): 0.4946 ± 0.0418 nm/s; residual 0.44σ → 0.05σ.
    let (est, sigma) = (first["estimate"].as_f64().unwrap(), first["sigma"].as_f64().unwrap());
    assert!((est - 0.5).abs() < 3.0 * sigma && sigma < 0.1, "{est} ± {sigma} nm/s");
    let after = v["residual_rms_after_sigma"].as_f64().unwrap();
    assert!(after <= 0.3, "residual {after}σ after");
}

/// An optical path scale (the air index ignored: 268 ppm) is named first, alone, within 3σ.
/// It shares the q2 moves with a q2 scale error; the motions that tell them apart are
/// rotations, and the design avoids those whose gap turns inside them (their tracking missed
/// by up to 33 nm at the truth, and the path scale came out at 687 ppm after a q2 scale).
#[test]
fn diagnose_names_a_hidden_path_scale_from_virtual_bench_traces() {
    use photorobot_core::model::effects::Effect;
    let v = diagnose_hidden("hidden-path-scale", vec![Effect::PathScale { ppm: 268.0 }], "DIAGNOSE_DUMP_PATH");
    assert_eq!(v["verdict"], "named", "{v}");
    let effects = v["effects"].as_array().unwrap();
    assert_eq!(effects.len(), 1, "{v}");
    assert_eq!(effects[0]["name"], "optical path scale", "{v}");
    let (est, sigma) = (effects[0]["estimate"].as_f64().unwrap(), effects[0]["sigma"].as_f64().unwrap());
    assert!((est - 268.0).abs() < 3.0 * sigma && sigma < 20.0, "{est} ± {sigma} ppm");
    let avoided = v["steps"].as_array().map_or(0, |s| {
        s.iter().filter(|st| st["Designed"]["avoided"].as_array().is_some_and(|a| !a.is_empty())).count()
    });
    assert!(avoided >= 1, "the design avoids the rotations whose gap turns: {v}");
    assert!(v["residual_rms_after_sigma"].as_f64().unwrap() <= 0.3, "{v}");
}

/// The beam's Gouy phase hidden wrong (the bench has none, the model has it): the calibration
/// without it keeps the branch at the truth (θ_et −0.594°: the mirrored lamella, θ_et +0.595°,
/// fits its own analysis closer, χ² 245 against 301, but is charged for the motions its motion
/// hint led) and is refused by its validation (34.6 nm on a 6° rotation about X_f). The diagnosis
/// names the Gouy phase from the session's traces; had the calibration chosen another branch,
/// the diagnosis tries it again with the effect, analysing the traces with that branch's
/// motion hint (a `Branch` step), which must end at the truth. The extrinsics end at the truth.
#[test]
fn diagnose_names_the_gouy_phase_and_ends_on_the_truths_branch() {
    use photorobot_core::model::effects::Effect;
    let v = diagnose_hidden("hidden-gouy", vec![Effect::GouyPhase { scale_error: -1.0 }], "DIAGNOSE_DUMP_GOUY");
    assert_eq!(v["verdict"], "named", "{v}");
    let effects = v["effects"].as_array().unwrap();
    assert_eq!(effects.len(), 1, "{v}");
    assert_eq!(effects[0]["name"], "Gouy phase scale error", "{v}");
    // Measured (seed 5): −0.9991 ± 0.0235; residual 2.50σ → 0.06σ.
    let (est, sigma) = (effects[0]["estimate"].as_f64().unwrap(), effects[0]["sigma"].as_f64().unwrap());
    assert!((est + 1.0).abs() < 3.0 * sigma && (0.5..=2.0).contains(&(sigma / 0.0235)), "{est} ± {sigma}");
    let after = v["residual_rms_after_sigma"].as_f64().unwrap();
    assert!(after <= 0.12, "residual {after}σ after, measured 0.06σ");
    let branch = v["steps"].as_array().unwrap().iter().find(|s| s.get("Branch").is_some());
    if let Some(step) = branch {
        let theta_et = step["Branch"]["to"]["theta_et_deg"].as_f64().unwrap();
        assert!((theta_et + 0.595).abs() < 0.01, "θ_et {theta_et}° after the branch step, truth −0.595°");
    }
    let e = &v["extrinsics"];
    for (field, truth) in [("theta_et_deg", -0.595), ("theta_wf_deg", -0.520), ("beta_et_deg", 0.744)] {
        let got = e[field].as_f64().unwrap();
        assert!((got - truth).abs() < 0.01, "{field} {got}, truth {truth}");
    }
}

/// Hidden effects the traces cannot show are reported as such, not named and not called
/// unexplained: a 0.6 mrad tilt of the q4 goniometer's axis toward its link x (it turns the
/// lamella about the beam: no motion of the session or the pool sees it at that size) and a
/// 2 nm fringe nonlinearity (the fringe analysis fits the fringe's harmonics, so the cyclic
/// error never reaches the gap changes).
#[test]
fn diagnose_reports_hidden_effects_the_traces_cannot_show() {
    use photorobot_core::model::effects::Effect;
    let cases = [
        (
            "axis tilt q4 toward link x",
            "not_detectable",
            Effect::AxisTilt { joint: "q4".into(), tilt_mrad: [0.6, 0.0] },
        ),
        ("fringe nonlinearity cos φ", "not_seen", Effect::FringeNonlinearity { in_phase_nm: 2.0, quadrature_nm: 0.0 }),
    ];
    for (name, field, effect) in cases {
        let v = diagnose_hidden(&format!("hidden {name}"), vec![effect], "DIAGNOSE_DUMP_UNSEEN");
        assert_eq!(v["discriminating_motions_ran"], true);
        assert_eq!(v["verdict"], "none", "{name}: {v}");
        let listed = |f: &str| v[f].as_array().unwrap().iter().any(|n| n.as_str() == Some(name));
        assert!(listed(field), "{name} not in {field}: {v}");
        assert!(!listed("equivalent_to_extrinsics"), "{name}: {v}");
        // Effects the motions see at their typical size are in neither list.
        for other in ["joint zero offset q4", "optical path scale", "thermal drift rate"] {
            assert!(!v["not_detectable"].as_array().unwrap().iter().any(|n| n.as_str() == Some(other)), "{other}: {v}");
            assert!(!v["not_seen"].as_array().unwrap().iter().any(|n| n.as_str() == Some(other)), "{other}: {v}");
        }
    }
}

/// Two effects whose signatures cancel on the designed plan's motions: a q5 pivot of -17.2 µm
/// along X_w and a q5 zero offset of -0.060° (a random bench of the multi-effect report). The
/// residual stays at the floor and neither can be named from the session. With the bench,
/// motions designed for the pair run and both are named within 3σ. From the recordings alone
/// the result must not read as "nothing there" for both: they need the proposed motions, and
/// the text says so.
#[test]
fn two_effects_that_cancel_are_told_apart_by_motions_designed_for_the_pair() {
    use photorobot_core::model::effects::Effect;
    use photorobot_e2e::multi_effect::{named, names_it, scalars_of};
    let dir = tempfile::tempdir().unwrap();
    let mut preset = BenchPreset::resolve("table2-ideal").unwrap();
    preset.name = "q5 pivot and zero offset that cancel".into();
    preset.effects = vec![
        Effect::PivotOffset { joint: "q5".into(), offset_world_um: [-17.155, 0.0, 0.0] },
        Effect::JointZeroOffset { joint: "q5".into(), offset: -0.05987 },
    ];
    let file = dir.path().join("bench.ron");
    save_ron(&file, &preset).unwrap();
    let run =
        photorobot_e2e::multi_effect::calibrate_then_diagnose(&file, 20, &["--plan", "optimised"], dir.path()).unwrap();
    let v = &run.diagnosis;
    let pair = ["pivot offset q5 along X_w", "joint zero offset q5"];
    let designed_for_the_pair = v["steps"].as_array().unwrap().iter().any(|s| {
        let needy = s["Designed"]["needy"].as_array().into_iter().flatten().filter_map(|n| n.as_str());
        needy.filter(|n| pair.contains(n)).count() == 2 && s["Designed"]["added_observations"].as_u64() > Some(0)
    });
    assert!(designed_for_the_pair, "no motions ran for the pair: {}", v["steps"]);
    assert_eq!(v["verdict"], "named", "{v}");
    let found = named(v);
    println!("named: {found:?}");
    for hidden in preset.effects.iter().flat_map(scalars_of) {
        assert!(found.iter().any(|n| names_it(n, &hidden)), "{} not named within 3σ: {found:?}", hidden.name);
    }
    // From the recordings alone: both need the proposed motions, in the JSON and in the text.
    let session = dir.path().join("session");
    let args = ["photorobot", "diagnose", session.to_str().unwrap(), "--bench", "none"];
    let v: serde_json::Value =
        serde_json::from_str(&photorobot_e2e::multi_effect::cli(&[&args[..], &["--json"]].concat()).unwrap()).unwrap();
    assert_eq!(v["verdict"], "none", "{v}");
    let needs = |n: &str| v["need_motions"].as_array().unwrap().iter().any(|m| m.as_str() == Some(n));
    assert!(pair.iter().all(|n| needs(n)), "not left to the proposed motions: {}", v["need_motions"]);
    let text = photorobot_e2e::multi_effect::cli(&args).unwrap();
    let line = text.lines().find(|l| l.starts_with("the recorded data cannot tell these")).unwrap_or_default();
    assert!(pair.iter().all(|n| line.contains(n)), "{text}");
    // The text gives each family's residual as the JSON does.
    let line = text.lines().find(|l| l.starts_with("residual by family of observations")).unwrap_or_default();
    let families = v["residual_by_family"].as_array().unwrap();
    assert!(families.len() >= 3, "{v}");
    for f in families {
        let (before, after) = (f["before_sigma"].as_f64().unwrap(), f["after_sigma"].as_f64().unwrap());
        let words = f["family"].as_str().unwrap().replace('_', " ");
        assert!(line.contains(&format!("{words} {before:.2}σ → {after:.2}σ (n = {})", f["count"])), "{line}\n{f}");
    }
}

#[test]
fn diagnose_on_a_folder_without_traces_says_what_it_expected() {
    let dir = tempfile::tempdir().unwrap();
    let mut out = Vec::new();
    let err = photorobot_app::cli::run(["photorobot", "diagnose", dir.path().to_str().unwrap()], &mut out).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("traces") && msg.contains("photorobot calibrate"), "{msg}");
}

/// femto-lab (five effects at once) calibrated with `calibration` on `seed`, then `diagnose` with
/// its discriminating motions: at least 4 of the 5 named within 3σ, the q5 zero offset among
/// them, nothing named that is not there, and with the named effects the validation on the truth
/// within `bounds` (circle, 6° about X_f, 6° about Z_f, 45.5° about the beam; nm).
fn femto_lab_through(calibration: &[&str], seed: u64, bounds: [f64; 4]) {
    use photorobot_e2e::multi_effect::validation_on_the_truth;
    use photorobot_e2e::multi_effect::{calibrate_then_diagnose, named, names_it, scalars_of, score};
    let dir = tempfile::tempdir().unwrap();
    let preset = BenchPreset::resolve("femto-lab").unwrap();
    let run = calibrate_then_diagnose(std::path::Path::new("femto-lab"), seed, calibration, dir.path()).unwrap();
    let v = &run.diagnosis;
    let s = score(v, &preset.effects);
    println!("named {:?}\nmissed {:?}\nwrong {:?}", s.named, s.missed, s.wrong);
    assert!(s.named.len() >= 4, "{s:?}");
    assert!(s.wrong.is_empty(), "{s:?}");
    let zero = preset.effects.iter().flat_map(scalars_of).find(|h| h.name == "joint zero offset q5").unwrap();
    assert!(named(v).iter().any(|n| names_it(n, &zero)), "{s:?}");
    let rows = validation_on_the_truth(&dir.path().join("session"), &preset).unwrap();
    println!("{rows:?}");
    assert_eq!(rows.len(), bounds.len(), "{rows:?}");
    for ((motion, _, with), bound) in rows.iter().zip(bounds) {
        assert!(*with <= bound, "{motion}: {with:.1} nm with the named effects");
    }
}

/// femto-lab on seed 3 of the designed plan: the q5 zero offset is shown only by motions run
/// together; the validation on the truth within twice the figures docs/diagnosis.md gives.
#[test]
fn femto_lab_names_four_of_its_five_effects_and_nothing_else() {
    femto_lab_through(&["--plan", "optimised"], 3, [2.0 * 13.7, 2.0 * 1.5, 2.0 * 2.8, 2.0 * 0.4]);
}

/// femto-lab through the paper's strategies (`calibrate --mode joint`) on seed 5, which names
/// the q5 zero offset only on its second look, once the q4 pivot is named; the validation on
/// the truth within twice the figures docs/diagnosis.md gives.
#[test]
fn femto_lab_on_the_joint_plans_names_its_effects_and_validates_on_the_truth() {
    femto_lab_through(&["--mode", "joint"], 5, [2.0 * 7.1, 2.0 * 1.0, 2.0 * 1.3, 2.0 * 2.2]);
}

/// femto-lab with only its drift (0.5 nm/s) and its q5 zero offset (0.02°), calibrated on the
/// joint plans (seed 1) and diagnosed: both named within 3σ and nothing else. Two of the
/// session's sweeps used to be read a whole fringe order off (the sweep fit stepping away from
/// its seed), and the diagnosis then bent the drift to them (0.676 nm/s, "unexplained").
#[test]
fn on_the_joint_plans_a_drift_beside_a_q5_zero_offset_is_read_right() {
    use photorobot_core::model::effects::Effect;
    use photorobot_e2e::multi_effect::{calibrate_then_diagnose, score};
    let dir = tempfile::tempdir().unwrap();
    let mut preset = BenchPreset::resolve("femto-lab").unwrap();
    preset.effects = vec![
        Effect::ThermalDrift { nm_per_s: 0.5, nm_per_s2: 0.0 },
        Effect::JointZeroOffset { joint: "q5".into(), offset: 0.02 },
    ];
    let bench = dir.path().join("drift-and-q5.ron");
    save_ron(&bench, &preset).unwrap();
    let run = calibrate_then_diagnose(&bench, 1, &["--mode", "joint"], dir.path()).unwrap();
    let v = &run.diagnosis;
    let s = score(v, &preset.effects);
    println!("verdict {}; named {:?}; missed {:?}; wrong {:?}", v["verdict"], s.named, s.missed, s.wrong);
    assert_eq!(v["verdict"], "named");
    assert_eq!(s.named.len(), 2, "{s:?}");
    assert!(s.wrong.is_empty(), "{s:?}");
}
