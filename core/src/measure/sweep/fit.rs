//! The sweep's gap by nonlinear least squares of the two-beam model (levenberg-marquardt),
//! started by a variable-projection grid around the FFT seed.

use super::{
    check_n_air, fft_estimate, linear_at, validate, FringePhase, GapEstimate, GapMethod, Spectrum, SweepConfig,
    SweepError, SweepFit, GRID_SAMPLES, MIN_FRINGES,
};
use crate::measure::signal::sincos;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, MinimizationReport};
use nalgebra::{storage::Owned, Dyn, OMatrix, OVector, SMatrix, SVector, U6};
use std::cell::RefCell;
use std::f64::consts::{PI, TAU};

/// The model's derivatives at every sample, one row each.
type Jacobian = OMatrix<f64, Dyn, U6>;

/// The LM problem: parameters (A, a1, a2, B, L, ψ0).
struct SweepProblem<'a> {
    sp: &'a Spectrum,
    k0: f64,
    half: f64,
    n_air: f64,
    w0: Option<f64>,
    p: SVector<f64, 6>,
    /// The Jacobian computed beside the last residuals, with the parameters it is at: the
    /// solver asks for the Jacobian right after the residuals of a step it accepts.
    jacobian_at: RefCell<Option<(SVector<f64, 6>, Jacobian)>>,
}

impl SweepProblem<'_> {
    /// Calls `row(i, residual, ∂r/∂p)` for every sample, one sine-cosine each.
    #[inline]
    fn for_each_row(&self, mut row: impl FnMut(usize, f64, [f64; 6])) {
        let [a, a1, a2, b, l, psi] = [self.p[0], self.p[1], self.p[2], self.p[3], self.p[4], self.p[5]];
        let theta = FringePhase::new(self.k0, self.half, l, self.n_air, self.w0);
        for (i, (&k, &y)) in self.sp.k.iter().zip(self.sp.y.iter()).enumerate() {
            let x = (k - self.k0) / self.half;
            let shape = 1.0 + a1 * x + a2 * x * x;
            let (th, dth) = theta.phase_and_slope(k);
            let (s, c) = sincos(th + psi);
            row(i, a * shape + b * c - y, [shape, a * x, a * x * x, c, -b * s * dth, -b * s]);
        }
    }

    /// The residuals and the Jacobian.
    fn evaluate(&self) -> (OVector<f64, Dyn>, Jacobian) {
        let n = self.sp.k.len();
        let mut r = OVector::<f64, Dyn>::zeros(n);
        let mut j = Jacobian::zeros(n);
        self.for_each_row(|i, ri, ji| {
            r[i] = ri;
            for (c, v) in ji.into_iter().enumerate() {
                j[(i, c)] = v;
            }
        });
        (r, j)
    }

    /// The residual sum of squares and JᵀJ, without holding the Jacobian.
    fn normal_matrix(&self) -> (f64, SMatrix<f64, 6, 6>) {
        let (mut rss, mut jtj) = (0.0, [[0.0; 6]; 6]);
        self.for_each_row(|_, ri, ji| {
            rss += ri * ri;
            for (r, row) in jtj.iter_mut().enumerate() {
                for (c, v) in row.iter_mut().enumerate().take(r + 1) {
                    *v += ji[r] * ji[c];
                }
            }
        });
        (rss, SMatrix::<f64, 6, 6>::from_fn(|r, c| if c <= r { jtj[r][c] } else { jtj[c][r] }))
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
        let (r, j) = self.evaluate();
        *self.jacobian_at.borrow_mut() = Some((self.p, j));
        Some(r)
    }

    fn jacobian(&self) -> Option<Jacobian> {
        match self.jacobian_at.borrow_mut().take() {
            Some((p, j)) if p == self.p => Some(j),
            _ => Some(self.evaluate().1),
        }
    }
}

/// Absolute gap by nonlinear least squares (levenberg-marquardt) of the two-beam model,
/// seeded by the FFT peak and a variable-projection grid over ±2.5 fringes (which removes
/// the leakage bias of the seed when there are few fringes), on the samples averaged in blocks
/// of at most 0.01 rad of fringe phase. σ from the covariance of every sample,
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
    fit_spectrum(&validate(wavelength_nm, irradiance)?, cfg, MAX_BLOCK_PHASE_RAD)
}

/// [`fit_gap`] on a validated sweep, its samples averaged in blocks spanning at most
/// `max_block_phase_rad` of the fringes' phase.
pub(super) fn fit_spectrum(sp: &Spectrum, cfg: &SweepConfig, max_block_phase_rad: f64) -> Result<SweepFit, SweepError> {
    let n = sp.k.len();
    let n_air = cfg.n_air;
    let seed = fft_estimate(sp, n_air)?;
    let span = sp.k[n - 1] - sp.k[0];
    let half = 0.5 * span;
    let k0 = 0.5 * (sp.k[0] + sp.k[n - 1]);
    let l_per_fringe = PI / (n_air * span);
    // The start only has to be in the fit's basin: a few thousand samples spread over the
    // fringes place it.
    let coarse = sp.strided(GRID_SAMPLES);
    let l_start = grid_start(&coarse, k0, half, seed.fringes_across_sweep, l_per_fringe, cfg);
    let (lin, _) = linear_at(&coarse, k0, half, l_start, n_air, cfg.gouy_waist_nm);
    let a_start = lin[0];
    let (a1_start, a2_start) = if a_start != 0.0 { (lin[1] / a_start, lin[2] / a_start) } else { (0.0, 0.0) };
    let b_start = (lin[3] * lin[3] + lin[4] * lin[4]).sqrt();
    let psi_start = (-lin[4]).atan2(lin[3]);

    // The fit runs on block means short enough in phase that a block's mean is the model at its
    // mean wavenumber (a fringe's contrast falls by δ²/24, 4e-6 at 0.01 rad, and B absorbs it):
    // the gap of a fit to every sample within a few hundredths of its σ, at a twentieth of the
    // solver's cost on a dense sweep.
    let fringe_phase_per_sample = 2.0 * n_air * l_start * span / (n - 1) as f64;
    let block = ((max_block_phase_rad / fringe_phase_per_sample).floor() as usize).clamp(1, n / MIN_BLOCKS + 1);
    let binned = sp.binned(block);
    let problem = SweepProblem {
        sp: &binned,
        k0,
        half,
        n_air,
        w0: cfg.gouy_waist_nm,
        p: SVector::<f64, 6>::from([a_start, a1_start, a2_start, b_start, l_start, psi_start]),
        jacobian_at: RefCell::new(None),
    };
    // Converged at 1e-10 relative (0.1 pm at 900 µm) rather than the solver's 7e-15: the steps
    // below it cost half the evaluations and move the gap by femtometres.
    let (problem, report) = LevenbergMarquardt::new().with_xtol(1e-10).with_ftol(1e-10).minimize(problem);
    // The covariance and the residuals' rms from every sample.
    fit_outcome(&SweepProblem { sp, ..problem }, &report, l_start, span, seed)
}

/// The phase of the fringes across one block of the sweep the fit averages samples over, rad.
const MAX_BLOCK_PHASE_RAD: f64 = 0.01;
/// Fewest blocks a sweep is averaged into.
const MIN_BLOCKS: usize = 1024;

/// Where the fit starts: the gap of least RSS on a variable-projection grid in fringes across
/// the sweep, ±2.5 fringes around the FFT seed `f_seed`, refined by a parabola (nm), on the
/// thinned sweep `coarse`.
fn grid_start(coarse: &Spectrum, k0: f64, half: f64, f_seed: f64, l_per_fringe: f64, cfg: &SweepConfig) -> f64 {
    let rss = |f: f64| linear_at(coarse, k0, half, f * l_per_fringe, cfg.n_air, cfg.gouy_waist_nm).1;
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
    let (rss, jtj) = problem.normal_matrix();
    let dof = (n as f64 - 6.0).max(1.0);
    let s2 = rss / dof;
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
/// (stays defined when the Jacobian is rank-deficient), on the matrix scaled to unit diagonal:
/// the parameters' units differ by orders of magnitude (the gap's column is the amplitude times
/// 2nk, 10⁻⁵ at a tilted pose's contrast, against 1 for the offset), and a threshold on the
/// unscaled eigenvalues dropped the gap's direction once decorrelated from the phase, which
/// made its σ zero.
fn pseudo_inverse_sym(m: &SMatrix<f64, 6, 6>) -> SMatrix<f64, 6, 6> {
    let d = SVector::<f64, 6>::from_fn(|i, _| {
        let v = m[(i, i)];
        if v > 0.0 && v.is_finite() {
            1.0 / v.sqrt()
        } else {
            0.0
        }
    });
    let scaled = SMatrix::<f64, 6, 6>::from_fn(|r, c| m[(r, c)] * d[r] * d[c]);
    let eig = scaled.symmetric_eigen();
    let emax = eig.eigenvalues.iter().fold(0f64, |a, &e| a.max(e.abs()));
    let mut inv = SMatrix::<f64, 6, 6>::zeros();
    for i in 0..6 {
        let e = eig.eigenvalues[i];
        if e > emax * 1e-14 {
            let v = eig.eigenvectors.column(i);
            inv += v * v.transpose() / e;
        }
    }
    SMatrix::<f64, 6, 6>::from_fn(|r, c| inv[(r, c)] * d[r] * d[c])
}
