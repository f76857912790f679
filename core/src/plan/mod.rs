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
//! measurement strategies (Bettahar et al. 2020, section V.A).

mod error;
mod limits;
pub mod random;
mod timing;

pub use error::PlanError;
pub use limits::{LaserLimits, MotionLimits};
pub use timing::{segment_at, total_duration_s, TimedMotion, TimedSegment, TrapezoidProfile};

use crate::files::{self, FileError};
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

    /// Accepts a number (float or integer), `Some(number)`, `None` or `()`.
    struct OptionalNumberVisitor;
    impl<'de> Visitor<'de> for OptionalNumberVisitor {
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
            d.deserialize_any(OptionalNumberVisitor)
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
        d.deserialize_any(OptionalNumberVisitor)
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

/// Moves and dwells are recorded unless the plan says otherwise.
fn record_by_default() -> bool {
    true
}

/// `through` is written only when set, so plans without it read and write as before.
fn is_false(b: &bool) -> bool {
    !*b
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
        #[serde(default = "record_by_default")]
        record: bool,
        /// Free label, copied into the trace (default "").
        #[serde(default)]
        label: String,
        /// Go on to the next move without settling at `to` (default false): the waypoints of one
        /// recorded path, which the stages run through as one motion and settle once at its end.
        #[serde(default, skip_serializing_if = "is_false")]
        through: bool,
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
        #[serde(default = "record_by_default")]
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
        for (index, segment) in self.segments.iter().enumerate() {
            let label = || segment.label().to_string();
            let finite = |field: &str, value: f64| {
                if value.is_finite() {
                    Ok(())
                } else {
                    Err(PlanError::NonFinite { segment: index, label: label(), field: field.into(), value })
                }
            };
            let positive = |field: &str, value: f64| {
                finite(field, value)?;
                if value > 0.0 {
                    Ok(())
                } else {
                    Err(PlanError::NotPositive { segment: index, label: label(), field: field.into(), value })
                }
            };
            match segment {
                Segment::Move { to, through, .. } => {
                    for (name, v) in JOINT_FIELDS.iter().zip(to.values()) {
                        if let Some(v) = v {
                            finite(&format!("to.{name}"), v)?;
                        }
                    }
                    if *through && !self.segments.get(index + 1).is_some_and(Segment::is_move) {
                        return Err(PlanError::ThroughNotToMove { segment: index, label: label() });
                    }
                }
                Segment::Sweep { from_nm, to_nm, rate_nm_per_s, .. } => {
                    positive("from_nm", *from_nm)?;
                    positive("to_nm", *to_nm)?;
                    positive("rate_nm_per_s", *rate_nm_per_s)?;
                    if from_nm == to_nm {
                        return Err(PlanError::EmptySweep { segment: index, label: label(), wavelength_nm: *from_nm });
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

    /// Number of wavelength sweeps.
    pub fn sweeps(&self) -> usize {
        self.segments.iter().filter(|s| matches!(s, Segment::Sweep { .. })).count()
    }

    /// The plan for a bench without a tunable laser: the same motions with every wavelength
    /// sweep left out (the moves that set a sweep up still run; they record nothing).
    pub fn without_sweeps(&self) -> Plan {
        let mut p = self.clone();
        p.segments.retain(|s| !matches!(s, Segment::Sweep { .. }));
        p
    }
}

#[cfg(test)]
mod tests;
