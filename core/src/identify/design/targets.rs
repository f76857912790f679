//! The targets of a design: required σ on linear combinations of the extrinsics, and the weak
//! prior that keeps the information matrix invertible.

use crate::identify::observability::{DEFAULT_USEFUL_ANGLE_DEG, DEFAULT_USEFUL_LENGTH_UM};
use crate::identify::{parameter_scale, N_EXTRINSICS};
use crate::model::extrinsics::PARAMETER_NAMES;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// A required standard uncertainty on a linear combination of the parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Target {
    /// Name, e.g. `beta_et` or `y_wf - Z_et`.
    pub name: String,
    /// Display unit of the combination (° or µm).
    pub unit: String,
    /// Coefficients over the eight parameters (order of [`PARAMETER_NAMES`], display units).
    pub combination: [f64; N_EXTRINSICS],
    /// Required standard uncertainty (display unit).
    pub max_sigma: f64,
    /// Count only sweeps and free only these parameters (the identifier's bootstrap); `None`:
    /// every candidate, every parameter.
    #[serde(default)]
    pub bootstrap: bool,
}

/// Parameters the identifier's bootstrap frees: β_et, θ_et, y_wf.
pub const BOOTSTRAP_FREE: [bool; N_EXTRINSICS] = [true, true, false, false, false, false, true, false];

impl Target {
    /// A target on one parameter, by name (as in [`PARAMETER_NAMES`]).
    pub fn parameter(name: &str, max_sigma: f64) -> Self {
        let i = PARAMETER_NAMES.iter().position(|p| p.0 == name).expect("a known parameter name");
        let mut combination = [0.0; N_EXTRINSICS];
        combination[i] = 1.0;
        Self { name: name.into(), unit: PARAMETER_NAMES[i].1.into(), combination, max_sigma, bootstrap: false }
    }

    /// The acceptance targets on `table2-ideal` (joint mode): σ ≤ 0.005° for β_et, θ_et,
    /// ≤ 0.01° for β_wf, θ_wf, ≤ 0.2 µm for x_wf, z_wf, and the gap y_wf − Z_et within 0.05 µm,
    /// read as 3σ ≤ 0.05 µm; plus the bootstrap: the sweeps alone must fix the lamella normal to
    /// 0.05° (a rough start for the motion hints, [`Target::bootstrap`]).
    pub fn acceptance_targets() -> Vec<Self> {
        let mut gap = [0.0; N_EXTRINSICS];
        gap[6] = 1.0;
        gap[4] = -1.0;
        let mut out = vec![
            Self::parameter("beta_et", 0.005),
            Self::parameter("theta_et", 0.005),
            Self::parameter("beta_wf", 0.01),
            Self::parameter("theta_wf", 0.01),
            Self::parameter("x_wf", 0.2),
            Self::parameter("z_wf", 0.2),
            Self {
                name: "y_wf - Z_et".into(),
                unit: "µm".into(),
                combination: gap,
                max_sigma: 0.05 / 3.0,
                bootstrap: false,
            },
        ];
        for name in ["beta_et", "theta_et"] {
            let mut t = Self::parameter(name, 0.05);
            t.name = format!("{name} (bootstrap: sweeps alone)");
            t.bootstrap = true;
            out.push(t);
        }
        out
    }

    /// Coefficients in internal units (mrad, µm): `cᵀp = c'ᵀx` with `p_i = x_i · scale_i`.
    pub(super) fn internal(&self) -> DVector<f64> {
        DVector::from_fn(N_EXTRINSICS, |i, _| self.combination[i] * parameter_scale(i))
    }
}

/// The prior information `Λ₀ = diag(1/σ₀²)` in internal units: σ₀ = 1° for angles, 10 µm for
/// lengths (the identifiability report's useful bounds).
pub fn weak_prior() -> DMatrix<f64> {
    DMatrix::from_fn(N_EXTRINSICS, N_EXTRINSICS, |i, j| {
        if i != j {
            0.0
        } else {
            let s0 = if PARAMETER_NAMES[i].1 == "°" { DEFAULT_USEFUL_ANGLE_DEG } else { DEFAULT_USEFUL_LENGTH_UM };
            (parameter_scale(i) / s0).powi(2)
        }
    })
}
