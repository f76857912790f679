//! The effect library: named, parametrised extensions of the bench model, neutral at zero.
//! Owns how each effect acts on the forward model; the virtual bench hides effects and the diagnosis fits them with this same code.
//!
//! An effect acts in one of three places: on the robot's intrinsic geometry (through
//! [`crate::model::robot::JointErrors`]), on the cavity length over time (drift, index scale),
//! or on the signal. The diagnosis workflow extends this list; bench files name effects by
//! these variants, with units in every field name.

use crate::model::robot::RobotDescription;
use serde::{Deserialize, Serialize};

/// One effect with its parameters. Every field is zero (or absent) at its neutral value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Effect {
    /// Thermal drift of the cavity: the gap grows by `nm_per_s·t + ½·nm_per_s2·t²` (t from the
    /// start of the session).
    ThermalDrift {
        /// Drift rate (nm/s).
        nm_per_s: f64,
        /// Drift acceleration (nm/s²).
        #[serde(default)]
        nm_per_s2: f64,
    },
    /// Optical path scale error (ppm), e.g. the air index left out (268 ppm) or a wavelength
    /// error: the optical gap is the geometric gap × (1 + ppm·1e-6).
    PathScale {
        /// Scale error (ppm).
        ppm: f64,
    },
    /// Scale (gain) error of a joint (ppm).
    JointScale {
        /// Joint name, e.g. "q2".
        joint: String,
        /// Scale error (ppm).
        ppm: f64,
    },
    /// Zero offset of a joint, in its display unit (µm or °).
    JointZeroOffset {
        /// Joint name.
        joint: String,
        /// Offset (µm or °).
        offset: f64,
    },
    /// A revolute joint's axis misses the common origin: it passes through this point, given in
    /// world coordinates at q = 0 (µm).
    PivotOffset {
        /// Joint name, e.g. "q4".
        joint: String,
        /// Offset of the axis, world X, Y, Z at q = 0 (µm).
        offset_world_um: [f64; 3],
    },
    /// A joint's axis is tilted toward the link frame's x and y axes (mrad).
    AxisTilt {
        /// Joint name.
        joint: String,
        /// Tilt toward the link x and y axes (mrad).
        tilt_mrad: [f64; 2],
    },
}

/// Why an effect cannot be applied.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EffectError {
    /// The effect names a joint the robot does not have.
    #[error("effect {effect}: no joint named `{joint}` (the robot has {known})")]
    UnknownJoint {
        /// The effect's name.
        effect: &'static str,
        /// The joint it names.
        joint: String,
        /// The joints the robot has.
        known: String,
    },
}

impl Effect {
    /// The effect's name, as used in reports.
    pub fn name(&self) -> &'static str {
        match self {
            Effect::ThermalDrift { .. } => "thermal drift",
            Effect::PathScale { .. } => "optical path scale",
            Effect::JointScale { .. } => "joint scale error",
            Effect::JointZeroOffset { .. } => "joint zero offset",
            Effect::PivotOffset { .. } => "pivot offset",
            Effect::AxisTilt { .. } => "axis tilt",
        }
    }

    /// A one-line physical description.
    pub fn description(&self) -> &'static str {
        match self {
            Effect::ThermalDrift { .. } => "the mechanical loop expands with temperature: the gap drifts in time",
            Effect::PathScale { .. } => {
                "the optical path differs from the geometric one by a constant factor (air index, wavelength error)"
            }
            Effect::JointScale { .. } => "a stage moves more or less than commanded, in proportion",
            Effect::JointZeroOffset { .. } => "a stage's zero is not where the model puts it",
            Effect::PivotOffset { .. } => "a goniometer's rotation axis misses the common rotation centre",
            Effect::AxisTilt { .. } => "a stage's axis is not along its nominal direction",
        }
    }

    /// Apply the geometric part of the effect to a robot description (intrinsic errors add).
    pub fn apply_to_robot(&self, robot: &mut RobotDescription) -> Result<(), EffectError> {
        let index = |joint: &str| {
            robot.links.iter().position(|l| l.name == joint).ok_or_else(|| EffectError::UnknownJoint {
                effect: self.name(),
                joint: joint.to_string(),
                known: robot.joint_names().join(", "),
            })
        };
        match self {
            Effect::JointScale { joint, ppm } => {
                let i = index(joint)?;
                robot.links[i].errors.scale_ppm += ppm;
            }
            Effect::JointZeroOffset { joint, offset } => {
                let i = index(joint)?;
                robot.links[i].errors.zero_offset += offset;
            }
            Effect::AxisTilt { joint, tilt_mrad } => {
                let i = index(joint)?;
                robot.links[i].errors.axis_tilt_mrad[0] += tilt_mrad[0];
                robot.links[i].errors.axis_tilt_mrad[1] += tilt_mrad[1];
            }
            Effect::PivotOffset { joint, offset_world_um } => {
                let i = index(joint)?;
                // Express the world offset in the joint's frame at q = 0 (nominal chain).
                let mut nominal = robot.clone();
                for l in &mut nominal.links {
                    l.errors = Default::default();
                }
                let chain = crate::model::kinematics::Chain::new(nominal);
                let q0 = vec![0.0; chain.dof()];
                let frame = if i == 0 { nalgebra::Isometry3::identity() } else { chain.frames(&q0)[i - 1] };
                let before = frame * chain.link_transform(i, 0.0);
                let local = before.rotation.inverse() * nalgebra::Vector3::from(*offset_world_um);
                for k in 0..3 {
                    robot.links[i].errors.axis_offset_um[k] += local[k];
                }
            }
            Effect::ThermalDrift { .. } | Effect::PathScale { .. } => {}
        }
        Ok(())
    }

    /// Change of the optical gap (nm) at time `t_s` caused by the effect, for a geometric gap
    /// `gap_um`.
    #[inline]
    pub fn gap_change_nm(&self, t_s: f64, gap_um: f64) -> f64 {
        match self {
            Effect::ThermalDrift { nm_per_s, nm_per_s2 } => nm_per_s * t_s + 0.5 * nm_per_s2 * t_s * t_s,
            Effect::PathScale { ppm } => gap_um * ppm * 1e-3,
            _ => 0.0,
        }
    }
}

/// Apply a list of effects to a robot description.
pub fn apply_all(effects: &[Effect], robot: &RobotDescription) -> Result<RobotDescription, EffectError> {
    let mut r = robot.clone();
    for e in effects {
        e.apply_to_robot(&mut r)?;
    }
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::kinematics::Chain;
    use approx::assert_relative_eq;
    use nalgebra::Vector3;

    #[test]
    fn pivot_offset_in_world_terms_moves_the_rotation_centre() {
        // Joint 4 (about X_w at q = 0) with its axis 20 µm off along Y_w (SPEC section 9).
        let e = Effect::PivotOffset { joint: "q4".into(), offset_world_um: [0.0, 20.0, 0.0] };
        let robot = apply_all(&[e], &RobotDescription::femto_6dof()).unwrap();
        let c = Chain::new(robot);
        let phi = 2f64.to_radians();
        let p = c.end_effector(&[0.0, 0.0, 0.0, phi, 0.0, 0.0]).translation.vector;
        assert_relative_eq!(p, Vector3::new(0.0, 20.0 - 20.0 * phi.cos(), -20.0 * phi.sin()), epsilon = 1e-9);
    }

    #[test]
    fn unknown_joint_is_named() {
        let e = Effect::JointScale { joint: "q9".into(), ppm: 1.0 };
        let err = apply_all(&[e], &RobotDescription::femto_6dof()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "effect joint scale error: no joint named `q9` (the robot has q1, q2, q3, q4, q5, q6)"
        );
    }

    #[test]
    fn drift_and_path_scale_change_the_gap() {
        let d = Effect::ThermalDrift { nm_per_s: 0.1, nm_per_s2: 0.002 };
        assert_relative_eq!(d.gap_change_nm(10.0, 900.0), 1.0 + 0.1, epsilon = 1e-12);
        let s = Effect::PathScale { ppm: 268.0 };
        assert_relative_eq!(s.gap_change_nm(0.0, 300.0), 80.4, epsilon = 1e-9);
    }
}
