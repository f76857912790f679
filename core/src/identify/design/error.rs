//! Why a design cannot be made.

use crate::plan::PlanError;

/// Why a design cannot be made: the plan, the pilot bench, the targets or the input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DesignError {
    /// A candidate or the assembled plan does not fit the robot, limits or laser.
    #[error("plan: {0}")]
    Plan(#[from] PlanError),
    /// The pilot bench could not be built or run.
    #[error("pilot bench: {0}")]
    Pilot(String),
    /// Even the whole pool does not reach the targets.
    #[error("the candidate pool cannot reach the targets: {0}")]
    Unreachable(String),
    /// Bad input (targets, margin, sizes).
    #[error("{0}")]
    Input(String),
}
