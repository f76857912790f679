//! Wall time of a whole calibration on emulated controllers at real time, as a user runs it:
//! `photorobot emulate all` serves the PI E-712, the SmarAct MCS and the Keysight laser on
//! loopback (realistic timing), and `photorobot calibrate --bench <its hardware file> --plan
//! optimised` measures the experiment design's plan on them, identifies and validates. Prints
//! the command's wall time, each stage's (`timing.stages` of its report), each validation
//! motion's figure and verdict, and each plan run's planned and bench time with what the
//! controllers and the recorder added; asserts the wall time stays under `--max-s`.
//!
//!     cargo build --release -p photorobot
//!     cargo run --release -p photorobot-e2e --example hardware_wall_time -- \
//!         [--runs N] [--seed S] [--max-s LIMIT] [--bin PATH] [-- EXTRA CALIBRATE ARGS]
//!
//! EXTRA is passed to `calibrate` (e.g. `--before` for the paper's comparison, `--no-validation`).
//! Runs one after the other; each on fresh emulators.

use photorobot_core::calibration::CalibrationReport;
use photorobot_core::hardware::controller_bench::FEMTO_HARDWARE_RON;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Instant;

/// The emulators' process, stopped when dropped.
struct Emulators(Child);

impl Drop for Emulators {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Start `photorobot emulate all` at real time and return it with its ready line's addresses
/// (name, host:port).
fn emulate(bin: &Path, seed: u64) -> (Emulators, Vec<(String, String)>) {
    let mut child = Command::new(bin)
        .args(["emulate", "all", "--seed", &seed.to_string()])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot run {bin:?}: {e}"));
    let mut line = String::new();
    BufReader::new(child.stdout.take().expect("piped")).read_line(&mut line).expect("the ready line");
    let list = line.split("emulated: ").nth(1).and_then(|r| r.split(';').next()).unwrap_or_else(|| panic!("{line}"));
    let addresses = list
        .split(", ")
        .filter_map(|part| part.rsplit_once(" at ").map(|(n, a)| (n.to_string(), a.trim().to_string())))
        .collect();
    (Emulators(child), addresses)
}

/// The embedded femto hardware file with the emulators' addresses.
fn hardware_file(dir: &Path, addresses: &[(String, String)]) -> PathBuf {
    let mut text = FEMTO_HARDWARE_RON.to_string();
    for (name, default) in
        [("PI E-712", "127.0.0.1:50000"), ("SmarAct MCS", "127.0.0.1:5000"), ("Keysight laser", "127.0.0.1:5025")]
    {
        let at = addresses.iter().find(|(n, _)| n == name).unwrap_or_else(|| panic!("no {name} in {addresses:?}"));
        text = text.replace(&format!("\"{default}\""), &format!("\"{}\"", at.1));
    }
    let file = dir.join("bench.ron");
    std::fs::write(&file, text).expect("the hardware file");
    file
}

/// One calibration: its wall time, the stages its log gives and its report.
fn calibrate(bin: &Path, seed: u64, extra: &[String]) -> (f64, Vec<(String, f64)>, CalibrationReport) {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let (_emulators, addresses) = emulate(bin, seed);
    let bench = hardware_file(dir.path(), &addresses);
    let t0 = Instant::now();
    let out = Command::new(bin)
        .args(["-v", "calibrate"])
        .arg("--bench")
        .arg(&bench)
        .args(["--model", "table2-ideal", "--plan", "optimised", "--json", "--out"])
        .arg(dir.path().join("session"))
        .args(extra)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {bin:?}: {e}"));
    let wall_s = t0.elapsed().as_secs_f64();
    let stderr = String::from_utf8_lossy(&out.stderr);
    // A calibration its validation does not prove exits 1 with its report written: its time
    // counts all the same, and the reason is printed.
    if !out.status.success() {
        let reason = stderr.lines().rev().find(|l| l.starts_with("error:")).unwrap_or("(no error line)");
        println!("calibrate exited {:?}: {reason}", out.status.code());
    }
    let report: CalibrationReport =
        serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("no report ({e}):\n{stderr}"));
    (wall_s, photorobot_e2e::logged_stages(&stderr), report)
}

fn print(wall_s: f64, stages: &[(String, f64)], r: &CalibrationReport) {
    println!("calibrate {wall_s:>8.2} s wall");
    for (stage, s) in stages {
        println!("  {stage:<12} {s:>8.2} s");
    }
    for v in &r.validation {
        let Some(e) = &v.after_evidence else { continue };
        println!(
            "  after: {:<52} {:>8.2} nm {:<12} tracked gap {:>7.1} nm, model-free {:>7.1} nm",
            v.motion,
            e.measured_nm,
            e.verdict.word(),
            e.tracked_gap_nm,
            e.model_free_gap_nm.unwrap_or(f64::NAN)
        );
    }
    let Some(t) = &r.timing else { return println!("  (no segment timing in the report)") };
    println!("  {:<60} {:>5} {:>8} {:>8} {:>8} {:>8}", "run", "segs", "planned", "bench", "waiting", "recorder");
    let runs = t.runs().into_iter().map(|(stage, r)| (format!("{stage}: {}", r.name), r));
    for (name, r) in runs.chain(t.stage_totals().into_iter().map(|r| (format!("total {}", r.name), r))) {
        println!(
            "  {name:<60} {:>5} {:>8.2} {:>8.2} {:>8.2} {:>8.2}",
            r.segments, r.planned_s, r.bench_s, r.waiting_s, r.recorder_after_s
        );
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (ours, extra) = match args.iter().position(|a| a == "--") {
        Some(i) => (&args[..i], args[i + 1..].to_vec()),
        None => (&args[..], vec![]),
    };
    let value = |flag: &str| ours.iter().position(|a| a == flag).and_then(|i| ours.get(i + 1)).cloned();
    let runs: usize = value("--runs").map_or(1, |v| v.parse().expect("--runs N"));
    let seed: u64 = value("--seed").map_or(11, |v| v.parse().expect("--seed S"));
    let max_s: Option<f64> = value("--max-s").map(|v| v.parse().expect("--max-s LIMIT"));
    let bin = value("--bin")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/release/photorobot"));
    let mut walls = Vec::new();
    for k in 0..runs {
        let (wall_s, stages, report) = calibrate(&bin, seed + k as u64, &extra);
        print(wall_s, &stages, &report);
        walls.push(wall_s);
    }
    walls.sort_by(f64::total_cmp);
    println!("wall time over {runs} run(s): {:.1}-{:.1} s", walls[0], walls[walls.len() - 1]);
    if let Some(max) = max_s {
        assert!(walls[walls.len() - 1] <= max, "a calibration took {:.1} s, above {max} s", walls[walls.len() - 1]);
    }
}
