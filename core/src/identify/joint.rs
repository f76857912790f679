//! The joint estimate: every extrinsic parameter from every observation at once (fringe phase, absolute gaps, power),
//! by Levenberg-Marquardt, with per-parameter masks and priors. Owns the convergence report.

use crate::identify::observability::{analyse, IdentifiabilityReport, Options, ParamInfo};
use crate::identify::{parameter_scale, predict, Observation, ObservationKind, N_EXTRINSICS};
use crate::model::extrinsics::{Extrinsics, PARAMETER_NAMES};
use crate::model::optics::FabryPerot;
use crate::model::phase::PhaseModel;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{storage::Owned, DMatrix, DVector, Dyn};
use serde::Serialize;
use std::sync::Mutex;

/// A Gaussian prior on a parameter (display units: ° or µm).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Prior {
    /// Prior mean.
    pub value: f64,
    /// Prior standard deviation.
    pub sigma: f64,
}

/// Options of the joint estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct JointOptions {
    /// Which of the eight parameters are free (order of [`PARAMETER_NAMES`]); fixed ones keep the start value.
    pub free: [bool; N_EXTRINSICS],
    /// Optional priors per parameter.
    pub priors: [Option<Prior>; N_EXTRINSICS],
    /// Iteration budget (function evaluations of the solver, × parameters).
    pub patience: usize,
}

impl Default for JointOptions {
    fn default() -> Self {
        Self { free: [true; N_EXTRINSICS], priors: [None; N_EXTRINSICS], patience: 200 }
    }
}

/// The outcome of the joint estimate, with an honest convergence report.
#[derive(Debug, Clone)]
pub struct JointEstimate {
    /// The estimate (fixed parameters at their start values).
    pub extrinsics: Extrinsics,
    /// Detector gain per amplitude group.
    pub gains: Vec<f64>,
    /// True only when the solver reports convergence *and* the residuals are finite.
    pub converged: bool,
    /// The solver's own words on how it stopped.
    pub termination: String,
    /// Function evaluations used.
    pub evaluations: usize,
    /// Residual per observation (measured − predicted, in the observation's unit).
    pub residuals: Vec<f64>,
    /// Residual per observation in σ units.
    pub normalised_residuals: Vec<f64>,
    /// Jacobian of the normalised residuals w.r.t. the free parameters in internal units
    /// (mrad, µm, then relative gains), rows = observations then priors.
    pub weighted_jacobian: DMatrix<f64>,
    /// Names of the Jacobian's columns.
    pub column_names: Vec<String>,
    /// Index into [`PARAMETER_NAMES`] of each extrinsic column (gain columns: None).
    pub column_parameter: Vec<Option<usize>>,
}

struct Problem<'a> {
    model: &'a PhaseModel,
    fps: Vec<(f64, FabryPerot)>,
    obs: &'a [Observation],
    start: [f64; N_EXTRINSICS],
    options: &'a JointOptions,
    free: Vec<usize>,
    groups: usize,
    x: DVector<f64>,
    /// The last residuals computed by [`Problem::residuals_cached`] and where: the solver asks
    /// for the Jacobian right after the residuals of the step it accepts.
    last: Mutex<Option<(DVector<f64>, DVector<f64>)>>,
}

impl Problem<'_> {
    fn unpack(&self, x: &DVector<f64>) -> (Extrinsics, Vec<f64>) {
        let mut a = self.start;
        for (k, &i) in self.free.iter().enumerate() {
            a[i] = x[k] * parameter_scale(i);
        }
        let gains = (0..self.groups).map(|g| x[self.free.len() + g]).collect();
        (Extrinsics::from_array(a), gains)
    }

    fn fp(&self, wavelength_nm: f64) -> &FabryPerot {
        &self.fps.iter().find(|(w, _)| *w == wavelength_nm).expect("a FabryPerot per wavelength").1
    }

    fn residuals_at(&self, x: &DVector<f64>) -> DVector<f64> {
        use rayon::prelude::*;
        let (e, gains) = self.unpack(x);
        let priors: Vec<(usize, Prior)> =
            self.options.priors.iter().enumerate().filter_map(|(i, p)| p.map(|p| (i, p))).collect();
        let observed: Vec<f64> = self
            .obs
            .par_iter()
            .map(|o| {
                let gain = match o.kind {
                    ObservationKind::FringeAmplitude { group, .. } => gains[group],
                    _ => 1.0,
                };
                let p = predict(self.model, self.fp(o.wavelength_nm), &e, o, gain);
                if p.is_finite() {
                    (o.value() - p) / o.sigma
                } else {
                    1e6
                }
            })
            .collect();
        let a = e.to_array();
        let prior = priors.iter().map(|(i, p)| (a[*i] - p.value) / p.sigma);
        DVector::from_iterator(observed.len() + priors.len(), observed.iter().copied().chain(prior))
    }

    /// [`Problem::residuals_at`], kept: computed again only when `x` moved since the last call.
    fn residuals_cached(&self, x: &DVector<f64>) -> DVector<f64> {
        let mut last = self.last.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        match &*last {
            Some((at, r)) if at == x => r.clone(),
            _ => {
                let r = self.residuals_at(x);
                *last = Some((x.clone(), r.clone()));
                r
            }
        }
    }

    /// The Jacobian at `x`: the extrinsic columns by central differences (`central`: what the
    /// reported uncertainties read) or forward ones (the solver's steps, at half the cost).
    fn jacobian_at(&self, x: &DVector<f64>, central: bool) -> DMatrix<f64> {
        use rayon::prelude::*;
        let n = x.len();
        let r0 = self.residuals_cached(x);
        let mut j = DMatrix::zeros(r0.len(), n);
        // Extrinsic columns by differences of 1e-4 mrad or µm, in parallel: each evaluates
        // every observation once or twice.
        let columns: Vec<DVector<f64>> = (0..self.free.len())
            .into_par_iter()
            .map(|c| {
                let h = 1e-4;
                let (mut a, mut b) = (x.clone(), x.clone());
                a[c] += h;
                b[c] -= h;
                // The residual is measured − predicted: its derivative is minus the model's.
                if central {
                    (self.residuals_at(&a) - self.residuals_at(&b)) / (2.0 * h)
                } else {
                    (self.residuals_at(&a) - &r0) / h
                }
            })
            .collect();
        for (c, d) in columns.iter().enumerate() {
            j.set_column(c, d);
        }
        // Gain columns in closed form: an amplitude's prediction is linear in its group's gain,
        // so ∂r/∂g = −prediction / (g·σ), the prediction being measured − r·σ.
        let (_, gains) = self.unpack(x);
        for (k, o) in self.obs.iter().enumerate() {
            if let ObservationKind::FringeAmplitude { group, .. } = o.kind {
                let g = gains[group];
                let predicted = o.value() - r0[k] * o.sigma;
                if g != 0.0 && r0[k].abs() < 1e6 {
                    j[(k, self.free.len() + group)] = -predicted / (g * o.sigma);
                }
            }
        }
        j
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.x.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        // The solver minimises ½‖r‖² with r = model − data: negate our data − model.
        Some(-self.residuals_cached(&self.x))
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        Some(-self.jacobian_at(&self.x, false))
    }
}

/// Estimate the extrinsics (and one detector gain per amplitude group) from the observations,
/// starting at `start`.
pub fn estimate(
    model: &PhaseModel,
    observations: &[Observation],
    start: &Extrinsics,
    options: &JointOptions,
) -> JointEstimate {
    run(model, observations, start, options, true)
}

/// Residuals and Jacobian at `at` without moving (gains fitted linearly): for the uncertainty of
/// an estimate made by another method (the paper's steps).
pub fn evaluate(
    model: &PhaseModel,
    observations: &[Observation],
    at: &Extrinsics,
    options: &JointOptions,
) -> JointEstimate {
    run(model, observations, at, options, false)
}

fn run(
    model: &PhaseModel,
    observations: &[Observation],
    start: &Extrinsics,
    options: &JointOptions,
    minimise: bool,
) -> JointEstimate {
    let mut wavelengths: Vec<f64> = observations.iter().map(|o| o.wavelength_nm).collect();
    wavelengths.sort_by(f64::total_cmp);
    wavelengths.dedup();
    let fps = wavelengths
        .iter()
        .filter_map(|&w| FabryPerot::new(&model.optics, w, model.n_air).ok().map(|fp| (w, fp)))
        .collect();
    let groups = observations
        .iter()
        .filter_map(|o| match o.kind {
            ObservationKind::FringeAmplitude { group, .. } => Some(group + 1),
            _ => None,
        })
        .max()
        .unwrap_or(0);
    let free: Vec<usize> = (0..N_EXTRINSICS).filter(|&i| options.free[i]).collect();
    let start_a = start.to_array();
    let mut x = DVector::zeros(free.len() + groups);
    for (k, &i) in free.iter().enumerate() {
        x[k] = start_a[i] / parameter_scale(i);
    }
    let mut problem =
        Problem { model, fps, obs: observations, start: start_a, options, free, groups, x, last: Mutex::new(None) };
    // Start each gain at the ratio of measured to predicted amplitudes (linear in the gain).
    if groups > 0 {
        let (e, _) = problem.unpack(&problem.x);
        for g in 0..groups {
            let (mut num, mut den) = (0.0, 0.0);
            for o in observations {
                if let ObservationKind::FringeAmplitude { group, .. } = o.kind {
                    if group == g {
                        let p = predict(model, problem.fp(o.wavelength_nm), &e, o, 1.0);
                        if p.is_finite() {
                            num += p * o.value();
                            den += p * p;
                        }
                    }
                }
            }
            let k = problem.free.len() + g;
            problem.x[k] = if den > 0.0 { num / den } else { 1.0 };
        }
    }
    let (problem, converged, termination, evaluations) = if minimise {
        let (problem, report) = LevenbergMarquardt::new().with_patience(options.patience.max(1)).minimize(problem);
        let t = crate::solver::termination_words(&report.termination);
        (problem, report.termination.was_successful(), t, report.number_of_evaluations)
    } else {
        (problem, true, "evaluated, not minimised".to_string(), 1)
    };
    let r = problem.residuals_cached(&problem.x);
    let finite = r.iter().all(|v| v.is_finite());
    let (extrinsics, gains) = problem.unpack(&problem.x);
    let weighted_jacobian = problem.jacobian_at(&problem.x, true);
    let mut column_names: Vec<String> = problem.free.iter().map(|&i| PARAMETER_NAMES[i].0.to_string()).collect();
    let mut column_parameter: Vec<Option<usize>> = problem.free.iter().map(|&i| Some(i)).collect();
    for g in 0..groups {
        column_names.push(format!("gain[{g}]"));
        column_parameter.push(None);
    }
    let residuals: Vec<f64> = observations.iter().zip(r.iter()).map(|(o, ri)| ri * o.sigma).collect();
    JointEstimate {
        extrinsics,
        gains,
        converged: converged && finite,
        termination,
        evaluations,
        normalised_residuals: r.iter().take(observations.len()).copied().collect(),
        residuals,
        weighted_jacobian,
        column_names,
        column_parameter,
    }
}

/// The identifiability report of a joint estimate: its weighted Jacobian and residuals, the
/// free extrinsics with their useful bounds, and the detector gains as nuisance parameters.
pub fn analyse_estimate(est: &JointEstimate) -> IdentifiabilityReport {
    let all = ParamInfo::extrinsics();
    let params: Vec<ParamInfo> = est
        .column_parameter
        .iter()
        .zip(&est.column_names)
        .map(|(p, name)| match p {
            Some(i) => all[*i].clone(),
            None => ParamInfo::new(name.clone(), "(gain)", 1.0),
        })
        .collect();
    let rows = est.weighted_jacobian.nrows();
    let mut r = nalgebra::DVector::zeros(rows);
    for (k, v) in est.normalised_residuals.iter().enumerate().take(rows) {
        r[k] = *v;
    }
    match analyse(&est.weighted_jacobian, &r, &params, &Options::default()) {
        Ok(report) => report,
        Err(e) => {
            // Inconsistent input is a bug, but the user still gets a report that says so.
            let mut report = analyse(
                &nalgebra::DMatrix::zeros(1, params.len()),
                &nalgebra::DVector::zeros(1),
                &params,
                &Options::default(),
            )
            .expect("a zero Jacobian is valid input");
            report.warnings.push(format!("identifiability analysis failed: {e}"));
            report
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::air::AmbientConditions;
    use crate::model::optics::OpticalParams;
    use crate::model::robot::RobotDescription;

    fn model() -> PhaseModel {
        PhaseModel::new(
            RobotDescription::femto_6dof(),
            Extrinsics::table2(),
            OpticalParams::default(),
            &AmbientConditions::default(),
            1560.0,
        )
        .unwrap()
    }

    /// Exact observations predicted from the truth: gap changes of translations and rotations,
    /// absolute gaps and amplitudes of a tilt scan.
    fn synthetic(truth: &Extrinsics) -> Vec<Observation> {
        let m = model();
        let fp = FabryPerot::new(&m.optics, 1560.0, m.n_air).unwrap();
        let mut out = Vec::new();
        let mut push = |kind: ObservationKind, sigma: f64| {
            let mut o = Observation {
                label: "s".into(),
                kind,
                sigma,
                wavelength_nm: 1560.0,
                time_s: [0.0; 2],
                approach: Default::default(),
            };
            let v = predict(&m, &fp, truth, &o, 2.0);
            match &mut o.kind {
                ObservationKind::GapChange { dl_nm, .. } => *dl_nm = v,
                ObservationKind::AbsoluteGap { gap_um, .. } => *gap_um = v,
                ObservationKind::FringeAmplitude { amplitude_mw, .. } => *amplitude_mw = v,
            }
            out.push(o);
        };
        for q in [[0.0, 0.0, 150.0, 0.0, 0.0, 0.0], [150.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 10.0, 0.0, 0.0, 0.0, 0.0]] {
            let mut from = q;
            for v in from.iter_mut().take(3) {
                *v = -*v;
            }
            push(ObservationKind::GapChange { from_display: from, to_display: q, dl_nm: 0.0 }, 2.0);
        }
        for lateral in [-150.0, 0.0, 150.0] {
            for (j, a) in [(3, 4.0), (4, 4.0), (3, -4.0), (4, -4.0), (5, 40.0)] {
                let mut from = [lateral, 0.0, lateral, 0.0, 0.0, 0.0];
                from[1] = 50.0;
                let mut to = from;
                to[j] = a;
                push(ObservationKind::GapChange { from_display: from, to_display: to, dl_nm: 0.0 }, 2.0);
            }
            push(
                ObservationKind::AbsoluteGap {
                    at_display: [lateral, -100.0, lateral, 0.0, 0.0, 0.0],
                    gap_um: 0.0,
                    sweep_nm_per_s: 0.0,
                },
                0.02,
            );
        }
        for a in [-2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0] {
            push(
                ObservationKind::FringeAmplitude {
                    at_display: [0.0, 0.0, 0.0, a, 0.0, 0.0],
                    amplitude_mw: 0.0,
                    group: 0,
                    neighbours: None,
                },
                1e-6,
            );
            push(
                ObservationKind::FringeAmplitude {
                    at_display: [0.0, 0.0, 0.0, 0.0, a, 0.0],
                    amplitude_mw: 0.0,
                    group: 0,
                    neighbours: None,
                },
                1e-6,
            );
        }
        out
    }

    #[test]
    fn recovers_the_truth_from_exact_observations() {
        let truth = Extrinsics::table2();
        let obs = synthetic(&truth);
        let start = Extrinsics::from_array({
            let a = truth.to_array();
            std::array::from_fn(|i| if i < 4 { a[i] * 0.5 } else { a[i] + 8.0 })
        });
        let est = estimate(&model(), &obs, &start, &JointOptions::default());
        assert!(est.converged, "{}", est.termination);
        let (got, want) = (est.extrinsics.to_array(), truth.to_array());
        for i in [0, 1, 2, 3, 5, 7] {
            assert!((got[i] - want[i]).abs() < 1e-4, "{}: {} vs {}", PARAMETER_NAMES[i].0, got[i], want[i]);
        }
        // The gap (y_wf − Z_et) is fixed by the absolute gaps.
        assert!(((got[6] - got[4]) - (want[6] - want[4])).abs() < 1e-3);
        assert!((est.gains[0] - 2.0).abs() < 1e-6);
    }

    #[test]
    fn masked_parameters_stay_and_priors_pull() {
        let truth = Extrinsics::table2();
        let obs = synthetic(&truth);
        let mut options = JointOptions::default();
        options.free[4] = false; // Z_et fixed at the start value
        options.priors[6] = Some(Prior { value: 905.0, sigma: 1e-6 }); // y_wf pinned by a tight prior
        let est = estimate(&model(), &obs, &truth, &options);
        assert_eq!(est.extrinsics.z_et_um, truth.z_et_um);
        assert!((est.extrinsics.y_wf_um - 905.0).abs() < 1e-3, "y_wf {}", est.extrinsics.y_wf_um);
        assert!(!est.column_names.contains(&"Z_et".to_string()));
    }

    #[test]
    fn a_failure_is_not_called_a_success() {
        let truth = Extrinsics::table2();
        let obs = synthetic(&truth);
        let options = JointOptions { patience: 1, ..Default::default() };
        let mut start = truth;
        start.beta_et_deg = 3.0;
        let est = estimate(&model(), &obs, &start, &options);
        assert!(!est.converged, "one evaluation cannot converge from 3° away: {}", est.termination);
    }

    /// Monte Carlo over 200 seeds: the σ the identifiability report gives each determined
    /// parameter matches the scatter of the estimates within 20 % (observations predicted from
    /// the truth plus Gaussian noise of their stated σ).
    #[test]
    fn reported_sigma_matches_the_monte_carlo_scatter() {
        use rand::{rngs::StdRng, SeedableRng};
        use rand_distr::{Distribution, StandardNormal};
        let truth = Extrinsics::table2();
        let exact = synthetic(&truth);
        let m = model();
        let seeds = 200;
        let mut values: Vec<[f64; N_EXTRINSICS]> = Vec::new();
        let mut sigmas: Vec<[Option<f64>; N_EXTRINSICS]> = Vec::new();
        for seed in 0..seeds {
            let mut rng = StdRng::seed_from_u64(seed);
            let noisy: Vec<Observation> = exact
                .iter()
                .map(|o| {
                    let mut o = o.clone();
                    let n: f64 = StandardNormal.sample(&mut rng);
                    let d = n * o.sigma;
                    match &mut o.kind {
                        ObservationKind::GapChange { dl_nm, .. } => *dl_nm += d,
                        ObservationKind::AbsoluteGap { gap_um, .. } => *gap_um += d,
                        ObservationKind::FringeAmplitude { amplitude_mw, .. } => *amplitude_mw += d,
                    }
                    o
                })
                .collect();
            let est = estimate(&m, &noisy, &truth, &JointOptions::default());
            assert!(est.converged, "seed {seed}: {}", est.termination);
            let report = analyse_estimate(&est);
            values.push(est.extrinsics.to_array());
            sigmas.push(std::array::from_fn(|i| {
                report
                    .parameters
                    .iter()
                    .find(|p| p.name == PARAMETER_NAMES[i].0)
                    .filter(|p| p.determined)
                    .and_then(|p| p.sigma)
            }));
        }
        let mut checked = 0;
        for i in 0..N_EXTRINSICS {
            if sigmas.iter().any(|s| s[i].is_none()) {
                continue;
            }
            let mean = values.iter().map(|v| v[i]).sum::<f64>() / seeds as f64;
            let scatter = (values.iter().map(|v| (v[i] - mean).powi(2)).sum::<f64>() / (seeds - 1) as f64).sqrt();
            let reported = (sigmas.iter().map(|s| s[i].unwrap().powi(2)).sum::<f64>() / seeds as f64).sqrt();
            eprintln!("{}: scatter {scatter:.3e}, reported σ {reported:.3e}", PARAMETER_NAMES[i].0);
            assert!(
                (reported / scatter - 1.0).abs() < 0.2,
                "{}: σ {reported} vs scatter {scatter}",
                PARAMETER_NAMES[i].0
            );
            checked += 1;
        }
        assert!(checked >= 6, "only {checked} parameters determined");
    }
}
