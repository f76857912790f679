//! What the analysis finds: per parameter, per unseen combination, and as a whole.

use serde::{Deserialize, Serialize};

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

/// Everything [`super::analyse`] finds.
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
