//! What one move did, as the session keeps it and the report shows it: the target requested, the
//! joints, the forecast, the measured gap and the verdict.

use super::forecast::PoseForecast;
use super::target::Target;
use serde::{Deserialize, Serialize};

/// Joint values with their units in their names, as the trace CSV header has them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Joints {
    /// q1 (µm).
    pub q1_um: f64,
    /// q2 (µm).
    pub q2_um: f64,
    /// q3 (µm).
    pub q3_um: f64,
    /// q4 (°).
    pub q4_deg: f64,
    /// q5 (°).
    pub q5_deg: f64,
    /// q6 (°).
    pub q6_deg: f64,
}

impl From<[f64; 6]> for Joints {
    fn from(q: [f64; 6]) -> Self {
        Self { q1_um: q[0], q2_um: q[1], q3_um: q[2], q4_deg: q[3], q5_deg: q[4], q6_deg: q[5] }
    }
}

impl Joints {
    /// The six values in joint order (µm, °).
    pub fn to_array(&self) -> [f64; 6] {
        [self.q1_um, self.q2_um, self.q3_um, self.q4_deg, self.q5_deg, self.q6_deg]
    }
}

/// How a move ended, judged by a measurement that does not use the extrinsics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// The measured gap is within the bound (the forecast and the measurement's σ, ×3).
    Confirmed,
    /// The measured gap is beyond the bound: the lamella is not where it was asked to be.
    Off,
    /// The move ran but nothing measured its gap (no tunable laser and no measured reference).
    Unconfirmed,
    /// The technician stopped it.
    Stopped,
    /// The bench failed during the move, or the measurement could not be analysed.
    Failed,
}

impl Verdict {
    /// The verdict as one word.
    pub fn word(self) -> &'static str {
        match self {
            Verdict::Confirmed => "confirmed",
            Verdict::Off => "off",
            Verdict::Unconfirmed => "unconfirmed",
            Verdict::Stopped => "stopped",
            Verdict::Failed => "failed",
        }
    }
}

/// Standard uncertainties in the bound of a confirmed move: 3σ, 99.7 % of honest moves.
pub const BOUND_SIGMAS: f64 = 3.0;

/// The gap as measured at the end of a move, without the extrinsics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GapMeasurement {
    /// How: "wavelength sweep at the end pose" or "fringes along the path from …".
    pub method: String,
    /// The gap along the beam (µm).
    pub gap_um: f64,
    /// Its standard uncertainty (nm).
    pub sigma_nm: f64,
}

/// The lamella's pose as reached: the gap measured, the rest from the model at the joints read
/// back from the bench (no measurement sees the tilt, the lateral position or the rotation
/// without the extrinsics to the σ the calibration gives; [`MoveRecord::model_only`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Achieved {
    /// The measured gap (µm), when measured.
    pub gap_um: Option<f64>,
    /// Its σ (nm).
    pub gap_sigma_nm: Option<f64>,
    /// The model's target at the joints read back (the planned pose, to the stages' reading).
    pub model: Target,
}

/// One move of the lamella.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MoveRecord {
    /// A label (a recipe's step, or empty).
    #[serde(default)]
    pub label: String,
    /// The recipe and the index of its step, for a move of a recipe.
    #[serde(default)]
    pub recipe: Option<(String, usize)>,
    /// When it started (UTC, RFC 3339).
    #[serde(default)]
    pub started_utc: Option<String>,
    /// Where the extrinsics came from ("session …", "file …").
    pub extrinsics_source: String,
    /// What was asked.
    pub requested: Target,
    /// The gap was held (the larger of start and end) while the rest moved.
    #[serde(default)]
    pub keep_gap: bool,
    /// Joints at the start of the path.
    pub joints_start: Joints,
    /// Joints planned at the end.
    pub joints_end: Joints,
    /// Waypoints of the path.
    pub waypoints: usize,
    /// What the calibration allows at the end pose; `None` without an uncertainty (extrinsics
    /// from a file are taken as exact).
    pub forecast: Option<PoseForecast>,
    /// The gap measured at the end; `None` when nothing measured it.
    pub measurement: Option<GapMeasurement>,
    /// The tilt measured from the contrast at the end pose; `None` when it was not.
    #[serde(default)]
    pub tilt: Option<super::tilt::TiltMeasurement>,
    /// What was reached.
    pub achieved: Option<Achieved>,
    /// Measured − requested gap (nm).
    pub gap_error_nm: Option<f64>,
    /// The bound the error is held to (nm): [`BOUND_SIGMAS`] × √(forecast σ² + measurement σ²).
    pub bound_nm: Option<f64>,
    /// The coordinates set through the model only, with why.
    pub model_only: String,
    /// The verdict.
    pub verdict: Verdict,
    /// Why, in words.
    pub note: String,
    /// Bench time the move and its measurement took (s).
    pub bench_time_s: f64,
}

impl MoveRecord {
    /// The pose this move's measurement gives as a reference for the fringes of a later move
    /// (its end joints and the gap a sweep measured there); `None` when no sweep measured it.
    pub fn as_reference(&self) -> Option<super::Reference> {
        let m = self.measurement.as_ref().filter(|m| m.method == super::proof::SWEEP_METHOD)?;
        let label = if self.label.is_empty() { self.requested.describe() } else { self.label.clone() };
        Some(super::Reference {
            joints: self.joints_end.to_array(),
            gap_um: m.gap_um,
            sigma_nm: m.sigma_nm,
            source: format!("the sweep at the end of the move to {label}"),
        })
    }
}
