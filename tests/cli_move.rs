//! End to end: the lamella placed with a calibration through `photorobot move`, the path users
//! run. One joint calibration on the designed plan (`--plan optimised`, table2-ideal, seed 7),
//! then moves on a fresh virtual bench of the preset, each checked against the bench's hidden
//! truth (the preset's extrinsics at the joints the move ended at).

use photorobot_app::cli::{run, CliError};
use photorobot_core::bench::BenchPreset;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::session::Session;
use photorobot_e2e::moves::{random_recipe, true_gap_and_tilt};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn cli(args: &[&str]) -> (Result<(), CliError>, String) {
    let mut out = Vec::new();
    let argv: Vec<String> = std::iter::once("photorobot").chain(args.iter().copied()).map(String::from).collect();
    let r = run(argv, &mut out).map(|_| ());
    (r, String::from_utf8(out).unwrap())
}

/// The calibrated session, made once for the binary; each test copies it.
fn calibrated() -> &'static Path {
    static DIR: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("session");
        let args =
            ["calibrate", "--bench", "table2-ideal", "--seed", "7", "--plan", "optimised", "--no-validation", "--json"];
        let mut args: Vec<&str> = args.to_vec();
        args.extend(["--out", out.to_str().unwrap()]);
        let (r, _) = cli(&args);
        r.unwrap();
        (dir, out)
    })
    .1
}

/// A copy of the calibrated session in a fresh folder.
fn session_copy(into: &Path) -> PathBuf {
    let to = into.join("session");
    copy_dir(calibrated(), &to);
    to
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.path().is_dir() {
            copy_dir(&e.path(), &to.join(e.file_name()));
        } else if e.file_name() != "session.lock" {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

fn truth() -> PhaseModel {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    PhaseModel::of_preset(&preset, preset.truth).unwrap()
}

/// Random targets within the workspace, run as a recipe through `photorobot move`: every move
/// confirmed by the sweep at its end, the TRUE gap within 10 nm and within 3σ of the forecast,
/// the true tilt within 3σ of the forecast, and the moves in the session. The full 20 run in
/// the `random_moves` example.
#[test]
fn random_targets_reach_the_true_gap_within_the_forecast() {
    let dir = tempfile::tempdir().unwrap();
    let session = session_copy(dir.path());
    let recipe = dir.path().join("recipe.ron");
    let targets = random_recipe(&session, 6, 11, &recipe);
    let (r, text) = cli(&[
        "move",
        "--bench",
        "table2-ideal",
        "--session",
        session.to_str().unwrap(),
        "--recipe",
        recipe.to_str().unwrap(),
        "--json",
    ]);
    r.unwrap();
    let doc: Value = serde_json::from_str(&text).unwrap();
    let moves = doc["moves"].as_array().unwrap();
    assert_eq!(moves.len(), targets.len());
    let truth = truth();
    for (m, t) in moves.iter().zip(&targets) {
        assert_eq!(m["verdict"], "confirmed", "{m}");
        let (gap_um, tilt) = true_gap_and_tilt(&truth, m);
        let error_nm = (gap_um - t.gap_um) * 1e3;
        let sigma_nm = m["forecast"]["gap_sigma_nm"].as_f64().unwrap();
        eprintln!(
            "{}: true gap error {error_nm:+.2} nm (forecast σ {sigma_nm:.2} nm), measured {:+.2} nm; true tilt ({:+.5}°, {:+.5}°)",
            t.describe(),
            m["gap_error_nm"].as_f64().unwrap(),
            tilt[0] - t.tilt_deg[0],
            tilt[1] - t.tilt_deg[1]
        );
        assert!(error_nm.abs() <= 10.0, "true gap error {error_nm} nm");
        assert!(
            error_nm.abs() <= 3.0 * sigma_nm.max(0.3),
            "true gap error {error_nm} nm beyond 3σ = {}",
            3.0 * sigma_nm
        );
        for k in 0..2 {
            let s = m["forecast"]["tilt_sigma_deg"][k].as_f64().unwrap();
            assert!(
                (tilt[k] - t.tilt_deg[k]).abs() <= 3.0 * s.max(1e-6),
                "tilt {k}: {} vs σ {s}",
                tilt[k] - t.tilt_deg[k]
            );
        }
    }
    assert_eq!(Session::load(&session).unwrap().moves.len(), targets.len());
}
