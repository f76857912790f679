//! Where the technician wants the lamella, in the fiber's frame, and the lamella pose that puts
//! it there: owns the target's coordinates and their two-way map to the tool frame in the world.
//!
//! Coordinates (the fiber frame of [`crate::model::extrinsics`]: Y_f = n_f is the beam, X_f and
//! Z_f across it):
//! - `gap_um`: |L|, the distance from the fiber's end O_f along the beam to the lamella (µm);
//! - `tilt_deg` = (β, θ): the lamella normal against the beam, in the fiber's own convention,
//!   `n_t = R_f·RotX(β)·RotZ(θ)·e_y` (°); (0, 0) is parallel to the fiber's end face, and the
//!   angle between n_t and n_f is `acos(cos β·cos θ)`;
//! - `lateral_um` = (x, z): where the lamella's origin O_t sits relative to the beam, along the
//!   lamella's axes that run along X_f and Z_f when it is parallel and unrotated (µm); the beam
//!   hits the lamella at (−x, −z) from its origin;
//! - `rotation_deg`: the lamella turned about the beam through P_r (°); 0 is the orientation of
//!   the lamella at q = 0 on the nominal robot (its X axis along X_f, its normal along n_f).

use crate::model::extrinsics::Extrinsics;
use crate::model::kinematics::{rot_x, rot_y, rot_z};
use crate::model::phase::PhaseModel;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// A pose of the lamella relative to the fiber (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Target {
    /// Gap along the beam, |L| (µm).
    pub gap_um: f64,
    /// Lamella tilt against the fiber's end face, (β about X_f, θ about Z_f) (°).
    pub tilt_deg: [f64; 2],
    /// The lamella's origin relative to the beam, along X_f and Z_f (µm).
    #[serde(default)]
    pub lateral_um: [f64; 2],
    /// Rotation of the lamella about the beam (°).
    #[serde(default)]
    pub rotation_deg: f64,
}

impl Target {
    /// The angle between the lamella normal and the beam this target asks for (rad).
    pub fn tilt_angle_rad(&self) -> f64 {
        let [b, t] = self.tilt_deg.map(f64::to_radians);
        (b.cos() * t.cos()).abs().min(1.0).acos()
    }

    /// Every field finite, the gap positive and the tilts within ±45°: a bad target is refused
    /// with the field and what was expected.
    pub fn check(&self) -> Result<(), String> {
        let fields = [
            ("gap_um", self.gap_um),
            ("tilt_deg[0]", self.tilt_deg[0]),
            ("tilt_deg[1]", self.tilt_deg[1]),
            ("lateral_um[0]", self.lateral_um[0]),
            ("lateral_um[1]", self.lateral_um[1]),
            ("rotation_deg", self.rotation_deg),
        ];
        if let Some((name, v)) = fields.iter().find(|(_, v)| !v.is_finite()) {
            return Err(format!("{name}: expected a finite number, found {v}"));
        }
        if self.gap_um <= 0.0 {
            return Err(format!("gap_um: expected a gap above 0 µm, found {} µm", self.gap_um));
        }
        if let Some(t) = self.tilt_deg.iter().find(|t| t.abs() > 45.0) {
            return Err(format!("tilt_deg: expected tilts within ±45°, found {t}°"));
        }
        Ok(())
    }

    /// The target as a line for the user.
    pub fn describe(&self) -> String {
        format!(
            "gap {:.4} µm, tilt ({:.4}°, {:.4}°), lateral ({:.3}, {:.3}) µm, rotation {:.3}°",
            self.gap_um, self.tilt_deg[0], self.tilt_deg[1], self.lateral_um[0], self.lateral_um[1], self.rotation_deg
        )
    }
}

/// The lamella's orientation relative to the fiber frame at tilt 0 and rotation 0: its X axis
/// along X_f, its Y axis along −Z_f, its normal along n_f (the tool frame at q = 0, paper eq. 17).
fn home() -> UnitQuaternion<f64> {
    rot_x(-std::f64::consts::FRAC_PI_2)
}

/// The fiber frame seen by one set of extrinsics, and the side of the fiber the lamella is on:
/// the map between targets and lamella poses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskFrame {
    extrinsics: Extrinsics,
    /// The sign of L: +1 when the lamella lies along +n_f from the fiber, −1 along −n_f.
    side: f64,
}

impl TaskFrame {
    /// The frame of `extrinsics` with the lamella on the side it is at joints `q_display` of
    /// `model`'s robot; `None` when the beam misses the lamella there.
    pub fn at(model: &PhaseModel, extrinsics: &Extrinsics, q_display: &[f64; 6]) -> Option<Self> {
        let q = model.chain.description().q_from_display(q_display);
        let l = extrinsics.cavity(&model.chain.end_effector(&q)).ok()?.length_um;
        Some(Self { extrinsics: *extrinsics, side: if l < 0.0 { -1.0 } else { 1.0 } })
    }

    /// The same side with other extrinsics (the forecast's perturbed ones).
    pub fn with_extrinsics(&self, extrinsics: &Extrinsics) -> Self {
        Self { extrinsics: *extrinsics, side: self.side }
    }

    /// The extrinsics of this frame.
    pub fn extrinsics(&self) -> &Extrinsics {
        &self.extrinsics
    }

    /// The rotation that tilts the fiber frame to the lamella's normal: `R_f·RotX(β)·RotZ(θ)`.
    fn tilted(&self, tilt_deg: [f64; 2]) -> UnitQuaternion<f64> {
        self.extrinsics.fiber_rotation() * rot_x(tilt_deg[0].to_radians()) * rot_z(tilt_deg[1].to_radians())
    }

    /// The tool (lamella) frame in the world, `wTt`, that realises `target` (µm).
    pub fn tool_pose(&self, target: &Target) -> Isometry3<f64> {
        let e = &self.extrinsics;
        let turned = self.tilted(target.tilt_deg) * rot_y(target.rotation_deg.to_radians());
        let o_f = Point3::new(e.x_wf_um, e.y_wf_um, e.z_wf_um);
        let p_r = o_f + e.n_f().into_inner() * (self.side * target.gap_um);
        let o_t = p_r + turned * Vector3::new(target.lateral_um[0], 0.0, target.lateral_um[1]);
        Isometry3::from_parts(Translation3::from(o_t.coords), turned * home())
    }

    /// The end-effector pose `wTe` that realises `target` (µm).
    pub fn end_effector_pose(&self, target: &Target) -> Isometry3<f64> {
        self.tool_pose(target) * self.extrinsics.ee_to_tool().inverse()
    }

    /// The target a tool pose `wtt` realises; `None` when the beam misses the lamella.
    pub fn target_of(&self, wtt: &Isometry3<f64>) -> Option<Target> {
        let e = &self.extrinsics;
        let n_f = e.n_f().into_inner();
        let n_t = wtt.rotation * Vector3::z();
        let den = n_t.dot(&n_f);
        if den.abs() < 1e-12 {
            return None;
        }
        let o_f = Point3::new(e.x_wf_um, e.y_wf_um, e.z_wf_um);
        let o_t = Point3::from(wtt.translation.vector);
        let l = n_t.dot(&(o_t - o_f)) / den;
        let n = e.fiber_rotation().inverse() * n_t;
        let tilt_deg = [n.z.atan2(n.y).to_degrees(), (-n.x).clamp(-1.0, 1.0).asin().to_degrees()];
        // What is left of the tool's rotation once tilted back is a rotation about Y_f.
        let k = (self.tilted(tilt_deg).inverse() * wtt.rotation * home().inverse()).to_rotation_matrix();
        let rotation = k[(0, 2)].atan2(k[(0, 0)]);
        let turned = self.tilted(tilt_deg) * rot_y(rotation);
        let lateral = turned.inverse() * (o_t - (o_f + n_f * l));
        Some(Target {
            gap_um: l.abs(),
            tilt_deg,
            lateral_um: [lateral.x, lateral.z],
            rotation_deg: rotation.to_degrees(),
        })
    }

    /// The target realised at joints `q_display` of `model`'s robot (this frame's extrinsics).
    pub fn target_at(&self, model: &PhaseModel, q_display: &[f64; 6]) -> Option<Target> {
        let q = model.chain.description().q_from_display(q_display);
        self.target_of(&(model.chain.end_effector(&q) * self.extrinsics.ee_to_tool()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::BenchPreset;
    use proptest::prelude::*;

    fn model() -> PhaseModel {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        PhaseModel::of_preset(&preset, preset.truth).unwrap()
    }

    /// At q = 0 with Table II: the gap is |L| = 898.830 µm (docs/conventions.md), the tilt's angle
    /// the 19.46 mrad between n_t and n_f, and the lamella's origin sits about (−104, −102) µm
    /// from the beam (P_r = (104.243, 1.280, 101.818) µm in the world).
    #[test]
    fn the_target_at_q0_is_table2s_cavity() {
        let m = model();
        let frame = TaskFrame::at(&m, &m.extrinsics, &[0.0; 6]).unwrap();
        let t = frame.target_at(&m, &[0.0; 6]).unwrap();
        assert!((t.gap_um - 898.830).abs() < 1e-3, "{t:?}");
        assert!((t.tilt_angle_rad() * 1e3 - 19.46).abs() < 0.01, "{t:?}");
        assert!((t.lateral_um[0] + 104.2).abs() < 0.5 && (t.lateral_um[1] + 101.8).abs() < 0.5, "{t:?}");
        assert!(t.rotation_deg.abs() < 1.5, "{t:?}");
    }

    proptest! {
        /// The map and its inverse: a target's pose read back is the target, and the cavity of
        /// [`Extrinsics::cavity`] at that pose has the target's gap and tilt angle (an oracle that
        /// shares none of the target's algebra).
        #[test]
        fn a_target_read_back_from_its_pose_is_itself(
            gap in 100.0..2000.0f64, b in -8.0..8.0f64, t in -8.0..8.0f64,
            x in -300.0..300.0f64, z in -300.0..300.0f64, r in -170.0..170.0f64,
        ) {
            let m = model();
            let frame = TaskFrame::at(&m, &m.extrinsics, &[0.0; 6]).unwrap();
            let target = Target { gap_um: gap, tilt_deg: [b, t], lateral_um: [x, z], rotation_deg: r };
            let back = frame.target_of(&frame.tool_pose(&target)).unwrap();
            prop_assert!((back.gap_um - gap).abs() < 1e-9);
            for i in 0..2 {
                prop_assert!((back.tilt_deg[i] - target.tilt_deg[i]).abs() < 1e-9);
                prop_assert!((back.lateral_um[i] - target.lateral_um[i]).abs() < 1e-8);
            }
            prop_assert!((back.rotation_deg - r).abs() < 1e-9);
            let c = m.extrinsics.cavity(&frame.end_effector_pose(&target)).unwrap();
            prop_assert!((c.length_um.abs() - gap).abs() < 1e-9);
            prop_assert!((c.tilt_rad - target.tilt_angle_rad()).abs() < 1e-9);
            prop_assert!(c.length_um < 0.0, "the lamella stays on its side of the fiber");
        }
    }

    #[test]
    fn a_bad_target_names_its_field() {
        let t = Target { gap_um: 0.0, tilt_deg: [0.0, 0.0], lateral_um: [0.0, 0.0], rotation_deg: 0.0 };
        assert!(t.check().unwrap_err().starts_with("gap_um:"));
        let t = Target { gap_um: 800.0, tilt_deg: [0.0, f64::NAN], ..t };
        assert!(t.check().unwrap_err().starts_with("tilt_deg[1]:"));
        let t = Target { tilt_deg: [60.0, 0.0], ..t };
        assert!(t.check().unwrap_err().contains("±45°"));
    }
}
