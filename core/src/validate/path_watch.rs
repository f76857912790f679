//! Whether a validation motion ran along its path. Its joints sit on several controllers, which
//! start their moves one command after another: for as long as that takes the joints do not move
//! together along the planned line, and the lamella leaves the path that keeps |L| constant. A
//! host that stalls between two commands (measured on two cores with emulated controllers in the
//! same process: up to 26 ms of bench time in a segment of 135 ms) takes |L| tens of nm off a
//! true calibration's path, and the validation then contradicts a right calibration. The bench
//! reports each move's start spread; a run whose spread implies more than
//! [`MAX_PATH_DEPARTURE_NM`] is made again, up to [`MAX_RUNS`] runs.

use crate::bench::{Bench, BenchError, RunControl};
use crate::model::phase::PhaseModel;
use crate::plan::{TimedMotion, TimedSegment};
use crate::trace::{Trace, TraceMeta};

/// The departure from the path a run may have (nm): well under the tolerances of the checks
/// that read the tracked curve's smoothness (3-8 nm).
pub const MAX_PATH_DEPARTURE_NM: f64 = 2.0;

/// Runs of one motion at most.
pub const MAX_RUNS: usize = 3;

/// One recorded move and how far apart its controllers started, as a fraction of its duration.
#[derive(Debug, Clone, Copy)]
struct StartedApart {
    from: [f64; 6],
    to: [f64; 6],
    fraction: f64,
}

/// A bench that notes each recorded move's start spread, as the bench under it reports it.
pub(super) struct PathWatch<'a> {
    inner: &'a mut dyn Bench,
    moves: Vec<StartedApart>,
}

impl<'a> PathWatch<'a> {
    pub(super) fn new(inner: &'a mut dyn Bench) -> Self {
        PathWatch { inner, moves: Vec::new() }
    }

    /// The largest departure of |L| from the path (nm) the noted spreads imply, with `model`'s
    /// geometry ([`departure_nm`]); 0 on a bench that does not report them (a simulated one).
    pub(super) fn departure_nm(&self, model: &PhaseModel) -> f64 {
        self.moves.iter().map(|m| departure_nm(model, &m.from, &m.to, m.fraction)).fold(0.0, f64::max)
    }
}

/// The largest departure of |L| from a straight move `from` → `to` (µm, °) whose joints start up
/// to `fraction` of its duration apart (nm). Joints that start late fall behind the others by
/// that fraction of their travel; the joints of any group move |L| by ΔL_S = Σ_{j∈S} ∂L/∂q_j Δq_j
/// and the whole move keeps it (Σ_all ≈ 0), so |ΔL_S| ≤ ½ Σ_j |ΔL_j| for any group S.
pub fn departure_nm(model: &PhaseModel, from: &[f64; 6], to: &[f64; 6], fraction: f64) -> f64 {
    let Some((l0, _)) = model.gap_and_tilt(from) else { return 0.0 };
    let sum: f64 = (0..6)
        .filter(|&j| to[j] != from[j])
        .filter_map(|j| {
            let mut q = *from;
            q[j] = to[j];
            model.gap_and_tilt(&q).map(|(l, _)| (l - l0).abs() * 1e3)
        })
        .sum();
    fraction.max(0.0) * 0.5 * sum
}

impl Bench for PathWatch<'_> {
    crate::forward_bench_queries!(inner);

    fn run_segment(
        &mut self,
        segment: &TimedSegment,
        meta: TraceMeta,
        control: &mut RunControl<'_>,
    ) -> Result<Option<Trace>, BenchError> {
        let out = self.inner.run_segment(segment, meta, control);
        let is_move = matches!(segment.motion, TimedMotion::Move { .. });
        if let (true, true, Some(b)) =
            (segment.record && is_move, segment.duration_s > 0.0, self.inner.last_breakdown())
        {
            self.moves.push(StartedApart {
                from: segment.from_display,
                to: segment.to_display,
                fraction: b.start_spread_s / segment.duration_s,
            });
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::BenchPreset;
    use crate::validate::{waypoints, ValidationMotion};

    /// Brute force: each segment of the rotation about Z_f, the XYZ stage (or the wrist) starting a
    /// fraction of the segment late and moving at the same speed; |L| along that run against the
    /// planned line. The bound holds, and is within a factor of two of the worst departure.
    #[test]
    fn the_departure_bounds_a_late_start_on_either_controller() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let model = PhaseModel::of_preset(&preset, preset.truth).unwrap();
        let w = waypoints(&model, &preset.truth, ValidationMotion::RotationZf, [0.0; 6], 24).unwrap();
        let l_nm = |q: &[f64; 6]| model.gap_and_tilt(q).unwrap().0 * 1e3;
        let fraction = 0.05;
        for pair in w.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            let bound = departure_nm(&model, &a, &b, fraction);
            let mut worst: f64 = 0.0;
            for late in [0..3, 3..6] {
                for k in 0..=200 {
                    let s = k as f64 / 200.0 * (1.0 + fraction);
                    let at = |p: f64| -> [f64; 6] { std::array::from_fn(|j| a[j] + p.clamp(0.0, 1.0) * (b[j] - a[j])) };
                    let mut q = at(s);
                    let behind = at(s - fraction);
                    for j in late.clone() {
                        q[j] = behind[j];
                    }
                    worst = worst.max((l_nm(&q) - l_nm(&at(s))).abs());
                }
            }
            assert!(worst <= bound * 1.01 + 1e-6, "{worst} nm departed, bound {bound} nm");
            assert!(worst >= 0.5 * bound, "{worst} nm departed, bound {bound} nm: too loose");
        }
    }
}
