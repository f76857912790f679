//! Geometric models of a serial chain: link transforms, direct geometric model (DGM), Jacobian,
//! the closed-form inverse geometric model (IGM) of the 3P+3R layout, a damped-least-squares IGM and joint limits.
//!
//! The DGM is evaluated on a compiled form of the chain (the leading prismatic joints folded
//! into a constant rotation and an affine translation, one quaternion product per revolute
//! joint) with a branch-free [`sin_cos`] accurate to an ulp; [`Chain::end_effector_reference`]
//! keeps the plain product of link transforms it is tested against.
//!
//! Units: poses are `Isometry3<f64>` with translations in µm; joint vectors hold µm for prismatic
//! joints and radians for revolute joints (see [`crate::model::robot`]).

use crate::model::robot::{JointType, RobotDescription};
use nalgebra::{Isometry3, Matrix3, Point3, Translation3, Unit, UnitQuaternion, Vector3, Vector6};
use std::f64::consts::PI;
use std::fmt;
use thiserror::Error;

/// A joint value outside its limits, with the amount by which it is out of range.
#[derive(Debug, Clone, PartialEq, Error)]
pub struct LimitViolation {
    /// Joint name.
    pub joint: String,
    /// Requested value in the display unit.
    pub value: f64,
    /// The limit that is exceeded, in the display unit.
    pub limit: f64,
    /// Display unit (µm or °).
    pub unit: &'static str,
}

impl LimitViolation {
    /// How far past the limit the value is (display unit, positive).
    pub fn excess(&self) -> f64 {
        (self.value - self.limit).abs()
    }
}

impl fmt::Display for LimitViolation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let side = if self.value > self.limit { "above its upper" } else { "below its lower" };
        write!(
            f,
            "joint {} = {:.3} {u} is {:.3} {u} {side} limit {:.3} {u}",
            self.joint,
            self.value,
            self.excess(),
            self.limit,
            u = self.unit
        )
    }
}

/// Why an inverse geometric model found no solution.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum IgmError {
    /// The chain is not of the 3P+3R layout that has a closed form.
    #[error("the closed-form IGM needs three prismatic then three revolute joints; this robot is {0}")]
    NotThreePThreeR(String),
    /// The orientation cannot be reached by the wrist.
    #[error("orientation unreachable by the wrist (cosine of the middle joint would be {0:.6})")]
    OrientationUnreachable(f64),
    /// Every solution exceeds a joint limit; the nearest one is reported.
    #[error("target out of range: {0}")]
    OutOfLimits(LimitViolation),
    /// The numerical IGM did not converge.
    #[error("numerical IGM did not converge after {iterations} iterations (residual {residual_um:.3e} µm, {residual_rad:.3e} rad)")]
    NotConverged {
        /// Iterations run.
        iterations: usize,
        /// Remaining position error (µm).
        residual_um: f64,
        /// Remaining orientation error (rad).
        residual_rad: f64,
    },
    /// The translation axes are not independent.
    #[error("the three prismatic axes are not independent: no position solution")]
    SingularTranslation,
}

/// A link compiled for evaluation: `T(i-1,i) = C · Rz(q)` or `C · Tz(q)` for a nominal joint;
/// with intrinsic errors, `C · Trans(o)·Rot(u, q')·Trans(-o)` or `C · Trans(u·q')`, where
/// `q' = q·(1 + scale) + zero offset`, `u` the (tilted) axis and `o` a point on it.
#[derive(Debug, Clone)]
struct CompiledLink {
    constant: Isometry3<f64>,
    joint: JointType,
    /// None for a nominal joint (the fast path).
    errors: Option<CompiledErrors>,
}

#[derive(Debug, Clone)]
struct CompiledErrors {
    axis: Unit<Vector3<f64>>,
    point: Vector3<f64>,
    gain: f64,
    /// Zero offset in internal units (µm or rad).
    offset: f64,
}

impl CompiledLink {
    /// Joint variable as the joint really moves it (internal units).
    #[inline]
    fn effective(&self, q: f64) -> f64 {
        match &self.errors {
            None => q,
            Some(e) => q * e.gain + e.offset,
        }
    }

    /// The joint's axis direction and a point on it, in the frame after `constant`.
    fn axis(&self) -> (Vector3<f64>, Unit<Vector3<f64>>) {
        match &self.errors {
            None => (Vector3::zeros(), Vector3::z_axis()),
            Some(e) => (e.point, e.axis),
        }
    }

    /// d(effective)/dq.
    fn gain(&self) -> f64 {
        self.errors.as_ref().map_or(1.0, |e| e.gain)
    }
}

/// A serial chain ready for evaluation, built from a [`RobotDescription`].
#[derive(Debug, Clone)]
pub struct Chain {
    description: RobotDescription,
    links: Vec<CompiledLink>,
    fast: FastChain,
}

/// The chain compiled for the DGM hot path (same model as `links`, fewer operations):
/// - the leading prismatic joints (intrinsic errors included) only translate, so their part
///   of the chain is a constant rotation and a translation affine in their joint values;
/// - the remaining links keep a constant rotation, a translation that is skipped when it is
///   exactly zero, and a joint motion; a nominal revolute joint is a product with the
///   quaternion (cos q/2, 0, 0, sin q/2) written out (8 products instead of an isometry chain).
#[derive(Debug, Clone)]
struct FastChain {
    prefix_rotation: UnitQuaternion<f64>,
    /// Prefix translation at q = 0 (µm).
    prefix_origin: Vector3<f64>,
    /// d(prefix translation)/dq_j in the world, gain included (µm/µm).
    prefix_axes: Vec<Vector3<f64>>,
    rest: Vec<FastLink>,
}

#[derive(Debug, Clone)]
struct FastLink {
    rotation: UnitQuaternion<f64>,
    /// `None` when the constant translation is exactly zero.
    translation: Option<Vector3<f64>>,
    /// Index into `Chain::links` (joint motion with intrinsic errors).
    link: usize,
}

impl FastChain {
    fn new(links: &[CompiledLink]) -> Self {
        let prefix = links.iter().take_while(|l| l.joint == JointType::Prismatic).count();
        let mut t = Isometry3::identity();
        let mut prefix_axes = Vec::with_capacity(prefix);
        for l in &links[..prefix] {
            t *= l.constant;
            let (_, axis) = l.axis();
            prefix_axes.push(t.rotation * axis.into_inner() * l.gain());
            t *= Chain::joint_motion(l, 0.0);
        }
        let rest = links[prefix..]
            .iter()
            .enumerate()
            .map(|(i, l)| {
                let v = l.constant.translation.vector;
                FastLink {
                    rotation: l.constant.rotation,
                    translation: (v != Vector3::zeros()).then_some(v),
                    link: prefix + i,
                }
            })
            .collect();
        Self { prefix_rotation: t.rotation, prefix_origin: t.translation.vector, prefix_axes, rest }
    }
}

/// `r · (cos(a/2), 0, 0, sin(a/2))`: a rotation about the local z axis appended to `r`.
#[inline(always)]
fn mul_rot_z(r: &UnitQuaternion<f64>, a: f64) -> UnitQuaternion<f64> {
    let (s, c) = sin_cos(0.5 * a);
    let (w, x, y, z) = (r.w, r.i, r.j, r.k);
    UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(w * c - z * s, x * c + y * s, y * c - x * s, z * c + w * s))
}

/// Rotation about x by `a` rad.
pub fn rot_x(a: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), a)
}
/// Rotation about y by `a` rad.
pub fn rot_y(a: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::y_axis(), a)
}
/// Rotation about z by `a` rad.
pub fn rot_z(a: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a)
}

fn iso_rot(q: UnitQuaternion<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::identity(), q)
}
fn iso_trans(x: f64, y: f64, z: f64) -> Isometry3<f64> {
    Isometry3::translation(x, y, z)
}

// fdlibm's constants (e_rem_pio2.c, k_sin.c, k_cos.c), by their bits.
/// π/2 in three parts: the first 33 bits, the next 33 bits, the rest.
const PIO2_1: f64 = f64::from_bits(0x3FF9_21FB_5440_0000);
const PIO2_2: f64 = f64::from_bits(0x3DD0_B461_1A60_0000);
const PIO2_2T: f64 = f64::from_bits(0x3BA3_198A_2E03_7073);
/// sin r = r + r³·(S1 + r²·(S2 + …)) on [-π/4, π/4].
const SIN_POLY: [f64; 6] = [
    f64::from_bits(0xBFC5_5555_5555_5549),
    f64::from_bits(0x3F81_1111_1110_F8A6),
    f64::from_bits(0xBF2A_01A0_19C1_61D5),
    f64::from_bits(0x3EC7_1DE3_57B1_FE7D),
    f64::from_bits(0xBE5A_E5E6_8A2B_9CEB),
    f64::from_bits(0x3DE5_D93A_5ACF_D57C),
];
/// cos r = 1 - r²/2 + r⁴·(C1 + r²·(C2 + …)) on [-π/4, π/4].
const COS_POLY: [f64; 6] = [
    f64::from_bits(0x3FA5_5555_5555_554C),
    f64::from_bits(0xBF56_C16C_16C1_5177),
    f64::from_bits(0x3EFA_01A0_19CB_1590),
    f64::from_bits(0xBE92_7E4F_809C_52AD),
    f64::from_bits(0x3E21_EE9E_BDB4_B1C4),
    f64::from_bits(0xBDA8_FAE9_BE88_38D4),
];
/// Arguments beyond this go to the standard library: n·PIO2_1 and n·PIO2_2 stay exact.
const SIN_COS_LIMIT: f64 = 8.0e5;
/// Adding 1.5·2^52 rounds a number below 2^51 to an integer (and leaves it in the low bits).
const ROUNDING_SHIFT: f64 = 6_755_399_441_055_744.0;

/// The argument reduced to [-π/4, π/4] and the multiple of π/2 taken off, as the shifted float
/// whose low bits hold it: x = n·π/2 + r.
#[inline(always)]
fn reduce(x: f64) -> (f64, f64) {
    let shifted = x * std::f64::consts::FRAC_2_PI + ROUNDING_SHIFT;
    let n = shifted - ROUNDING_SHIFT;
    (((x - n * PIO2_1) - n * PIO2_2) - n * PIO2_2T, shifted)
}

/// fdlibm's __kernel_sin and __kernel_cos (no tail) on [-π/4, π/4].
#[inline(always)]
fn sin_cos_kernel(r: f64) -> (f64, f64) {
    let (s, c) = (&SIN_POLY, &COS_POLY);
    let z = r * r;
    let sin_tail = s[1] + z * (s[2] + z * (s[3] + z * (s[4] + z * s[5])));
    let sin = r + z * r * (s[0] + z * sin_tail);
    let cos_tail = z * (c[0] + z * (c[1] + z * (c[2] + z * (c[3] + z * (c[4] + z * c[5])))));
    let hz = 0.5 * z;
    let w = 1.0 - hz;
    (sin, w + (((1.0 - w) - hz) + z * cos_tail))
}

/// (sin x, cos x) from the kernel's values at r and the quadrant n mod 4 in the low bits of
/// `shifted`: odd quadrants swap sin and cos, quadrants 2, 3 negate sin and 1, 2 cos; chosen
/// with bit masks, without branches (fringe phases make the quadrant unpredictable).
#[inline(always)]
fn place_in_quadrant(sin_r: f64, cos_r: f64, shifted: f64) -> (f64, f64) {
    let bits = shifted.to_bits();
    let swap = (bits & 1).wrapping_neg(); // all ones in odd quadrants
    let pick = |a: f64, b: f64| (a.to_bits() & !swap) | (b.to_bits() & swap);
    let sin_sign = (bits >> 1) << 63;
    let cos_sign = ((bits >> 1) ^ bits) << 63;
    (f64::from_bits(pick(sin_r, cos_r) ^ sin_sign), f64::from_bits(pick(cos_r, sin_r) ^ cos_sign))
}

/// sin x and cos x together, to about 1 ulp, without a library call: the argument is reduced
/// by multiples of π/2 (Cody-Waite, π/2 in three parts, exact for |x| < 8e5, which covers
/// joint angles and fringe phases of gaps up to 100 mm) and the fdlibm kernels evaluate
/// sin and cos on [-π/4, π/4]; larger or non-finite arguments go to the standard library.
#[inline]
pub fn sin_cos(x: f64) -> (f64, f64) {
    if x.is_nan() || x.abs() > SIN_COS_LIMIT {
        return x.sin_cos();
    }
    let (r, shifted) = reduce(x);
    let (s, c) = sin_cos_kernel(r);
    place_in_quadrant(s, c, shifted)
}

/// [`sin_cos`] of two arguments at once: lane by lane the same operations and results,
/// written so that the compiler can evaluate both lanes with vector instructions.
#[inline(always)]
pub(crate) fn sin_cos_2(x: [f64; 2]) -> ([f64; 2], [f64; 2]) {
    if x.iter().any(|v| v.is_nan() || v.abs() > SIN_COS_LIMIT) {
        let (a, b) = (sin_cos(x[0]), sin_cos(x[1]));
        return ([a.0, b.0], [a.1, b.1]);
    }
    let ((r0, shifted0), (r1, shifted1)) = (reduce(x[0]), reduce(x[1]));
    let ((s0, c0), (s1, c1)) = (sin_cos_kernel(r0), sin_cos_kernel(r1));
    let ((s0, c0), (s1, c1)) = (place_in_quadrant(s0, c0, shifted0), place_in_quadrant(s1, c1, shifted1));
    ([s0, s1], [c0, c1])
}

/// Wrap an angle to (-π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let w = (a + PI).rem_euclid(2.0 * PI) - PI;
    if w <= -PI {
        w + 2.0 * PI
    } else {
        w
    }
}

impl Chain {
    /// Compile a description.
    pub fn new(description: RobotDescription) -> Self {
        let links = description
            .links
            .iter()
            .map(|l| CompiledLink {
                constant: iso_rot(rot_y(l.beta_deg.to_radians()))
                    * iso_rot(rot_x(l.alpha_deg.to_radians()))
                    * iso_trans(l.d_um, 0.0, 0.0)
                    * iso_rot(rot_z(l.theta_deg.to_radians()))
                    * iso_trans(0.0, 0.0, l.r_um),
                joint: l.joint,
                errors: (!l.errors.is_nominal()).then(|| {
                    let e = &l.errors;
                    let [tx, ty] = e.axis_tilt_mrad.map(|m| (m * 1e-3).tan());
                    CompiledErrors {
                        axis: Unit::new_normalize(Vector3::new(tx, ty, 1.0)),
                        point: Vector3::from(e.axis_offset_um),
                        gain: 1.0 + e.scale_ppm * 1e-6,
                        offset: match l.joint {
                            JointType::Prismatic => e.zero_offset,
                            JointType::Revolute => e.zero_offset.to_radians(),
                        },
                    }
                }),
            })
            .collect::<Vec<_>>();
        let fast = FastChain::new(&links);
        Self { description, links, fast }
    }

    /// The paper's robot.
    pub fn femto_6dof() -> Self {
        Self::new(RobotDescription::femto_6dof())
    }

    /// The description this chain was built from.
    pub fn description(&self) -> &RobotDescription {
        &self.description
    }

    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.links.len()
    }

    fn check_len(&self, q: &[f64]) {
        assert_eq!(q.len(), self.links.len(), "joint vector length must equal the number of joints");
    }

    #[inline]
    fn joint_motion(link: &CompiledLink, q: f64) -> Isometry3<f64> {
        match (&link.errors, link.joint) {
            (None, JointType::Prismatic) => iso_trans(0.0, 0.0, q),
            (None, JointType::Revolute) => iso_rot(rot_z(q)),
            (Some(e), JointType::Prismatic) => {
                let v = e.axis.into_inner() * link.effective(q);
                iso_trans(v.x, v.y, v.z)
            }
            (Some(e), JointType::Revolute) => {
                let r = UnitQuaternion::from_axis_angle(&e.axis, link.effective(q));
                // Rotation about the axis through `point`: Trans(o)·R·Trans(-o).
                Isometry3::from_parts(Translation3::from(e.point - r * e.point), r)
            }
        }
    }

    /// The link transform `T(i-1,i)` for joint index `i` (0-based) at joint value `qi`.
    pub fn link_transform(&self, i: usize, qi: f64) -> Isometry3<f64> {
        let l = &self.links[i];
        l.constant * Self::joint_motion(l, qi)
    }

    /// Poses of frames 1..n in the world (frame 0), `0T1, 0T2, …, 0Tn`.
    pub fn frames(&self, q: &[f64]) -> Vec<Isometry3<f64>> {
        self.check_len(q);
        let mut t = Isometry3::identity();
        self.links
            .iter()
            .zip(q)
            .map(|(l, &qi)| {
                t *= l.constant * Self::joint_motion(l, qi);
                t
            })
            .collect()
    }

    /// Direct geometric model: the end-effector pose `wTe = 0Tn`.
    ///
    /// Evaluated on the compiled form (affine prefix of prismatic joints, then one quaternion
    /// product per wrist link); [`Chain::end_effector_reference`] is the plain product of the
    /// link transforms, equal to it within rounding.
    #[inline]
    pub fn end_effector(&self, q: &[f64]) -> Isometry3<f64> {
        self.check_len(q);
        let f = &self.fast;
        let mut p = f.prefix_origin;
        for (axis, &qi) in f.prefix_axes.iter().zip(q) {
            p += axis * qi;
        }
        let mut r = f.prefix_rotation;
        for fl in &f.rest {
            if let Some(v) = &fl.translation {
                p += r * v;
            }
            r *= fl.rotation;
            let l = &self.links[fl.link];
            let qi = q[fl.link];
            match (&l.errors, l.joint) {
                (None, JointType::Revolute) => r = mul_rot_z(&r, qi),
                (None, JointType::Prismatic) => p += r * Vector3::new(0.0, 0.0, qi),
                _ => {
                    let m = Self::joint_motion(l, qi);
                    p += r * m.translation.vector;
                    r *= m.rotation;
                }
            }
        }
        Isometry3::from_parts(Translation3::from(p), r)
    }

    /// The DGM as the plain product `T(0,1)·T(1,2)···T(n-1,n)` of the link transforms: the
    /// reference [`Chain::end_effector`] is checked against.
    pub fn end_effector_reference(&self, q: &[f64]) -> Isometry3<f64> {
        self.check_len(q);
        let mut t = Isometry3::identity();
        for (l, &qi) in self.links.iter().zip(q) {
            t = t * l.constant * Self::joint_motion(l, qi);
        }
        t
    }

    /// The DGM and the geometric Jacobian in one pass, without allocating: `columns[i]`
    /// receives, per unit of joint i (µm or rad), the velocity of the end-effector origin
    /// (µm) and the angular velocity (rad), in the world (the columns of [`Chain::jacobian`]).
    pub fn end_effector_with_jacobian(
        &self,
        q: &[f64],
        columns: &mut [(Vector3<f64>, Vector3<f64>)],
    ) -> Isometry3<f64> {
        self.check_len(q);
        assert_eq!(columns.len(), self.links.len(), "one Jacobian column per joint");
        let mut t = Isometry3::identity();
        // First pass: a point on each axis (in .0) and its direction (in .1).
        for ((l, &qi), col) in self.links.iter().zip(q).zip(columns.iter_mut()) {
            let before = t * l.constant;
            let (point, axis) = l.axis();
            *col = ((before * Point3::from(point)).coords, before.rotation * axis.into_inner());
            t = before * Self::joint_motion(l, qi);
        }
        let pe = t.translation.vector;
        for (l, col) in self.links.iter().zip(columns.iter_mut()) {
            let (o, z) = *col;
            let g = l.gain();
            *col = match l.joint {
                JointType::Prismatic => (z * g, Vector3::zeros()),
                JointType::Revolute => (z.cross(&(pe - o)) * g, z * g),
            };
        }
        t
    }

    /// Joint axes in the world: for each joint, a point on its axis and the axis direction.
    pub fn joint_axes(&self, q: &[f64]) -> Vec<(Point3<f64>, Unit<Vector3<f64>>)> {
        self.check_len(q);
        let mut t = Isometry3::identity();
        let mut out = Vec::with_capacity(self.links.len());
        for (l, &qi) in self.links.iter().zip(q) {
            let before = t * l.constant;
            let (point, axis) = l.axis();
            out.push((before * Point3::from(point), Unit::new_normalize(before.rotation * axis.into_inner())));
            t = before * Self::joint_motion(l, qi);
        }
        out
    }

    /// Geometric Jacobian of the end effector (rows: linear velocity in µm per joint unit,
    /// then angular velocity in rad per joint unit; columns: joints).
    pub fn jacobian(&self, q: &[f64]) -> nalgebra::DMatrix<f64> {
        let pe = self.end_effector(q).translation.vector;
        let mut j = nalgebra::DMatrix::zeros(6, self.dof());
        for (c, ((o, z), l)) in self.joint_axes(q).into_iter().zip(&self.links).enumerate() {
            let g = l.gain();
            let (lin, ang) = match l.joint {
                JointType::Prismatic => (z.into_inner() * g, Vector3::zeros()),
                JointType::Revolute => (z.cross(&(pe - o.coords)) * g, z.into_inner() * g),
            };
            j.fixed_view_mut::<3, 1>(0, c).copy_from(&lin);
            j.fixed_view_mut::<3, 1>(3, c).copy_from(&ang);
        }
        j
    }

    /// Check a joint vector (internal units) against the limits; the first violation is returned.
    pub fn check_limits(&self, q: &[f64]) -> Result<(), LimitViolation> {
        self.check_len(q);
        let display = self.description.q_to_display(q);
        for (l, v) in self.description.links.iter().zip(display) {
            let unit = l.joint.display_unit();
            // A tolerance of 1e-9 of the display unit absorbs round-off at a limit.
            if v > l.limits.max + 1e-9 {
                return Err(LimitViolation { joint: l.name.clone(), value: v, limit: l.limits.max, unit });
            }
            if v < l.limits.min - 1e-9 {
                return Err(LimitViolation { joint: l.name.clone(), value: v, limit: l.limits.min, unit });
            }
        }
        Ok(())
    }

    /// Closed-form IGM of the 3P+3R layout (orientation from the wrist, then position from the
    /// three translations). Among the wrist solutions, those within the limits are preferred,
    /// then the one nearest `q_ref` (internal units).
    pub fn igm_closed_form(&self, target: &Isometry3<f64>, q_ref: &[f64]) -> Result<Vec<f64>, IgmError> {
        if !self.description.is_3p3r() {
            let kinds: String =
                self.links.iter().map(|l| if l.joint == JointType::Prismatic { 'P' } else { 'R' }).collect();
            return Err(IgmError::NotThreePThreeR(kinds));
        }
        self.check_len(q_ref);
        if self.links[3..].iter().any(|l| l.errors.is_some()) {
            return Err(IgmError::NotThreePThreeR("3P+3R with intrinsic wrist errors (use Chain::igm)".into()));
        }
        // Rotation of the three prismatic links (constant) and the wrist's fixed parts.
        let r03: Matrix3<f64> =
            (self.links[0].constant.rotation * self.links[1].constant.rotation * self.links[2].constant.rotation)
                .to_rotation_matrix()
                .into_inner();
        let a = |i: usize| self.links[i].constant.rotation.to_rotation_matrix().into_inner();
        let (a4, a5, a6) = (a(3), a(4), a(5));
        let w = a4.transpose() * r03.transpose() * target.rotation.to_rotation_matrix().into_inner();
        // ez·W·ez = (A5ᵀ ez)·Rz(q5)·(A6 ez): P cos q5 + Q sin q5 = rhs.
        let u = a6 * Vector3::z();
        let av = a5.transpose() * Vector3::z();
        let p = av.x * u.x + av.y * u.y;
        let qq = av.y * u.x - av.x * u.y;
        let rhs = w[(2, 2)] - av.z * u.z;
        let rho = p.hypot(qq);
        let mut q5_candidates = Vec::with_capacity(2);
        if rho < 1e-12 {
            q5_candidates.push(q_ref[4]);
        } else {
            let c = rhs / rho;
            if c.abs() > 1.0 + 1e-9 {
                return Err(IgmError::OrientationUnreachable(c));
            }
            let psi = qq.atan2(p);
            let d = c.clamp(-1.0, 1.0).acos();
            q5_candidates.push(psi + d);
            if d > 1e-12 {
                q5_candidates.push(psi - d);
            }
        }
        let rz = |t: f64| rot_z(t).to_rotation_matrix().into_inner();
        let mut solutions = Vec::new();
        for q5 in q5_candidates {
            let v = a5 * rz(q5) * u;
            let wz = w * Vector3::z();
            let q4 = if v.xy().norm() < 1e-12 { q_ref[3] } else { wz.y.atan2(wz.x) - v.y.atan2(v.x) };
            let m = (rz(q4) * a5 * rz(q5) * a6).transpose() * w;
            let q6 = m[(1, 0)].atan2(m[(0, 0)]);
            let mut q = q_ref.to_vec();
            for (k, ang) in [(3, q4), (4, q5), (5, q6)] {
                // The representative of the angle nearest the reference.
                q[k] = q_ref[k] + wrap_angle(ang - q_ref[k]);
            }
            self.solve_translations(target, &mut q)?;
            solutions.push(q);
        }
        let distance = |q: &[f64]| -> f64 { q[3..].iter().zip(&q_ref[3..]).map(|(a, b)| (a - b).powi(2)).sum() };
        solutions.sort_by(|a, b| distance(a).total_cmp(&distance(b)));
        if let Some(ok) = solutions.iter().find(|q| self.check_limits(q).is_ok()) {
            return Ok(ok.clone());
        }
        Err(IgmError::OutOfLimits(self.check_limits(&solutions[0]).unwrap_err()))
    }

    /// With the revolute joints of `q` set, solve the translation joints so the end effector
    /// reaches `target`'s position (the position is affine in the prismatic joints).
    fn solve_translations(&self, target: &Isometry3<f64>, q: &mut [f64]) -> Result<(), IgmError> {
        for v in q.iter_mut().take(3) {
            *v = 0.0;
        }
        let p0 = self.end_effector(q).translation.vector;
        let axes = self.joint_axes(q);
        let a = Matrix3::from_columns(&[0, 1, 2].map(|i| axes[i].1.into_inner() * self.links[i].gain()));
        let sol = a.lu().solve(&(target.translation.vector - p0)).ok_or(IgmError::SingularTranslation)?;
        q[..3].copy_from_slice(sol.as_slice());
        Ok(())
    }

    /// The IGM for any chain: the closed form where it applies (then polished by the numerical
    /// IGM when the chain carries intrinsic errors the closed form ignores), else the
    /// numerical IGM from `q_ref`.
    pub fn igm(&self, target: &Isometry3<f64>, q_ref: &[f64]) -> Result<Vec<f64>, IgmError> {
        let nominal = Chain::new(self.nominal_description());
        match nominal.igm_closed_form(target, q_ref) {
            Ok(q) if self.links.iter().all(|l| l.errors.is_none()) => Ok(q),
            Ok(q) => self.igm_numeric(target, &q),
            Err(IgmError::NotThreePThreeR(_)) => self.igm_numeric(target, q_ref),
            Err(e) => Err(e),
        }
    }

    /// The description with every intrinsic error set to zero.
    pub fn nominal_description(&self) -> RobotDescription {
        let mut d = self.description.clone();
        for l in &mut d.links {
            l.errors = Default::default();
        }
        d
    }

    /// Numerical IGM by damped least squares, from `q0` (internal units). Converges to
    /// 1e-9 µm and 1e-12 rad or reports failure. Works for any chain.
    pub fn igm_numeric(&self, target: &Isometry3<f64>, q0: &[f64]) -> Result<Vec<f64>, IgmError> {
        self.check_len(q0);
        // Orientation errors are weighted as lengths over 1 mm so both kinds of error count.
        const LEVER_UM: f64 = 1000.0;
        const DAMPING: f64 = 1e-6;
        let mut q = q0.to_vec();
        let mut err = (f64::INFINITY, f64::INFINITY);
        for it in 0..200 {
            let t = self.end_effector(&q);
            let dp = target.translation.vector - t.translation.vector;
            let dr = (target.rotation * t.rotation.inverse()).scaled_axis();
            err = (dp.norm(), dr.norm());
            if err.0 < 1e-9 && err.1 < 1e-12 {
                self.check_limits(&q).map_err(IgmError::OutOfLimits)?;
                return Ok(q);
            }
            let mut j = self.jacobian(&q);
            for c in 0..j.ncols() {
                for r in 3..6 {
                    j[(r, c)] *= LEVER_UM;
                }
            }
            let e = Vector6::new(dp.x, dp.y, dp.z, dr.x * LEVER_UM, dr.y * LEVER_UM, dr.z * LEVER_UM);
            let jjt = &j * j.transpose() + nalgebra::DMatrix::identity(6, 6) * DAMPING;
            let Some(y) = jjt.lu().solve(&nalgebra::DVector::from_column_slice(e.as_slice())) else {
                return Err(IgmError::NotConverged { iterations: it, residual_um: err.0, residual_rad: err.1 });
            };
            let dq = j.transpose() * y;
            for (qi, d) in q.iter_mut().zip(dq.iter()) {
                *qi += d;
            }
        }
        Err(IgmError::NotConverged { iterations: 200, residual_um: err.0, residual_rad: err.1 })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use proptest::prelude::*;

    fn deg(qd: [f64; 6]) -> Vec<f64> {
        RobotDescription::femto_6dof().q_from_display(&qd)
    }

    #[test]
    fn end_effector_at_zero_is_eq_17() {
        let t = Chain::femto_6dof().end_effector(&[0.0; 6]);
        let r = t.rotation.to_rotation_matrix().into_inner();
        let want = Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -1.0, 0.0);
        assert_relative_eq!(r, want, epsilon = 1e-15);
        assert_relative_eq!(t.translation.vector.norm(), 0.0, epsilon = 1e-12);
    }

    #[test]
    fn translation_joints_move_along_z_y_x_of_the_world() {
        let c = Chain::femto_6dof();
        for (i, axis) in [(0, Vector3::z()), (1, Vector3::y()), (2, Vector3::x())] {
            let mut q = vec![0.0; 6];
            q[i] = 7.5;
            assert_relative_eq!(c.end_effector(&q).translation.vector, axis * 7.5, epsilon = 1e-12);
        }
    }

    #[test]
    fn wrist_rotation_is_eq_25() {
        let c = Chain::femto_6dof();
        for (q4d, q5d) in [(1.0, -2.0), (-4.0, 4.0), (7.0, 3.0), (0.0, -9.0)] {
            let (q4, q5) = (f64::to_radians(q4d), f64::to_radians(q5d));
            let r = c.end_effector(&[0.0, 0.0, 0.0, q4, q5, 0.0]).rotation.to_rotation_matrix().into_inner();
            let (c4, s4, c5, s5) = (q4.cos(), q4.sin(), q5.cos(), q5.sin());
            let want = Matrix3::new(c5, 0.0, -s5, s5 * c4, s4, c5 * c4, s5 * s4, -c4, c5 * s4);
            assert_relative_eq!(r, want, epsilon = 1e-14);
        }
    }

    #[test]
    fn joint_six_axis_is_the_beam_direction_at_zero() {
        let axes = Chain::femto_6dof().joint_axes(&[0.0; 6]);
        assert_relative_eq!(axes[5].1.into_inner(), Vector3::y(), epsilon = 1e-15);
        // Joints 4 and 5 turn about X_w and Z_w at q = 0 (SPEC section 9).
        assert_relative_eq!(axes[3].1.into_inner(), Vector3::x(), epsilon = 1e-15);
        assert_relative_eq!(axes[4].1.into_inner().abs(), Vector3::z(), epsilon = 1e-15);
    }

    #[test]
    fn limit_violation_names_joint_and_excess() {
        let c = Chain::femto_6dof();
        let e = c.check_limits(&deg([0.0, 0.0, 0.0, 12.3, 0.0, 0.0])).unwrap_err();
        assert_eq!(e.joint, "q4");
        assert_relative_eq!(e.excess(), 2.3, epsilon = 1e-9);
        assert_eq!(e.to_string(), "joint q4 = 12.300 ° is 2.300 ° above its upper limit 10.000 °");
        let e = c.check_limits(&deg([-151.0, 0.0, 0.0, 0.0, 0.0, 0.0])).unwrap_err();
        assert_eq!(e.to_string(), "joint q1 = -151.000 µm is 1.000 µm below its lower limit -150.000 µm");
        assert!(c.check_limits(&deg([150.0, -150.0, 0.0, 10.0, -10.0, 180.0])).is_ok());
    }

    #[test]
    fn igm_reports_a_target_out_of_range() {
        let c = Chain::femto_6dof();
        let target = c.end_effector(&[0.0; 6]) * Isometry3::translation(0.0, 0.0, 0.0);
        let far = Isometry3::from_parts(Translation3::new(400.0, 0.0, 0.0), target.rotation);
        match c.igm_closed_form(&far, &[0.0; 6]) {
            Err(IgmError::OutOfLimits(v)) => {
                assert_eq!(v.joint, "q3");
                assert_relative_eq!(v.excess(), 250.0, epsilon = 1e-6);
            }
            other => panic!("expected an out-of-limits error, got {other:?}"),
        }
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let c = Chain::femto_6dof();
        let q = deg([10.0, -20.0, 30.0, 1.0, -2.0, 3.0]);
        let j = c.jacobian(&q);
        for k in 0..6 {
            let h = 1e-6;
            let mut qp = q.clone();
            qp[k] += h;
            let mut qm = q.clone();
            qm[k] -= h;
            let (tp, tm) = (c.end_effector(&qp), c.end_effector(&qm));
            let dv = (tp.translation.vector - tm.translation.vector) / (2.0 * h);
            let dw = (tp.rotation * tm.rotation.inverse()).scaled_axis() / (2.0 * h);
            for r in 0..3 {
                assert_relative_eq!(j[(r, k)], dv[r], epsilon = 1e-5);
                assert_relative_eq!(j[(r + 3, k)], dw[r], epsilon = 1e-7);
            }
        }
    }

    fn q_in_limits() -> impl Strategy<Value = Vec<f64>> {
        (-150.0..150.0f64, -150.0..150.0f64, -150.0..150.0f64, -10.0..10.0f64, -10.0..10.0f64, -180.0..180.0f64)
            .prop_map(|(a, b, c, d, e, f)| deg([a, b, c, d, e, f]))
    }

    fn assert_same_q(a: &[f64], b: &[f64]) {
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() < 1e-9, "{a:?} != {b:?}");
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(500))]
        #[test]
        fn closed_form_igm_inverts_dgm(q in q_in_limits()) {
            let c = Chain::femto_6dof();
            let t = c.end_effector(&q);
            let back = c.igm_closed_form(&t, &q).unwrap();
            assert_same_q(&back, &q);
            // From a far reference, the solution still reproduces the pose.
            let other = c.igm_closed_form(&t, &[0.0; 6]).unwrap();
            let t2 = c.end_effector(&other);
            prop_assert!((t2.translation.vector - t.translation.vector).norm() < 1e-9);
            prop_assert!(t2.rotation.angle_to(&t.rotation) < 1e-12);
        }

        #[test]
        fn numeric_igm_inverts_dgm(q in q_in_limits(), dq in proptest::collection::vec(-0.05..0.05f64, 6)) {
            let c = Chain::femto_6dof();
            let t = c.end_effector(&q);
            // Start a little away (µm and tens of mrad) from the solution.
            let q0: Vec<f64> = q.iter().zip(&dq).enumerate()
                .map(|(i, (a, d))| a + if i < 3 { d * 100.0 } else { *d }).collect();
            let back = c.igm_numeric(&t, &q0).unwrap();
            assert_same_q(&back, &q);
        }
    }

    #[test]
    fn intrinsic_errors_act_as_described() {
        let mut d = RobotDescription::femto_6dof();
        // q2 (Y_w) 800 ppm too long; q4 turns about an axis 20 µm off along Y_w; q5 zero 0.05° off.
        d.links[1].errors.scale_ppm = 800.0;
        let c0 = Chain::femto_6dof();
        // Link 4's frame at q = 0 has z = X_w; which local axis is Y_w?
        let f4 = c0.frames(&[0.0; 6])[3];
        let y_in_link4 = f4.rotation.inverse() * Vector3::y();
        d.links[3].errors.axis_offset_um = (y_in_link4 * 20.0).into();
        d.links[4].errors.zero_offset = 0.05;
        let c = Chain::new(d);
        let p = c.end_effector(&[0.0, 100.0, 0.0, 0.0, 0.0, 0.0]).translation.vector;
        assert_relative_eq!(p, Vector3::new(0.0, 100.08, 0.0), epsilon = 1e-9);
        // Rotating q4 by φ about an axis through (0, 20, 0) moves the origin to
        // (0, 20 - 20 cos φ, -20 sin φ) (rotation about +X_w), plus the q5 offset's effect (none on the origin).
        let phi = 3f64.to_radians();
        let p = c.end_effector(&[0.0, 0.0, 0.0, phi, 0.0, 0.0]).translation.vector;
        assert_relative_eq!(p, Vector3::new(0.0, 20.0 - 20.0 * phi.cos(), -20.0 * phi.sin()), epsilon = 1e-9);
        let r5 = c.end_effector(&[0.0; 6]).rotation.angle_to(&c0.end_effector(&[0.0; 6]).rotation);
        assert_relative_eq!(r5, 0.05f64.to_radians(), epsilon = 1e-12);
        // The combined IGM stays exact on the perturbed chain.
        let q = deg([10.0, -20.0, 30.0, 1.0, -2.0, 3.0]);
        let back = c.igm(&c.end_effector(&q), &[0.0; 6]).unwrap();
        assert_same_q(&back, &q);
        // And the Jacobian still matches finite differences.
        let j = c.jacobian(&q);
        for k in 0..6 {
            let mut qp = q.clone();
            qp[k] += 1e-6;
            let dv = (c.end_effector(&qp).translation.vector - c.end_effector(&q).translation.vector) / 1e-6;
            for r in 0..3 {
                assert!((j[(r, k)] - dv[r]).abs() < 1e-4, "J[{r},{k}] = {} vs {}", j[(r, k)], dv[r]);
            }
        }
    }

    #[test]
    fn sin_cos_agrees_with_the_standard_library_to_an_ulp() {
        let check = |x: f64| {
            let ((s, c), (s0, c0)) = (sin_cos(x), x.sin_cos());
            // An ulp of a value in [0.5, 1] is 1.1e-16; near zero, sin is relative.
            assert!((c - c0).abs() <= 2.3e-16, "cos {x}: {c} vs {c0}");
            assert!((s - s0).abs() <= 2.3e-16 * s0.abs().max(x.abs().min(1.0)), "sin {x}: {s} vs {s0}");
        };
        let mut x: f64 = 0.0;
        for i in 0..200_000 {
            // A low-discrepancy walk over 0..2e4 rad (fringe phases), scaled to joint angles and below.
            x = (x + 0.618_033_988_749_894_9 * 7.3).rem_euclid(2.0e4);
            for v in [x, -x, x * 1e-3, x * 1e-9] {
                check(v);
            }
            check(f64::from(i % 64) * std::f64::consts::FRAC_PI_4);
        }
        for x in [0.0, -0.0, 7.9e5, -7.9e5, 8.1e5, 1e10, f64::MIN_POSITIVE] {
            check(x);
        }
        // The two-lane version gives the same bits.
        let mut x: f64 = 0.1;
        for _ in 0..100_000 {
            x = (x + 0.618_033_988_749_894_9 * 7.3).rem_euclid(2.0e4);
            for pair in [[x, -x * 1e-3], [-x, x * 1e-9], [x, 9e5], [0.0, -0.0]] {
                let (s, c) = sin_cos_2(pair);
                for i in 0..2 {
                    let (s1, c1) = sin_cos(pair[i]);
                    assert_eq!((s[i].to_bits(), c[i].to_bits()), (s1.to_bits(), c1.to_bits()), "{}", pair[i]);
                }
            }
        }
        assert!(sin_cos(f64::NAN).0.is_nan() && sin_cos(f64::INFINITY).1.is_nan());
    }

    /// A chain with intrinsic errors on every kind of joint, and a wrist link with a translation.
    fn perturbed_chain() -> Chain {
        let mut d = RobotDescription::femto_6dof();
        d.links[1].errors.scale_ppm = 800.0;
        d.links[2].errors.axis_tilt_mrad = [0.3, -0.2];
        d.links[2].errors.zero_offset = 1.5;
        d.links[3].errors.axis_offset_um = [0.0, 10.0, 5.0];
        d.links[4].errors.zero_offset = 0.05;
        d.links[4].d_um = 3.0;
        d.links[5].errors.axis_tilt_mrad = [0.1, 0.2];
        Chain::new(d)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        /// The compiled DGM equals the plain product of the link transforms.
        #[test]
        fn compiled_dgm_equals_the_product_of_link_transforms(q in q_in_limits()) {
            for c in [Chain::femto_6dof(), perturbed_chain()] {
                let (a, b) = (c.end_effector(&q), c.end_effector_reference(&q));
                prop_assert!((a.translation.vector - b.translation.vector).norm() < 1e-12);
                prop_assert!(a.rotation.angle_to(&b.rotation) < 1e-14);
                let mut cols = [(Vector3::zeros(), Vector3::zeros()); 6];
                let t = c.end_effector_with_jacobian(&q, &mut cols);
                prop_assert!((t.translation.vector - b.translation.vector).norm() < 1e-12);
                let j = c.jacobian(&q);
                for (k, (lin, ang)) in cols.iter().enumerate() {
                    for r in 0..3 {
                        prop_assert!((j[(r, k)] - lin[r]).abs() < 1e-9 && (j[(r + 3, k)] - ang[r]).abs() < 1e-14);
                    }
                }
            }
        }
    }

    #[test]
    fn numeric_igm_works_for_a_chain_without_closed_form() {
        // A 2P+1R+1P+2R chain: not 3P+3R, so only the numerical IGM applies.
        let mut d = RobotDescription::femto_6dof();
        d.links.swap(2, 3);
        d.links[3].d_um = 50.0;
        let c = Chain::new(d);
        assert!(
            matches!(c.igm_closed_form(&Isometry3::identity(), &[0.0; 6]), Err(IgmError::NotThreePThreeR(k)) if k == "PPRPRR")
        );
        let q = vec![5.0, -7.0, 0.02, 12.0, -0.03, 0.4];
        let t = c.end_effector(&q);
        let back = c.igm_numeric(&t, &[0.0; 6]).unwrap();
        assert_same_q(&back, &q);
    }
}
