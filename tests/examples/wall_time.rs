//! Wall time of the user's chain on a fixed seed: `calibrate` on the virtual bench, `calibrate
//! --traces` on the traces it recorded, and `diagnose` on its session, each run as the release
//! `photorobot` binary with `-v`. Prints each command's wall time, each stage's time as the
//! command logs it (`stage done stage=<name> elapsed_s=<s>`), and the chain's time over the time
//! it takes just to read the session's CSV traces. Each command starts on a settled machine, as
//! a user's would: the previous command's writes flushed (`sync`) and a few seconds left for the
//! kernel to write back and reclaim what that command left, so that one command's 470 MB of
//! traces do not slow the next (as `hyperfine --prepare sync` does).
//!
//!     cargo build --release -p photorobot
//!     cargo run --release -p photorobot-e2e --example wall_time -- [SEED] [--bin PATH]
//!
//! SEED defaults to 7 (bench table2-ideal, joint mode); PATH to target/release/photorobot.
//! Asserts the README's targets: `calibrate` ≤ 8 s, `calibrate --traces` ≤ 3 s, its `identify`
//! and `validate` stages ≤ 2 s each, `diagnose` ≤ 10 s (on a quiet machine).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// One command's run: its wall time (s) and the stages it logged (name, s).
struct Timed {
    wall_s: f64,
    stages: Vec<(String, f64)>,
}

/// Run `bin` with `args` (and `-v`), failing loudly on a non-zero exit except for `ok_codes`.
fn run(bin: &Path, args: &[&str], ok_codes: &[i32]) -> Timed {
    settle();
    let t0 = Instant::now();
    let out = Command::new(bin).arg("-v").args(args).output().unwrap_or_else(|e| panic!("cannot run {bin:?}: {e}"));
    let wall_s = t0.elapsed().as_secs_f64();
    let code = out.status.code().unwrap_or(-1);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(ok_codes.contains(&code), "photorobot {} exited with {code}:\n{stderr}", args.join(" "));
    Timed { wall_s, stages: photorobot_e2e::logged_stages(&stderr) }
}

/// Flush the file system's pending writes and let the kernel finish with them.
fn settle() {
    // Best effort: where there is no `sync`, only the pause.
    let _ = Command::new("sync").status();
    std::thread::sleep(std::time::Duration::from_secs(SETTLE_S));
}

/// The pause before each command, s.
const SETTLE_S: u64 = 5;

fn print(name: &str, t: &Timed) {
    println!("{name:<28} {:>8.2} s wall", t.wall_s);
    for (stage, s) in &t.stages {
        println!("    {stage:<24} {s:>8.2} s");
    }
}

/// Time to read every CSV trace of `dir` (s), once, in parallel as the commands do.
fn read_csvs_s(dir: &Path) -> (f64, usize) {
    let t0 = Instant::now();
    let traces = photorobot_core::trace::import::read_folder(dir, None).expect("the session's traces");
    (t0.elapsed().as_secs_f64(), traces.iter().map(|t| t.len()).sum())
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let seed = args.iter().find_map(|a| a.parse::<u64>().ok()).unwrap_or(7).to_string();
    let bin = args
        .iter()
        .position(|a| a == "--bin")
        .and_then(|i| args.get(i + 1))
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/release/photorobot"));
    assert!(bin.is_file(), "{bin:?} not found: cargo build --release -p photorobot first");
    let dir = tempfile::tempdir().expect("a temporary folder");
    let (s, s2) = (dir.path().join("s"), dir.path().join("s2"));
    let (s_str, s2_str) = (s.to_str().unwrap(), s2.to_str().unwrap());
    let traces = s.join("traces");
    let calibrate =
        run(&bin, &["calibrate", "--bench", "table2-ideal", "--seed", &seed, "--mode", "joint", "--out", s_str], &[0]);
    let from_traces = run(
        &bin,
        &["calibrate", "--bench", "table2-ideal", "--traces", traces.to_str().unwrap(), "--out", s2_str],
        &[0],
    );
    let diagnose = run(&bin, &["diagnose", s_str], &[0]);
    settle();
    let (read_s, samples) = read_csvs_s(&traces);
    println!("seed {seed}: {samples} samples in {} traces", std::fs::read_dir(&traces).unwrap().count());
    print("calibrate (virtual bench)", &calibrate);
    print("calibrate --traces", &from_traces);
    print("diagnose", &diagnose);
    let chain = calibrate.wall_s + from_traces.wall_s + diagnose.wall_s;
    println!("reading the CSV traces alone: {read_s:.2} s");
    println!("chain {chain:.2} s = {:.1} × the time to read the CSVs", chain / read_s);
    println!(
        "calibrate --traces {:.2} s = {:.1} × the time to read the CSVs",
        from_traces.wall_s,
        from_traces.wall_s / read_s
    );
    // The README's targets, for a quiet machine: a loaded one fails here, and says by how much.
    let stage = |t: &Timed, name: &str| t.stages.iter().find(|s| s.0 == name).map_or(f64::NAN, |s| s.1);
    let checks = [
        ("calibrate (virtual bench)", calibrate.wall_s, 8.0),
        ("calibrate --traces", from_traces.wall_s, 3.0),
        ("identify stage (the GUI's Identify)", stage(&calibrate, "identify"), 2.0),
        ("validate stage (the GUI's Validation)", stage(&calibrate, "validate"), 2.0),
        ("diagnose", diagnose.wall_s, 10.0),
    ];
    let missed: Vec<String> = checks
        .iter()
        .filter(|c| c.1.is_nan() || c.1 > c.2)
        .map(|(n, s, t)| format!("{n}: {s:.2} s, target {t} s"))
        .collect();
    assert!(missed.is_empty(), "targets missed: {}", missed.join("; "));
    println!("every target met");
}
