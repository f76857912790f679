//! The direction each stage last moved in (its approach), which decides which side of its play
//! it sits on: carried from trace to trace, and read at any sample of a trace.

use crate::model::effects::update_approach;
use crate::trace::Trace;

/// Smallest joint motion that sets an approach direction (µm for q1-q3, ° for q4-q6): above
/// encoder noise (nm, µrad), below any real motion.
pub(super) const APPROACH_MIN_MOVE: [f64; 6] = [0.05, 0.05, 0.05, 5e-4, 5e-4, 5e-4];

/// Samples per block of [`Readings`].
const BLOCK: usize = 256;

/// The direction each joint last moved in, carried from trace to trace (recorded in order;
/// between two traces the stages move from one's last pose to the next one's first).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Approach {
    state: [i8; 6],
    last_pose: Option<[f64; 6]>,
}

impl Approach {
    /// The directions at the start of the trace (after the move to its first pose); the state
    /// becomes the directions at its end.
    pub(super) fn enter(&mut self, readings: &Readings) -> [i8; 6] {
        let trace = readings.trace;
        if trace.is_empty() {
            return self.state;
        }
        if let Some(last) = self.last_pose {
            update_approach(&mut self.state, &last, &trace.joints_display(0), &APPROACH_MIN_MOVE);
        }
        let start = self.state;
        self.state = readings.approach_at(trace.len() - 1, &start);
        self.last_pose = Some(trace.joints_display(trace.len() - 1));
        start
    }
}

/// A trace's joint readings with each joint's smallest and largest reading per block of
/// [`BLOCK`] samples, so that a search back for a reading far enough away skips the blocks
/// that hold none (a still joint's whole column, a moving one's pauses).
pub(super) struct Readings<'a> {
    trace: &'a Trace,
    /// Per joint, per block: (smallest, largest) reading, NaN ignored.
    extents: [Vec<(f64, f64)>; 6],
}

impl<'a> Readings<'a> {
    pub(super) fn new(trace: &'a Trace) -> Self {
        let extents = std::array::from_fn(|j| {
            let block_extent =
                |b: &[f64]| b.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &q| (lo.min(q), hi.max(q)));
            trace.joint_column(j).chunks(BLOCK).map(block_extent).collect()
        });
        Self { trace, extents }
    }

    /// The direction each joint last moved in before sample `i`: the sign of its reading at
    /// `i` minus the latest earlier reading more than [`APPROACH_MIN_MOVE`] away, or `start`
    /// when it has not moved that much since the trace began.
    pub(super) fn approach_at(&self, i: usize, start: &[i8; 6]) -> [i8; 6] {
        std::array::from_fn(|j| {
            let c = self.trace.joint_column(j);
            let qi = c[i];
            let far = |q: f64| (qi - q).abs() > APPROACH_MIN_MOVE[j];
            // Back from `i`: the rest of its block, then whole blocks, each read only when its
            // extremes show a reading far enough away.
            let mut end = i;
            while end > 0 {
                let block = (end - 1) / BLOCK;
                let (lo, hi) = self.extents[j][block];
                let from = block * BLOCK;
                if far(lo) || far(hi) {
                    if let Some(&q) = c[from..end].iter().rev().find(|&&q| far(q)) {
                        return if qi > q { 1 } else { -1 };
                    }
                }
                end = from;
            }
            start[j]
        })
    }

    /// The direction of each joint's first motion in the trace (more than
    /// [`APPROACH_MIN_MOVE`] from its first reading), `start` for the joints that do not move.
    pub(super) fn first_motion(&self, start: &[i8; 6]) -> [i8; 6] {
        std::array::from_fn(|j| {
            let c = self.trace.joint_column(j);
            let q0 = c.first().copied().unwrap_or(0.0);
            c.iter()
                .find(|&&q| (q - q0).abs() > APPROACH_MIN_MOVE[j])
                .map_or(start[j], |&q| if q > q0 { 1 } else { -1 })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::TraceMeta;
    use proptest::prelude::*;

    /// The search back sample by sample, without blocks.
    fn approach_at_by_samples(trace: &Trace, i: usize, start: &[i8; 6]) -> [i8; 6] {
        std::array::from_fn(|j| {
            let c = trace.joint_column(j);
            let qi = c[i];
            c[..i].iter().rev().find(|&&q| (qi - q).abs() > APPROACH_MIN_MOVE[j]).map_or(start[j], |&q| {
                if qi > q {
                    1
                } else {
                    -1
                }
            })
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 300, failure_persistence: None, ..ProptestConfig::default() })]

        /// Read through the blocks, the approach at any sample is the sample-by-sample search's,
        /// on walks of steps around the threshold with pauses, across block boundaries.
        #[test]
        fn approach_through_blocks_is_the_sample_by_sample_one(
            steps in prop::collection::vec((prop::sample::select(vec![0.0, 0.01, -0.02, 0.06, -0.3, 2e-4, -6e-4, f64::NAN]), 1usize..400), 1..12),
            queries in prop::collection::vec(any::<prop::sample::Index>(), 1..20),
            start in prop::array::uniform6(-1i8..=1),
        ) {
            let mut t = Trace::new(TraceMeta::default());
            let mut q = [0.0; 6];
            for (step, count) in &steps {
                for _ in 0..*count {
                    for (j, v) in q.iter_mut().enumerate() {
                        // Each joint its own walk: the step scaled, some joints still.
                        *v += step * [1.0, 0.0, -2.0, 1.0, 0.5, 0.0][j];
                        if step.is_nan() && j == 3 { *v = 0.0; }
                    }
                    t.push_sample(t.len() as f64, q, 1560.0, 0.5);
                }
            }
            let readings = Readings::new(&t);
            for index in &queries {
                let i = index.index(t.len());
                prop_assert_eq!(readings.approach_at(i, &start), approach_at_by_samples(&t, i, &start), "sample {}", i);
            }
        }
    }
}
