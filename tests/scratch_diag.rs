//! End to end: a session recorded on the virtual bench with a hidden pivot offset
//! (assets/benches/hidden-pivot.ron), then `photorobot diagnose <session> --json`: the workflow runs
//! its discriminating motions on that bench and names the hidden effect from the traces.

use photorobot_core::bench::{run_plan, BenchPreset, RunControl, VirtualBench};
use photorobot_core::files::save_ron;
use photorobot_core::plan::{JointTarget, Plan, Segment};
use std::sync::atomic::AtomicBool;

fn mv(to: [f64; 6], record: bool, label: &str) -> Segment {
    Segment::Move { to: JointTarget::all(to), record, label: label.into() }
}

/// A short calibration-like session: absolute gaps at three poses, X and Z translations, q4 and
/// q5 rotations of ±4° (the paper's kinds of motion, on which the pivot offset is absorbed).
fn session_plan() -> Plan {
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

#[test]
fn scratch() {
    let preset_name = std::env::var("PRESET").unwrap_or("hidden-pivot".into());
    let preset = BenchPreset::resolve(&preset_name).unwrap();
    let mut bench = VirtualBench::new(&preset, Some(5)).unwrap();
    let cancel = AtomicBool::new(false);
    let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
    let run = run_plan(&mut bench, &session_plan(), &mut control);
    run.outcome.unwrap();
    let dir = std::path::PathBuf::from("/tmp/diag/session");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("traces")).unwrap();
    for (i, t) in run.traces.iter().enumerate() {
        t.write_csv(&dir.join("traces").join(format!("{i:03}.csv"))).unwrap();
    }
    save_ron(&dir.join("extrinsics.ron"), &preset.truth).unwrap();
    let mut out = Vec::new();
    let args = ["photorobot", "diagnose", dir.to_str().unwrap()];
    photorobot_app::cli::run(args, &mut out).unwrap();
    println!("{}", String::from_utf8_lossy(&out));
}
