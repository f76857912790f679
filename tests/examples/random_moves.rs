//! Random targets placed with a calibration through `photorobot move`, checked against the
//! virtual bench's hidden truth: the figure of the positioning.
//!
//!     cargo run --release -p photorobot-e2e --example random_moves -- [TARGETS] [--seed S] [--plan PLAN]
//!
//! Calibrates `table2-ideal` (seed 7, joint mode) on PLAN (default `optimised`, the designed
//! plan; `joint` for the paper's strategies with the extra measurements), then runs TARGETS
//! random targets (default 20, target seed S, default 1) as one recipe, and again each with the
//! nominal design's extrinsics instead of the calibration. Asserts that every calibrated move is
//! confirmed with its true gap within 10 nm of the request and within 3σ of the forecast, its tilt
//! from the contrast within 3σ of the truth, and that every nominal move is off.

use photorobot_app::cli::run;
use photorobot_core::bench::BenchPreset;
use photorobot_core::model::phase::PhaseModel;
use photorobot_e2e::moves::{joints_end, random_recipe, true_gap_and_tilt};
use serde_json::Value;

fn cli(args: &[String]) -> (bool, String) {
    let mut out = Vec::new();
    let argv = std::iter::once("photorobot".to_string()).chain(args.iter().cloned());
    let ok = run(argv, &mut out).is_ok();
    (ok, String::from_utf8(out).unwrap())
}

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter().position(|a| a == name).and_then(|i| args.get(i + 1).cloned())
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let n: usize = args.first().and_then(|a| a.parse().ok()).unwrap_or(20);
    let seed: u64 = arg(&args, "--seed").and_then(|s| s.parse().ok()).unwrap_or(1);
    let plan = arg(&args, "--plan").unwrap_or("optimised".into());
    let dir = tempfile::tempdir().unwrap();
    let session = dir.path().join("session");
    let s = session.to_str().unwrap().to_string();
    let mut calibrate: Vec<String> =
        ["calibrate", "--bench", "table2-ideal", "--seed", "7", "--no-validation", "--out", &s]
            .map(String::from)
            .to_vec();
    if plan != "joint" {
        calibrate.extend(["--plan".to_string(), plan.clone()]);
    }
    let t0 = std::time::Instant::now();
    assert!(cli(&calibrate).0, "the calibration");
    println!("calibrated on {plan} in {:.1} s", t0.elapsed().as_secs_f64());
    let recipe = dir.path().join("recipe.ron");
    let targets = random_recipe(&session, n, seed, &recipe);
    let t0 = std::time::Instant::now();
    let (ok, text) =
        cli(&["move", "--bench", "table2-ideal", "--session", &s, "--recipe", recipe.to_str().unwrap(), "--json"]
            .map(String::from));
    println!("{n} moves in {:.1} s", t0.elapsed().as_secs_f64());
    let doc: Value = serde_json::from_str(&text).unwrap();
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let truth = PhaseModel::of_preset(&preset, preset.truth).unwrap();
    let (mut worst, mut confirmed, mut within) = (0.0f64, 0, 0);
    println!(
        "{:>3} {:>11} {:>12} {:>12} {:>10} {:>10} {:>9} {:>10} {:>10}  verdict",
        "#", "gap µm", "true err nm", "measured nm", "σ fc nm", "bound nm", "σ meas", "tilt °", "tilt err °"
    );
    let (mut tilt_z, mut tilt_sigmas, mut gap_z) = (Vec::new(), Vec::new(), Vec::new());
    for (k, (m, t)) in doc["moves"].as_array().unwrap().iter().zip(&targets).enumerate() {
        let (gap_um, _) = true_gap_and_tilt(&truth, m);
        let error_nm = (gap_um - t.gap_um) * 1e3;
        let sigma = m["forecast"]["gap_sigma_nm"].as_f64().unwrap();
        let verdict = m["verdict"].as_str().unwrap();
        let true_tilt_deg = truth.gap_and_tilt(&joints_end(m)).unwrap().1.to_degrees();
        let tilt = m["tilt"]["tilt_deg"].as_f64().unwrap_or(f64::NAN);
        let tilt_sigma = m["tilt"]["sigma_deg"].as_f64().unwrap_or(f64::NAN);
        tilt_z.push((tilt - true_tilt_deg) / tilt_sigma);
        tilt_sigmas.push(tilt_sigma);
        let measured_sigma = m["measurement"]["sigma_nm"].as_f64().unwrap_or(f64::NAN);
        gap_z.push(((m["gap_error_nm"].as_f64().unwrap_or(f64::NAN) - error_nm) / measured_sigma).abs());
        println!(
            "{k:>3} {:>11.4} {error_nm:>+12.3} {:>+12.3} {sigma:>10.2} {:>10.2} {:>9.2} {tilt:>10.4} {:>+10.4}  {verdict}",
            t.gap_um,
            m["gap_error_nm"].as_f64().unwrap_or(f64::NAN),
            m["bound_nm"].as_f64().unwrap_or(f64::NAN),
            m["measurement"]["sigma_nm"].as_f64().unwrap_or(f64::NAN),
            tilt - true_tilt_deg
        );
        worst = worst.max(error_nm.abs());
        confirmed += usize::from(verdict == "confirmed");
        within += usize::from(error_nm.abs() <= 10.0 && error_nm.abs() <= 3.0 * sigma);
    }
    let mean_z = tilt_z.iter().sum::<f64>() / tilt_z.len() as f64;
    let worst_z = tilt_z.iter().map(|z| z.abs()).fold(0.0, f64::max);
    let range = |v: &[f64]| (v.iter().copied().fold(f64::INFINITY, f64::min), v.iter().copied().fold(0.0, f64::max));
    let (s_lo, s_hi) = range(&tilt_sigmas);
    println!(
        "tilt from the contrast against the truth: mean {mean_z:+.2}σ, worst {worst_z:.2}σ (σ {s_lo:.4}-{s_hi:.4}°); \
         measured gap against the truth: worst {:.2}σ of the measurement",
        range(&gap_z).1
    );
    println!("calibrated: {confirmed} of {n} confirmed, {within} of {n} with the true gap within 10 nm and 3σ of the forecast, worst {worst:.3} nm");
    let mut nominal_errors = Vec::new();
    let nominal = concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/extrinsics/nominal.ron");
    for t in &targets {
        let (_, text) = cli(&[
            "move".into(),
            "--bench".into(),
            "table2-ideal".into(),
            "--extrinsics".into(),
            nominal.into(),
            "--gap-um".into(),
            t.gap_um.to_string(),
            "--tilt-deg".into(),
            format!("{},{}", t.tilt_deg[0], t.tilt_deg[1]),
            "--lateral-um".into(),
            format!("{},{}", t.lateral_um[0], t.lateral_um[1]),
            "--rotation-deg".into(),
            t.rotation_deg.to_string(),
            "--json".into(),
        ]);
        let doc: Value = serde_json::from_str(&text).unwrap();
        let m = &doc["moves"][0];
        let (gap_um, _) = true_gap_and_tilt(&truth, m);
        let measured = m["gap_error_nm"].as_f64().unwrap_or(f64::NAN);
        let sigma = m["measurement"]["sigma_nm"].as_f64().unwrap_or(f64::NAN);
        println!(
            "nominal: true gap error {:+.1} nm, measured {measured:+.1} ± {sigma:.2} nm",
            (gap_um - t.gap_um) * 1e3
        );
        nominal_errors.push(((gap_um - t.gap_um) * 1e3, m["verdict"] == "off"));
    }
    let abs: Vec<f64> = nominal_errors.iter().map(|e| e.0.abs()).collect();
    let off = nominal_errors.iter().filter(|e| e.1).count();
    println!(
        "nominal extrinsics: true gap error {:.0}-{:.0} nm, {off} of {n} off",
        abs.iter().copied().fold(f64::INFINITY, f64::min),
        abs.iter().copied().fold(0.0, f64::max)
    );
    assert!(ok, "every calibrated move confirmed");
    assert!(worst_z <= 3.0, "a tilt {worst_z}σ from the truth");
    assert_eq!((confirmed, within), (n, n));
    assert_eq!(off, n, "every nominal move is seen off");
}
