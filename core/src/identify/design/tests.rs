use super::*;
use crate::model::robot::RobotDescription;
use crate::plan::{MotionLimits, Plan, Segment};
use nalgebra::{DMatrix, DVector};

/// A linear model y = θ₀ + θ₁·x + θ₂·x² measured at x with noise σ: information of one
/// measurement `a aᵀ / σ²`, a = (1, x, x²).
fn measurement(x: f64, sigma: f64) -> DMatrix<f64> {
    let a = DVector::from_vec(vec![1.0, x, x * x]);
    &a * a.transpose() / (sigma * sigma)
}

fn problem(points: &[(f64, f64, f64)], bounds: [f64; 3]) -> SelectionProblem {
    SelectionProblem {
        information: points.iter().map(|&(x, s, _)| measurement(x, s)).collect(),
        cost: points.iter().map(|p| p.2).collect(),
        prior: DMatrix::identity(3, 3) * 1e-6,
        scatter: None,
        criteria: (0..3)
            .map(|i| Criterion {
                c: DVector::from_fn(3, |j, _| if i == j { 1.0 } else { 0.0 }),
                tau: bounds[i],
                free: None,
                members: None,
            })
            .collect(),
    }
}

#[test]
fn greedy_finds_the_brute_force_optimum_of_a_quadratic_fit() {
    // Points on [-1, 1]; the curvature and slope want the ends, the intercept the middle.
    let points: Vec<(f64, f64, f64)> = [-1.0, -0.75, -0.5, -0.25, 0.0, 0.25, 0.5, 0.75, 1.0]
        .iter()
        .enumerate()
        .map(|(k, &x)| (x, 0.1, 1.0 + 0.1 * k as f64))
        .collect();
    let p = problem(&points, [0.08, 0.1, 0.2]);
    let best = select_exhaustive(&p).unwrap().expect("feasible");
    let got = select(&p).unwrap();
    assert!(got.sigma.iter().zip(&p.criteria).all(|(s, c)| *s <= c.tau));
    assert!(
        (got.cost - best.cost).abs() < 1e-9,
        "greedy {:?} ({}) vs optimum {:?} ({})",
        got.chosen,
        got.cost,
        best.chosen,
        best.cost
    );
}

#[test]
fn greedy_is_feasible_and_near_the_optimum_on_random_problems() {
    use rand::{rngs::StdRng, Rng, SeedableRng};
    let mut rng = StdRng::seed_from_u64(4);
    let (mut exact, mut feasible, mut worst) = (0, 0, 1.0f64);
    for _ in 0..40 {
        let points: Vec<(f64, f64, f64)> = (0..12)
            .map(|_| (rng.random_range(-1.0..1.0), rng.random_range(0.05..0.3), rng.random_range(1.0..5.0)))
            .collect();
        let p = problem(&points, [0.1, 0.15, 0.4]);
        let Some(best) = select_exhaustive(&p).unwrap() else {
            assert!(matches!(select(&p), Err(DesignError::Unreachable(_))));
            continue;
        };
        feasible += 1;
        let got = select(&p).unwrap();
        assert!(got.sigma.iter().zip(&p.criteria).all(|(s, c)| *s <= c.tau), "infeasible selection");
        assert!(got.cost >= best.cost - 1e-9);
        worst = worst.max(got.cost / best.cost);
        exact += usize::from((got.cost - best.cost).abs() < 1e-9);
    }
    eprintln!("greedy + exchange: optimum in {exact} of {feasible} feasible problems, worst ratio {worst:.3}");
    assert!(feasible >= 20, "only {feasible} feasible problems: the test is too easy");
    assert!(worst < 1.1, "worst cost ratio {worst}");
    assert!(exact * 10 >= feasible * 9, "optimum found in only {exact} of {feasible}");
}

#[test]
fn an_unreachable_target_is_an_error_naming_it() {
    let p = problem(&[(0.0, 0.1, 1.0), (0.5, 0.1, 1.0)], [0.08, 0.1, 0.2]);
    let err = select(&p).unwrap_err().to_string();
    assert!(err.contains("criterion") && err.contains("cannot reach"), "{err}");
    let mut bad = problem(&[(0.0, 0.1, 1.0)], [0.1, 0.1, 0.1]);
    bad.cost[0] = 0.0;
    assert!(select(&bad).unwrap_err().to_string().contains("cost"));
}

#[test]
fn the_schur_complement_removes_a_nuisance_gain() {
    // y_k = g·(1 + θ·x_k): with g free, θ's information is that of the centred x.
    let xs = [-1.0, 0.0, 2.0];
    let j = DMatrix::from_fn(3, 2, |r, c| if c == 0 { xs[r] } else { 1.0 });
    let cols = [Some(0usize), None];
    let f = extrinsic_information(&j, &cols);
    let mean = xs.iter().sum::<f64>() / 3.0;
    let want: f64 = xs.iter().map(|x| (x - mean).powi(2)).sum();
    assert!((f[(0, 0)] - want).abs() < 1e-12, "{} vs {want}", f[(0, 0)]);
}

#[test]
fn the_shipped_optimised_plan_fits_in_ten_minutes() {
    let plan = Plan::optimised();
    let d = plan.duration_s(&RobotDescription::femto_6dof(), [0.0; 6], &MotionLimits::default()).unwrap();
    assert!(d <= 600.0, "{d} s");
    let sweeps = plan.segments.iter().filter(|s| matches!(s, Segment::Sweep { .. })).count();
    assert!(sweeps >= 3, "the identifier's bootstrap needs at least three sweeps, the plan has {sweeps}");
}

#[test]
fn the_pool_fits_the_robot_and_is_timed_by_the_plan_model() {
    let robot = RobotDescription::femto_6dof();
    let limits = MotionLimits::default();
    let pool = candidate_pool(&robot, &limits);
    assert!(pool.len() > 100, "{} candidates", pool.len());
    for c in &pool {
        assert!(c.duration_s > 0.0 && c.setup_s >= 0.0, "{}", c.label);
    }
    let sweep = pool.iter().find(|c| c.label == "sweep 1540-1580 nm at 10 nm/s at q = 0").unwrap();
    assert!((sweep.duration_s - 4.0).abs() < 1e-9 && sweep.setup_s == 0.0);
    let refs: Vec<&Candidate> = pool.iter().take(5).collect();
    let plan = assemble(&refs, &robot, &limits).unwrap();
    let text = plan_ron_with_header(&plan, "generated by a test").unwrap();
    assert!(text.starts_with("// generated by a test\n"));
    let back = Plan::from_ron_str(&text, std::path::Path::new("optimised.ron")).unwrap();
    assert_eq!(back, plan);
    assert_eq!(back.recorded_moves() + back.segments.iter().filter(|s| matches!(s, Segment::Sweep { .. })).count(), 5);
}
