//! What the calibration allows a move before it runs: the uncertainty of the identified
//! extrinsics carried to the target the lamella really reaches at the planned joints.
//!
//! The bench has extrinsics `e + δ`, δ drawn from the estimate's covariance; at the planned
//! joints the target it realises moves by `G·δ` to first order (`G`: the target's derivative
//! with respect to the extrinsics at those joints, by central differences). Each coordinate's σ
//! is `√(gᵀ·Σ·g)`, exact for a linear map of a Gaussian (the validation forecast of
//! [`crate::validate::forecast`] draws samples because a peak to peak is not linear).

use super::target::TaskFrame;
use crate::calibration::{uncertainty_of, CalibrationReport};
use crate::model::extrinsics::{Extrinsics, PARAMETER_NAMES};
use crate::model::phase::PhaseModel;
use serde::{Deserialize, Serialize};

/// The uncertainty of a set of identified extrinsics: σ per parameter of [`PARAMETER_NAMES`]
/// (° or µm; `None`: not determined, left out) and their correlations.
#[derive(Debug, Clone, PartialEq)]
pub struct Uncertainty {
    /// σ of each parameter.
    pub sigma: [Option<f64>; 8],
    /// Correlations (1 on the diagonal).
    pub correlation: [[f64; 8]; 8],
}

impl Uncertainty {
    /// The uncertainty a calibration reports (its determined parameters and correlations).
    pub fn of_report(report: &CalibrationReport) -> Self {
        let (sigma, correlation) = uncertainty_of(&report.parameters, &report.identifiability);
        Self { sigma, correlation }
    }

    /// The parameters left out (not determined), by name.
    pub fn left_out(&self) -> Vec<String> {
        PARAMETER_NAMES.iter().zip(&self.sigma).filter(|(_, s)| s.is_none()).map(|(p, _)| p.0.to_string()).collect()
    }

    /// The variance of `g·δ` (g per parameter unit).
    fn variance(&self, g: &[f64; 8]) -> f64 {
        let s = |i: usize| self.sigma[i].filter(|v| v.is_finite()).unwrap_or(0.0);
        let mut v = 0.0;
        for i in 0..8 {
            for j in 0..8 {
                let rho = if i == j { 1.0 } else { self.correlation[i][j] };
                v += g[i] * g[j] * rho * s(i) * s(j);
            }
        }
        v.max(0.0)
    }
}

/// The σ of each coordinate the lamella reaches at the planned joints.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseForecast {
    /// σ of the gap (nm).
    pub gap_sigma_nm: f64,
    /// σ of the two tilts (°).
    pub tilt_sigma_deg: [f64; 2],
    /// σ of the lateral position (µm).
    pub lateral_sigma_um: [f64; 2],
    /// σ of the rotation about the beam (°).
    pub rotation_sigma_deg: f64,
}

impl PoseForecast {
    /// σ of the angle between the lamella's normal and the beam (°): the two tilts' together.
    pub fn tilt_angle_sigma_deg(&self) -> f64 {
        self.tilt_sigma_deg[0].hypot(self.tilt_sigma_deg[1])
    }
}

/// The forecast at joints `q_display` of `model`'s robot, planned in `frame` (the identified
/// extrinsics) whose uncertainty is `u`; `None` when the beam misses the lamella.
pub fn forecast_at(
    model: &PhaseModel,
    frame: &TaskFrame,
    u: &Uncertainty,
    q_display: &[f64; 6],
) -> Option<PoseForecast> {
    let base = frame.extrinsics().to_array();
    let reached = |i: usize, h: f64| -> Option<[f64; 6]> {
        let mut a = base;
        a[i] += h;
        let e = Extrinsics::from_array(a);
        let t = frame.with_extrinsics(&e).target_at(model, q_display)?;
        Some([t.gap_um * 1e3, t.tilt_deg[0], t.tilt_deg[1], t.lateral_um[0], t.lateral_um[1], t.rotation_deg])
    };
    // g[k][i]: coordinate k per unit of parameter i.
    let mut g = [[0.0; 8]; 6];
    #[allow(clippy::needless_range_loop)]
    for i in 0..8 {
        let h = 1e-4;
        let (plus, minus) = (reached(i, h)?, reached(i, -h)?);
        for (row, (p, m)) in g.iter_mut().zip(plus.iter().zip(&minus)) {
            row[i] = (p - m) / (2.0 * h);
        }
    }
    let s = |k: usize| u.variance(&g[k]).sqrt();
    Some(PoseForecast {
        gap_sigma_nm: s(0),
        tilt_sigma_deg: [s(1), s(2)],
        lateral_sigma_um: [s(3), s(4)],
        rotation_sigma_deg: s(5),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::BenchPreset;
    use crate::position::Target;

    /// A target's coordinates as the forecast orders them.
    fn coords(t: &Target) -> [f64; 6] {
        [t.gap_um * 1e3, t.tilt_deg[0], t.tilt_deg[1], t.lateral_um[0], t.lateral_um[1], t.rotation_deg]
    }

    fn identity() -> [[f64; 8]; 8] {
        std::array::from_fn(|i| std::array::from_fn(|j| if i == j { 1.0 } else { 0.0 }))
    }

    /// One uncertain parameter at a time: each coordinate's σ is the direct change of the
    /// reached target with that parameter off by σ (evaluated without linearisation, 1 %), and
    /// a perfectly correlated pair adds up as one shift of both.
    #[test]
    fn the_forecast_is_the_direct_change_of_the_reached_target() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let model = PhaseModel::of_preset(&preset, preset.truth).unwrap();
        let q = [30.0, -40.0, 20.0, 2.0, -1.5, 10.0];
        let frame = TaskFrame::at(&model, &preset.truth, &q).unwrap();
        let planned = coords(&frame.target_at(&model, &q).unwrap());
        let direct = |shift: &[(usize, f64)]| {
            let mut a = preset.truth.to_array();
            for (i, d) in shift {
                a[*i] += d;
            }
            let t = frame.with_extrinsics(&Extrinsics::from_array(a)).target_at(&model, &q).unwrap();
            let c = coords(&t);
            std::array::from_fn::<f64, 6, _>(|k| (c[k] - planned[k]).abs())
        };
        let as_array = |f: PoseForecast| {
            [
                f.gap_sigma_nm,
                f.tilt_sigma_deg[0],
                f.tilt_sigma_deg[1],
                f.lateral_sigma_um[0],
                f.lateral_sigma_um[1],
                f.rotation_sigma_deg,
            ]
        };
        for (i, s) in [(0, 0.001), (3, 0.002), (4, 0.5), (5, 0.01), (6, 0.02)] {
            let mut sigma = [None; 8];
            sigma[i] = Some(s);
            let f = as_array(forecast_at(&model, &frame, &Uncertainty { sigma, correlation: identity() }, &q).unwrap());
            let d = direct(&[(i, s)]);
            for k in 0..6 {
                assert!(
                    (f[k] - d[k]).abs() <= 0.01 * d[k] + 1e-9,
                    "parameter {i}, coordinate {k}: {} vs {}",
                    f[k],
                    d[k]
                );
            }
        }
        // Z_et and y_wf correlated +1: the gap moves as y_wf − Z_et does.
        let (z, y) = (4, 6);
        let mut rho = identity();
        rho[z][y] = 1.0;
        rho[y][z] = 1.0;
        let mut sigma = [None; 8];
        sigma[z] = Some(2.0);
        sigma[y] = Some(2.0);
        let f = forecast_at(&model, &frame, &Uncertainty { sigma, correlation: rho }, &q).unwrap();
        let d = direct(&[(z, 2.0), (y, 2.0)]);
        assert!((f.gap_sigma_nm - d[0]).abs() < 0.01 * d[0] + 1e-6, "{} vs {}", f.gap_sigma_nm, d[0]);
        let none = forecast_at(&model, &frame, &Uncertainty { sigma: [None; 8], correlation: identity() }, &q).unwrap();
        assert_eq!(none.gap_sigma_nm, 0.0);
    }
}
