//! Gauss-Newton on the knot grid: each step a bordered block-tridiagonal least-squares
//! solve of the linearised model with its priors, and a noise variance re-estimated from the
//! predicted residuals.

use super::config::{FringeModel, TrackConfig};
use super::envelope::{fit_offset_gain, model_envelope_shape};
use super::factor::{add_diag, sym_to_mat, Factor, Sym3};
use super::grid::Grid;
use super::harmonic::Harmonic;
use super::inputs::TrackScale;
use super::kernel::{accumulate, Decimated, NormalEq, Samples, ShapeView, State};
use super::priors::Priors;
use super::Workspace;
use crate::measure::signal::FringeError;
use nalgebra::Vector3;

/// The buffers of one Gauss-Newton step: the data's normal equations, the weighted system
/// with its priors, its factor and its solution.
pub(super) struct System<'a> {
    /// Normal equations of the data alone (unweighted sums).
    pub(super) data: &'a mut NormalEq,
    /// Diagonal blocks of the weighted system.
    pub(super) diag: &'a mut [Sym3],
    /// Off-diagonal blocks of the weighted system.
    pub(super) off: &'a mut [Sym3],
    /// Right-hand side of the weighted system.
    pub(super) rhs: &'a mut [Vector3<f64>],
    /// Coupling of each knot's unknowns with γ, weighted.
    pub(super) border: &'a mut [Vector3<f64>],
    /// The step of each knot's (δ, A, B).
    pub(super) dx: &'a mut [Vector3<f64>],
    /// The system's inverse applied to the border.
    pub(super) z_border: &'a mut [Vector3<f64>],
    /// Block factor of the weighted system.
    pub(super) factor: &'a mut Factor,
}

impl<'a> System<'a> {
    /// The buffers sized for `n_knots` knots: the blocks and vectors zeroed, the normal
    /// equations and the factor resized.
    #[inline(always)]
    pub(super) fn sized(
        n_knots: usize,
        data: &'a mut NormalEq,
        [diag, off]: [&'a mut Vec<Sym3>; 2],
        [rhs, border, dx, z_border]: [&'a mut Vec<Vector3<f64>>; 4],
        factor: &'a mut Factor,
    ) -> Self {
        data.resize(n_knots);
        for v in [&mut *diag, &mut *off] {
            v.clear();
            v.resize(n_knots, [0.0; 6]);
        }
        for v in [&mut *rhs, &mut *border, &mut *dx, &mut *z_border] {
            v.clear();
            v.resize(n_knots, Vector3::zeros());
        }
        factor.resize(n_knots);
        Self {
            data,
            diag: diag.as_mut_slice(),
            off: off.as_mut_slice(),
            rhs: rhs.as_mut_slice(),
            border: border.as_mut_slice(),
            dx: dx.as_mut_slice(),
            z_border: z_border.as_mut_slice(),
            factor,
        }
    }
}

/// The prior means and priors the steps are pulled towards.
pub(super) struct PriorMeans<'a> {
    /// Initial (δ, A, B) per knot: the prior means.
    pub(super) x0: &'a mut [Vector3<f64>],
    /// Precision of the random walk of each segment.
    pub(super) seg_prec: &'a [Vector3<f64>],
    /// Absolute priors and the prior on γ.
    pub(super) priors: &'a Priors,
    /// The fringe model's (offset, amplitude) at the knots (empty when not used).
    pub(super) knot_model: &'a [(f64, f64)],
}

/// How the iteration ended.
pub(super) struct Convergence {
    /// Iterations run.
    pub(super) iterations: usize,
    /// Largest phase update of the last iteration, rad.
    pub(super) last_update: f64,
    /// Noise variance re-estimated from the residuals over the one weighing them.
    pub(super) chi2: f64,
    /// Whether the iteration converged.
    pub(super) converged: bool,
    /// Noise variance the last step weighed the samples with.
    pub(super) r_meas: f64,
    /// Schur complement of γ in the last system.
    pub(super) schur: f64,
}

/// Numbers the iteration needs besides buffers.
pub(super) struct IterationScale {
    /// Decimation of the first iterations.
    pub(super) decimation: usize,
    /// Initial noise variance.
    pub(super) r_meas: f64,
    /// Floor of the noise variance.
    pub(super) r_floor: f64,
    /// Largest phase lever of γ over the trace, rad.
    pub(super) u_max: f64,
    /// Typical amplitude B (the floor of B is 1e-3 of it).
    pub(super) b_typ: f64,
}

/// Gauss-Newton. Long traces converge (phase, envelope and noise variance) on every
/// `decimation`-th sample, then one full-resolution step gives the final estimate and its
/// covariance. The noise variance is re-estimated at convergence and the iteration continues
/// until it is stable.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn gauss_newton(
    state: &mut State,
    samples: &Samples,
    decimated: &Decimated,
    seg_harm: &[Harmonic],
    system: &mut System,
    prior: &mut PriorMeans,
    cfg: &TrackConfig,
    it: &IterationScale,
) -> Result<Convergence, FringeError> {
    let sigma_gamma = prior.priors.sigma_gamma;
    let mut stride = it.decimation;
    let mut conv = Convergence {
        iterations: 0,
        last_update: f64::INFINITY,
        chi2: 1.0,
        converged: false,
        r_meas: it.r_meas,
        schur: f64::NAN,
    };
    let mut model_refit = false;
    for _ in 0..cfg.max_iterations {
        conv.iterations += 1;
        if stride > 1 {
            accumulate(&decimated.samples(), state, seg_harm, system.data);
        } else {
            accumulate(samples, state, seg_harm, system.data);
        }
        let (s_gg, r_g) = weighted_system(system, state, prior, stride as f64 / conv.r_meas);
        if !system.factor.factor(system.diag, system.off) {
            return Err(FringeError::InvalidParameter {
                name: "trace",
                value: f64::NAN,
                reason: "the least-squares system is singular",
            });
        }
        let (dgamma, sch) = system.factor.solve_bordered(
            system.rhs,
            system.border,
            s_gg,
            r_g,
            1.0 / (sigma_gamma * sigma_gamma),
            system.dx,
            system.z_border,
        );
        conv.schur = sch;
        if !(dgamma.is_finite() && sch > 0.0 && system.dx.iter().all(|d| d.iter().all(|v| v.is_finite()))) {
            return Err(FringeError::FitDiverged("non-finite Gauss-Newton step"));
        }
        let data = &*system.data;
        let n_knots = state.delta.len();
        let rss_post = predicted_rss(data, system.dx, dgamma);
        let dof = (data.count as f64 - 3.0 * n_knots as f64).max(0.5 * data.count as f64);
        let r_new = (rss_post / dof).max(it.r_floor);
        let r_change = (r_new / conv.r_meas - 1.0).abs();
        conv.chi2 = r_new / conv.r_meas;

        let maxd = apply_step(state, system.dx, dgamma, it.u_max, it.b_typ);
        conv.last_update = maxd;
        let settled = if stride > 1 { maxd < 5e-3 && r_change < 0.1 } else { maxd < 1e-3 && r_change < 0.1 };
        if settled && !model_refit && !prior.knot_model.is_empty() {
            model_refit = true;
            if refit_model_envelope(prior, state) {
                conv.r_meas = r_new;
                continue;
            }
        }
        if stride > 1 {
            // 5 mrad = 0.6 nm: the full-resolution step that follows refines the rest
            conv.r_meas = r_new;
            if settled {
                stride = 1;
            }
            continue;
        }
        let done = if it.decimation > 1 {
            // final full-resolution step after decimated convergence
            maxd < 0.02 && r_change < 0.2
        } else {
            maxd < 1e-3 && r_change < 0.1
        };
        if done {
            conv.converged = true;
            break;
        }
        conv.r_meas = r_new;
    }
    Ok(conv)
}

/// The data's normal equations weighted by `weight` (samples per sum over the noise
/// variance) plus the priors, into the system; returns the γγ element and γ's right-hand side.
#[inline(always)]
fn weighted_system(system: &mut System, state: &State, prior: &PriorMeans, weight: f64) -> (f64, f64) {
    let System { data, diag, off, rhs, border, .. } = system;
    let (x0, seg_prec, abs_prec) = (&*prior.x0, prior.seg_prec, &prior.priors.abs_prec);
    let sigma_gamma = prior.priors.sigma_gamma;
    let n_knots = state.delta.len();
    let w = weight;
    for j in 0..n_knots {
        diag[j] = data.diag[j].map(|v| v * w);
        off[j] = data.off[j].map(|v| v * w);
        rhs[j] = data.rhs[j] * w;
        border[j] = data.border[j] * w;
    }
    let s_gg = data.s_gg * w + 1.0 / (sigma_gamma * sigma_gamma);
    let r_g = data.r_g * w - state.gamma / (sigma_gamma * sigma_gamma);
    for j in 0..n_knots {
        let xj = Vector3::new(state.delta[j], state.offset[j], state.amplitude[j]);
        add_diag(&mut diag[j], abs_prec, 1.0);
        rhs[j] -= abs_prec.component_mul(&(xj - x0[j]));
        if j + 1 < n_knots {
            let p = seg_prec[j];
            // random walk of the deviation from the initial profile (which already
            // follows the drift seen by the extrema)
            let d = Vector3::new(state.delta[j + 1], state.offset[j + 1], state.amplitude[j + 1])
                - x0[j + 1]
                - (xj - x0[j]);
            let pd = p.component_mul(&d);
            add_diag(&mut diag[j], &p, 1.0);
            add_diag(&mut diag[j + 1], &p, 1.0);
            add_diag(&mut off[j], &p, -1.0);
            rhs[j] += pd;
            rhs[j + 1] -= pd;
        }
    }
    (s_gg, r_g)
}

/// Predicted data residual after the step (unscaled sums), floored at 0: it re-estimates the
/// noise variance.
#[inline(always)]
fn predicted_rss(data: &NormalEq, dx: &[Vector3<f64>], dgamma: f64) -> f64 {
    let n_knots = dx.len();
    let mut quad = data.s_gg * dgamma * dgamma;
    let mut lin = data.r_g * dgamma;
    for j in 0..n_knots {
        quad += (dx[j].transpose() * sym_to_mat(&data.diag[j]) * dx[j])[0] + 2.0 * dgamma * data.border[j].dot(&dx[j]);
        if j + 1 < n_knots {
            quad += 2.0 * (dx[j].transpose() * sym_to_mat(&data.off[j]) * dx[j + 1])[0];
        }
        lin += data.rhs[j].dot(&dx[j]);
    }
    (data.nu2 - 2.0 * lin + quad).max(0.0)
}

/// Apply a step, each phase update clamped to ±0.5 rad, γ's to ±0.05 and B kept above
/// 1e-3 of `b_typ`; returns the largest phase update (γ's through its lever `u_max`).
#[inline(always)]
fn apply_step(state: &mut State, dx: &[Vector3<f64>], dgamma: f64, u_max: f64, b_typ: f64) -> f64 {
    let dgamma = dgamma.clamp(-0.05, 0.05);
    state.gamma += dgamma;
    let mut maxd = (dgamma * u_max).abs().min(0.5);
    for (j, d) in dx.iter().enumerate() {
        let dd = d[0].clamp(-0.5, 0.5);
        maxd = maxd.max(dd.abs());
        state.delta[j] += dd;
        state.offset[j] += d[1];
        state.amplitude[j] = (state.amplitude[j] + d[2]).max(1e-3 * b_typ);
    }
    maxd
}

/// The extrema set the model envelope's offset and gain with a bias (on rotations the
/// sampled extremum of A + B·f is not at f's extremum); the converged envelope sets them
/// without: move the prior mean there (true) so that the iteration goes on. Where the data
/// cannot fix the envelope (the trace's last partial fringe, where the phase error near an
/// extremum goes as the square root of the envelope error), the model's shape with these o
/// and g does.
#[inline(always)]
fn refit_model_envelope(prior: &mut PriorMeans, state: &State) -> bool {
    let knot_model = prior.knot_model;
    let n_knots = state.delta.len();
    let pts: Vec<(f64, f64, f64)> = (0..n_knots - 1)
        .flat_map(|j| [(1.0, knot_model[j].0, state.offset[j]), (0.0, knot_model[j].1, state.amplitude[j])])
        .collect();
    if let Some((o, g)) = fit_offset_gain(&pts) {
        for (x, &(p0, p1)) in prior.x0.iter_mut().zip(knot_model) {
            x[1] = o + g * p0;
            x[2] = g * p1;
        }
        return true;
    }
    false
}

/// What the smoother starts from besides the state.
pub(super) struct Smoothing<'a> {
    /// A fringe model's (offset, amplitude) at the knots (empty when not used).
    pub(super) knot_model: &'a [(f64, f64)],
    /// The detector gain fitted to the fringe model's envelope.
    pub(super) model_gain: Option<f64>,
    /// The priors.
    pub(super) priors: &'a Priors,
    /// Mean initial amplitude B over the knots.
    pub(super) b_typ: f64,
    /// Initial noise variance.
    pub(super) r_meas: f64,
    /// The hint's largest excursion from its first sample, nm.
    pub(super) excursion: f64,
}

/// The smoother: the samples (full and decimated) with a fringe model's envelope shape, the
/// system's buffers, then [`gauss_newton`].
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn smooth(
    ws: &mut Workspace,
    grid: &Grid,
    cgrid: &[f64],
    state: &mut State,
    from: &Smoothing,
    intensity: &[f64],
    hint_dl_nm: &[f64],
    model: Option<&FringeModel>,
    scale: &TrackScale,
    cfg: &TrackConfig,
) -> Result<Convergence, FringeError> {
    let n_knots = grid.knot_k.len();
    let shape = model.map(|m| m.harmonics);
    model_envelope_shape(model, from.model_gain, from.knot_model, grid, cgrid, &mut ws.env_r, &mut ws.env_ca);
    let dec = scale.decimation;
    if dec > 1 && model.is_some() {
        ws.decimated.r.extend(ws.env_r.iter().step_by(dec));
        ws.decimated.ca.extend(ws.env_ca.iter().step_by(dec));
    }
    if dec > 1 {
        ws.decimated.seg_first.extend(grid.seg_first.iter().map(|&k| k.div_ceil(dec)));
    }
    let shape_view = shape.map(|harm| ShapeView { harm, r: &ws.env_r, ca: &ws.env_ca });
    let samples = Samples { y: intensity, hint: hint_dl_nm, c: cgrid, seg_first: &grid.seg_first, shape: shape_view };
    let mut system = System::sized(
        n_knots,
        &mut ws.data,
        [&mut ws.diag, &mut ws.off],
        [&mut ws.rhs, &mut ws.border, &mut ws.dx, &mut ws.z_border],
        &mut ws.factor,
    );
    let mut prior =
        PriorMeans { x0: &mut ws.x0, seg_prec: &ws.seg_prec, priors: from.priors, knot_model: from.knot_model };
    let iteration = IterationScale {
        decimation: dec,
        r_meas: from.r_meas,
        r_floor: (super::config::NOISE_FLOOR_REL * from.b_typ).powi(2),
        u_max: from.excursion * state.rad_per_hint_nm, // largest phase lever of γ over the trace
        b_typ: from.b_typ,
    };
    gauss_newton(state, &samples, &ws.decimated, &ws.seg_harm, &mut system, &mut prior, cfg, &iteration)
}
