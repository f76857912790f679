//! Tests of the chain: DGM against the paper's equations, Jacobian, closed-form and numeric IGM,
//! joint limits and intrinsic errors.

use super::*;
use approx::assert_relative_eq;
use nalgebra::Matrix3;
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
    // Joints 4 and 5 turn about X_w and Z_w at q = 0.
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
