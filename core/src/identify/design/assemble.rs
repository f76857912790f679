//! The plan of a design: the chosen candidates in nearest-setup order, and its RON text.

use super::error::DesignError;
use super::pool::Candidate;
use crate::model::robot::RobotDescription;
use crate::plan::{JointTarget, MotionLimits, Plan, Segment};

/// Longest joint move time between two poses (s), from the plan timing model.
fn move_s(robot: &RobotDescription, limits: &MotionLimits, from: [f64; 6], to: [f64; 6]) -> f64 {
    let p = Plan {
        name: "m".into(),
        description: String::new(),
        segments: vec![Segment::Move { to: JointTarget::all(to), record: false, label: String::new(), through: false }],
    };
    p.duration_s(robot, from, limits).unwrap_or(f64::INFINITY)
}

/// The plan of the chosen candidates: nearest setup move first from q = 0, each candidate's
/// setup move then its recorded segment, ending at q = 0.
pub fn assemble(chosen: &[&Candidate], robot: &RobotDescription, limits: &MotionLimits) -> Result<Plan, DesignError> {
    let mut left: Vec<&Candidate> = chosen.to_vec();
    let mut at = [0.0; 6];
    let mut segments = Vec::new();
    while !left.is_empty() {
        let (i, _) = left
            .iter()
            .enumerate()
            .map(|(i, c)| (i, move_s(robot, limits, at, c.start_display)))
            .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)))
            .expect("left is not empty");
        let c = left.remove(i);
        segments.push(Segment::Move {
            to: JointTarget::all(c.start_display),
            record: false,
            label: format!("setup: {}", c.label),
            through: false,
        });
        segments.push(c.segment.clone());
        let end = match &c.segment {
            Segment::Move { to, .. } => to.resolve(c.start_display),
            _ => c.start_display,
        };
        at = end;
    }
    segments.push(Segment::Move {
        to: JointTarget::all([0.0; 6]),
        record: false,
        label: "return to 0".into(),
        through: false,
    });
    let plan = Plan {
        name: "optimised".into(),
        description: format!(
            "Experiment design (core/src/identify/design/): {} motions chosen from a candidate pool to reach the required σ of the joint estimate in the least bench time.",
            chosen.len()
        ),
        segments,
    };
    plan.expand(robot, [0.0; 6], limits)?;
    Ok(plan)
}

/// The plan as RON text with a header comment (each line prefixed with `// `).
pub fn plan_ron_with_header(plan: &Plan, header: &str) -> Result<String, DesignError> {
    let body = ron::ser::to_string_pretty(plan, ron::ser::PrettyConfig::default().struct_names(true).depth_limit(2))
        .map_err(|e| DesignError::Input(format!("plan to RON: {e}")))?;
    let mut out = String::new();
    for line in header.lines() {
        out.push_str("// ");
        out.push_str(line);
        out.push('\n');
    }
    out.push_str(&body);
    out.push('\n');
    Ok(out)
}
