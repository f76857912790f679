//! The straight path in task space from where the lamella is to a target, as joint waypoints
//! through the IGM: owns the legs (the gap held when asked), the spacing of the waypoints and
//! the limit check of every waypoint before anything moves.
//!
//! The bench moves in straight lines in joint space between waypoints; they are close enough
//! that the path between them stays on the task-space line to well under a nanometre of gap
//! (at most 10 µm of translation, 0.2° of tilt and 1° of rotation per step).

use super::target::{Target, TaskFrame};
use super::MoveError;
use crate::model::kinematics::IgmError;
use crate::model::phase::PhaseModel;

/// Largest step between waypoints along the gap and across the beam (µm).
const STEP_UM: f64 = 10.0;
/// Largest step between waypoints of the tilt (°).
const STEP_TILT_DEG: f64 = 0.2;
/// Largest step between waypoints of the rotation about the beam (°).
const STEP_ROTATION_DEG: f64 = 1.0;

/// A path to a target: its waypoints in joints (µm, °) and in task coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct Path {
    /// Joints at each waypoint (µm, °), the start first.
    pub joints: Vec<[f64; 6]>,
    /// The target realised at each waypoint (planned).
    pub targets: Vec<Target>,
}

impl Path {
    /// The joints at the end (µm, °).
    pub fn end(&self) -> [f64; 6] {
        *self.joints.last().expect("a path has its start")
    }
}

/// The task-space corners of the path from `from` to `to`: straight, or with the gap held at
/// the larger of the two while the rest moves (the lamella never comes closer to the fiber on
/// the way than at either end).
pub fn corners(from: &Target, to: &Target, keep_gap: bool) -> Vec<Target> {
    if !keep_gap {
        return vec![*from, *to];
    }
    let held = from.gap_um.max(to.gap_um);
    let mut out = vec![*from];
    for c in [Target { gap_um: held, ..*from }, Target { gap_um: held, ..*to }, *to] {
        if out.last() != Some(&c) {
            out.push(c);
        }
    }
    out
}

/// Steps a leg from `a` to `b` needs ([`STEP_UM`], [`STEP_TILT_DEG`], [`STEP_ROTATION_DEG`]).
fn steps(a: &Target, b: &Target) -> usize {
    let lateral = (b.lateral_um[0] - a.lateral_um[0]).hypot(b.lateral_um[1] - a.lateral_um[1]);
    let tilt = (b.tilt_deg[0] - a.tilt_deg[0]).hypot(b.tilt_deg[1] - a.tilt_deg[1]);
    let n = [
        (b.gap_um - a.gap_um).abs() / STEP_UM,
        lateral / STEP_UM,
        tilt / STEP_TILT_DEG,
        (b.rotation_deg - a.rotation_deg).abs() / STEP_ROTATION_DEG,
    ]
    .into_iter()
    .fold(1.0f64, f64::max);
    n.ceil() as usize
}

/// A point a fraction `s` of the way from `a` to `b`, every coordinate linear.
fn between(a: &Target, b: &Target, s: f64) -> Target {
    let lerp = |x: f64, y: f64| x + s * (y - x);
    Target {
        gap_um: lerp(a.gap_um, b.gap_um),
        tilt_deg: [lerp(a.tilt_deg[0], b.tilt_deg[0]), lerp(a.tilt_deg[1], b.tilt_deg[1])],
        lateral_um: [lerp(a.lateral_um[0], b.lateral_um[0]), lerp(a.lateral_um[1], b.lateral_um[1])],
        rotation_deg: lerp(a.rotation_deg, b.rotation_deg),
    }
}

/// Plan the path from joints `start` (µm, °) to `target` through the IGM of `model` (its robot,
/// with any effects a diagnosis added) in `frame`: every waypoint is solved and checked against
/// the joint limits, so a target out of reach is refused before anything moves, with the joint
/// and the limit.
pub fn plan_path(
    model: &PhaseModel,
    frame: &TaskFrame,
    start: [f64; 6],
    target: &Target,
    keep_gap: bool,
) -> Result<Path, MoveError> {
    let desc = model.chain.description();
    let from = frame.target_at(model, &start).ok_or(MoveError::NoCavity { joints: start })?;
    // The end first: a target out of reach says so about itself, not about a waypoint before it.
    let end = solve(model, frame, target, &desc.q_from_display(&start), target)?;
    let mut joints = vec![start];
    let mut targets = vec![from];
    let mut q_ref = desc.q_from_display(&start);
    for leg in corners(&from, target, keep_gap).windows(2) {
        let n = steps(&leg[0], &leg[1]);
        for k in 1..=n {
            let t = between(&leg[0], &leg[1], k as f64 / n as f64);
            q_ref = solve(model, frame, &t, &q_ref, target)?;
            let qd = desc.q_to_display(&q_ref);
            joints.push(std::array::from_fn(|i| qd[i]));
            targets.push(t);
        }
    }
    // The path ends where the end was solved on its own (the same solution branch).
    let last = desc.q_to_display(&end);
    let reached = joints.last().expect("a path has its start");
    if (0..6).any(|i| (reached[i] - last[i]).abs() > 1e-6) {
        return Err(MoveError::Unreachable {
            target: *target,
            reason: "the path reaches the target on another branch of the inverse model than the target's own".into(),
        });
    }
    Ok(Path { joints, targets })
}

/// The joints (internal units) that put the lamella at `t`, nearest `q_ref`, within the limits.
fn solve(
    model: &PhaseModel,
    frame: &TaskFrame,
    t: &Target,
    q_ref: &[f64],
    target: &Target,
) -> Result<Vec<f64>, MoveError> {
    let wte = frame.end_effector_pose(t);
    let q = model.chain.igm(&wte, q_ref).map_err(|e| unreachable(t, target, e))?;
    model.chain.check_limits(&q).map_err(|v| unreachable(t, target, IgmError::OutOfLimits(v)))?;
    Ok(q)
}

/// Why `t`, a point on the way to `target`, cannot be reached, in the technician's words.
fn unreachable(t: &Target, target: &Target, e: IgmError) -> MoveError {
    let on_the_way = if t == target { String::new() } else { format!(" (on the way, at {})", t.describe()) };
    let reason = match e {
        IgmError::OrientationUnreachable(_) => {
            format!("the goniometers cannot reach the tilt ({:.3}°, {:.3}°){on_the_way}", t.tilt_deg[0], t.tilt_deg[1])
        }
        IgmError::OutOfLimits(v) => format!("{v}{on_the_way}"),
        other => format!("{other}{on_the_way}"),
    };
    MoveError::Unreachable { target: *target, reason }
}
