//! The sign of a move from the absolute gaps of two wavelength sweeps, before and after it
//! (the paper's way of signing extremum counts).

use super::GapEstimate;
use crate::measure::signal::{check_non_negative, check_positive, FringeError};

/// Sign of a move from the absolute gaps measured before and after it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepSign {
    /// Gap after minus gap before, nm.
    pub gap_change_nm: f64,
    /// Standard uncertainty of `gap_change_nm`, nm.
    pub sigma_nm: f64,
    /// +1 if the gap grew, -1 if it shrank, 0 if exactly equal.
    pub sign: i8,
    /// |change| / σ.
    pub z_score: f64,
    /// Whether |change| > k·σ.
    pub significant: bool,
}

/// Sign of the gap change between two wavelength-sweep gap estimates (the paper's way of
/// signing extremum counts). The change is significant when it exceeds `k_sigma` standard
/// uncertainties (independent sweeps: σ² = σ_before² + σ_after²).
pub fn sign_from_sweeps(before: &GapEstimate, after: &GapEstimate, k_sigma: f64) -> Result<SweepSign, FringeError> {
    check_positive("k_sigma", k_sigma)?;
    for (name, v) in [("before.gap_um", before.gap_um), ("after.gap_um", after.gap_um)] {
        if !v.is_finite() {
            return Err(FringeError::InvalidParameter { name, value: v, reason: "must be finite" });
        }
    }
    check_non_negative("before.sigma_um", before.sigma_um)?;
    check_non_negative("after.sigma_um", after.sigma_um)?;
    let change = (after.gap_um - before.gap_um) * 1e3;
    let sigma = (before.sigma_um.powi(2) + after.sigma_um.powi(2)).sqrt() * 1e3;
    let z = if sigma > 0.0 {
        change.abs() / sigma
    } else if change != 0.0 {
        f64::INFINITY
    } else {
        0.0
    };
    Ok(SweepSign {
        gap_change_nm: change,
        sigma_nm: sigma,
        sign: if change > 0.0 {
            1
        } else if change < 0.0 {
            -1
        } else {
            0
        },
        z_score: z,
        significant: z > k_sigma,
    })
}
