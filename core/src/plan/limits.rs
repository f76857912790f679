//! The physical limits a plan is checked and timed against: the laser's wavelength range and the
//! stages' speeds, accelerations and settling time.

use super::PlanError;
use crate::model::robot::{JointType, LinkDescription};
use serde::{Deserialize, Serialize};

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

/// Speed and acceleration limits of the stages, used to time moves (display units): one pair per
/// joint type, for the axes whose robot file gives none of their own
/// ([`crate::model::robot::Limits`]).
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

    /// Speed and acceleration limits of one axis (display units): the robot file's own where it
    /// gives them, else its joint type's.
    pub fn for_link(&self, link: &LinkDescription) -> (f64, f64) {
        let (speed, accel) = self.for_joint(link.joint);
        (link.limits.speed_per_s.unwrap_or(speed), link.limits.accel_per_s2.unwrap_or(accel))
    }
}
