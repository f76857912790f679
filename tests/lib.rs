//! End-to-end tests live in the [[test]] targets of this crate.

use photorobot_core::model::effects::Effect;
use photorobot_core::model::optics::BackFace;
use photorobot_core::plan::{JointTarget, Plan, Segment};

fn mv(to: [f64; 6], record: bool, label: &str) -> Segment {
    Segment::Move { to: JointTarget::all(to), record, label: label.into(), through: false }
}

/// A short calibration-like session: absolute gaps at three poses, X and Z translations, q4 and
/// q5 rotations of ±4° (the paper's kinds of motion, on which the pivot offset is absorbed).
pub fn session_plan() -> Plan {
    let mut s = Vec::new();
    for (k, at) in [[0.0; 6], [0.0, -100.0, 0.0, 0.0, 0.0, 0.0], [120.0, 0.0, -120.0, 0.0, 0.0, 0.0]].iter().enumerate()
    {
        s.push(mv(*at, false, "setup"));
        s.push(Segment::Sweep { from_nm: 1540.0, to_nm: 1580.0, rate_nm_per_s: 10.0, label: format!("sweep {k}") });
    }
    for lateral in [-100.0, 100.0] {
        s.push(mv([lateral, 0.0, -150.0, 0.0, 0.0, 0.0], false, "setup"));
        s.push(mv([lateral, 0.0, 150.0, 0.0, 0.0, 0.0], true, &format!("X at q1 = {lateral}")));
        s.push(mv([-150.0, 0.0, lateral, 0.0, 0.0, 0.0], false, "setup"));
        s.push(mv([150.0, 0.0, lateral, 0.0, 0.0, 0.0], true, &format!("Z at q3 = {lateral}")));
    }
    for other in [-2.0, 0.0, 2.0] {
        s.push(mv([0.0, 0.0, 0.0, -4.0, other, 0.0], false, "setup"));
        s.push(mv([0.0, 0.0, 0.0, 4.0, other, 0.0], true, &format!("q4 at q5 = {other}")));
        s.push(mv([0.0, 0.0, 0.0, other, -4.0, 0.0], false, "setup"));
        s.push(mv([0.0, 0.0, 0.0, other, 4.0, 0.0], true, &format!("q5 at q4 = {other}")));
    }
    Plan { name: "diagnose e2e".into(), description: String::new(), segments: s }
}

/// One library effect at a time at its typical size (docs/diagnosis.md), as hidden on a virtual
/// bench: (candidate name, hidden value in the candidate's unit, effects hidden); the first
/// entry hides nothing.
pub fn library_effects_at_typical_size() -> Vec<(&'static str, f64, Vec<Effect>)> {
    let b = BackFace::default();
    let one = |name, value, e: Effect| (name, value, vec![e]);
    vec![
        ("nothing", 0.0, vec![]),
        one("thermal drift rate", 0.5, Effect::ThermalDrift { nm_per_s: 0.5, nm_per_s2: 0.0 }),
        one("optical path scale", 268.0, Effect::PathScale { ppm: 268.0 }),
        one("joint scale error q3", 800.0, Effect::JointScale { joint: "q3".into(), ppm: 800.0 }),
        one("joint zero offset q4", 0.05, Effect::JointZeroOffset { joint: "q4".into(), offset: 0.05 }),
        one(
            "pivot offset q4 along Z_w",
            20.0,
            Effect::PivotOffset { joint: "q4".into(), offset_world_um: [0.0, 0.0, 20.0] },
        ),
        one("axis tilt q4 toward link x", 0.6, Effect::AxisTilt { joint: "q4".into(), tilt_mrad: [0.6, 0.0] }),
        one("reversal error q3", 1.0, Effect::ReversalError { joint: "q3".into(), step: 1.0 }),
        one(
            "reversal error q4",
            20e-6f64.to_degrees(),
            Effect::ReversalError { joint: "q4".into(), step: 20e-6f64.to_degrees() },
        ),
        one("Gouy phase scale error", -1.0, Effect::GouyPhase { scale_error: -1.0 }),
        one(
            "lamella back face amplitude reflectance",
            0.2,
            Effect::LamellaBackFace {
                amplitude_reflectance: 0.2,
                thickness_um: b.thickness_um,
                phase_index: b.phase_index,
                group_index: b.group_index,
            },
        ),
        one("fringe nonlinearity cos φ", 2.0, Effect::FringeNonlinearity { in_phase_nm: 2.0, quadrature_nm: 0.0 }),
        // The observable direction of the q4 axis tilt (toward link x it turns the lamella about
        // the beam, row 6), and a q4 reversal 2.5× row 8's (still µrad-level).
        one("axis tilt q4 toward link y", 0.6, Effect::AxisTilt { joint: "q4".into(), tilt_mrad: [0.0, 0.6] }),
        one(
            "reversal error q4",
            50e-6f64.to_degrees(),
            Effect::ReversalError { joint: "q4".into(), step: 50e-6f64.to_degrees() },
        ),
    ]
}

/// The range `A..B` given after `flag` in an example's arguments, or `default` without it.
pub fn range_arg(args: &[String], flag: &str, default: std::ops::Range<u64>) -> std::ops::Range<u64> {
    let Some(k) = args.iter().position(|a| a == flag) else { return default };
    let (a, b) = args.get(k + 1).and_then(|r| r.split_once("..")).unwrap_or_else(|| panic!("{flag} A..B"));
    a.parse().unwrap_or_else(|_| panic!("{flag} A..B"))..b.parse().unwrap_or_else(|_| panic!("{flag} A..B"))
}

/// The optics named by `--optics` in `args`: `multi-beam` (the other simulator's own, the
/// default) or `two-beam` (the model farther from ours, [`two_beam::TwoBeamOptics`]).
pub fn optics_arg(args: &[String]) -> independent::OpticsModel {
    match args.iter().position(|a| a == "--optics").and_then(|k| args.get(k + 1)).map(String::as_str) {
        None | Some("multi-beam") => independent::Recorder::new(0).optics,
        Some("two-beam") => independent::OpticsModel::TwoBeam(Default::default()),
        Some(o) => panic!("--optics multi-beam|two-beam, not {o}"),
    }
}

pub mod independent;
pub mod lab_files;
pub mod lab_recordings;
pub mod multi_effect;
pub mod random;
pub mod recordings;

/// Random targets for the moves of the lamella and their truth on the virtual bench.
pub mod moves {
    use photorobot_core::bench::BenchPreset;
    use photorobot_core::model::extrinsics::Extrinsics;
    use photorobot_core::model::phase::PhaseModel;
    use photorobot_core::position::recipe::{Recipe, RecipeStep};
    use photorobot_core::position::{plan_move, ProofKind, Target, TaskFrame};
    use photorobot_core::session::Session;
    use rand::{Rng, SeedableRng};
    use std::path::Path;

    /// `n` random targets within the workspace of the calibrated `session` (table2-ideal),
    /// each reachable from the one before (from q = 0 first), written as a recipe to `file`:
    /// gap 780-1020 µm, tilts ±2°, the lamella's origin −200..20 µm from the beam along X_f and
    /// Z_f, rotation ±20°.
    pub fn random_recipe(session: &Path, n: usize, seed: u64, file: &Path) -> Vec<Target> {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let base = PhaseModel::of_preset(&preset, Extrinsics::nominal_design()).unwrap();
        let placement = Session::load(session).unwrap().placement(&base, "test").unwrap();
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let (mut from, mut targets) = ([0.0; 6], Vec::new());
        while targets.len() < n {
            let t = Target {
                gap_um: rng.random_range(780.0..1020.0),
                tilt_deg: [rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0)],
                lateral_um: [rng.random_range(-200.0..20.0), rng.random_range(-200.0..20.0)],
                rotation_deg: rng.random_range(-20.0..20.0),
            };
            if let Ok(plan) = plan_move(&placement, from, &t, false, ProofKind::Sweep) {
                from = plan.path.end();
                targets.push(t);
            }
        }
        let steps = targets
            .iter()
            .enumerate()
            .map(|(i, t)| RecipeStep { label: format!("random {i}"), target: *t, keep_gap: false })
            .collect();
        let recipe = Recipe { name: format!("random targets, seed {seed}"), description: String::new(), steps };
        photorobot_core::files::save_ron(file, &recipe).unwrap();
        targets
    }

    /// The true target (the bench's hidden extrinsics) at the joints a move's JSON ended at:
    /// its gap (µm) and tilt (°).
    pub fn true_gap_and_tilt(truth: &PhaseModel, m: &serde_json::Value) -> (f64, [f64; 2]) {
        let q = joints_end(m);
        let frame = TaskFrame::at(truth, &truth.extrinsics, &q).unwrap();
        let t = frame.target_at(truth, &q).unwrap();
        (t.gap_um, t.tilt_deg)
    }

    /// A move's `joints_end` (µm, °) from its `--json` record.
    pub fn joints_end(m: &serde_json::Value) -> [f64; 6] {
        let j = &m["joints_end"];
        std::array::from_fn(|i| j[["q1_um", "q2_um", "q3_um", "q4_deg", "q5_deg", "q6_deg"][i]].as_f64().unwrap())
    }
}
pub mod two_beam;
pub mod validation;

/// The `stage done` events of a command's log (`RUST_LOG` at info on stderr): each stage's name
/// and wall time (s), as the wall-time examples read them.
pub fn logged_stages(log: &str) -> Vec<(String, f64)> {
    let field = |line: &str, key: &str| -> Option<String> {
        let at = line.find(&format!("{key}="))? + key.len() + 1;
        Some(line[at..].split_whitespace().next()?.to_string())
    };
    log.lines()
        .filter(|l| l.contains("stage done"))
        .filter_map(|l| Some((field(l, "stage")?, field(l, "elapsed_s")?.parse().ok()?)))
        .collect()
}
