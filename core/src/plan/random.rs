//! Random motion plans: what a technician, another lab or a hand-edited plan might record, for
//! testing the identification on motions it did not design. Owns the plan families and their
//! draws, made here from the joints' ranges alone: no family of [`Family::ALL`] takes a motion
//! from the shipped plans or the experiment design's candidates.
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
    /// Each recorded move turns or translates one joint drawn among the six, between two random
    /// positions, from a pose offset in every joint (q6 included); zero to three sweeps at
    /// random poses.
    SingleJoints,
    /// Each recorded move drives two to six joints drawn at random (q6 among them) at once,
    /// between two random poses; zero to three sweeps at random poses.
    SeveralJoints,
    /// Translations of random axis, length and direction at random offsets and orientations,
    /// rotations at random offsets, a few sweeps at random poses.
    OtherOffsets,
    /// Rotations only (q4, q5, q6) at random offsets, one to three sweeps.
    RotationsOnly,
    /// Recorded moves chained end to end with no setup move: each starts where the last ended.
    Chained,
    /// Not a random family: the paper's strategies 1 and 2 with a single wavelength sweep at a
    /// random pose, for tests that want the paper's motions with one absolute gap. Not in
    /// [`Family::ALL`].
    PaperOneSweep,
}

impl Family {
    /// The random families, in the order the random-plan runs cycle through them.
    pub const ALL: [Family; 5] =
        [Family::SingleJoints, Family::SeveralJoints, Family::OtherOffsets, Family::RotationsOnly, Family::Chained];

    /// The random families and [`Family::PaperOneSweep`]: every plan [`random_plan`] makes.
    pub const EVERY: [Family; 6] = [
        Family::SingleJoints,
        Family::SeveralJoints,
        Family::OtherOffsets,
        Family::RotationsOnly,
        Family::Chained,
        Family::PaperOneSweep,
    ];

    /// The family's name in plan names and reports.
    pub fn name(self) -> &'static str {
        match self {
            Family::SingleJoints => "single-joints",
            Family::SeveralJoints => "several-joints",
            Family::OtherOffsets => "other-offsets",
            Family::RotationsOnly => "rotations-only",
            Family::Chained => "chained",
            Family::PaperOneSweep => "paper-one-sweep",
        }
    }

    /// The family of a name, [`Family::PaperOneSweep`] included.
    pub fn from_name(name: &str) -> Option<Family> {
        Family::EVERY.into_iter().find(|f| f.name() == name)
    }
}

/// Largest lateral stage travel used (µm): inside the ±150 µm limits.
const TRAVEL_UM: f64 = 150.0;
/// Largest goniometer angle used (°): beyond about ±5° the tilt loss hides the fringes.
const TILT_DEG: f64 = 4.5;
/// Largest travel along the beam (q2, µm): the gap stays between about 800 and 1000 µm.
const ALONG_BEAM_UM: f64 = 100.0;
/// Largest rotary-stage angle used (°), and the largest turn of one move (°): 30° at 2°/s is
/// 15 s of bench time.
const ROTARY_DEG: f64 = 90.0;
const ROTARY_TURN_DEG: f64 = 30.0;

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
        self.segments.push(Segment::Move {
            to: JointTarget::all(to),
            record: false,
            label: "setup".into(),
            through: false,
        });
    }

    fn record(&mut self, to: JointTarget) {
        self.moves += 1;
        let label = format!("motion {}", self.moves);
        self.segments.push(Segment::Move { to, record: true, label, through: false });
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

/// A random plan of `family`, reproducible from `seed`.
pub fn random_plan(family: Family, seed: u64) -> Plan {
    let mut rng = StdRng::seed_from_u64(seed ^ 0x9e37_79b9_7f4a_7c15);
    let mut builder = Builder::new();
    match family {
        Family::SingleJoints => single_joints(&mut builder, &mut rng),
        Family::SeveralJoints => several_joints(&mut builder, &mut rng),
        Family::OtherOffsets => other_offsets(&mut builder, &mut rng),
        Family::RotationsOnly => rotations_only(&mut builder, &mut rng),
        Family::Chained => chained(&mut builder, &mut rng),
        Family::PaperOneSweep => paper_one_sweep(&mut builder, &mut rng),
    }
    builder.plan(family, seed)
}

/// The range a joint's random positions are drawn from (µm, °): the stages' travel, the
/// goniometers' tilt with the fringes still visible, a share of the rotary stage's turn.
fn joint_range(joint: usize) -> f64 {
    match joint {
        0 | 2 => TRAVEL_UM,
        1 => ALONG_BEAM_UM,
        3 | 4 => TILT_DEG,
        _ => ROTARY_DEG,
    }
}

/// A pose offset in every joint, the goniometers within ±2° (so that a move of either stays
/// within the fringes' tilt range).
fn offset_pose(rng: &mut StdRng) -> [f64; 6] {
    std::array::from_fn(|j| {
        let range = if j == 3 || j == 4 { 2.0 } else { joint_range(j) };
        rng.random_range(-range..=range)
    })
}

/// Two positions of `joint` for a recorded move: both within its range, at least a fifth of
/// it apart (a tenth for the rotary stage), the rotary stage's turn at most [`ROTARY_TURN_DEG`].
fn move_ends(rng: &mut StdRng, joint: usize) -> (f64, f64) {
    let range = joint_range(joint);
    let (least, most) = if joint == 5 { (0.1 * range, ROTARY_TURN_DEG) } else { (0.2 * range, 2.0 * range) };
    let from = rng.random_range(-range..=range);
    let span = rng.random_range(least..=most);
    let up = if from + span <= range && (from - span < -range || rng.random_bool(0.5)) { span } else { -span };
    let to = (from + up).clamp(-range, range);
    (from, to)
}

/// Zero to three sweeps (none for one plan in four), each at a random offset pose.
fn random_sweeps(builder: &mut Builder, rng: &mut StdRng) {
    let count = if rng.random_bool(0.25) { 0 } else { rng.random_range(1..=3) };
    for _ in 0..count {
        builder.setup(offset_pose(rng));
        builder.sweep(rng);
    }
}

fn single_joints(builder: &mut Builder, rng: &mut StdRng) {
    for _ in 0..rng.random_range(8..=20) {
        let joint = rng.random_range(0..6);
        let mut from = offset_pose(rng);
        let (start, end) = move_ends(rng, joint);
        from[joint] = start;
        builder.setup(from);
        builder.record(JointTarget::default().with(joint, end));
    }
    random_sweeps(builder, rng);
}

fn several_joints(builder: &mut Builder, rng: &mut StdRng) {
    for _ in 0..rng.random_range(8..=20) {
        let mut joints: Vec<usize> = (0..6).collect();
        let driven = rng.random_range(2..=6);
        for k in 0..driven {
            joints.swap(k, rng.random_range(k..6));
        }
        let mut from = offset_pose(rng);
        let mut to = JointTarget::default();
        for &joint in &joints[..driven] {
            let (start, end) = move_ends(rng, joint);
            from[joint] = start;
            to = to.with(joint, end);
        }
        // Both goniometers driven: the pair keeps within the fringes' tilt range.
        if joints[..driven].contains(&3) && joints[..driven].contains(&4) {
            for j in [3, 4] {
                from[j] = from[j].clamp(-3.0, 3.0);
                to = to.with(j, to.values()[j].unwrap_or(0.0).clamp(-3.0, 3.0));
            }
        }
        builder.setup(from);
        builder.record(to);
    }
    random_sweeps(builder, rng);
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
        for family in Family::EVERY {
            for seed in 0..20 {
                let plan = random_plan(family, seed);
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
        for family in Family::EVERY {
            assert_eq!(random_plan(family, 3), random_plan(family, 3));
            assert_ne!(random_plan(family, 3).segments, random_plan(family, 4).segments);
        }
    }

    /// The joints a recorded move of `plan` drives (its target's joints that change).
    fn driven(plan: &Plan) -> Vec<Vec<usize>> {
        let robot = RobotDescription::femto_6dof();
        let timed = plan.expand(&robot, [0.0; 6], &MotionLimits::default()).unwrap();
        timed
            .iter()
            .filter(|s| s.record && matches!(s.motion, crate::plan::TimedMotion::Move { .. }))
            .map(|s| (0..6).filter(|&j| (s.to_display[j] - s.from_display[j]).abs() > 1e-9).collect())
            .collect()
    }

    #[test]
    fn the_random_families_drive_every_joint_several_at_once_with_sweeps_or_none() {
        let mut joints_driven = [false; 6];
        let (mut several_with_q6, mut without_sweeps, mut offset_q6) = (0, 0, 0);
        for family in [Family::SingleJoints, Family::SeveralJoints] {
            for seed in 0..20 {
                let plan = random_plan(family, seed);
                let moves = driven(&plan);
                for m in &moves {
                    m.iter().for_each(|&j| joints_driven[j] = true);
                    assert!(family != Family::SingleJoints || m.len() == 1, "{}: {m:?}", plan.name);
                    assert!(family != Family::SeveralJoints || m.len() >= 2, "{}: {m:?}", plan.name);
                    several_with_q6 += usize::from(m.len() >= 2 && m.contains(&5));
                }
                without_sweeps += usize::from(plan.sweeps() == 0);
                offset_q6 += plan.segments.iter().filter(|s| matches!(s, Segment::Move { to, record: false, .. } if to.values()[5].is_some_and(|q6| q6 != 0.0))).count();
            }
        }
        assert_eq!(joints_driven, [true; 6], "every joint moves in some recorded move");
        assert!(several_with_q6 > 10 && offset_q6 > 100, "q6 in moves of several joints, and as an offset");
        assert!((3..=20).contains(&without_sweeps), "{without_sweeps} of 40 plans without a sweep");
    }
}
