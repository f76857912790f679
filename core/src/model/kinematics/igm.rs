//! Inverse geometric models of the chain (closed form for the 3P+3R layout, damped least
//! squares for any chain) and the joint-limit check they rely on.

use super::{rot_z, wrap_angle, Chain};
use crate::model::robot::JointType;
use nalgebra::{Isometry3, Matrix3, Vector3, Vector6};
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

impl Chain {
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
