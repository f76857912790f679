//! Motion plans as data (RON files under `assets/plans/`) and their expansion into timed segments.
//! Owns the plan format and its validation, the joint-limit check run before anything moves, and the
//! synchronized trapezoidal timing of moves, sweeps and dwells.
//!
//! A plan is a list of segments run one after the other from a start joint vector:
//! - `Move`: a straight line in joint space to a [`JointTarget`] (a joint left out keeps its
//!   value); all joints start and stop together with one trapezoidal velocity profile.
//! - `Sweep`: joints fixed, the laser wavelength swept linearly (always recorded).
//! - `Dwell`: nothing moves for a while (recorded or not).
//!
//! Units are in the field names, as in the trace CSV header: µm for q1..q3, degrees for q4..q6,
//! nm, seconds. The shipped plans ([`STRATEGY1_RON`], [`STRATEGY2_RON`]) are the paper's two
//! measurement strategies (SPEC section 4).

pub mod random;

use crate::files::{self, FileError};
use crate::model::kinematics::{Chain, LimitViolation};
use crate::model::robot::{JointType, RobotDescription};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;
use std::path::Path;

/// The paper's strategy 1 (translations only), embedded.
pub const STRATEGY1_RON: &str = include_str!("../../../assets/plans/strategy1.ron");
/// The paper's strategy 2 (rotations q4, q5), embedded.
pub const STRATEGY2_RON: &str = include_str!("../../../assets/plans/strategy2.ron");
/// The measurements the paper lacks (tilt scans, absolute gaps at several poses, rotations at
/// other gaps), for the joint estimate.
pub const JOINT_EXTRAS_RON: &str = include_str!("../../../assets/plans/joint-extras.ron");
/// The plan chosen by the experiment design ([`crate::identify::design`]) for the joint
/// estimate on `table2-ideal` (its header says how it was generated).
pub const OPTIMISED_RON: &str = include_str!("../../../assets/plans/optimised.ron");

/// Names of the six joint fields, in order, with their units (as in the trace CSV header).
pub const JOINT_FIELDS: [&str; 6] = ["q1_um", "q2_um", "q3_um", "q4_deg", "q5_deg", "q6_deg"];

const EXPECTED: &str =
    "a Plan(name, description, segments: [Move(..) | Sweep(..) | Dwell(..)]) as in assets/plans/strategy1.ron";

/// The tunable laser's wavelength range: sweeps must stay inside it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LaserLimits {
    /// Shortest wavelength (nm). Default 1500 nm.
    pub min_nm: f64,
    /// Longest wavelength (nm). Default 1630 nm.
    pub max_nm: f64,
}

impl Default for LaserLimits {
    /// 1500-1630 nm: the S+C+L tuning range of a typical external-cavity tunable laser around
    /// the paper's 1560 nm (an assumption; the paper does not name its laser).
    fn default() -> Self {
        Self { min_nm: 1500.0, max_nm: 1630.0 }
    }
}

/// Speed and acceleration limits of the stages, used to time moves (display units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MotionLimits {
    /// Largest speed of a prismatic joint (µm/s). Default 100 µm/s.
    pub prismatic_speed_um_per_s: f64,
    /// Largest speed of a revolute joint (°/s). Default 2 °/s.
    pub revolute_speed_deg_per_s: f64,
    /// Largest acceleration of a prismatic joint (µm/s²). Default 1000 µm/s².
    pub prismatic_accel_um_per_s2: f64,
    /// Largest acceleration of a revolute joint (°/s²). Default 20 °/s².
    pub revolute_accel_deg_per_s2: f64,
    /// Time to settle after a move, before the next segment (s). Default 0.05 s.
    pub settle_s: f64,
}

impl Default for MotionLimits {
    /// Assumptions for the paper's stages, not datasheet values: the PI P-563.3CD piezo stage
    /// under E-712 closed loop (100 µm/s, 1000 µm/s²), the SmarAct SGO goniometers and SR-3610
    /// rotary stage under MCS closed loop (2 °/s, 20 °/s²), 50 ms settling. Check them against
    /// the real controllers' settings before timing a real run.
    fn default() -> Self {
        Self {
            prismatic_speed_um_per_s: 100.0,
            revolute_speed_deg_per_s: 2.0,
            prismatic_accel_um_per_s2: 1000.0,
            revolute_accel_deg_per_s2: 20.0,
            settle_s: 0.05,
        }
    }
}

impl MotionLimits {
    /// Check that speeds and accelerations are finite and positive and settling finite and ≥ 0.
    pub fn validate(&self) -> Result<(), PlanError> {
        for (field, value) in [
            ("prismatic_speed_um_per_s", self.prismatic_speed_um_per_s),
            ("revolute_speed_deg_per_s", self.revolute_speed_deg_per_s),
            ("prismatic_accel_um_per_s2", self.prismatic_accel_um_per_s2),
            ("revolute_accel_deg_per_s2", self.revolute_accel_deg_per_s2),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(PlanError::BadMotionLimits { field, value, expected: "a finite positive number" });
            }
        }
        if !(self.settle_s.is_finite() && self.settle_s >= 0.0) {
            return Err(PlanError::BadMotionLimits {
                field: "settle_s",
                value: self.settle_s,
                expected: "a finite number ≥ 0",
            });
        }
        Ok(())
    }

    /// Speed and acceleration limits of a joint of this type (display units).
    pub fn for_joint(&self, joint: JointType) -> (f64, f64) {
        match joint {
            JointType::Prismatic => (self.prismatic_speed_um_per_s, self.prismatic_accel_um_per_s2),
            JointType::Revolute => (self.revolute_speed_deg_per_s, self.revolute_accel_deg_per_s2),
        }
    }
}

/// (De)serialise an `Option<f64>` as a plain number: `q3_um: 150.0` (also accepts `Some(150.0)`,
/// an integer, or `None`); a missing field is `None`.
mod plain_option {
    use super::*;
    use serde::de::{self, Visitor};

    pub fn serialize<S: Serializer>(v: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
        match v {
            Some(x) => s.serialize_f64(*x),
            None => s.serialize_none(),
        }
    }

    struct V;
    impl<'de> Visitor<'de> for V {
        type Value = Option<f64>;
        fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
            f.write_str("a number")
        }
        fn visit_f64<E: de::Error>(self, v: f64) -> Result<Self::Value, E> {
            Ok(Some(v))
        }
        fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
            Ok(Some(v as f64))
        }
        fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
            Ok(Some(v as f64))
        }
        fn visit_i128<E: de::Error>(self, v: i128) -> Result<Self::Value, E> {
            Ok(Some(v as f64))
        }
        fn visit_u128<E: de::Error>(self, v: u128) -> Result<Self::Value, E> {
            Ok(Some(v as f64))
        }
        fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
        fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
        fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
            d.deserialize_any(V)
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
        d.deserialize_any(V)
    }
}

/// Target of a move, in display units; a joint left out (`None`) keeps its current value.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointTarget {
    /// q1 (µm).
    #[serde(default, skip_serializing_if = "Option::is_none", with = "plain_option")]
    pub q1_um: Option<f64>,
    /// q2 (µm).
    #[serde(default, skip_serializing_if = "Option::is_none", with = "plain_option")]
    pub q2_um: Option<f64>,
    /// q3 (µm).
    #[serde(default, skip_serializing_if = "Option::is_none", with = "plain_option")]
    pub q3_um: Option<f64>,
    /// q4 (°).
    #[serde(default, skip_serializing_if = "Option::is_none", with = "plain_option")]
    pub q4_deg: Option<f64>,
    /// q5 (°).
    #[serde(default, skip_serializing_if = "Option::is_none", with = "plain_option")]
    pub q5_deg: Option<f64>,
    /// q6 (°).
    #[serde(default, skip_serializing_if = "Option::is_none", with = "plain_option")]
    pub q6_deg: Option<f64>,
}

impl JointTarget {
    /// A target for all six joints (display units).
    pub fn all(q_display: [f64; 6]) -> Self {
        Self::from_values(q_display.map(Some))
    }

    /// A target from six optional values (display units).
    pub fn from_values(v: [Option<f64>; 6]) -> Self {
        Self { q1_um: v[0], q2_um: v[1], q3_um: v[2], q4_deg: v[3], q5_deg: v[4], q6_deg: v[5] }
    }

    /// This target with joint `j` (0-based) set to `value` (display unit).
    ///
    /// # Panics
    /// If `j >= 6`.
    pub fn with(self, j: usize, value: f64) -> Self {
        let mut v = self.values();
        v[j] = Some(value);
        Self::from_values(v)
    }

    /// The six optional values in joint order.
    pub fn values(&self) -> [Option<f64>; 6] {
        [self.q1_um, self.q2_um, self.q3_um, self.q4_deg, self.q5_deg, self.q6_deg]
    }

    /// The joint vector reached from `current`: given joints replaced, the others kept.
    pub fn resolve(&self, current: [f64; 6]) -> [f64; 6] {
        let v = self.values();
        std::array::from_fn(|j| v[j].unwrap_or(current[j]))
    }
}

fn yes() -> bool {
    true
}

/// One step of a plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum Segment {
    /// A straight line in joint space to `to`, all joints synchronized.
    Move {
        /// Where to go; joints left out keep their values.
        to: JointTarget,
        /// Record a trace during the move (default true).
        #[serde(default = "yes")]
        record: bool,
        /// Free label, copied into the trace (default "").
        #[serde(default)]
        label: String,
    },
    /// Joints fixed, the laser wavelength swept linearly from `from_nm` to `to_nm`; always recorded.
    Sweep {
        /// Start wavelength (nm).
        from_nm: f64,
        /// End wavelength (nm), different from the start (either direction).
        to_nm: f64,
        /// Sweep rate (nm/s, positive).
        rate_nm_per_s: f64,
        /// Free label (default "").
        #[serde(default)]
        label: String,
    },
    /// Nothing moves for `duration_s`.
    Dwell {
        /// Duration (s, positive).
        duration_s: f64,
        /// Record a trace during the dwell (default true).
        #[serde(default = "yes")]
        record: bool,
        /// Free label (default "").
        #[serde(default)]
        label: String,
    },
}

impl Segment {
    /// The segment's label.
    pub fn label(&self) -> &str {
        match self {
            Segment::Move { label, .. } | Segment::Sweep { label, .. } | Segment::Dwell { label, .. } => label,
        }
    }

    /// True if a trace is recorded during the segment (always for a sweep).
    pub fn is_recorded(&self) -> bool {
        match self {
            Segment::Move { record, .. } | Segment::Dwell { record, .. } => *record,
            Segment::Sweep { .. } => true,
        }
    }

    /// True for a move.
    pub fn is_move(&self) -> bool {
        matches!(self, Segment::Move { .. })
    }
}

/// A motion plan: segments run in order from a start joint vector.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plan {
    /// Short name.
    pub name: String,
    /// What the plan does and where it comes from (default "").
    #[serde(default)]
    pub description: String,
    /// The steps, in order.
    pub segments: Vec<Segment>,
}

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
    let k = segments.partition_point(|s| s.end_s() < t_s);
    segments.get(k)
}

/// Why a plan cannot run. Every error about a segment names its index in `segments` and its
/// label, and says what was expected.
#[derive(Debug, Clone, PartialEq)]
pub enum PlanError {
    /// A number is NaN or infinite.
    NonFinite {
        /// Segment index.
        segment: usize,
        /// Segment label.
        label: String,
        /// Field, e.g. `to.q3_um` or `rate_nm_per_s`.
        field: String,
        /// The value.
        value: f64,
    },
    /// A rate or duration is zero or negative.
    NotPositive {
        /// Segment index.
        segment: usize,
        /// Segment label.
        label: String,
        /// Field, e.g. `rate_nm_per_s` or `duration_s`.
        field: String,
        /// The value.
        value: f64,
    },
    /// A sweep starts and ends at the same wavelength.
    EmptySweep {
        /// Segment index.
        segment: usize,
        /// Segment label.
        label: String,
        /// The wavelength (nm).
        wavelength_nm: f64,
    },
    /// A sweep leaves the laser's range.
    SweepOutOfRange {
        /// Segment index.
        segment: usize,
        /// Segment label.
        label: String,
        /// `from_nm` or `to_nm`.
        field: String,
        /// The wavelength (nm).
        value_nm: f64,
        /// The laser's range (nm).
        laser: LaserLimits,
    },
    /// A move ends outside the joint limits.
    OutOfLimits {
        /// Segment index.
        segment: usize,
        /// Segment label.
        label: String,
        /// Which joint, by how much.
        violation: LimitViolation,
    },
    /// The start joint vector is outside the limits.
    StartOutOfLimits {
        /// Which joint, by how much.
        violation: LimitViolation,
    },
    /// The start joint vector has a NaN or infinite value.
    StartNotFinite {
        /// Joint field name.
        joint: &'static str,
        /// The value.
        value: f64,
    },
    /// The plan has no segments.
    EmptyPlan,
    /// A motion limit is not usable.
    BadMotionLimits {
        /// Field of [`MotionLimits`].
        field: &'static str,
        /// The value.
        value: f64,
        /// What was expected.
        expected: &'static str,
    },
    /// The laser range is not usable.
    BadLaserLimits {
        /// The range as given.
        laser: LaserLimits,
    },
    /// The robot does not match the plan's joints (three prismatic then three revolute).
    IncompatibleRobot {
        /// What does not match.
        problem: String,
    },
}

impl PlanError {
    /// The segment the error is about, if any.
    pub fn segment(&self) -> Option<usize> {
        match self {
            PlanError::NonFinite { segment, .. }
            | PlanError::NotPositive { segment, .. }
            | PlanError::EmptySweep { segment, .. }
            | PlanError::SweepOutOfRange { segment, .. }
            | PlanError::OutOfLimits { segment, .. } => Some(*segment),
            _ => None,
        }
    }

    /// Path of the field in the plan file (e.g. `segments[3].rate_nm_per_s`), if any.
    pub fn field_path(&self) -> Option<String> {
        match self {
            PlanError::NonFinite { segment, field, .. }
            | PlanError::NotPositive { segment, field, .. }
            | PlanError::SweepOutOfRange { segment, field, .. } => Some(format!("segments[{segment}].{field}")),
            PlanError::EmptySweep { segment, .. } => Some(format!("segments[{segment}].to_nm")),
            PlanError::OutOfLimits { segment, violation, .. } => {
                let field = violation_field(violation);
                Some(format!("segments[{segment}].to{}", field.map(|f| format!(".{f}")).unwrap_or_default()))
            }
            PlanError::EmptyPlan => Some("segments".into()),
            _ => None,
        }
    }

    /// The label of the segment the error is about, if it has one.
    pub fn label(&self) -> Option<&str> {
        match self {
            PlanError::NonFinite { label, .. }
            | PlanError::NotPositive { label, .. }
            | PlanError::EmptySweep { label, .. }
            | PlanError::SweepOutOfRange { label, .. }
            | PlanError::OutOfLimits { label, .. } => Some(label.as_str()).filter(|l| !l.is_empty()),
            _ => None,
        }
    }

    /// What is wrong and what was expected, without the location.
    pub fn problem(&self) -> String {
        match self {
            PlanError::NonFinite { value, .. } => {
                format!("expected a finite number, found {value}")
            }
            PlanError::NotPositive { value, .. } => {
                format!("expected a positive number, found {value}")
            }
            PlanError::EmptySweep { wavelength_nm, .. } => {
                format!("expected to_nm different from from_nm, found both {wavelength_nm} nm (an empty sweep)")
            }
            PlanError::SweepOutOfRange { value_nm, laser, .. } => format!(
                "expected a wavelength inside the laser's range {}-{} nm, found {value_nm} nm",
                laser.min_nm, laser.max_nm
            ),
            PlanError::OutOfLimits { violation, .. } => {
                format!("the move ends out of the joint limits: {violation}")
            }
            PlanError::StartOutOfLimits { violation } => {
                format!("the start position is out of the joint limits: {violation}")
            }
            PlanError::StartNotFinite { joint, value } => {
                format!("start position `{joint}`: expected a finite number, found {value}")
            }
            PlanError::EmptyPlan => "expected at least one segment, found none".into(),
            PlanError::BadMotionLimits { field, value, expected } => {
                format!("motion limit `{field}`: expected {expected}, found {value}")
            }
            PlanError::BadLaserLimits { laser } => {
                format!("laser range: expected finite min_nm < max_nm, found {}-{} nm", laser.min_nm, laser.max_nm)
            }
            PlanError::IncompatibleRobot { problem } => {
                format!("robot does not fit the plan: {problem}")
            }
        }
    }

    /// The problem with the segment's label in front, as shown after a field path.
    pub fn labelled_problem(&self) -> String {
        match self.label() {
            Some(l) => format!("(segment \"{l}\") {}", self.problem()),
            None => self.problem(),
        }
    }
}

fn violation_field(v: &LimitViolation) -> Option<&'static str> {
    // The femto-6dof joints are named q1..q6; other robots may name them otherwise.
    let k = v.joint.strip_prefix('q')?.parse::<usize>().ok()?;
    JOINT_FIELDS.get(k.checked_sub(1)?).copied()
}

impl fmt::Display for PlanError {
    /// `segments[2].to.q3_um (segment "label") the move ends out of …`, or the bare problem for
    /// errors that are not about a field of the plan.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.field_path() {
            Some(path) => write!(f, "{path}: {}", self.labelled_problem()),
            None => f.write_str(&self.problem()),
        }
    }
}

impl std::error::Error for PlanError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            PlanError::OutOfLimits { violation, .. } | PlanError::StartOutOfLimits { violation } => Some(violation),
            _ => None,
        }
    }
}

impl Plan {
    /// The paper's strategy 1, from the embedded asset.
    pub fn strategy1() -> Self {
        Self::from_ron_str(STRATEGY1_RON, Path::new("assets/plans/strategy1.ron"))
            .expect("the embedded plan is valid (checked by tests)")
    }

    /// The paper's strategy 2, from the embedded asset.
    pub fn strategy2() -> Self {
        Self::from_ron_str(STRATEGY2_RON, Path::new("assets/plans/strategy2.ron"))
            .expect("the embedded plan is valid (checked by tests)")
    }

    /// The extra measurements of the joint estimate, from the embedded asset.
    pub fn joint_extras() -> Self {
        Self::from_ron_str(JOINT_EXTRAS_RON, Path::new("assets/plans/joint-extras.ron"))
            .expect("the embedded plan is valid (checked by tests)")
    }

    /// The experiment design's plan for the joint estimate, from the embedded asset.
    pub fn optimised() -> Self {
        Self::from_ron_str(OPTIMISED_RON, Path::new("assets/plans/optimised.ron"))
            .expect("the embedded plan is valid (checked by tests)")
    }

    /// Load and validate a plan file ([`Plan::validate`]; the joint limits and the laser range
    /// are checked by [`Plan::expand`], which knows the robot).
    pub fn load(path: &Path) -> Result<Self, FileError> {
        let text = files::read_text(path)?;
        Self::from_ron_str(&text, path)
    }

    /// Parse and validate plan text; `origin` names it in errors (file, line and column for
    /// syntax and unknown or missing fields, field path for invalid values).
    pub fn from_ron_str(text: &str, origin: &Path) -> Result<Self, FileError> {
        let plan: Self = files::parse_ron(text, origin, EXPECTED)?;
        plan.validate().map_err(|e| FileError::Invalid {
            file: origin.to_path_buf(),
            field: e.field_path().unwrap_or_else(|| "segments".into()),
            problem: e.labelled_problem(),
        })?;
        Ok(plan)
    }

    /// Save as RON, atomically.
    pub fn save(&self, path: &Path) -> Result<(), FileError> {
        files::save_ron(path, self)
    }

    /// Checks that need no robot: at least one segment, finite numbers, positive rates and
    /// durations, sweeps of non-zero span.
    pub fn validate(&self) -> Result<(), PlanError> {
        if self.segments.is_empty() {
            return Err(PlanError::EmptyPlan);
        }
        for (k, seg) in self.segments.iter().enumerate() {
            let label = || seg.label().to_string();
            let finite = |field: &str, value: f64| {
                if value.is_finite() {
                    Ok(())
                } else {
                    Err(PlanError::NonFinite { segment: k, label: label(), field: field.into(), value })
                }
            };
            let positive = |field: &str, value: f64| {
                finite(field, value)?;
                if value > 0.0 {
                    Ok(())
                } else {
                    Err(PlanError::NotPositive { segment: k, label: label(), field: field.into(), value })
                }
            };
            match seg {
                Segment::Move { to, .. } => {
                    for (name, v) in JOINT_FIELDS.iter().zip(to.values()) {
                        if let Some(v) = v {
                            finite(&format!("to.{name}"), v)?;
                        }
                    }
                }
                Segment::Sweep { from_nm, to_nm, rate_nm_per_s, .. } => {
                    positive("from_nm", *from_nm)?;
                    positive("to_nm", *to_nm)?;
                    positive("rate_nm_per_s", *rate_nm_per_s)?;
                    if from_nm == to_nm {
                        return Err(PlanError::EmptySweep { segment: k, label: label(), wavelength_nm: *from_nm });
                    }
                }
                Segment::Dwell { duration_s, .. } => positive("duration_s", *duration_s)?,
            }
        }
        Ok(())
    }

    /// Number of recorded moves (the measurements a strategy yields).
    pub fn recorded_moves(&self) -> usize {
        self.segments.iter().filter(|s| s.is_move() && s.is_recorded()).count()
    }

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
        let kinds: Vec<JointType> = robot.links.iter().map(|l| l.joint).collect();
        if !robot.is_3p3r() {
            return Err(PlanError::IncompatibleRobot {
                problem: format!(
                    "plans drive q1..q3 in µm and q4..q6 in degrees, which needs three prismatic then three revolute joints; `{}` has {:?}",
                    robot.name, kinds
                ),
            });
        }
        let chain = Chain::new(robot.clone());
        for (name, &v) in JOINT_FIELDS.iter().zip(&start_q_display) {
            if !v.is_finite() {
                return Err(PlanError::StartNotFinite { joint: name, value: v });
            }
        }
        chain
            .check_limits(&robot.q_from_display(&start_q_display))
            .map_err(|violation| PlanError::StartOutOfLimits { violation })?;

        let mut out = Vec::with_capacity(self.segments.len());
        let mut current = start_q_display;
        let mut t = 0.0;
        for (k, seg) in self.segments.iter().enumerate() {
            let label = seg.label().to_string();
            let (target, motion, duration_s) =
                match seg {
                    Segment::Move { to, .. } => {
                        let target = to.resolve(current);
                        chain.check_limits(&robot.q_from_display(&target)).map_err(|violation| {
                            PlanError::OutOfLimits { segment: k, label: label.clone(), violation }
                        })?;
                        let (profile, settle_s) = move_profile(&kinds, current, target, limits);
                        let duration_s = profile.duration_s + settle_s;
                        (target, TimedMotion::Move { profile, settle_s }, duration_s)
                    }
                    Segment::Sweep { from_nm, to_nm, rate_nm_per_s, .. } => {
                        for (field, v) in [("from_nm", *from_nm), ("to_nm", *to_nm)] {
                            if v < laser.min_nm || v > laser.max_nm {
                                return Err(PlanError::SweepOutOfRange {
                                    segment: k,
                                    label,
                                    field: field.into(),
                                    value_nm: v,
                                    laser: *laser,
                                });
                            }
                        }
                        let duration_s = (to_nm - from_nm).abs() / rate_nm_per_s;
                        (current, TimedMotion::Sweep { from_nm: *from_nm, to_nm: *to_nm }, duration_s)
                    }
                    Segment::Dwell { duration_s, .. } => (current, TimedMotion::Dwell, *duration_s),
                };
            out.push(TimedSegment {
                index: k,
                label,
                record: seg.is_recorded(),
                start_s: t,
                duration_s,
                from_display: current,
                to_display: target,
                motion,
            });
            t += duration_s;
            current = target;
        }
        Ok(out)
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

/// The synchronized profile of a straight-line move and its settling time. On the unit path,
/// joint j moves `d_j·s`, so its speed and acceleration are `d_j` times the path's: the path's
/// limits are the smallest `v_j/d_j` and `a_j/d_j` over the moving joints.
fn move_profile(kinds: &[JointType], from: [f64; 6], to: [f64; 6], limits: &MotionLimits) -> (TrapezoidProfile, f64) {
    let (mut rate, mut accel) = (f64::INFINITY, f64::INFINITY);
    for j in 0..6 {
        let d = (to[j] - from[j]).abs();
        if d > 0.0 {
            let (v, a) = limits.for_joint(kinds[j]);
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

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use proptest::prelude::*;
    use std::path::PathBuf;

    fn robot() -> RobotDescription {
        RobotDescription::femto_6dof()
    }

    fn no_settle() -> MotionLimits {
        MotionLimits { settle_s: 0.0, ..MotionLimits::default() }
    }

    fn mv(to: JointTarget, label: &str) -> Segment {
        Segment::Move { to, record: true, label: label.into() }
    }

    fn plan(segments: Vec<Segment>) -> Plan {
        Plan { name: "t".into(), description: String::new(), segments }
    }

    /// Closed-form time of a single-joint trapezoid.
    fn closed_form(d: f64, v: f64, a: f64) -> f64 {
        if d >= v * v / a {
            d / v + v / a
        } else {
            2.0 * (d / a).sqrt()
        }
    }

    #[test]
    fn move_timing_matches_the_trapezoid_and_triangle_closed_forms() {
        let l = no_settle();
        // (joint, distance): prismatic long (trapezoid, cruise reached) and short (triangle),
        // revolute long and short. v²/a = 10 µm for the piezo, 0.2° for the goniometers.
        for (j, d) in [(2, 300.0), (0, 20.0), (1, 5.0), (2, 0.4), (3, 8.0), (4, 0.5), (5, 0.05)] {
            let (v, a) = if j < 3 { (100.0, 1000.0) } else { (2.0, 20.0) };
            let p = plan(vec![mv(JointTarget::default().with(j, d / 2.0), "m")]);
            let start = {
                let mut q = [0.0; 6];
                q[j] = -d / 2.0;
                q
            };
            let segs = p.expand(&robot(), start, &l).unwrap();
            assert_eq!(segs.len(), 1);
            let want = closed_form(d, v, a);
            assert_relative_eq!(segs[0].duration_s, want, max_relative = 1e-12);
            // The profile peaks at the joint's speed limit when the cruise is reached.
            let peak = segs[0].velocity_at(want / 2.0)[j];
            if d >= v * v / a {
                assert_relative_eq!(peak, v, max_relative = 1e-12);
            } else {
                assert_relative_eq!(peak, (a * d).sqrt(), max_relative = 1e-12);
            }
        }
        // The paper's 300 µm move at the defaults: 3 s cruise + 0.1 s of ramps + 0.05 s settling.
        let p = plan(vec![mv(JointTarget::default().with(2, 150.0), "X_w")]);
        let segs = p.expand(&robot(), [0.0, 0.0, -150.0, 0.0, 0.0, 0.0], &MotionLimits::default()).unwrap();
        assert_relative_eq!(segs[0].duration_s, 3.15, max_relative = 1e-12);
    }

    #[test]
    fn synchronized_joints_start_and_end_together_on_a_straight_line() {
        let l = no_settle();
        // q1 by 300 µm (3.1 s alone) with q4 by 1° (0.6 s alone) and q2 by 20 µm.
        let from = [-150.0, -10.0, 0.0, 0.0, 0.0, 0.0];
        let to = [150.0, 10.0, 0.0, 1.0, 0.0, 0.0];
        let segs = plan(vec![mv(JointTarget::all(to), "sync")]).expand(&robot(), from, &l).unwrap();
        let s = &segs[0];
        // The path limits are min(v_j/d_j) = 100/300 and min(a_j/d_j) = 1000/300, both from q1:
        // q1 alone sets the time.
        assert_relative_eq!(s.duration_s, closed_form(300.0, 100.0, 1000.0), max_relative = 1e-12);
        assert_eq!(s.position_at(s.duration_s), to);
        assert_eq!(s.position_at(0.0), from);
        let n = 1000;
        for i in 1..n {
            let t = s.duration_s * i as f64 / n as f64;
            let p = s.position_at(t);
            let fractions: Vec<f64> =
                (0..6).filter(|&j| to[j] != from[j]).map(|j| (p[j] - from[j]) / (to[j] - from[j])).collect();
            for f in &fractions {
                assert!((f - fractions[0]).abs() < 1e-12, "joints out of step at t = {t}");
                assert!(*f > 0.0 && *f < 1.0, "a joint finished early or not started at t = {t}");
            }
            let v = s.velocity_at(t);
            assert!(v[0].abs() <= 100.0 + 1e-9 && v[3].abs() <= 2.0 + 1e-9);
        }
    }

    #[test]
    fn same_type_joints_take_the_slowest_joints_time() {
        // Three translations of 300, 100 and 3 µm: the 300 µm one sets the duration.
        let from = [0.0; 6];
        let to = [100.0, 3.0, -150.0, 0.0, 0.0, 0.0];
        let s = &plan(vec![mv(JointTarget::all(to), "xyz")]).expand(&robot(), from, &no_settle()).unwrap()[0];
        assert_relative_eq!(s.duration_s, closed_form(150.0, 100.0, 1000.0), max_relative = 1e-12);
    }

    #[test]
    fn partial_target_keeps_the_other_joints() {
        let start = [12.5, -3.0, 140.0, 1.5, -2.5, 30.0];
        let p = plan(vec![
            mv(JointTarget { q2_um: Some(7.0), q5_deg: Some(4.0), ..Default::default() }, "partial"),
            Segment::Dwell { duration_s: 1.0, record: false, label: "wait".into() },
            mv(JointTarget { q6_deg: Some(-30.0), ..Default::default() }, "q6 only"),
        ]);
        let segs = p.expand(&robot(), start, &MotionLimits::default()).unwrap();
        assert_eq!(segs[0].to_display, [12.5, 7.0, 140.0, 1.5, 4.0, 30.0]);
        assert_eq!(segs[1].from_display, segs[0].to_display);
        assert_eq!(segs[1].to_display, segs[0].to_display);
        assert_eq!(segs[2].to_display, [12.5, 7.0, 140.0, 1.5, 4.0, -30.0]);
        // Joints not in the target do not move at all during the move.
        for i in 0..=10 {
            let p = segs[0].position_at(segs[0].duration_s * i as f64 / 10.0);
            assert_eq!([p[0], p[2], p[3], p[5]], [12.5, 140.0, 1.5, 30.0]);
        }
    }

    #[test]
    fn position_is_continuous_within_and_across_segments() {
        let p = plan(vec![
            mv(JointTarget::all([-150.0, 0.0, -150.0, 0.0, 0.0, 0.0]), "a"),
            Segment::Sweep { from_nm: 1550.0, to_nm: 1570.0, rate_nm_per_s: 10.0, label: "s".into() },
            mv(JointTarget::default().with(2, 150.0), "b"),
            mv(JointTarget::default().with(1, 0.3), "tiny"),
            mv(JointTarget::default().with(1, 0.3), "zero-length"),
            mv(JointTarget { q4_deg: Some(-4.0), q5_deg: Some(3.0), ..Default::default() }, "rot"),
            Segment::Dwell { duration_s: 0.5, record: true, label: "d".into() },
        ]);
        let limits = MotionLimits::default();
        let segs = p.expand(&robot(), [0.0; 6], &limits).unwrap();
        // Zero-length moves take no time; sweeps take span/rate.
        assert_eq!(segs[4].duration_s, 0.0);
        assert_relative_eq!(segs[1].duration_s, 2.0);
        assert_eq!(segs[1].wavelength_at(1.0), Some(1560.0));
        assert_eq!(segs[1].wavelength_at(9.0), Some(1570.0));
        assert_eq!(segs[0].wavelength_at(0.0), None);
        let total = total_duration_s(&segs);
        for w in segs.windows(2) {
            assert_eq!(w[0].to_display, w[1].from_display);
            assert_eq!(w[0].end_s(), w[1].start_s);
        }
        let at = |t: f64| {
            let s = segment_at(&segs, t).unwrap();
            s.position_at(t - s.start_s)
        };
        // A joint cannot move faster than its limit: bound the jump over each small step.
        let dt = 1e-3;
        let mut t = 0.0;
        let mut prev = at(0.0);
        while t + dt <= total {
            t += dt;
            let p = at(t);
            for j in 0..6 {
                let vmax = if j < 3 { limits.prismatic_speed_um_per_s } else { limits.revolute_speed_deg_per_s };
                assert!((p[j] - prev[j]).abs() <= vmax * dt * (1.0 + 1e-9) + 1e-9, "jump of joint {j} at t = {t}");
            }
            prev = p;
        }
        assert_eq!(at(total), [-150.0, 0.3, 150.0, -4.0, 3.0, 0.0]);
        assert!(segment_at(&segs, total + 1e-6).is_none() && segment_at(&segs, -1e-6).is_none());
    }

    #[test]
    fn limit_violations_name_the_segment_label_and_joint_before_anything_runs() {
        let ok = mv(JointTarget::default().with(2, 150.0), "fine");
        let p = plan(vec![ok.clone(), ok.clone(), mv(JointTarget::default().with(2, 200.0), "too far")]);
        let err = p.expand(&robot(), [0.0; 6], &MotionLimits::default()).unwrap_err();
        match &err {
            PlanError::OutOfLimits { segment, label, violation } => {
                assert_eq!((*segment, label.as_str(), violation.joint.as_str()), (2, "too far", "q3"));
                assert_eq!((violation.value, violation.limit), (200.0, 150.0));
            }
            other => panic!("expected OutOfLimits, got {other:?}"),
        }
        assert_eq!(
            err.to_string(),
            "segments[2].to.q3_um: (segment \"too far\") the move ends out of the joint limits: joint q3 = 200.000 µm is 50.000 µm above its upper limit 150.000 µm"
        );
        assert_eq!(err.field_path().as_deref(), Some("segments[2].to.q3_um"));
        // A revolute joint, below its lower limit, reached through a partial target from a start
        // that is itself fine.
        let p = plan(vec![mv(JointTarget { q5_deg: Some(-12.0), ..Default::default() }, "")]);
        let err = p.expand(&robot(), [0.0, 0.0, 0.0, 9.0, 0.0, 0.0], &MotionLimits::default()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "segments[0].to.q5_deg: the move ends out of the joint limits: joint q5 = -12.000 ° is 2.000 ° below its lower limit -10.000 °"
        );
        // The start itself.
        let err =
            plan(vec![ok]).expand(&robot(), [0.0, 0.0, 0.0, 0.0, 0.0, 181.0], &MotionLimits::default()).unwrap_err();
        assert!(
            err.to_string().starts_with("the start position is out of the joint limits: joint q6 = 181.000 °"),
            "{err}"
        );
    }

    #[test]
    fn bad_numbers_and_limits_are_refused_with_the_segment() {
        let r = robot();
        let l = MotionLimits::default();
        let cases: Vec<(Segment, &str)> = vec![
            (
                Segment::Sweep { from_nm: 1550.0, to_nm: 1650.0, rate_nm_per_s: 1.0, label: "long".into() },
                "segments[0].to_nm: (segment \"long\") expected a wavelength inside the laser's range 1500-1630 nm, found 1650 nm",
            ),
            (
                Segment::Sweep { from_nm: 1550.0, to_nm: 1570.0, rate_nm_per_s: 0.0, label: "".into() },
                "segments[0].rate_nm_per_s: expected a positive number, found 0",
            ),
            (
                Segment::Sweep { from_nm: 1560.0, to_nm: 1560.0, rate_nm_per_s: 1.0, label: "".into() },
                "segments[0].to_nm: expected to_nm different from from_nm, found both 1560 nm (an empty sweep)",
            ),
            (
                Segment::Dwell { duration_s: -1.0, record: true, label: "w".into() },
                "segments[0].duration_s: (segment \"w\") expected a positive number, found -1",
            ),
            (
                Segment::Dwell { duration_s: f64::INFINITY, record: true, label: "".into() },
                "segments[0].duration_s: expected a finite number, found inf",
            ),
            (
                mv(JointTarget { q4_deg: Some(f64::NAN), ..Default::default() }, "nan"),
                "segments[0].to.q4_deg: (segment \"nan\") expected a finite number, found NaN",
            ),
        ];
        for (seg, want) in cases {
            let err = plan(vec![seg]).expand(&r, [0.0; 6], &l).unwrap_err();
            assert_eq!(err.to_string(), want);
        }
        let ok = plan(vec![mv(JointTarget::default(), "")]);
        let bad_limits = MotionLimits { revolute_accel_deg_per_s2: 0.0, ..l };
        assert_eq!(
            ok.expand(&r, [0.0; 6], &bad_limits).unwrap_err().to_string(),
            "motion limit `revolute_accel_deg_per_s2`: expected a finite positive number, found 0"
        );
        let err = ok.expand(&r, [f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0], &l).unwrap_err();
        assert_eq!(err.to_string(), "start position `q1_um`: expected a finite number, found NaN");
        assert_eq!(plan(vec![]).expand(&r, [0.0; 6], &l).unwrap_err(), PlanError::EmptyPlan);
        let narrow = LaserLimits { min_nm: 1555.0, max_nm: 1565.0 };
        let sweep = plan(vec![Segment::Sweep { from_nm: 1550.0, to_nm: 1560.0, rate_nm_per_s: 1.0, label: "".into() }]);
        assert!(sweep.expand(&r, [0.0; 6], &l).is_ok());
        assert!(matches!(
            sweep.expand_with_laser(&r, [0.0; 6], &l, &narrow),
            Err(PlanError::SweepOutOfRange { segment: 0, .. })
        ));
        // A robot whose joints do not match the plan's units is refused, not indexed out of range.
        let mut five = robot();
        five.links.pop();
        let err = ok.expand(&five, [0.0; 6], &l).unwrap_err().to_string();
        assert!(err.starts_with("robot does not fit the plan"), "{err}");
    }

    fn parse(text: &str) -> Result<Plan, FileError> {
        Plan::from_ron_str(text, Path::new("bad.ron"))
    }

    #[test]
    fn plan_files_parse_partial_targets_and_defaults() {
        let p = parse(
            "Plan(name: \"p\", segments: [\n  Move(to: (q3_um: 150, q5_deg: Some(-2.5))),\n  Dwell(duration_s: 1.0, record: false),\n  Sweep(from_nm: 1550.0, to_nm: 1570.0, rate_nm_per_s: 1.0, label: \"s\"),\n])",
        )
        .unwrap();
        assert_eq!(p.description, "");
        assert_eq!(
            p.segments[0],
            Segment::Move {
                to: JointTarget { q3_um: Some(150.0), q5_deg: Some(-2.5), ..Default::default() },
                record: true,
                label: String::new()
            }
        );
        assert!(!p.segments[1].is_recorded() && p.segments[2].is_recorded());
        // Save and load again.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.ron");
        p.save(&path).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("q3_um: 150.0") && !text.contains("q1_um"), "{text}");
        assert_eq!(Plan::load(&path).unwrap(), p);
    }

    #[test]
    fn bad_plan_files_give_clear_errors() {
        let cases: &[(&str, &[&str])] = &[
            (
                "Plan(name: \"p\", segments: [\n  Move(to: (q3: 150.0)),\n])",
                &["bad.ron:2:13: Unexpected field named `q3`", "expected one of `q1_um`", "expected a Plan("],
            ),
            ("Plan(name: \"p\", segments: [\n  Move(record: false),\n])", &["bad.ron:2:", "`to`"]),
            ("Plan(name: \"p\", segments: [\n\n  Jump(to: ()),\n])", &["bad.ron:3:", "Jump"]),
            (
                "Plan(name: \"p\", segments: [\n  Sweep(from_nm: 1550.0, to_nm: 1570.0, rate_nm_per_s: -2.0, label: \"before X_w\"),\n])",
                &["bad.ron: field `segments[0].rate_nm_per_s`: (segment \"before X_w\") expected a positive number, found -2"],
            ),
            (
                "Plan(name: \"p\", segments: [Dwell(duration_s: 0.0), Move(to: (q1_um: NaN))])",
                &["bad.ron: field `segments[0].duration_s`", "expected a positive number, found 0"],
            ),
            (
                "Plan(name: \"p\", segments: [Move(to: (q1_um: inf))])",
                &["bad.ron: field `segments[0].to.q1_um`", "expected a finite number, found inf"],
            ),
            ("Plan(name: \"p\", segments: [])", &["bad.ron: field `segments`: expected at least one segment, found none"]),
            ("Plan(name: \"p\", segments: [Move(to: (q2_um: \"ten\"))])", &["bad.ron:1:", "expected a Plan("]),
        ];
        for (text, wants) in cases {
            let err = parse(text).expect_err(text).to_string();
            println!("{err}");
            for want in *wants {
                assert!(err.contains(want), "{text}\n  got `{err}`\n  want `{want}`");
            }
        }
        let err = Plan::load(Path::new("/no/such/plan.ron")).unwrap_err().to_string();
        assert!(err.contains("/no/such/plan.ron"), "{err}");
    }

    fn shipped(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/plans").join(name)
    }

    /// Recorded moves as (moving joint, joint vector at the start, distance).
    fn recorded_moves(segs: &[TimedSegment]) -> Vec<(usize, [f64; 6], f64)> {
        segs.iter()
            .filter(|s| s.record && matches!(s.motion, TimedMotion::Move { .. }))
            .map(|s| {
                let moving: Vec<usize> = (0..6).filter(|&j| s.to_display[j] != s.from_display[j]).collect();
                assert_eq!(moving.len(), 1, "{}: a recorded move drives exactly one joint", s.label);
                let j = moving[0];
                (j, s.from_display, s.to_display[j] - s.from_display[j])
            })
            .collect()
    }

    #[test]
    fn shipped_strategy1_is_the_papers_translation_strategy() {
        let p = Plan::load(&shipped("strategy1.ron")).unwrap();
        assert_eq!(p, Plan::strategy1());
        let segs = p.expand(&robot(), [0.0; 6], &MotionLimits::default()).unwrap();
        assert_eq!(p.recorded_moves(), 18);
        // Orientation fixed throughout: only translations.
        for s in &segs {
            assert_eq!(&s.to_display[3..], [0.0; 3], "{}", s.label);
        }
        // The paper: lamella positions -150, 0, +150 µm along Z_w (q1), then Y_w (q2), then X_w (q3);
        // at each, two continuous translations: X_w 300 µm and Y_w 20 µm; X_w and Z_w 300 µm;
        // Z_w 300 µm and Y_w 20 µm. 300 µm moves run -150 -> +150, 20 µm ones -10 -> +10
        // (both centred on the stage); the joints not named stay at the centre.
        // q1 moves along Z_w, q2 along Y_w, q3 along X_w.
        let (z, y, x) = (0usize, 1usize, 2usize);
        let mut want = Vec::new();
        for (held, moves) in [(z, [x, y]), (y, [x, z]), (x, [z, y])] {
            for pos in [-150.0, 0.0, 150.0] {
                for m in moves {
                    let half = if m == y { 10.0 } else { 150.0 };
                    let mut from = [0.0; 6];
                    from[held] = pos;
                    from[m] = -half;
                    want.push((m, from, 2.0 * half));
                }
            }
        }
        assert_eq!(recorded_moves(&segs), want);
        // A wavelength sweep right before and right after every X_w and Z_w move (the sign of dL).
        let mut sweeps_checked = 0;
        for (k, s) in segs.iter().enumerate() {
            if s.record && matches!(s.motion, TimedMotion::Move { .. }) && s.to_display[y] == s.from_display[y] {
                for n in [&segs[k - 1], &segs[k + 1]] {
                    assert!(matches!(n.motion, TimedMotion::Sweep { .. }), "{} needs sweeps around it", s.label);
                    assert!(n.record);
                }
                sweeps_checked += 2;
            }
        }
        assert_eq!(sweeps_checked, 24);
        let sweeps = segs.iter().filter(|s| matches!(s.motion, TimedMotion::Sweep { .. })).count();
        assert_eq!(sweeps, 24, "no sweep beyond those the paper uses");
        let total = total_duration_s(&segs);
        println!("strategy 1: {} segments, 18 recorded moves, {total:.1} s of bench time", segs.len());
        assert!(total > 120.0 && total < 20.0 * 60.0, "implausible bench time {total} s");
        // It ends where it started.
        assert_eq!(segs.last().unwrap().to_display, [0.0; 6]);
    }

    #[test]
    fn shipped_joint_extras_is_inside_the_limits_with_tilt_scans_and_sweeps() {
        let p = Plan::joint_extras();
        let robot = RobotDescription::femto_6dof();
        let segs = p.expand(&robot, [0.0; 6], &MotionLimits::default()).unwrap();
        let scans = segs.iter().filter(|s| s.record && s.label.starts_with("tilt scan")).count();
        let sweeps = segs.iter().filter(|s| matches!(s.motion, TimedMotion::Sweep { .. })).count();
        assert_eq!((scans, sweeps), (4, 5));
        let d = total_duration_s(&segs);
        assert!(d > 60.0 && d < 300.0, "{d} s");
    }

    #[test]
    fn shipped_strategy2_is_the_papers_rotation_strategy() {
        let p = Plan::load(&shipped("strategy2.ron")).unwrap();
        assert_eq!(p, Plan::strategy2());
        let segs = p.expand(&robot(), [0.0; 6], &MotionLimits::default()).unwrap();
        assert_eq!(p.recorded_moves(), 10);
        for s in &segs {
            assert_eq!(&s.to_display[..3], [0.0; 3], "{}: translations stay at 0", s.label);
            assert_eq!(s.to_display[5], 0.0, "{}: q6 stays at 0", s.label);
        }
        let mut want = Vec::new();
        for (sweeping, other) in [(3usize, 4usize), (4, 3)] {
            for v in [-4.0, -2.0, 0.0, 2.0, 4.0] {
                let mut from = [0.0; 6];
                from[sweeping] = -4.0;
                from[other] = v;
                want.push((sweeping, from, 8.0));
            }
        }
        assert_eq!(recorded_moves(&segs), want);
        let total = total_duration_s(&segs);
        println!("strategy 2: {} segments, 10 recorded moves, {total:.1} s of bench time", segs.len());
        assert!(total > 40.0 && total < 10.0 * 60.0, "implausible bench time {total} s");
        let both = total + Plan::strategy1().duration_s(&robot(), [0.0; 6], &MotionLimits::default()).unwrap();
        println!(
            "both strategies: {:.1} min of bench time (paper: about 30 min for measurement and identification)",
            both / 60.0
        );
        assert!(both < 30.0 * 60.0);
        assert_eq!(segs.last().unwrap().to_display, [0.0; 6]);
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 300, failure_persistence: None, ..ProptestConfig::default() })]

        /// Any move within the limits: ends exactly at the target, never exceeds the joint
        /// speeds, lasts at least as long as each joint alone would need.
        #[test]
        fn random_moves_respect_speed_limits_and_end_on_target(
            from in prop::array::uniform6(-1.0f64..1.0),
            to in prop::array::uniform6(-1.0f64..1.0),
            mask in prop::array::uniform6(any::<bool>()),
        ) {
            let scale = [150.0, 150.0, 150.0, 10.0, 10.0, 180.0];
            let from: [f64; 6] = std::array::from_fn(|j| from[j] * scale[j]);
            let target: [Option<f64>; 6] = std::array::from_fn(|j| mask[j].then_some(to[j] * scale[j]));
            let l = no_settle();
            let segs = plan(vec![mv(JointTarget::from_values(target), "r")]).expand(&robot(), from, &l).unwrap();
            let s = &segs[0];
            let end = JointTarget::from_values(target).resolve(from);
            prop_assert_eq!(s.position_at(s.duration_s), end);
            for j in 0..6 {
                let (v, a) = if j < 3 { (100.0, 1000.0) } else { (2.0, 20.0) };
                let d = (end[j] - from[j]).abs();
                prop_assert!(s.duration_s >= closed_form(d, v, a) * (1.0 - 1e-12));
                for i in 0..=50 {
                    let t = s.duration_s * i as f64 / 50.0;
                    prop_assert!(s.velocity_at(t)[j].abs() <= v * (1.0 + 1e-12));
                }
            }
        }
    }
}
