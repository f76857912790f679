//! Random motion plans: what a technician, another lab or a hand-edited plan might record, for
//! testing the identification on motions it did not design. Owns the plan families and their draws.
//!
//! Every plan is a valid plan file (joint limits, laser range) with neutral labels ("motion 7",
//! "sweep 2"): nothing in a label tells the analysis what a motion is for.

use crate::plan::{JointTarget, Plan, Segment};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

/// A family of random plans.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Family {
    /// Motions drawn from the experiment design's candidate pool, each with its setup move.
    Pool,
    /// The paper's strategies 1 and 2 with a single wavelength sweep, at a random pose.
    PaperOneSweep,
    /// Translations of random axis, length and direction at random offsets and orientations,
    /// rotations at random offsets, a few sweeps at random poses.
    OtherOffsets,
    /// Rotations only (q4, q5, q6) at random offsets, one to three sweeps.
    RotationsOnly,
    /// Recorded moves chained end to end with no setup move: each starts where the last ended.
    Chained,
}

impl Family {
    /// Every family, in the order [`random_plan`] cycles through them.
    pub const ALL: [Family; 5] =
        [Family::Pool, Family::PaperOneSweep, Family::OtherOffsets, Family::RotationsOnly, Family::Chained];

    /// The family's name in plan names and reports.
    pub fn name(self) -> &'static str {
        match self {
            Family::Pool => "pool",
            Family::PaperOneSweep => "paper-one-sweep",
            Family::OtherOffsets => "other-offsets",
            Family::RotationsOnly => "rotations-only",
            Family::Chained => "chained",
        }
    }
}

/// Largest lateral stage travel used (µm): inside the ±150 µm limits.
const TRAVEL_UM: f64 = 150.0;
/// Largest goniometer angle used (°): beyond about ±5° the tilt loss hides the fringes.
const TILT_DEG: f64 = 4.5;

/// Plan builder with neutral labels.
struct Builder {
    segments: Vec<Segment>,
    moves: usize,
    sweeps: usize,
}

impl Builder {
    fn new() -> Self {
        Self { segments: Vec::new(), moves: 0, sweeps: 0 }
    }

    fn setup(&mut self, to: [f64; 6]) {
        self.segments.push(Segment::Move { to: JointTarget::all(to), record: false, label: "setup".into() });
    }

    fn record(&mut self, to: JointTarget) {
        self.moves += 1;
        let label = format!("motion {}", self.moves);
        self.segments.push(Segment::Move { to, record: true, label });
    }

    fn sweep(&mut self, rng: &mut StdRng) {
        self.sweeps += 1;
        let (from_nm, to_nm, rate_nm_per_s) = match rng.random_range(0..3) {
            0 => (1550.0, 1570.0, 2.0),
            1 => (1540.0, 1580.0, 10.0),
            _ => (1555.0, 1565.0, 1.0),
        };
        let label = format!("sweep {}", self.sweeps);
        self.segments.push(Segment::Sweep { from_nm, to_nm, rate_nm_per_s, label });
    }

    fn plan(self, family: Family, seed: u64) -> Plan {
        Plan {
            name: format!("random-{}-{seed}", family.name()),
            description: format!("Random plan of family {} (seed {seed}).", family.name()),
            segments: self.segments,
        }
    }
}

fn lateral(rng: &mut StdRng) -> f64 {
    rng.random_range(-TRAVEL_UM..=TRAVEL_UM)
}

fn random_pose(rng: &mut StdRng, tilt_deg: f64) -> [f64; 6] {
    [
        lateral(rng),
        rng.random_range(-100.0..=100.0),
        lateral(rng),
        rng.random_range(-tilt_deg..=tilt_deg),
        rng.random_range(-tilt_deg..=tilt_deg),
        0.0,
    ]
}

/// A motion a random plan of [`Family::Pool`] may draw: where it starts and what it records.
/// The experiment design's candidates are such motions.
pub trait PoolMotion {
    /// Joints at the start of the recorded segment (µm, °).
    fn start_display(&self) -> [f64; 6];
    /// The recorded segment.
    fn segment(&self) -> &Segment;
}

/// A random plan of `family`, reproducible from `seed`. Plans of [`Family::Pool`] draw from
/// `pool` (typically the design's candidate pool).
pub fn random_plan<M: PoolMotion>(family: Family, seed: u64, pool: &[M]) -> Plan {
    let mut rng = StdRng::seed_from_u64(seed ^ 0x9e37_79b9_7f4a_7c15);
    let mut builder = Builder::new();
    match family {
        Family::Pool => pool_plan(&mut builder, &mut rng, pool),
        Family::PaperOneSweep => paper_one_sweep(&mut builder, &mut rng),
        Family::OtherOffsets => other_offsets(&mut builder, &mut rng),
        Family::RotationsOnly => rotations_only(&mut builder, &mut rng),
        Family::Chained => chained(&mut builder, &mut rng),
    }
    builder.plan(family, seed)
}

fn pool_plan<M: PoolMotion>(builder: &mut Builder, rng: &mut StdRng, pool: &[M]) {
    if pool.is_empty() {
        return;
    }
    let moves = rng.random_range(10..=30);
    for _ in 0..moves {
        let candidate = &pool[rng.random_range(0..pool.len())];
        builder.setup(candidate.start_display());
        match candidate.segment() {
            Segment::Sweep { .. } => builder.sweep(rng),
            Segment::Move { to, .. } => builder.record(*to),
            Segment::Dwell { .. } => {}
        }
    }
}

fn paper_one_sweep(builder: &mut Builder, rng: &mut StdRng) {
    // Strategy 1's translations without their sweeps.
    for held in 0..3 {
        for at in [-TRAVEL_UM, 0.0, TRAVEL_UM] {
            let mut start = [0.0; 6];
            start[held] = at;
            let (first, second) = match held {
                0 => (2, 1), // at q1: X_w (q3), then Y_w (q2)
                1 => (2, 0), // at q2: X_w, then Z_w (q1)
                _ => (0, 1), // at q3: Z_w, then Y_w
            };
            for axis in [first, second] {
                let span = if axis == 1 { 10.0 } else { TRAVEL_UM };
                let mut from = start;
                from[axis] = -span;
                builder.setup(from);
                builder.record(JointTarget::default().with(axis, span));
            }
        }
    }
    // Strategy 2's rotations.
    for (turned, held) in [(3, 4), (4, 3)] {
        for at in [-4.0, -2.0, 0.0, 2.0, 4.0] {
            let mut from = [0.0; 6];
            from[held] = at;
            from[turned] = -4.0;
            builder.setup(from);
            builder.record(JointTarget::default().with(turned, 4.0));
        }
    }
    builder.setup(random_pose(rng, 2.0));
    builder.sweep(rng);
}

fn other_offsets(builder: &mut Builder, rng: &mut StdRng) {
    let moves = rng.random_range(8..=20);
    for _ in 0..moves {
        let tilt_deg = if rng.random_bool(0.3) { 2.0 } else { 0.0 };
        let mut from = random_pose(rng, tilt_deg);
        if rng.random_bool(0.6) {
            // A translation along one stage or two.
            let axes: Vec<usize> = if rng.random_bool(0.7) {
                vec![rng.random_range(0..3)]
            } else {
                let first = rng.random_range(0..3);
                vec![first, (first + rng.random_range(1..3)) % 3]
            };
            let mut to = JointTarget::default();
            for &axis in &axes {
                let limit = if axis == 1 { 100.0 } else { TRAVEL_UM };
                let span = rng.random_range(0.2..=1.0) * limit;
                from[axis] = if rng.random_bool(0.5) { -span } else { span };
                to = to.with(axis, -from[axis]);
            }
            builder.setup(from);
            builder.record(to);
        } else {
            let joint = rng.random_range(3..5);
            from[5] = 0.0;
            let angle_deg = rng.random_range(2.0..=TILT_DEG);
            from[joint] = if rng.random_bool(0.5) { -angle_deg } else { angle_deg };
            builder.setup(from);
            builder.record(JointTarget::default().with(joint, -from[joint]));
        }
    }
    for _ in 0..rng.random_range(2..=4) {
        builder.setup(random_pose(rng, 2.0));
        builder.sweep(rng);
    }
}

fn rotations_only(builder: &mut Builder, rng: &mut StdRng) {
    for _ in 0..rng.random_range(1..=3) {
        builder.setup(random_pose(rng, 2.0));
        builder.sweep(rng);
    }
    for _ in 0..rng.random_range(6..=16) {
        let mut from = random_pose(rng, 0.0);
        let joint = rng.random_range(3..6);
        let angle_deg = if joint == 5 { rng.random_range(10.0..=30.0) } else { rng.random_range(2.0..=TILT_DEG) };
        from[joint] = if rng.random_bool(0.5) { -angle_deg } else { angle_deg };
        if joint != 3 && rng.random_bool(0.5) {
            from[3] = rng.random_range(-2.0..=2.0);
        }
        builder.setup(from);
        builder.record(JointTarget::default().with(joint, -from[joint]));
    }
}

fn chained(builder: &mut Builder, rng: &mut StdRng) {
    builder.setup([0.0; 6]);
    builder.sweep(rng);
    for k in 0..rng.random_range(12..=30) {
        let to = random_pose(rng, TILT_DEG);
        builder.record(JointTarget::all(to));
        if k % 6 == 5 {
            builder.sweep(rng);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::robot::RobotDescription;
    use crate::plan::MotionLimits;

    #[test]
    fn every_family_gives_plans_that_fit_the_robot_with_neutral_labels() {
        let robot = RobotDescription::femto_6dof();
        let limits = MotionLimits::default();
        let pool = crate::identify::design::candidate_pool(&robot, &limits);
        for family in Family::ALL {
            for seed in 0..20 {
                let plan = random_plan(family, seed, &pool);
                plan.expand(&robot, [0.0; 6], &limits).unwrap_or_else(|e| panic!("{} seed {seed}: {e}", family.name()));
                assert!(plan.recorded_moves() >= 3, "{} seed {seed}", family.name());
                for s in &plan.segments {
                    let l = s.label();
                    assert!(l == "setup" || l.starts_with("motion ") || l.starts_with("sweep "), "{l}");
                }
            }
        }
    }

    #[test]
    fn the_same_seed_gives_the_same_plan_and_another_seed_another() {
        let pool = crate::identify::design::candidate_pool(&RobotDescription::femto_6dof(), &MotionLimits::default());
        for family in Family::ALL {
            assert_eq!(random_plan(family, 3, &pool), random_plan(family, 3, &pool));
            assert_ne!(random_plan(family, 3, &pool).segments, random_plan(family, 4, &pool).segments);
        }
    }
}
