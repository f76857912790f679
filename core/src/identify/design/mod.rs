//! Experiment design: choose motions from a candidate pool so that the joint estimate reaches
//! required standard uncertainties in the least bench time. Owns the candidate pool, the Fisher
//! information of each candidate, the selection and the plan it writes.
//!
//! # Method
//!
//! 1. **Candidate pool** ([`candidate_pool`]): single recorded segments with the unrecorded setup
//!    move that brings the robot to their start — translations (X_w, Z_w 300 µm; Y_w 20 µm) at
//!    several held positions, absolute-gap sweeps (three sweep settings) at nine poses, q4 and q5
//!    rotations (±2.5° and ±4°) at several gaps and lateral offsets, read for fringe amplitudes
//!    as tilt scans, and q6 rotations of ±20°. Every candidate is checked against the joint
//!    limits and timed by the plan's own timing model ([`Plan::expand`]: synchronized
//!    trapezoidal moves, settling, sweep rates), so the bench time of a candidate is
//!    `setup_s + duration_s`, its setup move counted from q = 0.
//! 2. **Fisher information** ([`pilot`]): the pool is run once on a *pilot* virtual bench built
//!    from the bench preset (its detector, stages, sampling rate, optics, air) whose truth is the
//!    **prior** extrinsics (the nominal design by default, never the hidden truth) and which
//!    hides no effects. Each recorded trace goes through the same extraction as a calibration
//!    ([`observations_from_trace`]: gap changes, absolute gaps, fringe amplitudes, each with the
//!    σ the analysis assigns), and the same joint machinery evaluates the weighted Jacobian
//!    `J` at the prior ([`joint::evaluate`], internal units mrad and µm). The information of a
//!    candidate is `F = JᵀJ` with its detector-gain nuisance parameter (one per tilt scan)
//!    eliminated by the Schur complement `F_ee − F_eg F_gg⁻¹ F_ge`, so informations of
//!    different candidates add. The pilot's truth being the prior, its residuals at the prior
//!    are pure noise, and the pool's robust reduced χ² of each observation kind (median of r²;
//!    the fringe amplitudes scatter several times more than the σ the extraction gives them)
//!    predicts the residual variance of a design. The identifier's report scales every σ by
//!    `√max(1, χ²_red)` of the whole fit, so the predicted σ are scaled the same way:
//!    `σ_t(S) · √max(1, Σ_{k∈S} E[Σr²]_k / (m_S − 8 − gains_S))`. The design is *locally* optimal at
//!    the prior, like any design for a nonlinear model.
//! 3. **Targets** ([`Target`]): a required σ on a linear combination `cᵀp` of the parameters
//!    (display units), e.g. σ(β_et) ≤ 0.005° or σ(y_wf − Z_et) ≤ 0.0167 µm. The predicted σ is
//!    `√(c'ᵀ I⁻¹ c')` with `I = Λ₀ + Σ_{k∈S} F_k`. A target may count only some candidates and
//!    free only some parameters: the identifier's bootstrap uses the absolute gaps alone with
//!    (β_et, θ_et, y_wf) free, so the design requires that sub-problem to be determined too.
//! 4. **Unidentifiable directions.** The information matrix of any plan of these motions is
//!    singular or nearly so: the split of the gap between y_wf and Z_et is seen only at second
//!    order, and a small plan may not see the fiber direction at all. Its determinant is then
//!    zero and `I⁻¹` does not exist. The design adds a weak Gaussian prior
//!    `Λ₀ = diag(1/σ₀²)` with σ₀ = the identifiability report's useful bounds (1° for angles,
//!    10 µm for lengths): `I` is then positive definite, and since every target is far below
//!    its σ₀ (0.2 µm ≪ 10 µm), a target can only be met by information from the data, never by
//!    the prior (the prior changes a met σ by less than 0.1 %). The targets are on determined
//!    combinations (the gap, not y_wf and Z_et separately), so the criterion stays meaningful
//!    where a D-criterion over all eight parameters would be dominated by the undetermined
//!    split. The log-determinant of `I` (D-criterion) is reported for information only.
//! 5. **Selection** ([`select`]): a cost-weighted greedy on the targets followed by pruning and
//!    exchange. The deficiency `f(S) = Σ_t max(0, ln(σ_t²(S) / τ_t²))` (τ_t the target bound
//!    times the design margin) is zero exactly when every target is met; the greedy adds the
//!    candidate with the largest decrease of `f` per second of bench time until `f = 0`, then
//!    removes every candidate (most expensive first) that is not needed, then swaps a chosen
//!    candidate for a cheaper unchosen one while the targets stay met. [`select_exhaustive`]
//!    (pools of at most 20) is the brute-force oracle the tests compare it with.
//! 6. **Plan** ([`Design::plan`]): the chosen candidates ordered by nearest setup move from
//!    q = 0, each preceded by its setup move, ending back at q = 0; its total bench time is the
//!    plan's own ([`Plan::duration_s`]), usually a little less than the sum of the candidates'
//!    costs (setup moves between neighbours are shorter than from q = 0).
//!
//! A design is only as good as its model: run the plan (`photorobot calibrate --plan`) and
//! check the reported σ; the design margin (default 0.8) leaves room for the difference between
//! prior and truth and for the residual-variance scaling of the reported σ.

mod assemble;
mod designer;
mod error;
mod pilot;
mod pool;
mod selection;
mod targets;

pub use assemble::{assemble, plan_ron_with_header};
pub use designer::{design, ChosenMotion, Design, DesignOptions, TargetResult};
pub use error::DesignError;
pub use pilot::{extrinsic_information, pilot, plans_information, PilotResult, Scatter, KIND_NAMES};
pub use pool::{candidate_pool, Candidate, CandidateKind};
pub use selection::{select, select_exhaustive, Criterion, Selection, SelectionProblem};
pub use targets::{weak_prior, Target, BOOTSTRAP_FREE};

#[cfg(test)]
mod tests;
