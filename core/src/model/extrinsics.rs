//! The extrinsic parameters: where the fiber is in the world and how the lamella sits on the end effector,
//! and the measurement equation they define (signed cavity length L, reflection point P_r).
//!
//! Conventions (docs/conventions.md, paper eq. 6-7, 22-23):
//! - Fiber frame: `wTf = Trans(x_wf, y_wf, z_wf) · RotX(β_wf) · RotZ(θ_wf)`. The optical axis
//!   `n_f` is the **Y column** of that rotation, `(-sin θ_wf, cos θ_wf cos β_wf, cos θ_wf sin β_wf)`.
//!   The paper calls this axis Z_f; we keep its matrix (and so its parameter values) and call the
//!   axis what it is, Y_f. The two axes across the beam are X_f and Z_f (the paper's X_f and Y_f).
//! - Tool (lamella) frame: `eTt = TransZ(Z_et) · RotX(β_et) · RotY(θ_et)`; the lamella normal `n_t`
//!   is its Z column and the lamella plane passes through its origin O_t.
//! - Signed cavity length: `L = n_t·(O_t - O_f) / (n_t·n_f)`, so that `P_r = O_f + L·n_f` lies on
//!   the lamella plane. With Table II values `n_f` points away from the lamella and L ≈ -898.8 µm;
//!   the physical gap is |L|.

use crate::files::{self, FieldError, FileError};
use crate::model::kinematics::{rot_x, rot_y, rot_z};
use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::path::Path;
use thiserror::Error;

/// Table II of the paper, embedded.
pub const TABLE2_RON: &str = include_str!("../../../assets/extrinsics/table2.ron");
/// The design values a bench starts from before calibration, embedded.
pub const NOMINAL_RON: &str = include_str!("../../../assets/extrinsics/nominal.ron");

/// The eight extrinsic parameters, with the paper's names. Lengths in µm, angles in degrees.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Extrinsics {
    /// Fiber origin, world X (µm).
    pub x_wf_um: f64,
    /// Fiber origin, world Y (µm): along the beam.
    pub y_wf_um: f64,
    /// Fiber origin, world Z (µm).
    pub z_wf_um: f64,
    /// Fiber frame rotation about world X (°).
    pub beta_wf_deg: f64,
    /// Fiber frame rotation about its Z after β_wf (°).
    pub theta_wf_deg: f64,
    /// Lamella plane offset along the end-effector Z (µm).
    pub z_et_um: f64,
    /// Lamella rotation about the end-effector X (°).
    pub beta_et_deg: f64,
    /// Lamella rotation about Y after β_et (°).
    pub theta_et_deg: f64,
}

/// The eight parameters in a fixed order, with units: the order of [`Extrinsics::to_array`].
pub const PARAMETER_NAMES: [(&str, &str); 8] = [
    ("beta_et", "°"),
    ("theta_et", "°"),
    ("beta_wf", "°"),
    ("theta_wf", "°"),
    ("Z_et", "µm"),
    ("x_wf", "µm"),
    ("y_wf", "µm"),
    ("z_wf", "µm"),
];

/// Why a cavity cannot be formed.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum CavityError {
    /// The beam runs (almost) parallel to the lamella plane and never meets it.
    #[error("the beam is parallel to the lamella (n_t·n_f = {0:.2e}): no cavity")]
    BeamParallelToLamella(f64),
}

/// The Fabry-Perot cavity at one robot pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cavity {
    /// Signed cavity length L (µm); the gap is |L|.
    pub length_um: f64,
    /// Optical axis in the world.
    pub n_f: Unit<Vector3<f64>>,
    /// Lamella normal in the world.
    pub n_t: Unit<Vector3<f64>>,
    /// Reflection point in the world (µm).
    pub reflection_point_world_um: Point3<f64>,
    /// Reflection point in the tool frame (µm); its z is 0 by construction.
    pub reflection_point_tool_um: Point3<f64>,
    /// Angle between n_t and n_f (rad), folded to [0, π/2]: the tilt that sets the coupling.
    pub tilt_rad: f64,
}

impl Extrinsics {
    /// The paper's Table II values.
    pub fn table2() -> Self {
        Self::from_ron_str(TABLE2_RON, Path::new("assets/extrinsics/table2.ron"))
            .expect("the embedded Table II is valid (checked by tests)")
    }

    /// The design values before calibration (square lamella and fiber).
    pub fn nominal_design() -> Self {
        Self::from_ron_str(NOMINAL_RON, Path::new("assets/extrinsics/nominal.ron"))
            .expect("the embedded nominal extrinsics are valid (checked by tests)")
    }

    /// Parse and validate; `origin` names the text in errors.
    pub fn from_ron_str(text: &str, origin: &Path) -> Result<Self, FileError> {
        let e: Self = files::parse_ron(
            text,
            origin,
            "Extrinsics(x_wf_um, y_wf_um, z_wf_um, beta_wf_deg, theta_wf_deg, z_et_um, beta_et_deg, theta_et_deg)",
        )?;
        e.validate().map_err(|f| f.in_file(origin))?;
        Ok(e)
    }

    /// Load and validate a file.
    pub fn load(path: &Path) -> Result<Self, FileError> {
        let text = files::read_text(path)?;
        Self::from_ron_str(&text, path)
    }

    /// Every value finite; angles within ±90°.
    pub fn validate(&self) -> Result<(), FieldError> {
        self.validate_within(90.0)
    }

    /// Every value finite; angles within ±`max_deg`. A fit's record allows ±180° (its angles
    /// wrapped, [`Extrinsics::with_angles_wrapped`]): a fit that ended beyond ±90° along an
    /// angle its data do not see is kept as it ended, and is no calibration.
    pub fn validate_within(&self, max_deg: f64) -> Result<(), FieldError> {
        let a = self.to_array();
        for (i, (name, unit)) in PARAMETER_NAMES.iter().enumerate() {
            let field = format!("{}_{}", name.to_lowercase(), if *unit == "°" { "deg" } else { "um" });
            if !a[i].is_finite() {
                return Err(FieldError::new(field, format!("expected a finite number, found {}", a[i])));
            }
            if *unit == "°" && a[i].abs() > max_deg {
                return Err(FieldError::new(field, format!("expected an angle within ±{max_deg}°, found {}°", a[i])));
            }
        }
        Ok(())
    }

    /// The parameters in the order of [`PARAMETER_NAMES`] (° and µm).
    pub fn to_array(&self) -> [f64; 8] {
        [
            self.beta_et_deg,
            self.theta_et_deg,
            self.beta_wf_deg,
            self.theta_wf_deg,
            self.z_et_um,
            self.x_wf_um,
            self.y_wf_um,
            self.z_wf_um,
        ]
    }

    /// The inverse of [`Extrinsics::to_array`].
    pub fn from_array(a: [f64; 8]) -> Self {
        Self {
            beta_et_deg: a[0],
            theta_et_deg: a[1],
            beta_wf_deg: a[2],
            theta_wf_deg: a[3],
            z_et_um: a[4],
            x_wf_um: a[5],
            y_wf_um: a[6],
            z_wf_um: a[7],
        }
    }

    /// The same extrinsics with every angle brought into (-180°, 180°]: a rotation by a full
    /// turn more is the same rotation, and a solver free along an angle the data do not see can
    /// end whole turns away (-349.4° for 10.6°).
    pub fn with_angles_wrapped(&self) -> Self {
        let mut a = self.to_array();
        for (v, (_, unit)) in a.iter_mut().zip(PARAMETER_NAMES.iter()) {
            if *unit == "°" && v.is_finite() {
                *v = 180.0 - (180.0 - *v).rem_euclid(360.0);
            }
        }
        Self::from_array(a)
    }

    /// Rotation of the fiber frame in the world.
    pub fn fiber_rotation(&self) -> UnitQuaternion<f64> {
        rot_x(self.beta_wf_deg.to_radians()) * rot_z(self.theta_wf_deg.to_radians())
    }

    /// `wTf`, the fiber frame in the world (µm).
    pub fn world_to_fiber(&self) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::new(self.x_wf_um, self.y_wf_um, self.z_wf_um), self.fiber_rotation())
    }

    /// `eTt`, the tool (lamella) frame in the end-effector frame (µm).
    pub fn ee_to_tool(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.0, 0.0, self.z_et_um),
            rot_x(self.beta_et_deg.to_radians()) * rot_y(self.theta_et_deg.to_radians()),
        )
    }

    /// The optical axis `n_f` in the world (Y column of the fiber rotation).
    pub fn n_f(&self) -> Unit<Vector3<f64>> {
        let (b, t) = (self.beta_wf_deg.to_radians(), self.theta_wf_deg.to_radians());
        Unit::new_unchecked(Vector3::new(-t.sin(), t.cos() * b.cos(), t.cos() * b.sin()))
    }

    /// The lamella normal in the end-effector frame (Z column of `eTt`).
    pub fn n_t_in_ee(&self) -> Unit<Vector3<f64>> {
        Unit::new_unchecked(self.ee_to_tool().rotation * Vector3::z())
    }

    /// The signed cavity length alone (µm), for hot loops: `wte` is the end-effector pose.
    /// Returns NaN when the beam is parallel to the lamella.
    ///
    /// With `n_t = R·n_t(e)` and `O_t = R·O_t(e) + p` (the tool frame seen from the end
    /// effector), `n_t·(O_t - O_f) = n_t(e)·O_t(e) + n_t·(p - O_f)`: one rotation of a vector.
    #[inline]
    pub fn cavity_length_um(&self, wte: &Isometry3<f64>, fiber: &FiberGeometry) -> f64 {
        let n_t = wte.rotation * fiber.n_t_in_ee;
        let den = n_t.dot(&fiber.n_f);
        if den.abs() < 1e-12 {
            return f64::NAN;
        }
        (n_t.dot(&(wte.translation.vector - fiber.origin.coords)) + fiber.n_t_dot_o_t_in_ee) / den
    }

    /// Precompute the pose-independent geometry for [`Extrinsics::cavity_length_um`].
    pub fn geometry(&self) -> FiberGeometry {
        let ee_to_tool = self.ee_to_tool();
        let n_t_in_ee = ee_to_tool.rotation * Vector3::z();
        FiberGeometry {
            origin: Point3::new(self.x_wf_um, self.y_wf_um, self.z_wf_um),
            n_f: self.n_f().into_inner(),
            ee_to_tool,
            n_t_in_ee,
            n_t_dot_o_t_in_ee: n_t_in_ee.dot(&ee_to_tool.translation.vector),
        }
    }

    /// The full cavity at an end-effector pose.
    pub fn cavity(&self, wte: &Isometry3<f64>) -> Result<Cavity, CavityError> {
        let wtt = wte * self.ee_to_tool();
        let n_t = Unit::new_unchecked(wtt.rotation * Vector3::z());
        let n_f = self.n_f();
        let o_f = Point3::new(self.x_wf_um, self.y_wf_um, self.z_wf_um);
        let o_t = Point3::from(wtt.translation.vector);
        let den = n_t.dot(&n_f);
        if den.abs() < 1e-12 {
            return Err(CavityError::BeamParallelToLamella(den));
        }
        let l = n_t.dot(&(o_t - o_f)) / den;
        let p_r = o_f + n_f.into_inner() * l;
        Ok(Cavity {
            length_um: l,
            n_f,
            n_t,
            reflection_point_world_um: p_r,
            reflection_point_tool_um: wtt.inverse_transform_point(&p_r),
            tilt_rad: den.abs().min(1.0).acos(),
        })
    }
}

/// Pose-independent geometry precomputed from the extrinsics, for fast evaluation.
#[derive(Debug, Clone, Copy)]
pub struct FiberGeometry {
    origin: Point3<f64>,
    n_f: Vector3<f64>,
    ee_to_tool: Isometry3<f64>,
    /// Lamella normal in the end-effector frame.
    n_t_in_ee: Vector3<f64>,
    /// n_t·O_t in the end-effector frame (µm): invariant under the end-effector pose.
    n_t_dot_o_t_in_ee: f64,
}

impl FiberGeometry {
    /// |L| (µm) and the tilt (rad) of the cavity at end-effector pose `wte`, as
    /// [`Extrinsics::cavity`] gives them (to rounding); None when the beam runs parallel to the
    /// lamella.
    #[inline]
    pub fn gap_and_tilt(&self, wte: &Isometry3<f64>) -> Option<(f64, f64)> {
        let n_t = wte.rotation * self.n_t_in_ee;
        let den = n_t.dot(&self.n_f);
        if den.abs() < 1e-12 {
            return None;
        }
        let l = (n_t.dot(&(wte.translation.vector - self.origin.coords)) + self.n_t_dot_o_t_in_ee) / den;
        Some((l.abs(), den.abs().min(1.0).acos()))
    }

    /// Fiber origin O_f in the world (µm).
    pub fn origin(&self) -> Point3<f64> {
        self.origin
    }

    /// Optical axis n_f in the world.
    pub fn n_f(&self) -> Vector3<f64> {
        self.n_f
    }

    /// Lamella normal in the end-effector frame.
    pub fn n_t_in_ee(&self) -> Vector3<f64> {
        self.n_t_in_ee
    }

    /// `eTt`, the tool (lamella) frame in the end-effector frame (µm).
    pub fn ee_to_tool(&self) -> Isometry3<f64> {
        self.ee_to_tool
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::kinematics::Chain;
    use crate::model::robot::RobotDescription;
    use approx::assert_relative_eq;
    use proptest::prelude::*;

    fn q_display(qd: [f64; 6]) -> Vec<f64> {
        RobotDescription::femto_6dof().q_from_display(&qd)
    }

    #[test]
    fn table2_optical_axis() {
        let n = Extrinsics::table2().n_f();
        assert_relative_eq!(n.into_inner(), Vector3::new(0.009076, 0.999877, 0.012775), epsilon = 5e-7);
        // It is the Y column of the fiber rotation.
        let y = Extrinsics::table2().world_to_fiber().rotation * Vector3::y();
        assert_relative_eq!(n.into_inner(), y, epsilon = 1e-15);
    }

    #[test]
    fn table2_cavity_at_zero_matches_spec_to_a_nanometre() {
        let e = Extrinsics::table2();
        let wte = Chain::femto_6dof().end_effector(&[0.0; 6]);
        let c = e.cavity(&wte).unwrap();
        assert!((c.length_um - -898.830).abs() < 1e-3, "L = {}", c.length_um);
        let p = c.reflection_point_world_um;
        for (got, want) in [(p.x, 104.243), (p.y, 1.280), (p.z, 101.818)] {
            assert!((got - want).abs() < 1e-3, "P_r = {p:?}");
        }
        assert_relative_eq!(c.reflection_point_tool_um.z, 0.0, epsilon = 1e-9);
        assert!((c.tilt_rad * 1e3 - 19.46).abs() < 0.01, "tilt {} mrad", c.tilt_rad * 1e3);
        assert_relative_eq!(e.cavity_length_um(&wte, &e.geometry()), c.length_um, epsilon = 1e-9);
    }

    #[test]
    fn table2_cavity_at_a_general_pose() {
        let e = Extrinsics::table2();
        let wte = Chain::femto_6dof().end_effector(&q_display([10.0, -20.0, 30.0, 1.0, -2.0, 3.0]));
        let l = e.cavity(&wte).unwrap().length_um;
        assert!((l - -923.295).abs() < 1e-3, "L = {l}");
    }

    #[test]
    fn parallel_beam_is_an_error_not_a_nan() {
        let mut e = Extrinsics::table2();
        e.beta_et_deg = 0.0;
        e.theta_et_deg = 0.0;
        e.beta_wf_deg = 0.0;
        e.theta_wf_deg = 90.0; // beam along -X_w, lamella normal along +Y_w
        let wte = Chain::femto_6dof().end_effector(&[0.0; 6]);
        assert!(matches!(e.cavity(&wte), Err(CavityError::BeamParallelToLamella(_))));
        assert!(e.cavity_length_um(&wte, &e.geometry()).is_nan());
    }

    #[test]
    fn bad_extrinsics_file_names_the_field() {
        let text = TABLE2_RON.replace("theta_et_deg: -0.595", "theta_et_deg: 95.0");
        let err = Extrinsics::from_ron_str(&text, Path::new("ex.ron")).unwrap_err().to_string();
        assert_eq!(err, "ex.ron: field `theta_et_deg`: expected an angle within ±90°, found 95°");
        let text = TABLE2_RON.replace("z_et_um: 1.52,", "");
        let err = Extrinsics::from_ron_str(&text, Path::new("ex.ron")).unwrap_err().to_string();
        assert!(err.starts_with("ex.ron:") && err.contains("z_et_um"), "{err}");
    }

    /// Independent oracle: march along the beam and bisect the sign change of the point's
    /// z coordinate in the tool frame (no use of n_t or the closed-form quotient).
    fn brute_force_length(e: &Extrinsics, wte: &Isometry3<f64>) -> f64 {
        let wtt = wte * e.ee_to_tool();
        let o_f = Point3::new(e.x_wf_um, e.y_wf_um, e.z_wf_um);
        let n_f = e.n_f().into_inner();
        let height = |s: f64| wtt.inverse_transform_point(&(o_f + n_f * s)).z;
        let (mut lo, mut hi) = (-5000.0, 5000.0);
        let mut s = lo;
        while s < hi {
            if height(s).signum() != height(s + 1.0).signum() {
                lo = s;
                hi = s + 1.0;
                break;
            }
            s += 1.0;
        }
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if height(lo).signum() == height(mid).signum() {
                lo = mid
            } else {
                hi = mid
            }
        }
        0.5 * (lo + hi)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        #[test]
        fn cavity_length_equals_brute_force_ray_plane_intersection(
            q in (-150.0..150.0f64, -150.0..150.0f64, -150.0..150.0f64, -10.0..10.0f64, -10.0..10.0f64, -180.0..180.0f64),
            tilt in (-3.0..3.0f64, -3.0..3.0f64, -3.0..3.0f64, -3.0..3.0f64),
            pos in (-50.0..50.0f64, 100.0..2000.0f64, -50.0..50.0f64, -20.0..20.0f64),
        ) {
            let e = Extrinsics {
                beta_et_deg: tilt.0, theta_et_deg: tilt.1, beta_wf_deg: tilt.2, theta_wf_deg: tilt.3,
                x_wf_um: pos.0, y_wf_um: pos.1, z_wf_um: pos.2, z_et_um: pos.3,
            };
            let wte = Chain::femto_6dof().end_effector(&q_display([q.0, q.1, q.2, q.3, q.4, q.5]));
            let c = e.cavity(&wte).unwrap();
            let brute = brute_force_length(&e, &wte);
            prop_assert!((c.length_um - brute).abs() < 1e-6, "{} vs {}", c.length_um, brute);
            prop_assert!(c.reflection_point_tool_um.z.abs() < 1e-9);
        }
    }

    proptest! {
        /// Wrapped angles lie in (-180°, 180°] and give the same frames: the rotations of the
        /// fiber and the lamella agree to rounding, whatever whole turns the input carried.
        #[test]
        fn wrapped_angles_are_the_same_rotations(
            a in prop::array::uniform8(-1.0e3f64..1.0e3),
        ) {
            let e = Extrinsics::from_array(a);
            let w = e.with_angles_wrapped();
            for (i, (_, unit)) in PARAMETER_NAMES.iter().enumerate() {
                let v = w.to_array()[i];
                if *unit == "°" {
                    prop_assert!(v > -180.0 && v <= 180.0, "{v}");
                } else {
                    prop_assert_eq!(v, a[i]);
                }
            }
            prop_assert!(e.fiber_rotation().angle_to(&w.fiber_rotation()) < 1e-9);
            prop_assert!(e.ee_to_tool().rotation.angle_to(&w.ee_to_tool().rotation) < 1e-9);
        }
    }
}
