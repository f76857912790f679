//! The paper's method (Bettahar et al. 2020, section III): step A, step B, step C, as published
//! (with the eq. 27 erratum fixed). Owns the paper's measurement equation and its three steps.
//!
//! The paper models the fringe measure as the change of L, the length along the optical axis.
//! The fringe phase really follows the perpendicular fiber-to-lamella distance `|L|·cos γ`
//! ([`crate::measure`]); this module applies the paper's equations to such data on purpose, to
//! reproduce what the paper's method can and cannot determine, biases included.

use crate::identify::Observation;
use crate::identify::ObservationKind;
use crate::model::extrinsics::Extrinsics;
use crate::model::kinematics::Chain;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{storage::Owned, DMatrix, DVector, Dyn, OMatrix, OVector, Vector3, Vector4, U4};

/// Result of step A: the two unit vectors (as angles).
#[derive(Debug, Clone, PartialEq)]
pub struct StepA {
    /// β_et, θ_et, β_wf, θ_wf (°).
    pub angles_deg: [f64; 4],
    /// Weighted residual RMS (in σ units).
    pub residual_rms_sigma: f64,
    /// Residuals per equation (nm).
    pub residuals_nm: Vec<f64>,
    /// Singular values of the weighted Jacobian at the solution, per mrad.
    pub singular_values: Vec<f64>,
    /// Whether the solver reported convergence.
    pub converged: bool,
}

/// Result of step B: the origins.
#[derive(Debug, Clone, PartialEq)]
pub struct StepB {
    /// Z_et, x_wf, y_wf, z_wf (µm).
    pub origins_um: [f64; 4],
    /// Residuals per equation (nm).
    pub residuals_nm: Vec<f64>,
    /// Singular values of the weighted design matrix, per µm.
    pub singular_values: Vec<f64>,
}

/// The paper's signed L at joints `q_display` (eq. 29): the intersection of the optical axis
/// with the lamella plane.
fn paper_length(chain: &Chain, e: &Extrinsics, q_display: &[f64; 6]) -> f64 {
    let q = chain.description().q_from_display(q_display);
    e.cavity(&chain.end_effector(&q)).map_or(f64::NAN, |c| c.length_um)
}

/// The paper reads the fringes as the change of L; our measure is the change of the gap
/// (`−ΔL` for the paper's orientation, where n_f points away from the lamella and L < 0).
fn paper_dl_nm(obs: &Observation) -> Option<([f64; 6], [f64; 6], f64)> {
    match obs.kind {
        ObservationKind::GapChange { from_display, to_display, dl_nm } => Some((from_display, to_display, -dl_nm)),
        _ => None,
    }
}

/// Step A: nonlinear least squares of eq. 14, `(n_t·n_f)·dL = n_t·dp`, over the four angles,
/// from translation-only observations (strategy 1). `start` gives the initial angles (and is
/// what the solver returns for directions the data do not see).
pub fn step_a(chain: &Chain, observations: &[Observation], start: &Extrinsics) -> StepA {
    step_a_with(chain, observations, start, false)
}

/// Step A with the fiber direction held at `start` when `hold_fiber`: eq. 14 sees n_f only
/// through n_t·n_f, so the paper's data cannot place it (docs/method.md); holding it at the
/// design value keeps step B on a sane beam instead of one the solver wandered to.
pub fn step_a_with(chain: &Chain, observations: &[Observation], start: &Extrinsics, hold_fiber: bool) -> StepA {
    struct P<'a> {
        rows: Vec<(Vector3<f64>, f64, f64)>, // dp (µm), dL (nm), σ (nm)
        ree: nalgebra::Rotation3<f64>,
        base: &'a Extrinsics,
        x: Vector4<f64>,  // angles in mrad
        x0: Vector4<f64>, // start angles (mrad)
        hold_fiber: bool,
    }
    impl P<'_> {
        fn extr(&self, x: &Vector4<f64>) -> Extrinsics {
            let mut e = *self.base;
            let d = |m: f64| (m * 1e-3).to_degrees();
            e.beta_et_deg = d(x[0]);
            e.theta_et_deg = d(x[1]);
            e.beta_wf_deg = d(x[2]);
            e.theta_wf_deg = d(x[3]);
            e
        }
        fn res(&self, x: &Vector4<f64>) -> DVector<f64> {
            let e = self.extr(x);
            let n_t = self.ree * e.n_t_in_ee().into_inner();
            let n_f = e.n_f().into_inner();
            let c = n_t.dot(&n_f);
            // Eq. 14 sees the fiber direction only through n_t·n_f, flat near n_f ∥ n_t: two weak
            // prior rows (σ = 1°) keep the fiber angles at their start instead of letting the
            // solver wander where the data are silent. They move a determined angle by far
            // less than its σ.
            // Held: a stiff prior (1 nrad) instead of a zero column, which the solver's column
            // scaling cannot take.
            let prior_mrad = if self.hold_fiber { 1e-6 } else { 1f64.to_radians() * 1e3 };
            DVector::from_iterator(
                self.rows.len() + 2,
                self.rows
                    .iter()
                    .map(|(dp, dl, s)| (c * dl * 1e-3 - n_t.dot(dp)) * 1e3 / s)
                    .chain((2..4).map(|k| (x[k] - self.x0[k]) / prior_mrad)),
            )
        }
    }
    impl LeastSquaresProblem<f64, Dyn, U4> for P<'_> {
        type ResidualStorage = Owned<f64, Dyn>;
        type JacobianStorage = Owned<f64, Dyn, U4>;
        type ParameterStorage = Owned<f64, U4>;
        fn set_params(&mut self, x: &Vector4<f64>) {
            self.x = *x;
        }
        fn params(&self) -> Vector4<f64> {
            self.x
        }
        fn residuals(&self) -> Option<OVector<f64, Dyn>> {
            Some(self.res(&self.x))
        }
        fn jacobian(&self) -> Option<OMatrix<f64, Dyn, U4>> {
            let mut j = OMatrix::<f64, Dyn, U4>::zeros(self.rows.len() + 2);
            for c in 0..4 {
                let h = 1e-4;
                let (mut a, mut b) = (self.x, self.x);
                a[c] += h;
                b[c] -= h;
                let d = (self.res(&a) - self.res(&b)) / (2.0 * h);
                j.set_column(c, &d);
            }
            Some(j)
        }
    }
    let rows: Vec<_> = observations
        .iter()
        .filter_map(|o| {
            let (from, to, dl) = paper_dl_nm(o)?;
            let p = |q: &[f64; 6]| chain.end_effector(&chain.description().q_from_display(q)).translation.vector;
            Some((p(&to) - p(&from), dl, o.sigma))
        })
        .collect();
    let ree = chain.end_effector(&[0.0; 6]).rotation.to_rotation_matrix();
    let mrad = |deg: f64| deg.to_radians() * 1e3;
    let x0 = Vector4::new(
        mrad(start.beta_et_deg),
        mrad(start.theta_et_deg),
        mrad(start.beta_wf_deg),
        mrad(start.theta_wf_deg),
    );
    let problem = P { rows, ree, base: start, x: x0, x0, hold_fiber };
    let (problem, report) = LevenbergMarquardt::new().minimize(problem);
    let r_all = problem.res(&problem.x);
    let r = r_all.rows(0, problem.rows.len());
    let j = problem.jacobian().unwrap();
    // Singular values of the data rows over all four angles (held ones included: they show
    // what the data cannot see).
    let sv = j.rows(0, problem.rows.len()).clone_owned().svd(false, false).singular_values;
    let mut singular_values: Vec<f64> = sv.iter().copied().collect();
    singular_values.sort_by(|a, b| b.total_cmp(a));
    let e = problem.extr(&problem.x);
    StepA {
        angles_deg: [e.beta_et_deg, e.theta_et_deg, e.beta_wf_deg, e.theta_wf_deg],
        residual_rms_sigma: (r.norm_squared() / r.len().max(1) as f64).sqrt(),
        residuals_nm: r.iter().zip(&problem.rows).map(|(ri, (_, _, s))| ri * s).collect(),
        singular_values,
        converged: report.termination.was_successful(),
    }
}

/// Step B: linear least squares of eq. 31 in (Z_et, x_wf, y_wf, z_wf), with the angles of step A
/// fixed, from rotation observations (strategy 2). L is affine in the four unknowns at fixed
/// orientations, so each row is found exactly by evaluating eq. 29 at the unit vectors; this is
/// eq. 31 with the eq. 27 erratum fixed (`c'_wt`, not `c_wt`, in `d'_wt`), checked against the
/// printed formula in the tests.
pub fn step_b(chain: &Chain, observations: &[Observation], angles_deg: [f64; 4]) -> StepB {
    let with = |p: [f64; 4]| Extrinsics {
        beta_et_deg: angles_deg[0],
        theta_et_deg: angles_deg[1],
        beta_wf_deg: angles_deg[2],
        theta_wf_deg: angles_deg[3],
        z_et_um: p[0],
        x_wf_um: p[1],
        y_wf_um: p[2],
        z_wf_um: p[3],
    };
    let rows: Vec<_> = observations.iter().filter_map(|o| Some((paper_dl_nm(o)?, o.sigma))).collect();
    let m = rows.len();
    let mut a = DMatrix::zeros(m, 4);
    let mut b = DVector::zeros(m);
    for (i, ((from, to, dl_nm), sigma)) in rows.iter().enumerate() {
        let dl_model = |p: [f64; 4]| paper_length(chain, &with(p), to) - paper_length(chain, &with(p), from);
        let c0 = dl_model([0.0; 4]);
        for k in 0..4 {
            let mut p = [0.0; 4];
            p[k] = 1.0;
            a[(i, k)] = (dl_model(p) - c0) / sigma * 1e3; // nm per µm, weighted
        }
        b[i] = (dl_nm - c0 * 1e3) / sigma;
    }
    let svd = a.clone().svd(true, true);
    let x = svd.solve(&b, 1e-12).unwrap_or_else(|_| DVector::zeros(4));
    let r = &a * &x - &b;
    let mut singular_values: Vec<f64> = svd.singular_values.iter().copied().collect();
    singular_values.sort_by(|p, q| q.total_cmp(p));
    StepB {
        origins_um: [x[0], x[1], x[2], x[3]],
        residuals_nm: r.iter().zip(&rows).map(|(ri, (_, s))| ri * s).collect(),
        singular_values,
    }
}

/// Step C (eq. 32-34): the reflection point at q = 0 in the world and tool frames.
pub fn step_c(chain: &Chain, e: &Extrinsics) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let c = e.cavity(&chain.end_effector(&[0.0; 6])).ok()?;
    Some((c.reflection_point_world_um.coords, c.reflection_point_tool_um.coords))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::robot::RobotDescription;
    use crate::plan::Plan;

    /// Exact paper-model observations (dL along n_f, sign as our gap change) for the recorded
    /// moves of a plan.
    fn paper_observations(plan: &Plan, e: &Extrinsics) -> Vec<Observation> {
        let chain = Chain::femto_6dof();
        let segs = plan.expand(&RobotDescription::femto_6dof(), [0.0; 6], &Default::default()).unwrap();
        segs.iter()
            .filter(|s| s.record && s.from_display != s.to_display)
            .map(|s| Observation {
                label: s.label.clone(),
                kind: ObservationKind::GapChange {
                    from_display: s.from_display,
                    to_display: s.to_display,
                    dl_nm: -(paper_length(&chain, e, &s.to_display) - paper_length(&chain, e, &s.from_display)) * 1e3,
                },
                sigma: 2.0,
                wavelength_nm: 1560.0,
                time_s: [0.0; 2],
                approach: Default::default(),
            })
            .collect()
    }

    #[test]
    fn step_a_recovers_the_lamella_angles_but_not_the_fiber_direction() {
        let truth = Extrinsics::table2();
        let obs = paper_observations(&Plan::strategy1(), &truth);
        assert_eq!(obs.len(), 18);
        let mut start = truth;
        start.beta_et_deg = 0.0;
        start.theta_et_deg = 0.0;
        start.beta_wf_deg = 0.0;
        start.theta_wf_deg = 0.0;
        let a = step_a(&Chain::femto_6dof(), &obs, &start);
        assert!(a.converged);
        assert!((a.angles_deg[0] - 0.744).abs() < 1e-4 && (a.angles_deg[1] + 0.595).abs() < 1e-4, "{:?}", a.angles_deg);
        // Singular values per mrad (σ = 2 nm weighting ×2): 0.735, 0.735, 9.5e-4, ~0.
        let sv: Vec<f64> = a.singular_values.iter().map(|s| s * 2.0 / 1e3).collect();
        assert!(sv[3] < 1e-6 * sv[0], "{sv:?}");
    }

    #[test]
    fn step_b_recovers_the_origins_from_exact_paper_data() {
        let truth = Extrinsics::table2();
        let obs = paper_observations(&Plan::strategy2(), &truth);
        assert_eq!(obs.len(), 10);
        let t = truth.to_array();
        let b = step_b(&Chain::femto_6dof(), &obs, [t[0], t[1], t[2], t[3]]);
        // Rotations see the beam line, not where the fiber sits on it: O_f slides along n_f
        // without changing any dL (an exact null direction), so the minimum-norm solution puts
        // O_f elsewhere on the true line. Z_et is seen only at second order.
        let of = Vector3::new(b.origins_um[1], b.origins_um[2], b.origins_um[3]);
        let true_of = Vector3::new(112.40, 900.0, 113.3);
        let n_f = truth.n_f().into_inner();
        let off_line = (of - true_of) - n_f * (of - true_of).dot(&n_f);
        assert!(off_line.norm() < 1e-3, "O_f is {} µm off the true beam line", off_line.norm());
        assert!((b.origins_um[0] - 1.52).abs() < 1e-3, "Z_et {}", b.origins_um[0]);
        assert!(b.singular_values[3] < 1e-6 * b.singular_values[0], "{:?}", b.singular_values);
        assert!(b.singular_values[2] < 1e-3 * b.singular_values[0], "{:?}", b.singular_values);
    }

    /// Independent oracle: the printed eq. 27 and 31 (with c'_wt in d'_wt) for a q4/q5 rotation.
    #[test]
    fn step_b_rows_equal_the_printed_equation_31_with_the_erratum_fixed() {
        let e = Extrinsics::table2();
        let chain = Chain::femto_6dof();
        let ee = e.n_t_in_ee();
        let (aet, bet, cet) = (ee.x, ee.y, ee.z);
        // `b_sign` = +1 is the second row of eq. 25 applied to n_et; the paper prints -1 (a second
        // erratum in eq. 27, besides c'_wt in d'_wt).
        let plane = |q4: f64, q5: f64, b_sign: f64| {
            let (c4, s4, c5, s5) = (q4.cos(), q4.sin(), q5.cos(), q5.sin());
            let a = c5 * aet - s5 * cet;
            let b = c4 * s5 * aet + s4 * bet + b_sign * c4 * c5 * cet;
            let c = s4 * s5 * aet - c4 * bet + c5 * s4 * cet;
            let z = e.z_et_um;
            let d = a * z * s5 - b * z * c4 * c5 - c * z * c5 * s4; // erratum fixed: c', not c
            (a, b, c, d)
        };
        let nf = e.n_f();
        let l = |q4: f64, q5: f64, b_sign: f64| {
            let (a, b, c, d) = plane(q4, q5, b_sign);
            -(a * e.x_wf_um + b * e.y_wf_um + c * e.z_wf_um + d) / (a * nf.x + b * nf.y + c * nf.z)
        };
        for (q4, q5) in [(4.0f64, -2.0f64), (-4.0, 3.0), (1.0, 4.0)] {
            let (q4r, q5r) = (q4.to_radians(), q5.to_radians());
            let fixed = l(q4r, q5r, 1.0) - l(0.0, 0.0, 1.0);
            let ours = paper_length(&chain, &e, &[0.0, 0.0, 0.0, q4, q5, 0.0]) - paper_length(&chain, &e, &[0.0; 6]);
            assert!((fixed - ours).abs() < 1e-9, "q4 {q4}, q5 {q5}: {fixed} vs {ours}");
            let as_printed = l(q4r, q5r, -1.0) - l(0.0, 0.0, -1.0);
            assert!((as_printed - ours).abs() > 1.0, "the printed sign is wrong by µm: {as_printed} vs {ours}");
        }
    }
}
