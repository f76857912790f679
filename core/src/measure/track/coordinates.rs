//! The tracker's two coordinates along a motion: the knot grid's (path in fringes plus time in
//! knots, refined over the first fringe) and the envelope's (path in fringes plus time).

/// Samples per time knot: the grid coordinate is c = path/Δs + k/T_KNOT.
pub(super) const T_KNOT: f64 = 4096.0;

/// Knots over the first unit of the plain grid coordinate c₀ = path/Δs + k/T (the first
/// fringe of travel) when [`super::TrackConfig::start_walk_rad`] is set: REFINE_START + 1 knots
/// instead of 2, each segment with that loose phase walk. A stage that reverses takes up its
/// play first: its reading moves, its platform does not, and the fringe phase stays while the
/// hint moves (10–20 nm of hint for a µm of lateral play, more along the axis). One knot per
/// fringe with a stiff walk makes the start phase a compromise over the whole first fringe that
/// misses that step; with these knots the samples before the play is taken up set it.
pub(super) const REFINE_START: usize = 64;

/// Grid coordinate with `r` knot intervals over the first unit: c₀ ↦ r·c₀ on [0, 1),
/// c₀ + r − 1 beyond. Continuous and strictly increasing; the identity for r = 1.
#[inline]
pub(super) fn refine_start(c0: f64, r: f64) -> f64 {
    if c0 >= 1.0 {
        c0 + (r - 1.0)
    } else {
        c0 * r
    }
}

/// Inverse of [`refine_start`].
#[inline]
pub(super) fn unrefine_start(c: f64, r: f64) -> f64 {
    if c >= r {
        c - (r - 1.0)
    } else {
        c / r
    }
}

/// Samples per unit of the envelope's coordinate in time ([`envelope_coordinate`]).
pub(super) const T_ENVELOPE: f64 = 4096.0;

/// Where the levels of the fringe extrema are placed to be interpolated into the initial
/// envelope: fringes of path travelled plus time in units of [`T_ENVELOPE`] samples (the
/// grid's own mix). The envelope follows the coupling, which follows the joints; along the
/// path alone, a motion whose gap stands still while a goniometer turns (a turning point of
/// the gap) squeezes the coupling's change into no path at all (`diagnose::motions` test
/// `a_rotation_that_starts_on_a_gap_turning_point_...`). Time costs accuracy on some
/// synthetic rotations; over the pool motions of table2-ideal it is the better coordinate
/// (`effect_visibility -- 5 --hinted --tracks`).
pub(super) fn envelope_coordinate(path_nm: f64, k: f64, fringe_nm: f64) -> f64 {
    path_nm / fringe_nm + k / T_ENVELOPE
}
