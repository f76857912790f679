//! Identifiability and uncertainty of a weighted least-squares problem, rank-deficient or not: which parameters
//! the data determine, their standard uncertainties and correlations, and the combinations they cannot see, in words.
//!
//! Generic over the parameters: the input is a weighted Jacobian `J` (row `r` already divided by the standard
//! uncertainty σ_r of observation `r`, columns in the estimator's internal units, e.g. mrad and µm), the weighted
//! residual vector, and [`ParamInfo`] metadata (name, display unit, scale internal → display, free or masked,
//! a "useful" uncertainty bound). [`analyse`] returns an [`IdentifiabilityReport`] (SPEC section 8).
//!
//! # Method
//!
//! * **SVD.** `J_F = U·S·Vᵀ` over the free columns `F`, in internal units (the units are chosen so the columns are
//!   comparable, SPEC section 6.4, and the reported singular values are the SPEC's numbers). When `J_F` has fewer
//!   rows than columns it is padded with zero rows, so `V` is always complete and the missing directions appear
//!   as zero singular values.
//! * **Numerical rank.** A direction `v_k` is *null* when `s_k ≤ relative_tolerance · s_max · max(m, n)`.
//! * **Covariance.** `C = f · Σ_{k not null} v_k v_kᵀ / s_k²`, the SVD pseudo-inverse of `JᵀJ` (defined for a
//!   rank-deficient `J`). `f = 1` gives the σ of the noise model alone ([`ParameterUncertainty::sigma_noise_model`]);
//!   the reported [`ParameterUncertainty::sigma`] uses `f = max(χ²_red, chi2_floor)` with
//!   `χ²_red = rss / (m − rank)`. The floor (default 1) is a deliberate choice: a fit that happens to leave residuals
//!   smaller than the noise model must not shrink σ below what the noise model promises; residuals larger than
//!   the noise model (model error, underestimated noise) do scale σ up. `chi2_floor = 0` gives the plain
//!   "scaled by the residual variance" convention. With no redundancy (`m ≤ rank`) `f = 1`.
//! * **Determined or not.** A direction `v_k` with singular value `s_k` contributes `f·(v_{k,i}/s_k)²` to
//!   `var(p_i)`. A free parameter is *not determined* when
//!   1. it has a component larger than `null_component_tolerance` in the null space: moving along a null
//!      combination changes it while leaving every prediction unchanged, so its variance is unbounded (the
//!      pseudo-inverse's finite number is then the minimum-norm convention, not information); or
//!   2. its σ (display units) exceeds its user-supplied useful bound ([`ParamInfo::useful_sigma`], e.g. 10 µm, 1°):
//!      its variance is dominated by directions the data see too weakly to be of use. The reason names the
//!      direction carrying the largest share of the variance.
//!
//!   A direction that is not null but alone gives some parameter a σ above its useful bound is *weak*; the
//!   number of directions neither null nor weak is the effective rank. A parameter that is not determined gets
//!   `sigma: None` and a reason: its value must never be shown as a bare number ([`ParameterUncertainty::format_value`]).
//! * **Correlations** `ρ_ij = C_ij / √(C_ii C_jj)` for parameters with a finite, non-zero variance; `None` (undefined)
//!   for masked parameters, parameters with a null-space component (infinite variance) or zero variance. A weakly
//!   determined parameter has a finite variance, so its correlations are given. `|ρ| > correlation_flag` is listed.
//! * **Base set.** Businger–Golub column-pivoted QR (pivot = largest remaining column norm) of `J_F` with each
//!   column scaled to "one useful bound" (internal bound = `useful_sigma / |scale|`, or one internal unit without a
//!   bound), so a column's norm is the data change, in σ, of a move of one useful bound. The first `effective_rank`
//!   pivots are the base set: the parameters to estimate if the others are held at nominal values. (nalgebra's
//!   `ColPivQR` pivots on the largest single *entry* of the remaining block, not the largest column norm, so its
//!   order is not the rank-revealing one; the few lines of pivoted Gram-Schmidt below are.)
//! * **Condition numbers** of `J_F` with every column scaled to unit norm (van der Sluis: close to the best
//!   diagonal scaling, and independent of units), for all free parameters and for the determined ones; a value
//!   above `condition_warning` (default 100) adds a warning sentence.
//! * **Unobservable combinations.** The null directions (an orthonormal basis of the null space, made sparse by
//!   Gauss-Jordan elimination with largest-entry pivoting) and the weak directions, each written as a sparse
//!   combination (largest |coefficient| normalised to +1, |coefficients| below `coefficient_cutoff` dropped) and
//!   described with the physical interpretations of SPEC section 6.4 where the parameter names match (fiber
//!   direction β_wf/θ_wf, gap split y_wf/Z_et, beam origin x_wf/z_wf against beam angles), or a generic sentence.

mod analysis;
mod estimate;
mod numerics;
mod words;

pub use analysis::analyse;
pub use estimate::analyse_estimate;
pub use numerics::{pseudo_inverse_covariance, PseudoInverse};

use super::parameter_scale;
use crate::model::extrinsics::PARAMETER_NAMES;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Default useful bound for an angle (°): an angle known worse than this is not determined.
pub const DEFAULT_USEFUL_ANGLE_DEG: f64 = 1.0;
/// Default useful bound for a length (µm): a length known worse than this is not determined.
pub const DEFAULT_USEFUL_LENGTH_UM: f64 = 10.0;

/// What the analysis needs to know about one parameter (one column of the Jacobian).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParamInfo {
    /// Name, e.g. `beta_wf`.
    pub name: String,
    /// Display unit, e.g. `°` or `µm`.
    pub unit: String,
    /// Display value per internal unit: `display = internal · scale` (e.g. 0.0573 °/mrad).
    pub scale: f64,
    /// Estimated (`true`) or held fixed / masked (`false`: its column is ignored).
    pub free: bool,
    /// Largest standard uncertainty (display units) at which the parameter is still useful; above it the
    /// parameter is reported as not determined. `None`: only the null-space test applies.
    pub useful_sigma: Option<f64>,
}

impl ParamInfo {
    /// A free parameter without a useful bound.
    pub fn new(name: impl Into<String>, unit: impl Into<String>, scale: f64) -> Self {
        Self { name: name.into(), unit: unit.into(), scale, free: true, useful_sigma: None }
    }

    /// The same parameter with a useful bound (display units).
    pub fn with_useful_sigma(mut self, bound: f64) -> Self {
        self.useful_sigma = Some(bound);
        self
    }

    /// The same parameter held fixed (masked).
    pub fn fixed(mut self) -> Self {
        self.free = false;
        self
    }

    /// The eight extrinsic parameters in the order of [`PARAMETER_NAMES`], all free, with the internal scales of
    /// [`parameter_scale`] (mrad, µm) and useful bounds [`DEFAULT_USEFUL_ANGLE_DEG`], [`DEFAULT_USEFUL_LENGTH_UM`].
    pub fn extrinsics() -> Vec<Self> {
        PARAMETER_NAMES
            .iter()
            .enumerate()
            .map(|(i, (name, unit))| {
                let bound = if *unit == "°" { DEFAULT_USEFUL_ANGLE_DEG } else { DEFAULT_USEFUL_LENGTH_UM };
                Self::new(*name, *unit, parameter_scale(i)).with_useful_sigma(bound)
            })
            .collect()
    }
}

/// Thresholds of the analysis; [`Options::default`] gives the documented defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Options {
    /// A singular value `s ≤ relative_tolerance · s_max · max(m, n)` is treated as zero (default 1e-8).
    pub relative_tolerance: f64,
    /// A parameter whose unit vector has a null-space component above this is not determined (default 1e-6).
    pub null_component_tolerance: f64,
    /// Floor of the reduced χ² used to scale the covariance (default 1; 0 = plain residual-variance scaling).
    pub chi2_floor: f64,
    /// Correlations with |ρ| above this are listed (default 0.8).
    pub correlation_flag: f64,
    /// Condition numbers above this produce a warning (default 100).
    pub condition_warning: f64,
    /// Coefficients below this (after normalising the largest to 1) are dropped from combinations (default 0.05).
    pub coefficient_cutoff: f64,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            relative_tolerance: 1e-8,
            null_component_tolerance: 1e-6,
            chi2_floor: 1.0,
            correlation_flag: 0.8,
            condition_warning: 100.0,
            coefficient_cutoff: 0.05,
        }
    }
}

/// Inputs that cannot be analysed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum AnalysisError {
    /// The Jacobian, the residuals and the parameter list disagree in size.
    #[error("size mismatch: Jacobian {rows}×{cols}, {residuals} residuals, {params} parameters")]
    Shape {
        /// Rows of the Jacobian.
        rows: usize,
        /// Columns of the Jacobian.
        cols: usize,
        /// Length of the residual vector.
        residuals: usize,
        /// Number of parameter descriptions.
        params: usize,
    },
    /// A NaN or infinite entry.
    #[error("{what} contains a non-finite value at index {index}")]
    NonFinite {
        /// `Jacobian` or `residuals`.
        what: &'static str,
        /// Index (column-major for the Jacobian).
        index: usize,
    },
    /// A parameter description is unusable.
    #[error("parameter {name}: {problem}")]
    BadParameter {
        /// Its name.
        name: String,
        /// What is wrong.
        problem: String,
    },
}

/// What the data say about one parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterUncertainty {
    /// Name.
    pub name: String,
    /// Display unit.
    pub unit: String,
    /// Standard uncertainty (display units) scaled by `max(χ²_red, floor)`; `None` when not determined.
    pub sigma: Option<f64>,
    /// Standard uncertainty (display units) from the noise model alone; `None` when not determined.
    pub sigma_noise_model: Option<f64>,
    /// Whether the data determine the parameter (see the module documentation).
    pub determined: bool,
    /// Why it is not determined (masked, not seen, too weakly seen); `None` when determined.
    pub reason: Option<String>,
}

impl ParameterUncertainty {
    /// The value with its uncertainty, e.g. `0.7440 ± 0.0016 °`, with σ to two significant digits; for a parameter
    /// the data do not determine, `not determined (reason)` and never the number.
    pub fn format_value(&self, value: f64) -> String {
        match (self.determined, self.sigma) {
            (true, Some(s)) if s > 0.0 && s.is_finite() => {
                let decimals = (1 - s.log10().floor() as i64).clamp(0, 12) as usize;
                format!("{value:.decimals$} ± {s:.decimals$} {}", self.unit)
            }
            (true, _) => format!("{value} {} (σ = 0: the noise model claims no uncertainty)", self.unit),
            (false, _) => format!("not determined ({})", self.reason.as_deref().unwrap_or("no reason recorded")),
        }
    }
}

/// Whether a combination is invisible or only weakly visible.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum CombinationKind {
    /// In the numerical null space: the data do not see it at all.
    NotSeen,
    /// Seen, but so weakly that it alone pushes some parameter's σ above its useful bound.
    Weak,
}

/// A parameter combination the data cannot determine.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Combination {
    /// `(name, coefficient)` in internal units, largest |coefficient| normalised to +1, small ones dropped,
    /// sorted by decreasing |coefficient|.
    pub coefficients: Vec<(String, f64)>,
    /// `‖J·c‖ / ‖c‖` for the full (undropped) combination `c`: the singular value for a single direction.
    pub singular_value: f64,
    /// Not seen at all, or only weakly.
    pub kind: CombinationKind,
    /// Standard uncertainty along the unit direction (internal units, scaled like `sigma`); `None` when not seen.
    pub sigma_along: Option<f64>,
    /// A sentence saying what the data do not see.
    pub description: String,
}

/// Everything [`analyse`] finds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IdentifiabilityReport {
    /// Number of observations (rows).
    pub n_observations: usize,
    /// Singular values of the free columns of `J` in internal units, descending; one per free parameter (zeros
    /// for the directions missing when there are fewer rows than free parameters).
    pub singular_values: Vec<f64>,
    /// Numerical rank (singular values above the relative tolerance).
    pub rank: usize,
    /// Directions that are neither null nor weak.
    pub effective_rank: usize,
    /// Condition number of the free columns scaled to unit norm; infinite when exactly singular (serde_json
    /// writes that as `null`); `None` without free parameters.
    pub condition_number: Option<f64>,
    /// The same for the determined parameters only; `None` when none is determined.
    pub condition_number_determined: Option<f64>,
    /// Identifiable (base) set in pivot order: the parameters to estimate with the others held fixed.
    pub base_set: Vec<String>,
    /// One entry per parameter, in input order (masked ones included, not determined).
    pub parameters: Vec<ParameterUncertainty>,
    /// Correlation matrix over all parameters in input order; `None` where undefined.
    pub correlation: Vec<Vec<Option<f64>>>,
    /// Pairs with |ρ| above the flag, `(name_i, name_j, ρ)` with i before j.
    pub strong_correlations: Vec<(String, String, f64)>,
    /// Combinations not seen, then those seen only weakly.
    pub unobservable: Vec<Combination>,
    /// `rss / (m − rank)`; `None` without redundancy.
    pub reduced_chi2: Option<f64>,
    /// Factor applied to the noise-model covariance: `max(χ²_red, chi2_floor)`, or 1 without redundancy.
    pub covariance_scale: f64,
    /// `√(rss / m)` in units of σ (1 = residuals at the noise floor); `None` without observations.
    pub residual_rms: Option<f64>,
    /// Sentences for the user.
    pub warnings: Vec<String>,
}

#[cfg(test)]
mod tests;
