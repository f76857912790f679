//! The robot description: a serial chain of Khalil-Kleinfinger links with Hayati's β, read from a data file.
//! Owns the description format (`assets/robots/*.ron`), its validation and the joint-unit conventions.
//!
//! Units: in files and on screen, prismatic joints are in µm and revolute joints in degrees.
//! Inside the library a joint vector `q` holds µm for prismatic joints and **radians** for
//! revolute joints; [`RobotDescription::q_from_display`] and [`RobotDescription::q_to_display`]
//! convert.

use crate::files::{self, FieldError, FileError};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The robot shipped with the project (the paper's bench), embedded so the app runs anywhere.
pub const FEMTO_6DOF_RON: &str = include_str!("../../../assets/robots/femto-6dof.ron");

/// Joints of every robot the software drives: poses, plans and traces carry six.
pub const JOINTS: usize = 6;

/// The kind of a joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum JointType {
    /// Translation along the link's z axis; the joint variable adds to `r` (µm).
    Prismatic,
    /// Rotation about the link's z axis; the joint variable adds to `θ` (°).
    Revolute,
}

impl JointType {
    /// The unit the joint is shown and stored in, in files and on screen.
    pub fn display_unit(self) -> &'static str {
        match self {
            JointType::Prismatic => "µm",
            JointType::Revolute => "°",
        }
    }
}

/// Joint limits, in the joint's display unit (µm or °), and how fast the axis may move.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Limits {
    /// Lower limit (µm or °).
    pub min: f64,
    /// Upper limit (µm or °).
    pub max: f64,
    /// Largest speed of the axis in its display unit per second (µm/s or °/s); `None`: the
    /// bench's speed for the joint type ([`crate::plan::MotionLimits`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed_per_s: Option<f64>,
    /// Largest acceleration of the axis in its display unit per second squared (µm/s² or °/s²);
    /// `None`: the bench's acceleration for the joint type.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accel_per_s2: Option<f64>,
}

/// Which controller and channel drives a joint (used by the hardware drivers).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Drive {
    /// Controller model, e.g. "PI E-712" or "SmarAct MCS".
    pub controller: String,
    /// Channel or axis identifier on that controller.
    pub channel: String,
}

/// One link of the chain: `T(i-1,i) = RotY(β)·RotX(α)·TransX(d)·RotZ(θ)·TransZ(r)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinkDescription {
    /// Joint name (e.g. "q1").
    pub name: String,
    /// The physical stage, free text.
    #[serde(default)]
    pub stage: String,
    /// Prismatic or revolute.
    pub joint: JointType,
    /// Hayati's β, about the previous y axis (°).
    pub beta_deg: f64,
    /// α, about the previous x axis (°).
    pub alpha_deg: f64,
    /// d, along the previous x axis (µm).
    pub d_um: f64,
    /// θ offset about z (°); the joint variable adds to it for a revolute joint.
    pub theta_deg: f64,
    /// r offset along z (µm); the joint variable adds to it for a prismatic joint.
    pub r_um: f64,
    /// Joint limits in the display unit (µm or °).
    pub limits: Limits,
    /// Controller and channel driving the joint, if known.
    #[serde(default)]
    pub drive: Option<Drive>,
    /// Intrinsic errors of the joint (all zero for a nominal robot). The diagnosis effects and
    /// the virtual bench's hidden effects act through these.
    #[serde(default, skip_serializing_if = "JointErrors::is_nominal")]
    pub errors: JointErrors,
}

/// Intrinsic errors of one joint, neutral at zero. Expressed in the link frame after the
/// constant part of the link transform (z = the nominal joint axis).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct JointErrors {
    /// A point the (revolute) joint axis passes through, in the link frame (µm): a pivot offset.
    pub axis_offset_um: [f64; 3],
    /// Tilt of the joint axis toward the link's x and y axes (mrad).
    pub axis_tilt_mrad: [f64; 2],
    /// Scale (gain) error of the joint (ppm): the joint moves q·(1 + scale).
    pub scale_ppm: f64,
    /// Zero offset of the joint, in the display unit (µm or °).
    pub zero_offset: f64,
}

impl JointErrors {
    /// True when every error is zero.
    pub fn is_nominal(&self) -> bool {
        *self == Self::default()
    }
}

/// A serial robot described link by link.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobotDescription {
    /// Name of the robot.
    pub name: String,
    /// Where the numbers come from.
    #[serde(default)]
    pub source: String,
    /// The links from the base outward.
    pub links: Vec<LinkDescription>,
}

const EXPECTED: &str = "a RobotDescription(name, source, links: [...]) as in assets/robots/femto-6dof.ron";

impl RobotDescription {
    /// The paper's robot (Table I), from the embedded asset.
    pub fn femto_6dof() -> Self {
        Self::from_ron_str(FEMTO_6DOF_RON, Path::new("assets/robots/femto-6dof.ron"))
            .expect("the embedded robot description is valid (checked by tests)")
    }

    /// Load and validate a description file.
    pub fn load(path: &Path) -> Result<Self, FileError> {
        let text = files::read_text(path)?;
        Self::from_ron_str(&text, path)
    }

    /// Parse and validate description text; `origin` names it in errors.
    pub fn from_ron_str(text: &str, origin: &Path) -> Result<Self, FileError> {
        let d: Self = files::parse_ron(text, origin, EXPECTED)?;
        d.validate().map_err(|e| e.in_file(origin))?;
        Ok(d)
    }

    /// Check every field (six links): finite numbers, ordered limits that contain zero, unique names.
    pub fn validate(&self) -> Result<(), FieldError> {
        // Poses, plans and traces all carry six joints (three stages, two goniometers, a rotary
        // stage): another count would reach the kinematics with vectors of the wrong length.
        if self.links.len() != JOINTS {
            return Err(FieldError::new(
                "links",
                format!("expected {JOINTS} links (q1..q6, base to end effector), found {}", self.links.len()),
            ));
        }
        for (i, l) in self.links.iter().enumerate() {
            let f = |name: &str| format!("links[{i}].{name}");
            if l.name.trim().is_empty() {
                return Err(FieldError::new(f("name"), "expected a joint name, found an empty string"));
            }
            if self.links[..i].iter().any(|o| o.name == l.name) {
                return Err(FieldError::new(f("name"), format!("joint name `{}` is used twice", l.name)));
            }
            for (name, v) in [
                ("beta_deg", l.beta_deg),
                ("alpha_deg", l.alpha_deg),
                ("d_um", l.d_um),
                ("theta_deg", l.theta_deg),
                ("r_um", l.r_um),
                ("limits.min", l.limits.min),
                ("limits.max", l.limits.max),
                ("errors.axis_offset_um", l.errors.axis_offset_um.iter().sum::<f64>()),
                ("errors.axis_tilt_mrad", l.errors.axis_tilt_mrad.iter().sum::<f64>()),
                ("errors.scale_ppm", l.errors.scale_ppm),
                ("errors.zero_offset", l.errors.zero_offset),
            ] {
                if !v.is_finite() {
                    return Err(FieldError::new(f(name), format!("expected a finite number, found {v}")));
                }
            }
            let unit = l.joint.display_unit();
            if l.limits.min >= l.limits.max {
                return Err(FieldError::new(
                    f("limits"),
                    format!("expected min < max, found min = {} {unit}, max = {} {unit}", l.limits.min, l.limits.max),
                ));
            }
            if l.limits.min > 0.0 || l.limits.max < 0.0 {
                return Err(FieldError::new(
                    f("limits"),
                    format!(
                        "expected limits that contain the zero position, found [{}, {}] {unit}",
                        l.limits.min, l.limits.max
                    ),
                ));
            }
            if l.joint == JointType::Revolute && (l.limits.min < -360.0 || l.limits.max > 360.0) {
                return Err(FieldError::new(
                    f("limits"),
                    format!("expected revolute limits within ±360°, found [{}, {}]°", l.limits.min, l.limits.max),
                ));
            }
            for (name, per, value) in
                [("speed_per_s", "/s", l.limits.speed_per_s), ("accel_per_s2", "/s²", l.limits.accel_per_s2)]
            {
                if let Some(v) = value.filter(|v| !(v.is_finite() && *v > 0.0)) {
                    return Err(FieldError::new(
                        f(&format!("limits.{name}")),
                        format!("expected a finite positive number ({unit}{per}), found {v}"),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.links.len()
    }

    /// Joint names in order.
    pub fn joint_names(&self) -> Vec<&str> {
        self.links.iter().map(|l| l.name.as_str()).collect()
    }

    /// Convert a joint vector from display units (µm, °) to internal units (µm, rad).
    pub fn q_from_display(&self, q_display: &[f64]) -> Vec<f64> {
        self.links
            .iter()
            .zip(q_display)
            .map(|(l, &v)| match l.joint {
                JointType::Prismatic => v,
                JointType::Revolute => v.to_radians(),
            })
            .collect()
    }

    /// Convert a joint vector from internal units (µm, rad) to display units (µm, °).
    pub fn q_to_display(&self, q: &[f64]) -> Vec<f64> {
        self.links
            .iter()
            .zip(q)
            .map(|(l, &v)| match l.joint {
                JointType::Prismatic => v,
                JointType::Revolute => v.to_degrees(),
            })
            .collect()
    }

    /// True for the 3P+3R layout (three prismatic joints, then three revolute joints) that
    /// has a closed-form inverse geometric model.
    pub fn is_3p3r(&self) -> bool {
        use JointType::*;
        let kinds: Vec<_> = self.links.iter().map(|l| l.joint).collect();
        kinds == [Prismatic, Prismatic, Prismatic, Revolute, Revolute, Revolute]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_description_is_table_one() {
        let r = RobotDescription::femto_6dof();
        assert_eq!(r.dof(), 6);
        assert!(r.is_3p3r());
        assert_eq!(r.joint_names(), ["q1", "q2", "q3", "q4", "q5", "q6"]);
        let alphas: Vec<f64> = r.links.iter().map(|l| l.alpha_deg).collect();
        assert_eq!(alphas, [0.0, -90.0, -90.0, 0.0, -90.0, -90.0]);
        let thetas: Vec<f64> = r.links.iter().map(|l| l.theta_deg).collect();
        assert_eq!(thetas, [0.0, -90.0, -90.0, 0.0, -90.0, 0.0]);
    }

    fn with_edit(from: &str, to: &str) -> Result<RobotDescription, FileError> {
        assert!(FEMTO_6DOF_RON.contains(from), "test edit `{from}` not found");
        RobotDescription::from_ron_str(&FEMTO_6DOF_RON.replacen(from, to, 1), Path::new("bad.ron"))
    }

    #[test]
    fn bad_descriptions_name_the_file_field_and_expectation() {
        let cases: &[(&str, &str, &str)] = &[
            (
                "limits: (min: -10.0, max: 10.0)",
                "limits: (min: 10.0, max: -10.0)",
                "bad.ron: field `links[3].limits`: expected min < max",
            ),
            (
                "limits: (min: -150.0, max: 150.0)",
                "limits: (min: 20.0, max: 150.0)",
                "bad.ron: field `links[0].limits`: expected limits that contain the zero position",
            ),
            ("name: \"q2\"", "name: \"q1\"", "bad.ron: field `links[1].name`: joint name `q1` is used twice"),
            ("joint: Revolute", "joint: Spherical", "bad.ron:"),
            ("beta_deg: 0.0, alpha_deg: -90.0", "beta_deg: \"x\", alpha_deg: -90.0", "expected a RobotDescription"),
            (
                "limits: (min: -180.0, max: 180.0)",
                "limits: (min: -720.0, max: 180.0)",
                "field `links[5].limits`: expected revolute limits within ±360°",
            ),
            (
                "limits: (min: -180.0, max: 180.0)",
                "limits: (min: -180.0, max: 180.0, speed_per_s: Some(0.0))",
                "bad.ron: field `links[5].limits.speed_per_s`: expected a finite positive number (°/s), found 0",
            ),
            (
                "limits: (min: -150.0, max: 150.0)",
                "limits: (min: -150.0, max: 150.0, accel_per_s2: Some(-5.0))",
                "bad.ron: field `links[0].limits.accel_per_s2`: expected a finite positive number (µm/s²), found -5",
            ),
        ];
        for (from, to, want) in cases {
            let err = with_edit(from, to).unwrap_err().to_string();
            assert!(err.contains(want), "edit {from} -> {to}: got `{err}`, want `{want}`");
        }
    }

    #[test]
    fn empty_chain_is_refused() {
        let err = RobotDescription::from_ron_str("RobotDescription(name: \"x\", links: [])", Path::new("e.ron"))
            .unwrap_err()
            .to_string();
        assert_eq!(err, "e.ron: field `links`: expected 6 links (q1..q6, base to end effector), found 0");
        // Five links: refused by name, before the kinematics could see five joints.
        let mut five = RobotDescription::femto_6dof();
        five.links.pop();
        let text = ron::ser::to_string(&five).unwrap();
        let err = RobotDescription::from_ron_str(&text, Path::new("five.ron")).unwrap_err().to_string();
        assert_eq!(err, "five.ron: field `links`: expected 6 links (q1..q6, base to end effector), found 5");
    }

    #[test]
    fn display_units_round_trip() {
        let r = RobotDescription::femto_6dof();
        let qd = [10.0, -20.0, 30.0, 1.0, -2.0, 3.0];
        let q = r.q_from_display(&qd);
        assert!((q[3] - 1f64.to_radians()).abs() < 1e-15 && q[0] == 10.0);
        let back = r.q_to_display(&q);
        for (a, b) in back.iter().zip(qd) {
            assert!((a - b).abs() < 1e-12);
        }
    }
}
