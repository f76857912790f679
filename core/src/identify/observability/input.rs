//! What the analysis takes: the description of each parameter, the thresholds, and the errors of
//! input it cannot analyse.

use crate::identify::parameter_scale;
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
