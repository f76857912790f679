//! End-to-end tests live in the [[test]] targets of this crate.

use photorobot_core::plan::{JointTarget, Plan, Segment};

fn mv(to: [f64; 6], record: bool, label: &str) -> Segment {
    Segment::Move { to: JointTarget::all(to), record, label: label.into() }
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
