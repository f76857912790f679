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
use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use std::f64::consts::PI;

mod fast_sin_cos;
mod igm;

pub use fast_sin_cos::sin_cos;
pub(crate) use fast_sin_cos::sin_cos_2;
pub use igm::{IgmError, LimitViolation};

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

    /// The description with every intrinsic error set to zero.
    pub fn nominal_description(&self) -> RobotDescription {
        let mut d = self.description.clone();
        for l in &mut d.links {
            l.errors = Default::default();
        }
        d
    }
}

#[cfg(test)]
mod tests;
