//! Model-free reading of a fringe signal: what the samples alone say about the phase-equivalent
//! gap, with no hint from any extrinsics. Owns the dither envelope, the extremum count with its
//! bounds on the gap's peak to peak, and the phase unwrapped at the signal's own turning points.
//!
//! The fringe is `I = A + B·f(u)` with `u` the phase-equivalent gap in steps of λ/(4n): its
//! maxima sit at even `u`, its minima at odd `u`. An extremum of `I` in time is either a
//! *fringe extremum* (the gap crosses an integer `u`, the value at the fringe's top or bottom)
//! or a *turning point* of the gap (a value in between). A single photodiode cannot tell a
//! crossing from a reversal at the same fringe extremum, so the count bounds the gap only with
//! what the motion's geometry says about its turning points ([`PathShape`]).

mod count;
mod envelope;
mod pinned;
mod unwrap;

pub use count::{count_fringes, gap_bounds, ExtremumClass, FringeCount, GapBounds, PathShape};
pub use envelope::{dither_envelope, dither_envelope_where, Envelope};
pub use pinned::{piecewise_linear, pinned_to_extrema};
pub use unwrap::{unwrap_gap_nm, PathForm, Unwrapped};

/// Hysteresis of the model-free extremum detector, in units of the signal's white-noise σ
/// (estimated from its own third differences): a swing of noise alone over 10⁵ samples stays
/// under about 9σ.
pub const NOISE_HYSTERESIS_SIGMA: f64 = 12.0;

/// The smallest tolerance on the normalised value (I − A)/B for an extremum to stand at the
/// fringe's top (≥ 1 − τ) or bottom (≤ −1 + τ).
pub const MIN_TOP_TOLERANCE: f64 = 0.05;
