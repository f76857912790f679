//! Placing a plan in time: the synchronized trapezoidal profile of a move, the timed segments a
//! plan expands into, and where the bench is at a given time.

use super::{LaserLimits, MotionLimits, Plan, PlanError, Segment, JOINT_FIELDS};
use crate::model::kinematics::Chain;
use crate::model::robot::{JointType, LinkDescription, RobotDescription};

/// A trapezoidal velocity profile over a path of unit length (the fraction `s` of a move goes
/// from 0 to 1): constant acceleration, cruise at the peak rate, constant deceleration; a
/// triangle when the path is too short to reach the rate limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrapezoidProfile {
    /// Total time (s).
    pub duration_s: f64,
    /// Time spent accelerating, and again decelerating (s).
    pub accel_time_s: f64,
    /// Time at the peak rate (s); 0 for a triangle.
    pub cruise_time_s: f64,
    /// Peak rate (fraction of the path per second).
    pub peak_rate_per_s: f64,
    /// Acceleration (fraction of the path per second²).
    pub accel_per_s2: f64,
}

impl TrapezoidProfile {
    /// A profile that takes no time (zero-length move).
    pub const INSTANT: TrapezoidProfile = TrapezoidProfile {
        duration_s: 0.0,
        accel_time_s: 0.0,
        cruise_time_s: 0.0,
        peak_rate_per_s: 0.0,
        accel_per_s2: 0.0,
    };

    /// The fastest profile over a unit path with rate ≤ `max_rate` and |acceleration| ≤
    /// `max_accel` (both positive): duration `1/v + v/a` if `v²/a ≤ 1`, else `2·√(1/a)`.
    pub fn new(max_rate: f64, max_accel: f64) -> Self {
        let (v, a) = (max_rate, max_accel);
        if v * v / a <= 1.0 {
            let accel_time_s = v / a;
            // Never negative, even when v²/a rounds to 1.
            let cruise_time_s = (1.0 / v - accel_time_s).max(0.0);
            Self {
                duration_s: 2.0 * accel_time_s + cruise_time_s,
                accel_time_s,
                cruise_time_s,
                peak_rate_per_s: v,
                accel_per_s2: a,
            }
        } else {
            let accel_time_s = (1.0 / a).sqrt();
            Self {
                duration_s: 2.0 * accel_time_s,
                accel_time_s,
                cruise_time_s: 0.0,
                peak_rate_per_s: a * accel_time_s,
                accel_per_s2: a,
            }
        }
    }

    /// Fraction of the path done at time `t_s` (0 before the start, 1 from the end on).
    pub fn fraction_at(&self, t_s: f64) -> f64 {
        let (a, ta, tc, tt) = (self.accel_per_s2, self.accel_time_s, self.cruise_time_s, self.duration_s);
        if t_s.is_nan() || t_s <= 0.0 {
            0.0
        } else if t_s >= tt {
            1.0
        } else if t_s < ta {
            0.5 * a * t_s * t_s
        } else if t_s < ta + tc {
            0.5 * a * ta * ta + self.peak_rate_per_s * (t_s - ta)
        } else {
            let r = tt - t_s;
            (1.0 - 0.5 * a * r * r).clamp(0.0, 1.0)
        }
    }

    /// Rate (fraction of the path per second) at time `t_s`.
    pub fn rate_at(&self, t_s: f64) -> f64 {
        let (a, ta, tc, tt) = (self.accel_per_s2, self.accel_time_s, self.cruise_time_s, self.duration_s);
        if t_s.is_nan() || t_s <= 0.0 || t_s >= tt {
            0.0
        } else if t_s < ta {
            a * t_s
        } else if t_s < ta + tc {
            self.peak_rate_per_s
        } else {
            a * (tt - t_s)
        }
    }
}

/// What a timed segment does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TimedMotion {
    /// A synchronized straight-line move, followed by settling (a zero-length move takes no time).
    Move {
        /// The common profile of all joints.
        profile: TrapezoidProfile,
        /// Settling time after the motion (s).
        settle_s: f64,
        /// The stages go on to the next move without settling ([`Segment::Move`]'s `through`):
        /// they may still be closing in on the target when the segment ends.
        through: bool,
    },
    /// A linear wavelength sweep, joints fixed.
    Sweep {
        /// Start wavelength (nm).
        from_nm: f64,
        /// End wavelength (nm).
        to_nm: f64,
    },
    /// Nothing moves.
    Dwell,
}

/// A plan segment placed in time, with its start and end joint vectors (display units).
#[derive(Debug, Clone, PartialEq)]
pub struct TimedSegment {
    /// Index of the segment in [`Plan::segments`].
    pub index: usize,
    /// Its label.
    pub label: String,
    /// True if a trace is recorded during it.
    pub record: bool,
    /// Bench time at which it starts (s since the start of the plan).
    pub start_s: f64,
    /// Its duration (s), settling included.
    pub duration_s: f64,
    /// Joint vector at the start (µm, °).
    pub from_display: [f64; 6],
    /// Joint vector at the end (µm, °).
    pub to_display: [f64; 6],
    /// What it does.
    pub motion: TimedMotion,
}

impl TimedSegment {
    /// Bench time at which it ends (s).
    pub fn end_s(&self) -> f64 {
        self.start_s + self.duration_s
    }

    /// Joint vector (µm, °) at time `t_s` since the segment's start; clamped to the segment
    /// (before it: the start; after it: the end, exactly).
    pub fn position_at(&self, t_s: f64) -> [f64; 6] {
        match self.motion {
            TimedMotion::Move { profile, .. } => {
                let s = profile.fraction_at(t_s);
                if s >= 1.0 {
                    self.to_display
                } else {
                    std::array::from_fn(|j| self.from_display[j] + s * (self.to_display[j] - self.from_display[j]))
                }
            }
            TimedMotion::Sweep { .. } | TimedMotion::Dwell => self.from_display,
        }
    }

    /// Joint velocities (µm/s, °/s) at time `t_s` since the segment's start.
    pub fn velocity_at(&self, t_s: f64) -> [f64; 6] {
        match self.motion {
            TimedMotion::Move { profile, .. } => {
                let r = profile.rate_at(t_s);
                std::array::from_fn(|j| r * (self.to_display[j] - self.from_display[j]))
            }
            TimedMotion::Sweep { .. } | TimedMotion::Dwell => [0.0; 6],
        }
    }

    /// Laser wavelength (nm) at time `t_s` since the segment's start, for a sweep (clamped to
    /// the sweep); `None` for other segments (the laser sits at the bench's nominal wavelength).
    pub fn wavelength_at(&self, t_s: f64) -> Option<f64> {
        match self.motion {
            TimedMotion::Sweep { from_nm, to_nm } => {
                let f = if self.duration_s > 0.0 { (t_s / self.duration_s).clamp(0.0, 1.0) } else { 1.0 };
                let f = if f.is_nan() { 0.0 } else { f };
                Some(if f >= 1.0 { to_nm } else { from_nm + f * (to_nm - from_nm) })
            }
            _ => None,
        }
    }
}

/// Total bench time of expanded segments (s).
pub fn total_duration_s(segments: &[TimedSegment]) -> f64 {
    segments.last().map_or(0.0, TimedSegment::end_s)
}

/// The segment running at bench time `t_s` (the first whose end is at or after `t_s`; `None`
/// before 0 or after the end).
pub fn segment_at(segments: &[TimedSegment], t_s: f64) -> Option<&TimedSegment> {
    if t_s.is_nan() || t_s < 0.0 || t_s > total_duration_s(segments) {
        return None;
    }
    let running = segments.partition_point(|s| s.end_s() < t_s);
    segments.get(running)
}

impl Plan {
    /// Expand into timed segments with the default laser range (see [`Plan::expand_with_laser`]).
    pub fn expand(
        &self,
        robot: &RobotDescription,
        start_q_display: [f64; 6],
        limits: &MotionLimits,
    ) -> Result<Vec<TimedSegment>, PlanError> {
        self.expand_with_laser(robot, start_q_display, limits, &LaserLimits::default())
    }

    /// Check the whole plan, then place every segment in time. Nothing is returned unless every
    /// segment passes: all numbers valid, every sweep inside the laser range, the start and
    /// every move's end inside the joint limits (moves are straight lines in joint space, so
    /// their ends suffice). Moves use one trapezoidal profile for all joints (they start and
    /// stop together); the most constrained joint sets the duration.
    pub fn expand_with_laser(
        &self,
        robot: &RobotDescription,
        start_q_display: [f64; 6],
        limits: &MotionLimits,
        laser: &LaserLimits,
    ) -> Result<Vec<TimedSegment>, PlanError> {
        limits.validate()?;
        if !(laser.min_nm.is_finite() && laser.max_nm.is_finite() && laser.min_nm < laser.max_nm) {
            return Err(PlanError::BadLaserLimits { laser: *laser });
        }
        self.validate()?;
        check_joint_kinds(robot)?;
        let chain = Chain::new(robot.clone());
        check_start(&chain, robot, start_q_display)?;

        let mut timed = Vec::with_capacity(self.segments.len());
        let mut current = start_q_display;
        let mut clock_s = 0.0;
        for (index, segment) in self.segments.iter().enumerate() {
            let label = segment.label().to_string();
            let (target, motion, duration_s) =
                match segment {
                    Segment::Move { to, through, .. } => {
                        let target = to.resolve(current);
                        chain.check_limits(&robot.q_from_display(&target)).map_err(|violation| {
                            PlanError::OutOfLimits { segment: index, label: label.clone(), violation }
                        })?;
                        let (profile, settle_s) = move_profile(&robot.links, current, target, limits);
                        let settle_s = if *through { 0.0 } else { settle_s };
                        let duration_s = profile.duration_s + settle_s;
                        (target, TimedMotion::Move { profile, settle_s, through: *through }, duration_s)
                    }
                    Segment::Sweep { from_nm, to_nm, rate_nm_per_s, .. } => {
                        check_sweep_in_range(index, &label, *from_nm, *to_nm, laser)?;
                        let duration_s = (to_nm - from_nm).abs() / rate_nm_per_s;
                        (current, TimedMotion::Sweep { from_nm: *from_nm, to_nm: *to_nm }, duration_s)
                    }
                    Segment::Dwell { duration_s, .. } => (current, TimedMotion::Dwell, *duration_s),
                };
            timed.push(TimedSegment {
                index,
                label,
                record: segment.is_recorded(),
                start_s: clock_s,
                duration_s,
                from_display: current,
                to_display: target,
                motion,
            });
            clock_s += duration_s;
            current = target;
        }
        Ok(timed)
    }

    /// Total bench time of the plan (s); see [`Plan::expand`].
    pub fn duration_s(
        &self,
        robot: &RobotDescription,
        start_q_display: [f64; 6],
        limits: &MotionLimits,
    ) -> Result<f64, PlanError> {
        Ok(total_duration_s(&self.expand(robot, start_q_display, limits)?))
    }
}

/// The joint types of a robot a plan can drive: plans give q1..q3 in µm and q4..q6 in degrees,
/// so the robot must be three prismatic then three revolute joints.
fn check_joint_kinds(robot: &RobotDescription) -> Result<(), PlanError> {
    let kinds: Vec<JointType> = robot.links.iter().map(|l| l.joint).collect();
    if !robot.is_3p3r() {
        return Err(PlanError::IncompatibleRobot {
            problem: format!(
                "plans drive q1..q3 in µm and q4..q6 in degrees, which needs three prismatic then three revolute joints; `{}` has {:?}",
                robot.name, kinds
            ),
        });
    }
    Ok(())
}

/// The start joint vector must be finite and inside the joint limits.
fn check_start(chain: &Chain, robot: &RobotDescription, start_q_display: [f64; 6]) -> Result<(), PlanError> {
    for (name, &v) in JOINT_FIELDS.iter().zip(&start_q_display) {
        if !v.is_finite() {
            return Err(PlanError::StartNotFinite { joint: name, value: v });
        }
    }
    chain
        .check_limits(&robot.q_from_display(&start_q_display))
        .map_err(|violation| PlanError::StartOutOfLimits { violation })
}

/// Both ends of sweep `index` must lie inside the laser's range.
fn check_sweep_in_range(
    index: usize,
    label: &str,
    from_nm: f64,
    to_nm: f64,
    laser: &LaserLimits,
) -> Result<(), PlanError> {
    for (field, v) in [("from_nm", from_nm), ("to_nm", to_nm)] {
        if v < laser.min_nm || v > laser.max_nm {
            return Err(PlanError::SweepOutOfRange {
                segment: index,
                label: label.to_string(),
                field: field.into(),
                value_nm: v,
                laser: *laser,
            });
        }
    }
    Ok(())
}

/// The synchronized profile of a straight-line move and its settling time. On the unit path,
/// joint j moves `d_j·s`, so its speed and acceleration are `d_j` times the path's: the path's
/// limits are the smallest `v_j/d_j` and `a_j/d_j` over the moving joints, each joint's limits
/// its own ([`MotionLimits::for_link`]).
fn move_profile(
    links: &[LinkDescription],
    from: [f64; 6],
    to: [f64; 6],
    limits: &MotionLimits,
) -> (TrapezoidProfile, f64) {
    let (mut rate, mut accel) = (f64::INFINITY, f64::INFINITY);
    for j in 0..6 {
        let d = (to[j] - from[j]).abs();
        if d > 0.0 {
            let (v, a) = limits.for_link(&links[j]);
            rate = rate.min(v / d);
            accel = accel.min(a / d);
        }
    }
    if rate.is_infinite() {
        (TrapezoidProfile::INSTANT, 0.0)
    } else {
        (TrapezoidProfile::new(rate, accel), limits.settle_s)
    }
}
