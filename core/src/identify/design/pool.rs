//! The candidate pool: single recorded segments with the setup move to their start, checked
//! against the robot and timed by the plan's own timing model.

use crate::model::robot::RobotDescription;
use crate::plan::{JointTarget, MotionLimits, Plan, Segment};
use serde::{Deserialize, Serialize};

/// What a candidate motion is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CandidateKind {
    /// A translation (q1, q2 or q3) with the orientation fixed.
    Translation,
    /// A wavelength sweep at a fixed pose (absolute gap).
    Sweep,
    /// A q4 or q5 rotation, read for gap changes and fringe amplitudes (label "tilt scan …").
    TiltScan,
    /// A q6 rotation (about the beam direction).
    AxisRotation,
}

/// One candidate motion: a recorded segment and the setup move to its start.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// The recorded segment's label (also the trace's).
    pub label: String,
    /// What it is.
    pub kind: CandidateKind,
    /// Joints at the start of the recorded segment (µm, °).
    pub start_display: [f64; 6],
    /// The recorded segment.
    pub segment: Segment,
    /// Bench time of the setup move from q = 0 to the start (s).
    pub setup_s: f64,
    /// Bench time of the recorded segment, settling included (s).
    pub duration_s: f64,
}

impl Candidate {
    /// Bench time charged to the candidate by the selection (s): setup from q = 0 plus the segment.
    pub fn cost_s(&self) -> f64 {
        self.setup_s + self.duration_s
    }
}

/// A candidate before timing: label, kind, start joints (µm, °) and recorded segment.
type UntimedCandidate = (String, CandidateKind, [f64; 6], Segment);

fn joints(q1: f64, q2: f64, q3: f64, q4: f64, q5: f64, q6: f64) -> [f64; 6] {
    [q1, q2, q3, q4, q5, q6]
}

/// The non-zero joints of a pose in words, e.g. `q1 = +150µm, q4 = -2.5°`, or `q = 0`.
fn pose_text(q: &[f64; 6]) -> String {
    let names = ["q1", "q2", "q3", "q4", "q5", "q6"];
    let units = ["µm", "µm", "µm", "°", "°", "°"];
    let parts: Vec<String> = (0..6)
        .filter(|&j| q[j] != 0.0)
        .map(|j| format!("{} = {}{}{}", names[j], if q[j] > 0.0 { "+" } else { "" }, q[j], units[j]))
        .collect();
    if parts.is_empty() {
        "q = 0".into()
    } else {
        parts.join(", ")
    }
}

/// A recorded move to `to`, labelled.
fn recorded_move(to: JointTarget, label: &str) -> Segment {
    Segment::Move { to, record: true, label: label.to_string(), through: false }
}

/// The candidate pool (see the module documentation), timed with `limits` and checked against
/// the robot's joint limits and the default laser range. Candidates that do not fit are left out.
pub fn candidate_pool(robot: &RobotDescription, limits: &MotionLimits) -> Vec<Candidate> {
    let mut raw: Vec<UntimedCandidate> = Vec::new();
    push_translations(&mut raw);
    push_sweeps(&mut raw);
    push_tilt_scans(&mut raw);
    push_axis_rotations(&mut raw);
    raw.into_iter().filter_map(|candidate| timed(candidate, robot, limits)).collect()
}

/// Translations: X_w (q3) and Z_w (q1) over 300 µm, Y_w (q2) over 20 µm, at held positions.
fn push_translations(raw: &mut Vec<UntimedCandidate>) {
    let mv = recorded_move;
    for held in [-150.0, 0.0, 150.0] {
        for q2 in [-100.0, 0.0, 100.0] {
            let start = joints(held, q2, -150.0, 0.0, 0.0, 0.0);
            let label =
                format!("translation X_w (q3) -150 -> +150 µm at {}", pose_text(&joints(held, q2, 0.0, 0.0, 0.0, 0.0)));
            raw.push((
                label.clone(),
                CandidateKind::Translation,
                start,
                mv(JointTarget::default().with(2, 150.0), &label),
            ));
            let start = joints(-150.0, q2, held, 0.0, 0.0, 0.0);
            let label =
                format!("translation Z_w (q1) -150 -> +150 µm at {}", pose_text(&joints(0.0, q2, held, 0.0, 0.0, 0.0)));
            raw.push((
                label.clone(),
                CandidateKind::Translation,
                start,
                mv(JointTarget::default().with(0, 150.0), &label),
            ));
        }
    }
    for (q1, q3) in [(0.0, 0.0), (150.0, 150.0), (-150.0, 150.0), (150.0, -150.0), (-150.0, -150.0)] {
        let start = joints(q1, -10.0, q3, 0.0, 0.0, 0.0);
        let label = format!("translation Y_w (q2) -10 -> +10 µm at {}", pose_text(&joints(q1, 0.0, q3, 0.0, 0.0, 0.0)));
        raw.push((label.clone(), CandidateKind::Translation, start, mv(JointTarget::default().with(1, 10.0), &label)));
    }
}

/// Absolute-gap sweeps at nine poses, three settings each.
fn push_sweeps(raw: &mut Vec<UntimedCandidate>) {
    let sweep_poses = [
        joints(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        joints(0.0, -100.0, 0.0, 0.0, 0.0, 0.0),
        joints(0.0, 100.0, 0.0, 0.0, 0.0, 0.0),
        joints(120.0, 0.0, 120.0, 0.0, 0.0, 0.0),
        joints(120.0, 0.0, -120.0, 0.0, 0.0, 0.0),
        joints(-120.0, 0.0, 120.0, 0.0, 0.0, 0.0),
        joints(-120.0, 0.0, -120.0, 0.0, 0.0, 0.0),
        joints(0.0, 0.0, 0.0, 3.0, 0.0, 0.0),
        joints(0.0, 0.0, 0.0, 0.0, 3.0, 0.0),
    ];
    for q in sweep_poses {
        for (from_nm, to_nm, rate_nm_per_s) in [(1540.0, 1580.0, 10.0), (1520.0, 1600.0, 20.0), (1550.0, 1570.0, 1.0)] {
            let label = format!("sweep {from_nm}-{to_nm} nm at {rate_nm_per_s} nm/s at {}", pose_text(&q));
            raw.push((label.clone(), CandidateKind::Sweep, q, Segment::Sweep { from_nm, to_nm, rate_nm_per_s, label }));
        }
    }
}

/// q4 and q5 rotations (tilt scans) at several gaps (q2) and lateral offsets (q1, q3), then
/// strategy 2's cross rotations: q4 at q5 = ±4°, q5 at q4 = ±4°.
fn push_tilt_scans(raw: &mut Vec<UntimedCandidate>) {
    let mv = recorded_move;
    let lateral = [(0.0, 0.0), (120.0, 120.0), (120.0, -120.0), (-120.0, 120.0), (-120.0, -120.0)];
    for q2 in [-100.0, 0.0, 150.0] {
        for (q1, q3) in lateral {
            for amplitude in [2.5, 4.0] {
                for (joint, name) in [(3usize, "q4"), (4usize, "q5")] {
                    let mut start = joints(q1, q2, q3, 0.0, 0.0, 0.0);
                    start[joint] = -amplitude;
                    let at = joints(q1, q2, q3, 0.0, 0.0, 0.0);
                    // The tilt scan, and the same rotation read for its fringe phase (gap
                    // changes) only.
                    for kind in ["tilt scan", "rotation"] {
                        let label = format!("{kind} {name} -{amplitude} -> +{amplitude}° at {}", pose_text(&at));
                        raw.push((
                            label.clone(),
                            CandidateKind::TiltScan,
                            start,
                            mv(JointTarget::default().with(joint, amplitude), &label),
                        ));
                    }
                }
            }
        }
    }
    for (joint, other, name) in [(3usize, 4usize, "q4"), (4, 3, "q5")] {
        for o in [-4.0, 4.0] {
            let mut start = [0.0; 6];
            start[joint] = -4.0;
            start[other] = o;
            let mut at = [0.0; 6];
            at[other] = o;
            let label = format!("tilt scan {name} -4 -> +4° at {}", pose_text(&at));
            raw.push((
                label.clone(),
                CandidateKind::TiltScan,
                start,
                mv(JointTarget::default().with(joint, 4.0), &label),
            ));
        }
    }
}

/// q6 rotations about the beam direction.
fn push_axis_rotations(raw: &mut Vec<UntimedCandidate>) {
    let mv = recorded_move;
    for (q1, q3) in [(0.0, 0.0), (120.0, -120.0), (-120.0, -120.0)] {
        let start = joints(q1, 0.0, q3, 0.0, 0.0, -20.0);
        let label = format!("q6 -20 -> +20° at {}", pose_text(&joints(q1, 0.0, q3, 0.0, 0.0, 0.0)));
        raw.push((label.clone(), CandidateKind::AxisRotation, start, mv(JointTarget::default().with(5, 20.0), &label)));
    }
}

/// The candidate timed by the plan model (setup move from q = 0, then the segment); `None` when
/// it does not fit the robot, limits or laser.
fn timed(
    (label, kind, start, segment): UntimedCandidate,
    robot: &RobotDescription,
    limits: &MotionLimits,
) -> Option<Candidate> {
    let plan = Plan {
        name: "candidate".into(),
        description: String::new(),
        segments: vec![
            Segment::Move {
                to: JointTarget::all(start),
                record: false,
                label: format!("setup: {label}"),
                through: false,
            },
            segment.clone(),
        ],
    };
    let segs = plan.expand(robot, [0.0; 6], limits).ok()?;
    Some(Candidate {
        label,
        kind,
        start_display: start,
        segment,
        setup_s: segs[0].duration_s,
        duration_s: segs[1].duration_s,
    })
}
