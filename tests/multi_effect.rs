//! Benches that hide several library effects at once, diagnosed through the path users run:
//! `photorobot calibrate` on the bench, then `photorobot diagnose` on the session (its
//! discriminating motions run on the same bench). The result is scored against the hidden
//! truth: which hidden effects were named within 3σ (or as an exact equivalent, or listed among
//! those the named one cannot be told from), which were missed and how the result reports
//! them, and what was named that is not there. The validation motions planned with the
//! extended model are then run on the true bench without its noise.

use photorobot_app::cli::run;
use photorobot_core::bench::{BenchPreset, VirtualBench};
use photorobot_core::diagnose::validation::validate_with_effects;
use photorobot_core::model::effects::Effect;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::optics::BackFace;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::session::Session;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde_json::Value;
use std::path::Path;

/// One scalar of a hidden effect: the candidate that names it, its value, and the candidates
/// that are exactly equivalent to it with an extrinsic change (compared by magnitude).
#[derive(Debug, Clone, PartialEq)]
pub struct HiddenScalar {
    pub name: String,
    pub value: f64,
    pub equivalents: Vec<String>,
}

/// The pivot offsets that one another take up exactly with a shift of the beam (docs/diagnosis.md,
/// "Equivalent effects"): along Z_w of joints 4 and 6 and along X_w of joints 5 and 6; along
/// Y_w of joints 4 and 5.
fn pivot_equivalents(joint: &str, axis: usize) -> Vec<String> {
    let class: &[&str] = match (joint, axis) {
        ("q4", 2) | ("q6", 2) | ("q5", 0) | ("q6", 0) => &[
            "pivot offset q4 along Z_w",
            "pivot offset q6 along Z_w",
            "pivot offset q5 along X_w",
            "pivot offset q6 along X_w",
        ],
        ("q4", 1) | ("q5", 1) => &["pivot offset q4 along Y_w", "pivot offset q5 along Y_w"],
        _ => &[],
    };
    let own = format!("pivot offset {joint} along {}", ["X_w", "Y_w", "Z_w"][axis]);
    class.iter().filter(|n| **n != own).map(|n| n.to_string()).collect()
}

/// The candidates a hidden effect is named by, one per nonzero parameter.
pub fn scalars_of(e: &Effect) -> Vec<HiddenScalar> {
    let one = |name: String, value: f64| HiddenScalar { name, value, equivalents: vec![] };
    match e {
        Effect::ThermalDrift { nm_per_s, nm_per_s2 } => {
            let mut v = vec![one("thermal drift rate".into(), *nm_per_s)];
            if *nm_per_s2 != 0.0 {
                v.push(one("thermal drift acceleration".into(), *nm_per_s2));
            }
            v
        }
        Effect::PathScale { ppm } => vec![one("optical path scale".into(), *ppm)],
        Effect::JointScale { joint, ppm } => vec![one(format!("joint scale error {joint}"), *ppm)],
        Effect::JointZeroOffset { joint, offset } => vec![one(format!("joint zero offset {joint}"), *offset)],
        Effect::PivotOffset { joint, offset_world_um } => (0..3)
            .filter(|&a| offset_world_um[a] != 0.0)
            .map(|a| HiddenScalar {
                name: format!("pivot offset {joint} along {}", ["X_w", "Y_w", "Z_w"][a]),
                value: offset_world_um[a],
                equivalents: pivot_equivalents(joint, a),
            })
            .collect(),
        Effect::AxisTilt { joint, tilt_mrad } => (0..2)
            .filter(|&k| tilt_mrad[k] != 0.0)
            .map(|k| one(format!("axis tilt {joint} toward link {}", ["x", "y"][k]), tilt_mrad[k]))
            .collect(),
        Effect::ReversalError { joint, step } => vec![one(format!("reversal error {joint}"), *step)],
        Effect::GouyPhase { scale_error } => vec![one("Gouy phase scale error".into(), *scale_error)],
        Effect::LamellaBackFace { amplitude_reflectance, .. } => {
            vec![one("lamella back face amplitude reflectance".into(), *amplitude_reflectance)]
        }
        Effect::FringeNonlinearity { in_phase_nm, quadrature_nm } => {
            [("cos φ", *in_phase_nm), ("sin φ", *quadrature_nm)]
                .into_iter()
                .filter(|(_, v)| *v != 0.0)
                .map(|(t, v)| one(format!("fringe nonlinearity {t}"), v))
                .collect()
        }
    }
}

/// A named effect of the diagnosis' JSON: name, estimate, σ, and what it cannot be told from.
#[derive(Debug, Clone)]
pub struct Named {
    pub name: String,
    pub estimate: f64,
    pub sigma: f64,
    pub unit: String,
    pub ambiguous_with: Vec<String>,
}

/// The named effects of a diagnosis' JSON.
pub fn named(v: &Value) -> Vec<Named> {
    v["effects"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|e| Named {
            name: e["name"].as_str().unwrap_or("?").to_string(),
            estimate: e["estimate"].as_f64().unwrap_or(f64::NAN),
            sigma: e["sigma"].as_f64().unwrap_or(f64::NAN),
            unit: e["unit"].as_str().unwrap_or("").to_string(),
            ambiguous_with: e["ambiguous_with"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|n| n.as_str().map(String::from))
                .collect(),
        })
        .collect()
}

/// Whether named effect `n` names hidden scalar `h` within 3σ: the same candidate at its value,
/// or an exact equivalent (or a candidate `n` says it cannot be told from `h`) at its magnitude.
pub fn names_it(n: &Named, h: &HiddenScalar) -> bool {
    let within = |est: f64, value: f64| (est - value).abs() <= 3.0 * n.sigma;
    if n.name == h.name {
        return within(n.estimate, h.value);
    }
    if let Some(v) = as_exact_equivalent(&h.name, &n.name, h.value) {
        return within(n.estimate, v);
    }
    (h.equivalents.contains(&n.name) || n.ambiguous_with.contains(&h.name)) && within(n.estimate.abs(), h.value.abs())
}

/// Hidden scalar `name` of `value` expressed as candidate `other`, when the two are the same
/// effect on every motion in another unit, with an extrinsic change: a joint-6 axis tilt toward
/// link x (mrad) is a joint-5 zero offset (°) of the opposite sign with a fixed turn of the
/// lamella (docs/diagnosis.md, "Equivalent effects").
fn as_exact_equivalent(name: &str, other: &str, value: f64) -> Option<f64> {
    match (name, other) {
        ("joint zero offset q5", "axis tilt q6 toward link x") => Some(-value.to_radians() * 1e3),
        ("axis tilt q6 toward link x", "joint zero offset q5") => Some(-(value * 1e-3).to_degrees()),
        _ => None,
    }
}

/// How a diagnosis fared against the hidden effects.
#[derive(Debug, Clone, Default)]
pub struct Score {
    /// Hidden effects with every parameter named within 3σ.
    pub named: Vec<String>,
    /// Hidden effects not named, each with how the result reports it.
    pub missed: Vec<(String, String)>,
    /// Named effects that name no hidden one but list one among those they cannot be told from.
    pub equivalent: Vec<String>,
    /// Named effects that name no hidden one and list none.
    pub wrong: Vec<String>,
}

/// Whether the result lists hidden scalar `h` as equivalent to a change of the extrinsics: what
/// a calibration absorbs and no motion of the model tells apart.
fn equivalent_to_extrinsics(v: &Value, h: &HiddenScalar) -> bool {
    v["equivalent_to_extrinsics"].as_array().is_some_and(|a| a.iter().any(|n| n.as_str() == Some(h.name.as_str())))
}

/// Score a diagnosis' JSON against the hidden effects. An effect of several parameters (a pivot
/// offset along two axes) counts as named when some are named within 3σ and the others are
/// listed as equivalent to a change of the extrinsics: those the data cannot tell, listed as such.
pub fn score(v: &Value, hidden: &[Effect]) -> Score {
    let named = named(v);
    let mut s = Score::default();
    for e in hidden {
        let scalars = scalars_of(e);
        let label = format!("{e:?}");
        let is_named = |h: &HiddenScalar| named.iter().any(|n| names_it(n, h));
        let absorbed: Vec<&str> = scalars
            .iter()
            .filter(|h| !is_named(h) && equivalent_to_extrinsics(v, h))
            .map(|h| h.name.as_str())
            .collect();
        if scalars.iter().any(is_named) && scalars.iter().all(|h| is_named(h) || equivalent_to_extrinsics(v, h)) {
            s.named.push(match absorbed.is_empty() {
                true => label,
                false => format!("{label} ({} listed as equivalent to an extrinsic change)", absorbed.join(", ")),
            });
        } else {
            s.missed.push((label, reported_as(v, &scalars)));
        }
    }
    let all: Vec<HiddenScalar> = hidden.iter().flat_map(scalars_of).collect();
    for n in &named {
        if all.iter().any(|h| names_it(n, h)) {
            continue;
        }
        let text = format!("{} = {:.4} ± {:.4} {}", n.name, n.estimate, n.sigma, n.unit);
        match all.iter().find(|h| h.name != n.name && n.ambiguous_with.contains(&h.name)) {
            Some(h) => s.equivalent.push(format!("{text} (or {}, hidden)", h.name)),
            None => s.wrong.push(text),
        }
    }
    s
}

/// The bound `ruled_out_above` gives candidate `name` (below, unit).
fn bound(v: &Value, name: &str) -> Option<(f64, String)> {
    let b = v["ruled_out_above"].as_array()?.iter().find(|b| b["name"].as_str() == Some(name))?;
    Some((b["below"].as_f64()?, b["unit"].as_str().unwrap_or("").to_string()))
}

/// How the result reports hidden scalars it did not name: the lists that hold them.
fn reported_as(v: &Value, scalars: &[HiddenScalar]) -> String {
    let lists = ["need_motions", "not_detectable", "not_seen", "equivalent_to_extrinsics"];
    let named = named(v);
    let mut out = Vec::new();
    for h in scalars {
        let holds = |f: &str| v[f].as_array().is_some_and(|a| a.iter().any(|n| n.as_str() == Some(h.name.as_str())));
        let partial =
            v["partial"].as_array().into_iter().flatten().any(|p| p["name"].as_str() == Some(h.name.as_str()));
        if named.iter().any(|n| names_it(n, h)) {
            out.push(format!("{}: named within 3σ", h.name));
            continue;
        }
        let wrong_size = named.iter().any(|n| n.name == h.name);
        let beside = named.iter().find(|n| n.ambiguous_with.contains(&h.name));
        let removed = v["steps"].as_array().into_iter().flatten().find_map(|s| {
            let r = &s["Removed"];
            (r["effect"]["name"].as_str() == Some(h.name.as_str()))
                .then(|| r["reason"].as_str().unwrap_or("").to_string())
        });
        let paired = v["cancelling_pairs"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|p| p.as_array())
            .find(|p| p.iter().any(|n| n.as_str() == Some(h.name.as_str())));
        let why = match lists.iter().find(|f| holds(f)) {
            Some(f) => (*f).to_string(),
            None if wrong_size => "named, beyond 3σ of its value".into(),
            None if partial => "tried (partial)".into(),
            None if removed.is_some() => format!("tried and removed: {}", removed.unwrap_or_default()),
            None if beside.is_some() => {
                format!("listed as what the named {} cannot be told from", beside.map_or("", |n| n.name.as_str()))
            }
            None if bound(v, &h.name).is_some() => {
                let (below, unit) = bound(v, &h.name).unwrap_or_default();
                let side = if h.value.abs() < below { "cannot tell" } else { "WRONG: the hidden size is above it" };
                format!("bounded below {below:.4} {unit} ({side})")
            }
            None if paired.is_some() => format!(
                "cancelling pair ({})",
                paired.into_iter().flatten().filter_map(|n| n.as_str()).collect::<Vec<_>>().join(" ↔ ")
            ),
            None => "not reported".into(),
        };
        out.push(format!("{}: {why}", h.name));
    }
    out.join("; ")
}

/// `photorobot` with `args`: its output, or the error.
pub fn cli(args: &[&str]) -> Result<String, String> {
    let mut out = Vec::new();
    run(args.iter().copied(), &mut out).map_err(|e| e.to_string())?;
    Ok(String::from_utf8_lossy(&out).into_owned())
}

/// What `calibrate` then `diagnose` gave on one bench.
pub struct Run {
    /// The calibration's fit verdict (fits, does_not_fit, ambiguous) or its error.
    pub calibration: String,
    /// The diagnosis' JSON.
    pub diagnosis: Value,
}

/// `photorobot calibrate --bench BENCH --seed SEED [calibration…] --out DIR/session --json`,
/// then `photorobot diagnose DIR/session --bench BENCH --seed SEED+100 --json` (the bench file
/// named again: the traces name the preset).
pub fn calibrate_then_diagnose(bench_file: &Path, seed: u64, calibration: &[&str], dir: &Path) -> Result<Run, String> {
    let session = dir.join("session");
    let (b, s) = (bench_file.to_str().expect("utf-8"), session.to_str().expect("utf-8"));
    let seed_text = seed.to_string();
    let mut argv = vec!["photorobot", "calibrate", "--bench", b, "--seed", &seed_text];
    argv.extend_from_slice(calibration);
    argv.extend(["--out", s, "--json"]);
    // A refused calibration is an error of the command, but its session is written.
    let calibration = match cli(&argv) {
        Ok(text) => serde_json::from_str::<Value>(&text)
            .ok()
            .and_then(|d| d["fit"]["verdict"].as_str().map(String::from))
            .unwrap_or_else(|| "no verdict".into()),
        Err(e) if session.join("extrinsics.ron").exists() => format!("refused: {e}"),
        Err(e) => return Err(format!("calibrate: {e}")),
    };
    let discriminating_seed = (seed + 100).to_string();
    let text = cli(&["photorobot", "diagnose", s, "--bench", b, "--seed", &discriminating_seed, "--json"])
        .map_err(|e| format!("diagnose: {e}"))?;
    let diagnosis = serde_json::from_str(&text).map_err(|e| format!("diagnose JSON: {e}"))?;
    Ok(Run { calibration, diagnosis })
}

/// `preset` without its noise (stages, encoders, detector, laser, converter, gain drift), its
/// hidden effects kept: what the truth does along a motion.
pub fn noiseless(preset: &BenchPreset) -> BenchPreset {
    let mut p = preset.clone();
    p.name = format!("{} without noise", preset.name);
    p.stages.encoder_noise_nm = 0.0;
    p.stages.encoder_noise_urad = 0.0;
    p.stages.stage_noise_nm = 0.0;
    p.stages.stage_noise_urad = 0.0;
    p.detector.white_noise_rel_fringe = 1e-5;
    p.detector.shot_noise_mw_at_1mw = 0.0;
    p.detector.adc_bits = 0;
    p.detector.gain_drift_per_hour = 0.0;
    p.laser.rin_rel = 0.0;
    p
}

/// The validation motions planned without and with the extended model the diagnosis saved in
/// the session (`session.ron`'s diagnosis record), run on `preset` without its noise: (motion,
/// without, with) peak to peak, nm. Empty when no effect was added.
pub fn validation_on_the_truth(session: &Path, preset: &BenchPreset) -> Result<Vec<(String, f64, f64)>, String> {
    let s = Session::load(session).map_err(|e| e.to_string())?;
    let record = s.diagnosis.ok_or("no diagnosis in session.ron")?;
    if record.model_effects.is_empty() {
        return Ok(vec![]);
    }
    let calibrated = Extrinsics::load(&session.join("extrinsics.ron")).map_err(|e| e.to_string())?;
    let with = record.extrinsics.ok_or("no refitted extrinsics in the record")?;
    let base = PhaseModel::new(
        preset.robot_description().map_err(|e| e.to_string())?,
        calibrated,
        preset.optics,
        &preset.ambient,
        preset.laser.wavelength_nm,
    )?;
    let mut bench = VirtualBench::new(&noiseless(preset), Some(1)).map_err(|e| e.to_string())?;
    let rows = validate_with_effects(&mut bench, &base, &calibrated, &with, &record.model_effects)
        .map_err(|e| e.to_string())?;
    Ok(rows
        .into_iter()
        .map(|r| (r.motion, r.without_effect_nm.unwrap_or(f64::NAN), r.with_effect_nm.unwrap_or(f64::NAN)))
        .collect())
}

/// 2 to 4 library effects on random joints at random sizes (0.5 to 1.5 times their typical
/// size, random sign where the sign is free): the effects of bench `seed`, no two of one kind on
/// one joint.
pub fn random_effects(seed: u64) -> Vec<Effect> {
    let mut rng = StdRng::seed_from_u64(0x6d75_6c74 ^ seed);
    let count = rng.random_range(2..=4);
    let mut out: Vec<Effect> = Vec::new();
    while out.len() < count {
        let e = random_effect(&mut rng);
        let same = |a: &Effect| {
            std::mem::discriminant(a) == std::mem::discriminant(&e)
                && scalars_of(a).first().map(|h| &h.name) == scalars_of(&e).first().map(|h| &h.name)
        };
        if !out.iter().any(same) {
            out.push(e);
        }
    }
    out
}

fn random_effect(rng: &mut StdRng) -> Effect {
    let size = |rng: &mut StdRng, typical: f64| typical * rng.random_range(0.5..1.5);
    let signed = |rng: &mut StdRng, typical: f64| size(rng, typical) * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    let pick = |rng: &mut StdRng, joints: &[&str]| joints[rng.random_range(0..joints.len())].to_string();
    match rng.random_range(0..9) {
        0 => Effect::ThermalDrift { nm_per_s: signed(rng, 0.5), nm_per_s2: 0.0 },
        1 => Effect::PathScale { ppm: signed(rng, 268.0) },
        2 => Effect::JointScale { joint: pick(rng, &["q1", "q2", "q3"]), ppm: signed(rng, 800.0) },
        3 => Effect::JointZeroOffset { joint: pick(rng, &["q4", "q5"]), offset: signed(rng, 0.05) },
        4 => {
            let mut offset_world_um = [0.0; 3];
            offset_world_um[rng.random_range(0..3)] = signed(rng, 20.0);
            Effect::PivotOffset { joint: pick(rng, &["q4", "q5"]), offset_world_um }
        }
        5 => {
            let mut tilt_mrad = [0.0; 2];
            tilt_mrad[rng.random_range(0..2)] = signed(rng, 0.6);
            Effect::AxisTilt { joint: pick(rng, &["q1", "q2", "q3", "q4", "q5"]), tilt_mrad }
        }
        6 => Effect::ReversalError { joint: pick(rng, &["q1", "q3"]), step: size(rng, 1.0) },
        7 => Effect::GouyPhase { scale_error: -1.0 },
        _ => {
            let b = BackFace::default();
            Effect::LamellaBackFace {
                amplitude_reflectance: size(rng, 0.2),
                thickness_um: b.thickness_um,
                phase_index: b.phase_index,
                group_index: b.group_index,
            }
        }
    }
}
