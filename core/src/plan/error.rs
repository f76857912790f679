//! Why a plan cannot run, with the segment, its label and the field path of the problem.

use super::{LaserLimits, JOINT_FIELDS};
use crate::model::kinematics::LimitViolation;
use std::fmt;

/// Why a plan cannot run. Every error about a segment names its index in `segments` and its
/// label, and says what was expected.
#[derive(Debug, Clone, PartialEq)]
pub enum PlanError {
    /// A number is NaN or infinite.
    NonFinite {
        /// Segment index.
        segment: usize,
        /// Segment label.
        label: String,
        /// Field, e.g. `to.q3_um` or `rate_nm_per_s`.
        field: String,
        /// The value.
        value: f64,
    },
    /// A rate or duration is zero or negative.
    NotPositive {
        /// Segment index.
        segment: usize,
        /// Segment label.
        label: String,
        /// Field, e.g. `rate_nm_per_s` or `duration_s`.
        field: String,
        /// The value.
        value: f64,
    },
    /// A sweep starts and ends at the same wavelength.
    EmptySweep {
        /// Segment index.
        segment: usize,
        /// Segment label.
        label: String,
        /// The wavelength (nm).
        wavelength_nm: f64,
    },
    /// A sweep leaves the laser's range.
    SweepOutOfRange {
        /// Segment index.
        segment: usize,
        /// Segment label.
        label: String,
        /// `from_nm` or `to_nm`.
        field: String,
        /// The wavelength (nm).
        value_nm: f64,
        /// The laser's range (nm).
        laser: LaserLimits,
    },
    /// A move passes through its target (`through`) but what follows is not a move: a sweep, a
    /// dwell or the plan's end needs the stages settled.
    ThroughNotToMove {
        /// Segment index.
        segment: usize,
        /// Segment label.
        label: String,
    },
    /// A move ends outside the joint limits.
    OutOfLimits {
        /// Segment index.
        segment: usize,
        /// Segment label.
        label: String,
        /// Which joint, by how much.
        violation: LimitViolation,
    },
    /// The start joint vector is outside the limits.
    StartOutOfLimits {
        /// Which joint, by how much.
        violation: LimitViolation,
    },
    /// The start joint vector has a NaN or infinite value.
    StartNotFinite {
        /// Joint field name.
        joint: &'static str,
        /// The value.
        value: f64,
    },
    /// The plan has no segments.
    EmptyPlan,
    /// A motion limit is not usable.
    BadMotionLimits {
        /// Field of [`MotionLimits`](super::MotionLimits).
        field: &'static str,
        /// The value.
        value: f64,
        /// What was expected.
        expected: &'static str,
    },
    /// The laser range is not usable.
    BadLaserLimits {
        /// The range as given.
        laser: LaserLimits,
    },
    /// The robot does not match the plan's joints (three prismatic then three revolute).
    IncompatibleRobot {
        /// What does not match.
        problem: String,
    },
}

impl PlanError {
    /// The segment the error is about, if any.
    pub fn segment(&self) -> Option<usize> {
        match self {
            PlanError::NonFinite { segment, .. }
            | PlanError::NotPositive { segment, .. }
            | PlanError::EmptySweep { segment, .. }
            | PlanError::SweepOutOfRange { segment, .. }
            | PlanError::ThroughNotToMove { segment, .. }
            | PlanError::OutOfLimits { segment, .. } => Some(*segment),
            _ => None,
        }
    }

    /// Path of the field in the plan file (e.g. `segments[3].rate_nm_per_s`), if any.
    pub fn field_path(&self) -> Option<String> {
        match self {
            PlanError::NonFinite { segment, field, .. }
            | PlanError::NotPositive { segment, field, .. }
            | PlanError::SweepOutOfRange { segment, field, .. } => Some(format!("segments[{segment}].{field}")),
            PlanError::EmptySweep { segment, .. } => Some(format!("segments[{segment}].to_nm")),
            PlanError::ThroughNotToMove { segment, .. } => Some(format!("segments[{segment}].through")),
            PlanError::OutOfLimits { segment, violation, .. } => {
                let field = violation_field(violation);
                Some(format!("segments[{segment}].to{}", field.map(|f| format!(".{f}")).unwrap_or_default()))
            }
            PlanError::EmptyPlan => Some("segments".into()),
            _ => None,
        }
    }

    /// The label of the segment the error is about, if it has one.
    pub fn label(&self) -> Option<&str> {
        match self {
            PlanError::NonFinite { label, .. }
            | PlanError::NotPositive { label, .. }
            | PlanError::EmptySweep { label, .. }
            | PlanError::SweepOutOfRange { label, .. }
            | PlanError::ThroughNotToMove { label, .. }
            | PlanError::OutOfLimits { label, .. } => Some(label.as_str()).filter(|l| !l.is_empty()),
            _ => None,
        }
    }

    /// What is wrong and what was expected, without the location.
    pub fn problem(&self) -> String {
        match self {
            PlanError::NonFinite { value, .. } => {
                format!("expected a finite number, found {value}")
            }
            PlanError::NotPositive { value, .. } => {
                format!("expected a positive number, found {value}")
            }
            PlanError::EmptySweep { wavelength_nm, .. } => {
                format!("expected to_nm different from from_nm, found both {wavelength_nm} nm (an empty sweep)")
            }
            PlanError::SweepOutOfRange { value_nm, laser, .. } => format!(
                "expected a wavelength inside the laser's range {}-{} nm, found {value_nm} nm",
                laser.min_nm, laser.max_nm
            ),
            PlanError::ThroughNotToMove { .. } => {
                "expected another move after a move with `through: true` (a sweep, a dwell or the plan's end needs the stages settled)".into()
            }
            PlanError::OutOfLimits { violation, .. } => {
                format!("the move ends out of the joint limits: {violation}")
            }
            PlanError::StartOutOfLimits { violation } => {
                format!("the start position is out of the joint limits: {violation}")
            }
            PlanError::StartNotFinite { joint, value } => {
                format!("start position `{joint}`: expected a finite number, found {value}")
            }
            PlanError::EmptyPlan => "expected at least one segment, found none".into(),
            PlanError::BadMotionLimits { field, value, expected } => {
                format!("motion limit `{field}`: expected {expected}, found {value}")
            }
            PlanError::BadLaserLimits { laser } => {
                format!("laser range: expected finite min_nm < max_nm, found {}-{} nm", laser.min_nm, laser.max_nm)
            }
            PlanError::IncompatibleRobot { problem } => {
                format!("robot does not fit the plan: {problem}")
            }
        }
    }

    /// The problem with the segment's label in front, as shown after a field path.
    pub fn labelled_problem(&self) -> String {
        match self.label() {
            Some(l) => format!("(segment \"{l}\") {}", self.problem()),
            None => self.problem(),
        }
    }
}

fn violation_field(v: &LimitViolation) -> Option<&'static str> {
    // The femto-6dof joints are named q1..q6; other robots may name them otherwise.
    let joint_number = v.joint.strip_prefix('q')?.parse::<usize>().ok()?;
    JOINT_FIELDS.get(joint_number.checked_sub(1)?).copied()
}

impl fmt::Display for PlanError {
    /// `segments[2].to.q3_um (segment "label") the move ends out of …`, or the bare problem for
    /// errors that are not about a field of the plan.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.field_path() {
            Some(path) => write!(f, "{path}: {}", self.labelled_problem()),
            None => f.write_str(&self.problem()),
        }
    }
}

impl std::error::Error for PlanError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            PlanError::OutOfLimits { violation, .. } | PlanError::StartOutOfLimits { violation } => Some(violation),
            _ => None,
        }
    }
}
