//! The discrepancy workflow (docs/diagnosis.md): replay the calibrated model against the recorded
//! observations, score every candidate effect of the library against the residual, design and
//! run discriminating motions, name, add and confirm effects. Owns the steps and the result.
//!
//! A GUI or CLI steps through [`Diagnosis`]: create it from the nominal model, the
//! observations and the calibrated extrinsics, call [`Diagnosis::step`] until it returns
//! `Ok(None)`, and show each [`Step`] (every step has [`Step::title`] and [`Step::summary`]).
//! [`Diagnosis::result`] is the serialisable [`DiagnosisResult`] (`effects`, `verdict`,
//! `residual_rms_before_nm`, `residual_rms_after_nm`, …), meant to be stored with a session.
//!
//! The order: (1) baseline: fit the extrinsics (no effect), residuals and where they live;
//! (2) score each candidate on its signature projected off the extrinsics; (3) for candidates
//! the data cannot see at their typical size, pick motions from [`motions::pool`] whose
//! projected signature is large and run them when a bench is given (otherwise report them);
//! (4) add the best significant candidate, refit, confirm on held-out motions (every fifth
//! motion is kept out of every fit), rescore, repeat; (5) the verdict: named when effects were
//! added and the residual is at most [`NOISE_FLOOR_FACTOR`] times the noise, none when the
//! baseline already is and no candidate passes, unexplained otherwise (with where the residual
//! lives). Candidates whose signature the extrinsics absorb on every available motion are
//! reported as equivalent to an extrinsic change, never named.

pub mod candidates;
pub mod crossval;
pub mod fit;
pub mod motions;
pub mod projection;
pub mod replay;
pub mod result;
pub mod scoring;
pub mod settings;
pub mod step;
pub mod validation;
mod workflow;

pub use result::{Bound, DiagnoseError, DiagnosisResult, NamedEffect, Verdict};
pub use settings::{
    DETECTABLE_SCORE, DISCRIMINATING_PREFIX, EQUIVALENT_SHARE, EXCHANGE_MARGIN, EXTRACT_OPTIONS, MAX_EFFECTS,
    MAX_MOTIONS, NOISE_FLOOR_FACTOR, REANALYSE_OPTIONS, REMOVE_BELOW_SIGMA,
};
pub use step::Step;
pub use workflow::Diagnosis;

#[cfg(test)]
mod tests;
