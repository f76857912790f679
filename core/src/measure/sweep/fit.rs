//! The sweep's gap by nonlinear least squares of the two-beam model (levenberg-marquardt),
//! started by a variable-projection grid around the FFT seed.

use super::{
    check_n_air, fft_estimate, linear_at, validate, FringePhase, GapEstimate, GapMethod, Spectrum, SweepConfig,
    SweepError, SweepFit, GRID_SAMPLES, MIN_FRINGES,
};
use crate::measure::signal::sincos;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, MinimizationReport};
use nalgebra::{storage::Owned, Dyn, OMatrix, OVector, SMatrix, SVector, U6};
use std::f64::consts::{PI, TAU};

/// Residuals and (optionally) the Jacobian of the sweep model.
type Evaluation = (OVector<f64, Dyn>, Option<OMatrix<f64, Dyn, U6>>);

/// The LM problem: parameters (A, a1, a2, B, L, ψ0).
struct SweepProblem<'a> {
    sp: &'a Spectrum,
    k0: f64,
    half: f64,
    n_air: f64,
    w0: Option<f64>,
    p: SVector<f64, 6>,
}

impl SweepProblem<'_> {
    /// The residuals, or (`with_jac`) only the Jacobian: the solver asks for them apart.
    fn eval(&self, with_jac: bool) -> Evaluation {
        let n = self.sp.k.len();
        let [a, a1, a2, b, l, psi] = [self.p[0], self.p[1], self.p[2], self.p[3], self.p[4], self.p[5]];
        let theta = FringePhase::new(self.k0, self.half, l, self.n_air, self.w0);
        let mut r = OVector::<f64, Dyn>::zeros(if with_jac { 0 } else { n });
        let mut j = if with_jac { Some(OMatrix::<f64, Dyn, U6>::zeros(n)) } else { None };
        for (i, (&k, &y)) in self.sp.k.iter().zip(self.sp.y.iter()).enumerate() {
            let x = (k - self.k0) / self.half;
            let shape = 1.0 + a1 * x + a2 * x * x;
            match j.as_mut() {
                Some(j) => {
                    let (th, dth) = theta.phase_and_slope(k);
                    let (s, c) = sincos(th + psi);
                    j[(i, 0)] = shape;
                    j[(i, 1)] = a * x;
                    j[(i, 2)] = a * x * x;
                    j[(i, 3)] = c;
                    j[(i, 4)] = -b * s * dth;
                    j[(i, 5)] = -b * s;
                }
                None => r[i] = a * shape + b * sincos(theta.phase(k) + psi).1 - y,
            }
        }
        (r, j)
    }
}

impl LeastSquaresProblem<f64, Dyn, U6> for SweepProblem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, U6>;
    type ParameterStorage = Owned<f64, U6>;

    fn set_params(&mut self, x: &SVector<f64, 6>) {
        self.p.copy_from(x);
    }

    fn params(&self) -> SVector<f64, 6> {
        self.p
    }

    fn residuals(&self) -> Option<OVector<f64, Dyn>> {
        Some(self.eval(false).0)
    }

    fn jacobian(&self) -> Option<OMatrix<f64, Dyn, U6>> {
        self.eval(true).1
    }
}

/// Absolute gap by nonlinear least squares (levenberg-marquardt) of the two-beam model,
/// seeded by the FFT peak and a variable-projection grid over ±2.5 fringes (which removes
/// the leakage bias of the seed when there are few fringes). σ from the fit covariance
/// σ²·(JᵀJ)⁻¹ (pseudo-inverse) with σ² = RSS/(N - 6).
pub fn fit_gap(wavelength_nm: &[f64], irradiance: &[f64], cfg: &SweepConfig) -> Result<SweepFit, SweepError> {
    check_n_air(cfg.n_air)?;
    if let Some(w) = cfg.gouy_waist_nm {
        if !(w.is_finite() && w > 0.0) {
            return Err(SweepError::InvalidParameter {
                name: "gouy_waist_nm",
                value: w,
                reason: "must be finite and positive",
            });
        }
    }
    let sp = validate(wavelength_nm, irradiance)?;
    let n = sp.k.len();
    let n_air = cfg.n_air;
    let seed = fft_estimate(&sp, n_air)?;
    let span = sp.k[n - 1] - sp.k[0];
    let half = 0.5 * span;
    let k0 = 0.5 * (sp.k[0] + sp.k[n - 1]);
    let l_per_fringe = PI / (n_air * span);
    let l_start = grid_start(&sp, k0, half, seed.fringes_across_sweep, l_per_fringe, cfg);
    let (lin, _) = linear_at(&sp, k0, half, l_start, n_air, cfg.gouy_waist_nm);
    let a_start = lin[0];
    let (a1_start, a2_start) = if a_start != 0.0 { (lin[1] / a_start, lin[2] / a_start) } else { (0.0, 0.0) };
    let b_start = (lin[3] * lin[3] + lin[4] * lin[4]).sqrt();
    let psi_start = (-lin[4]).atan2(lin[3]);

    let problem = SweepProblem {
        sp: &sp,
        k0,
        half,
        n_air,
        w0: cfg.gouy_waist_nm,
        p: SVector::<f64, 6>::from([a_start, a1_start, a2_start, b_start, l_start, psi_start]),
    };
    // Converged at 1e-10 relative (0.1 pm at 900 µm) rather than the solver's 7e-15: the steps
    // below it cost half the evaluations and move the gap by femtometres.
    let (problem, report) = LevenbergMarquardt::new().with_xtol(1e-10).with_ftol(1e-10).minimize(problem);
    fit_outcome(&problem, &report, l_start, span, seed)
}

/// Where the fit starts: the gap of least RSS on a variable-projection grid in fringes across
/// the sweep, ±2.5 fringes around the FFT seed `f_seed`, refined by a parabola (nm).
fn grid_start(sp: &Spectrum, k0: f64, half: f64, f_seed: f64, l_per_fringe: f64, cfg: &SweepConfig) -> f64 {
    let n = sp.k.len();
    // The grid only places the start of the fit: every sample is not needed to find the RSS
    // minimum (a few thousand spread over tens of fringes), the fit uses them all.
    let stride = (n / GRID_SAMPLES).max(1);
    let coarse = Spectrum {
        k: sp.k.iter().step_by(stride).copied().collect(),
        y: sp.y.iter().step_by(stride).copied().collect(),
    };
    let rss = |f: f64| linear_at(&coarse, k0, half, f * l_per_fringe, cfg.n_air, cfg.gouy_waist_nm).1;
    // The RSS's main lobe is about a fringe wide: a tenth of a fringe finds it, a fiftieth
    // around the best tenth places its bottom.
    let f_lo = (f_seed - 2.5).max(0.3);
    let f_coarse = grid_minimum(f_lo, f_seed + 2.5, 0.1, &rss);
    let f_best = grid_minimum((f_coarse - 0.1).max(0.3), f_coarse + 0.1, 0.02, &rss);
    f_best * l_per_fringe
}

/// The minimum of `rss` on a grid of `step` over `lo..=hi`, refined by a parabola through the
/// best point and its neighbours.
fn grid_minimum(lo: f64, hi: f64, step: f64, rss: &impl Fn(f64) -> f64) -> f64 {
    let count = ((hi - lo) / step).ceil() as usize + 1;
    let values: Vec<f64> = (0..count).map(|i| rss(lo + step * i as f64)).collect();
    let (bi, _) =
        values.iter().copied().enumerate().fold(
            (0usize, f64::INFINITY),
            |(bi, bv), (i, v)| {
                if v < bv {
                    (i, v)
                } else {
                    (bi, bv)
                }
            },
        );
    let mut f = lo + step * bi as f64;
    if bi > 0 && bi + 1 < count {
        let (a, b, c) = (values[bi - 1], values[bi], values[bi + 1]);
        let den = a - 2.0 * b + c;
        if den > 0.0 {
            f += step * (0.5 * (a - c) / den).clamp(-0.5, 0.5);
        }
    }
    f
}

/// The fit's gap, its σ from the covariance and the fitted parameters; an error when the
/// optimiser failed, the fringes have no significant contrast or the sweep covers too few.
fn fit_outcome(
    problem: &SweepProblem,
    report: &MinimizationReport<f64>,
    l_start: f64,
    span: f64,
    seed: GapEstimate,
) -> Result<SweepFit, SweepError> {
    let (n, n_air, k0) = (problem.sp.k.len(), problem.n_air, problem.k0);
    if !report.termination.was_successful() {
        // the most useful diagnosis first: a sweep too short for this gap
        let fringes = 2.0 * n_air * problem.p[4].abs().max(l_start) * span / TAU;
        if fringes < MIN_FRINGES {
            return Err(SweepError::TooFewFringes { fringes, min: MIN_FRINGES });
        }
        return Err(SweepError::FitFailed(crate::solver::termination_words(&report.termination)));
    }
    let mut p = problem.p;
    if p.iter().any(|v| !v.is_finite()) {
        return Err(SweepError::FitFailed("non-finite parameters".to_string()));
    }
    let (r, j) = (problem.eval(false).0, problem.eval(true).1);
    let j = j.ok_or_else(|| SweepError::FitFailed("no Jacobian".to_string()))?;
    let rss = r.norm_squared();
    let dof = (n as f64 - 6.0).max(1.0);
    let s2 = rss / dof;
    let jtj: SMatrix<f64, 6, 6> = j.transpose() * &j;
    let cov = pseudo_inverse_sym(&jtj) * s2;
    if p[3] < 0.0 {
        p[3] = -p[3];
        p[5] += PI;
    }
    let l = p[4];
    let fringes = 2.0 * n_air * l * span / TAU;
    let sigma_b = cov[(3, 3)].max(0.0).sqrt();
    let significant = p[3] > 5.0 * sigma_b; // false for NaN too
    if !significant {
        return Err(SweepError::NoFringeContrast { amplitude: p[3], sigma: sigma_b });
    }
    if fringes < MIN_FRINGES {
        return Err(SweepError::TooFewFringes { fringes, min: MIN_FRINGES });
    }
    Ok(SweepFit {
        estimate: GapEstimate {
            method: GapMethod::ModelFit,
            gap_um: l * 1e-3,
            sigma_um: cov[(4, 4)].max(0.0).sqrt() * 1e-3,
            fringes_across_sweep: fringes,
            fit_rms: (rss / n as f64).sqrt(),
        },
        seed,
        offset: p[0],
        offset_slope: p[1],
        offset_curvature: p[2],
        amplitude: p[3],
        phase_rad: p[5].rem_euclid(TAU),
        center_wavenumber: k0,
        sigma_amplitude: sigma_b,
        evaluations: report.number_of_evaluations,
    })
}

/// Pseudo-inverse of a symmetric positive semi-definite matrix by eigen-decomposition
/// (stays defined when the Jacobian is rank-deficient).
fn pseudo_inverse_sym(m: &SMatrix<f64, 6, 6>) -> SMatrix<f64, 6, 6> {
    let eig = m.symmetric_eigen();
    let emax = eig.eigenvalues.iter().fold(0f64, |a, &e| a.max(e.abs()));
    let mut inv = SMatrix::<f64, 6, 6>::zeros();
    for i in 0..6 {
        let e = eig.eigenvalues[i];
        if e > emax * 1e-14 {
            let v = eig.eigenvectors.column(i);
            inv += v * v.transpose() / e;
        }
    }
    inv
}
