//! The plan of one validation motion: its approach, the envelope dither, the moves through its
//! waypoints, and the stops along it where the bench measures what the validation's proof needs
//! (the fringe contrast on a short axial dither, an absolute gap on a short wavelength sweep).
//! Owns where the stops fall and the commands that compensate stages with play.

use super::ValidationMotion;
use crate::model::effects::Backlash;
use crate::plan::{JointTarget, Plan, Segment};
use serde::{Deserialize, Serialize};

/// Label of the short axial dither recorded before each validation motion: with a good
/// calibration the motion itself shows no fringe, so the envelope is measured on the dither.
pub const ENVELOPE_DITHER: &str = "envelope dither";
/// Label of the axial dither at a stop (followed by the stop's number, 1 on): the contrast there.
pub const CONTRAST_DITHER: &str = "contrast dither";
/// Label of the sweep at a pose (followed by its number, 0 for the start): the absolute gap there.
pub const ABSOLUTE_GAP: &str = "absolute gap";
/// Half the span of a stop's sweep around the bench's wavelength (nm): 20 nm cross 15 fringes
/// at 900 µm, enough for the sweep fit (about 0.5 nm of σ on the virtual bench).
pub const SWEEP_HALF_SPAN_NM: f64 = 10.0;
/// The rate of a stop's sweep (nm/s): one second of bench time each.
pub const SWEEP_RATE_NM_PER_S: f64 = 20.0;
/// Joint moves smaller than this (display units) set no direction of travel: the IGM's
/// round-off, not a reversal.
const REVERSAL_EPS: f64 = 1e-9;

/// What a validation motion measures besides its fringes, at its start and at stops along it:
/// the fringe contrast (a 1 µm axial dither, a fraction of a second) at every stop, and an
/// absolute gap (a sweep of 20 nm, one second) at the start and every stop when the bench has a
/// tunable laser and `sweeps` is set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct StopSettings {
    /// Stops along the motion (0: none, only the start's envelope dither).
    pub stops: usize,
    /// Absolute gaps from sweeps at the start and the stops.
    pub sweeps: bool,
}

impl Default for StopSettings {
    /// Two stops (three poses with the start: what the tilt term about the optical axis needs)
    /// and their sweeps.
    fn default() -> Self {
        StopSettings { stops: 2, sweeps: true }
    }
}

impl StopSettings {
    /// No stop and no sweep: the motion and its envelope dither alone.
    pub const NONE: StopSettings = StopSettings { stops: 0, sweeps: false };
}

/// The waypoints (indices, 1 ..= count) after which a motion stops: evenly along it; a closed
/// path (the circle) does not stop at its end, which is its start.
pub fn stop_waypoints(motion: ValidationMotion, count: usize, stops: usize) -> Vec<usize> {
    let parts = if motion == ValidationMotion::Circle { stops + 1 } else { stops };
    let mut out: Vec<usize> =
        (1..=stops).map(|k| ((k * count) as f64 / parts.max(1) as f64).round() as usize).collect();
    out.retain(|&w| (1..=count).contains(&w));
    out.dedup();
    out
}

/// One pose or sweep a validation plan must reach, in order.
enum Wanted {
    Pose([f64; 6], String),
    Sweep(String),
}

/// What [`plan_reaching`] gives: the plan, the stages' state at its first recorded sample, and
/// the index of the segment that reaches the dither's far end, its return to the first
/// waypoint, then every later waypoint.
pub(crate) struct ValidationPlan {
    pub plan: Plan,
    pub state: Backlash,
    pub reaching: Vec<usize>,
}

/// The plan of a validation motion through `waypoints` with stops after the waypoints `stops`
/// (each a contrast dither, then a sweep around `sweep_nm` when given; a sweep at the start too):
/// an unrecorded move to the first waypoint, a recorded axial dither of 1 µm out and back (the
/// fringe envelope), then recorded moves through the waypoints.
///
/// For stages with play (reversal errors of width `play`, display units, zero for none; the
/// extended model's [`crate::model::effects::reversal_play`]) the commands lead the wanted
/// poses by half the play in each joint's direction of travel, so that the stages go through
/// the waypoints. Before the first recorded move every stage with play is loaded from the
/// side opposite its first travel (an unrecorded move of 1.5 plays back, then forward), so its
/// state is known whatever it did before; where a joint reverses, a recorded take-up move
/// carries its command across the play while the stage stands still.
pub(crate) fn plan_reaching(
    name: &str,
    label: &str,
    waypoints: &[[f64; 6]],
    play: &[f64; 6],
    stops: &[usize],
    sweep_nm: Option<f64>,
) -> ValidationPlan {
    let name_of_path = label;
    let w0 = waypoints[0];
    let dither = |w: [f64; 6]| {
        let mut out = w;
        out[1] += 1.0;
        out
    };
    let half: [f64; 6] = std::array::from_fn(|j| 0.5 * play[j].abs());
    let mut wanted = vec![Wanted::Pose(dither(w0), ENVELOPE_DITHER.into()), Wanted::Pose(w0, ENVELOPE_DITHER.into())];
    if sweep_nm.is_some() {
        wanted.push(Wanted::Sweep(format!("{ABSOLUTE_GAP} 0")));
    }
    for (k, w) in waypoints.iter().enumerate().skip(1) {
        wanted.push(Wanted::Pose(*w, label.into()));
        if let Some(s) = stops.iter().position(|&i| i == k) {
            let label = format!("{CONTRAST_DITHER} {}", s + 1);
            wanted.push(Wanted::Pose(dither(*w), label.clone()));
            wanted.push(Wanted::Pose(*w, label));
            if sweep_nm.is_some() {
                wanted.push(Wanted::Sweep(format!("{ABSOLUTE_GAP} {}", s + 1)));
            }
        }
    }
    // Each joint's first direction of travel.
    let mut dir = [0.0f64; 6];
    let mut prev = w0;
    for w in wanted.iter().filter_map(|w| if let Wanted::Pose(p, _) = w { Some(p) } else { None }) {
        for j in 0..6 {
            if dir[j] == 0.0 && (w[j] - prev[j]).abs() > REVERSAL_EPS {
                dir[j] = (w[j] - prev[j]).signum();
            }
        }
        prev = *w;
    }
    let dir = dir.map(|d| if d == 0.0 { 1.0 } else { d });
    let start: [f64; 6] = std::array::from_fn(|j| w0[j] + dir[j] * half[j]);
    let mut segments = Vec::new();
    if half.iter().any(|h| *h > 0.0) {
        let load: [f64; 6] = std::array::from_fn(|j| start[j] - 3.0 * dir[j] * half[j]);
        segments.push(Segment::Move {
            to: JointTarget::all(load),
            record: false,
            label: "approach".into(),
            through: false,
        });
    }
    segments.push(Segment::Move {
        to: JointTarget::all(start),
        record: false,
        label: "approach".into(),
        through: false,
    });
    let state = Backlash { offset: std::array::from_fn(|j| -dir[j] * half[j]), command: start };
    let mut dir = dir;
    let mut prev = w0;
    let mut command = start;
    let mut reaching = Vec::with_capacity(waypoints.len() + 1);
    for item in wanted {
        let (w, label) = match item {
            Wanted::Sweep(label) => {
                let centre = sweep_nm.unwrap_or_default();
                segments.push(Segment::Sweep {
                    from_nm: centre - SWEEP_HALF_SPAN_NM,
                    to_nm: centre + SWEEP_HALF_SPAN_NM,
                    rate_nm_per_s: SWEEP_RATE_NM_PER_S,
                    label,
                });
                continue;
            }
            Wanted::Pose(w, label) => (w, label),
        };
        let mut take_up = command;
        let mut reverses = false;
        for j in 0..6 {
            let d = w[j] - prev[j];
            if half[j] > 0.0 && d.abs() > REVERSAL_EPS && d.signum() != dir[j] {
                dir[j] = d.signum();
                take_up[j] = prev[j] + dir[j] * half[j];
                reverses = true;
            }
        }
        if reverses {
            segments.push(Segment::Move {
                to: JointTarget::all(take_up),
                record: true,
                label: label.clone(),
                through: false,
            });
        }
        command = std::array::from_fn(|j| w[j] + dir[j] * half[j]);
        if label == ENVELOPE_DITHER || label == name_of_path {
            reaching.push(segments.len());
        }
        segments.push(Segment::Move { to: JointTarget::all(command), record: true, label, through: false });
        prev = w;
    }
    let plan = Plan { name: name.to_string(), description: String::new(), segments };
    ValidationPlan { plan, state, reaching }
}

/// Every recorded move along the path (labelled `path`) followed by another goes through its
/// target without settling: the stages run the path's waypoints as one motion. They settle
/// before the dithers (whose fringe contrast the stages' last nanometres of travel would
/// spoil: the contrast's tilt term read 19-23 nm against 1.5 nm on the emulated controllers),
/// before a sweep and at the end.
pub(crate) fn run_through(segments: &mut [Segment], path: &str) {
    for i in 1..segments.len() {
        let next_on_path = matches!(&segments[i], Segment::Move { record: true, label, .. } if label == path);
        if let Segment::Move { record: true, through, label, .. } = &mut segments[i - 1] {
            *through = next_on_path && label == path;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two stops: the circle stops at a third and two thirds of its way, a rotation at its
    /// middle and its end; a plan with them reaches every waypoint in order, dithers at each
    /// stop and sweeps at the start and at each stop.
    #[test]
    fn stops_fall_evenly_and_the_plan_dithers_and_sweeps_there() {
        assert_eq!(stop_waypoints(ValidationMotion::Circle, 72, 2), vec![24, 48]);
        assert_eq!(stop_waypoints(ValidationMotion::RotationXf, 24, 2), vec![12, 24]);
        assert_eq!(stop_waypoints(ValidationMotion::RotationOpticalAxis, 46, 0), Vec::<usize>::new());
        let waypoints: Vec<[f64; 6]> = (0..=24).map(|k| [0.0, 0.0, 0.0, k as f64 * 0.25, 0.0, 0.0]).collect();
        let stops = stop_waypoints(ValidationMotion::RotationXf, 24, 2);
        let p = plan_reaching(
            "validation",
            ValidationMotion::RotationXf.name(),
            &waypoints,
            &[0.0; 6],
            &stops,
            Some(1560.0),
        );
        let labels: Vec<&str> = p.plan.segments.iter().map(|s| s.label()).collect();
        assert_eq!(labels.iter().filter(|l| l.starts_with(ABSOLUTE_GAP)).count(), 3, "{labels:?}");
        assert_eq!(labels.iter().filter(|l| l.starts_with(CONTRAST_DITHER)).count(), 4, "{labels:?}");
        assert_eq!(p.reaching.len(), waypoints.len() + 1);
        let i = labels.iter().position(|l| *l == "contrast dither 1").unwrap();
        assert_eq!(labels[i - 1], ValidationMotion::RotationXf.name(), "the first stop after waypoint 12");
        // Settled everywhere; run through, from one waypoint of the path to the next only (settled
        // before a dither or a sweep, along a dither and at the end).
        assert!(!p.plan.segments.iter().any(|s| matches!(s, Segment::Move { through: true, .. })));
        let path = ValidationMotion::RotationXf.name();
        let mut p = p;
        run_through(&mut p.plan.segments, path);
        for (i, seg) in p.plan.segments.iter().enumerate() {
            let next_on_path = p.plan.segments.get(i + 1).is_some_and(|n| n.is_move() && n.label() == path);
            if let Segment::Move { through, .. } = seg {
                assert_eq!(*through, seg.label() == path && next_on_path, "segment {i} {}", seg.label());
            }
        }
        assert_eq!(p.plan.segments.iter().filter(|s| matches!(s, Segment::Move { through: true, .. })).count(), 22);
        p.plan.validate().unwrap();
        let without =
            plan_reaching("validation", ValidationMotion::RotationXf.name(), &waypoints, &[0.0; 6], &[], None);
        assert_eq!(without.plan.segments.len(), 1 + 2 + 24, "approach, dither, waypoints");
    }
}
