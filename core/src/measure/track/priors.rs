//! The smoother's starting point and priors: the phase correction at the knots, the noise
//! variance to weigh the samples with, and the random walks between knots.

use super::config::{EnvelopeSource, FringeModel, TrackConfig};
use super::coordinates::envelope_coordinate;
use super::envelope::{knot_value, model_envelope_at_knots, Envelope, Knot, MAX_EXTRAP};
use super::grid::{Grid, PathView};
use super::harmonic::HarmonicProfile;
use super::hint_scale::ScaleFit;
use super::inputs::TrackScale;
use super::kernel::State;
use super::window::{anchor_phase, window_data};
use super::Workspace;
use crate::measure::extrema::estimate_noise_sigma;
use nalgebra::Vector3;

/// Where the phase at the start of the motion is fitted when the extrema give no phase.
pub(super) struct StartWindow<'a> {
    /// The hint's path along the samples.
    pub(super) path: &'a PathView<'a>,
    /// The intensity samples.
    pub(super) intensity: &'a [f64],
    /// The motion hint, nm.
    pub(super) hint_dl_nm: &'a [f64],
    /// The initial envelope.
    pub(super) envelope: &'a Envelope<'a>,
    /// The harmonic profile.
    pub(super) harm: &'a HarmonicProfile,
    /// The start window (samples).
    pub(super) window: (usize, usize),
    /// The last sample before the motion.
    pub(super) reference: usize,
}

/// The phase correction δ at the knots (into `delta`) and the phase intercept at the first
/// hint sample: the extrema's regression residuals, smoothed (5-extremum moving average) and
/// interpolated along the path; or, without usable extrema, δ = 0 and the intercept from a
/// local fit of the phase at the start of the motion, which also gives a noise variance
/// (second value).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn start_phase(
    scale_fit: Option<&ScaleFit>,
    residuals: &[(usize, f64)],
    ext_path: &[f64],
    resid_knots: &mut Vec<Knot>,
    grid: &Grid,
    start: &StartWindow,
    kappa: f64,
    rad_per_hint_nm: f64,
    delta: &mut Vec<f64>,
) -> (f64, Option<f64>) {
    delta.clear();
    match scale_fit {
        Some(f) => {
            let m = residuals.len();
            resid_knots.clear();
            resid_knots.extend((0..m).map(|i| {
                let lo = i.saturating_sub(2);
                let hi = (i + 3).min(m);
                let avg = residuals[lo..hi].iter().map(|r| r.1).sum::<f64>() / (hi - lo) as f64;
                Knot { s: ext_path[residuals[i].0], level: avg }
            }));
            let mut cur = 0usize;
            let knots = &*resid_knots;
            delta.extend(grid.knot_s.iter().map(|&s| knot_value(knots, s, &mut cur, 0.0)));
            (f.intercept, None)
        }
        None => {
            let harm = start.harm;
            let d = window_data(
                start.path,
                start.intensity,
                start.hint_dl_nm,
                start.envelope,
                harm,
                MAX_EXTRAP,
                start.window,
                4096,
            );
            let (theta, rss, m) = anchor_phase(&d.y, &d.hint, &d.a, &d.b, &harm.at(0.0, &mut 0), kappa);
            delta.resize(grid.knot_k.len(), 0.0);
            (theta - rad_per_hint_nm * start.hint_dl_nm[start.reference], Some(rss / (m as f64 - 1.0).max(1.0)))
        }
    }
}

/// The weak absolute priors of every knot's (δ, A, B) and the prior σ of the relative
/// hint-scale correction γ; the random walks between knots are in the workspace's `seg_prec`.
pub(super) struct Priors {
    /// Precision of each knot's (δ, A, B) about its initial value.
    pub(super) abs_prec: Vector3<f64>,
    /// Prior standard deviation of γ.
    pub(super) sigma_gamma: f64,
}

/// Priors: random walk between knots (precision per segment, into `seg_prec`), weak
/// absolute priors, and the prior on γ (from the extrema's regression when it was usable).
/// `b`: the initial amplitude at the knots; `b_typ` its mean.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn priors(
    cfg: &TrackConfig,
    grid: &Grid,
    scale: &TrackScale,
    b: &[f64],
    b_typ: f64,
    scale_fit: Option<&ScaleFit>,
    seg_prec: &mut Vec<Vector3<f64>>,
) -> Priors {
    let (fringe_nm, refine) = (scale.fringe_nm, scale.refine);
    let n_knots = grid.knot_k.len();
    let (env_a0, env_b0, env_walk) = match cfg.envelope {
        EnvelopeSource::Known(k) => {
            (k.offset_sigma.max(1e-9 * k.amplitude), k.amplitude_sigma.max(1e-9 * k.amplitude), false)
        }
        EnvelopeSource::FromData => (0.1 * b_typ, 0.1 * b_typ, true),
    };
    seg_prec.clear();
    seg_prec.extend((0..n_knots - 1).map(|j| {
        let ds_fr = (grid.knot_s[j + 1] - grid.knot_s[j]) / fringe_nm;
        let dk = grid.knot_k[j + 1] - grid.knot_k[j];
        let mut q_d = cfg.phase_walk_rad_per_sqrt_fringe.powi(2) * ds_fr
            + cfg.phase_noise_rad_per_sqrt_sample.powi(2) * dk
            + 1e-12;
        if (j as f64) < refine - 1.0 {
            // the samples, not the prior, say where the phase starts to follow the hint
            q_d = q_d.max(cfg.start_walk_rad * cfg.start_walk_rad);
        }
        let bj = 0.5 * (b[j] + b[j + 1]);
        let q_e = if env_walk {
            bj * bj
                * (cfg.envelope_walk_per_sqrt_fringe.powi(2) * ds_fr + cfg.envelope_noise_per_sqrt_sample.powi(2) * dk)
                + (1e-9 * bj).powi(2)
        } else {
            (1e-7 * bj).powi(2)
        };
        Vector3::new(1.0 / q_d, 1.0 / q_e, 1.0 / q_e)
    }));
    let abs_prec = Vector3::new(1e-2, 1.0 / (env_a0 * env_a0), 1.0 / (env_b0 * env_b0));
    let sigma_gamma = match scale_fit {
        Some(f) => (3.0 * f.sigma / f.scale).clamp(1e-4, cfg.scale_prior_sigma),
        None => cfg.scale_prior_sigma,
    };
    Priors { abs_prec, sigma_gamma }
}

/// What the initial state is built from besides the workspace and the start window.
pub(super) struct StartFrom<'a> {
    /// The knots.
    pub(super) grid: &'a Grid,
    /// The grid coordinate of every sample.
    pub(super) cgrid: &'a [f64],
    /// The fringe model, if any.
    pub(super) model: Option<&'a FringeModel<'a>>,
    /// The extrema's regression on the hint phase, when usable.
    pub(super) scale_fit: Option<&'a ScaleFit>,
    /// The noise variance of the harmonic window fits, if any.
    pub(super) noise_ls: Option<f64>,
    /// The hint's phase per nm, g·κ.
    pub(super) rad_per_hint_nm: f64,
}

/// The initial state on the grid and what the smoother needs with it.
pub(super) struct Start {
    /// Phase correction, envelope and hint scale at the start.
    pub(super) state: State,
    /// A fringe model's (offset, amplitude) at the knots (empty when not used).
    pub(super) knot_model: Vec<(f64, f64)>,
    /// The detector gain fitted to the fringe model's envelope.
    pub(super) model_gain: Option<f64>,
    /// Mean initial amplitude B over the knots.
    pub(super) b_typ: f64,
    /// Initial noise variance.
    pub(super) r_meas: f64,
    /// The priors.
    pub(super) priors: Priors,
}

/// The initial state on the grid: the envelope at the knots (the initial envelope, or a
/// fringe model's scaled to the extrema), the start phase, the noise variance to start
/// with, the prior means (`ws.x0`) and the priors. The state's buffers come from the
/// workspace.
#[inline(always)]
pub(super) fn initial_state(
    ws: &mut Workspace,
    from: &StartFrom,
    start: &StartWindow,
    cfg: &TrackConfig,
    scale: &TrackScale,
    warnings: &mut Vec<String>,
) -> Start {
    let (grid, rad_per_hint_nm) = (from.grid, from.rad_per_hint_nm);
    let n_knots = grid.knot_k.len();
    let mut state = State {
        intercept: 0.0,
        rad_per_hint_nm,
        hint_ref: start.hint_dl_nm[0],
        gamma: 0.0,
        delta: std::mem::take(&mut ws.delta),
        offset: std::mem::take(&mut ws.offset),
        amplitude: std::mem::take(&mut ws.amplitude),
    };
    let knot_c: Vec<f64> =
        grid.knot_s.iter().zip(&grid.knot_k).map(|(&s, &k)| envelope_coordinate(s, k, scale.fringe_nm)).collect();
    start.envelope.eval_into(&knot_c, &grid.knot_s, start.harm, MAX_EXTRAP, &mut state.offset, &mut state.amplitude);
    let (knot_model, model_gain) = model_envelope_at_knots(
        from.model,
        &cfg.envelope,
        grid,
        from.cgrid,
        &ws.extrema,
        &mut state.offset,
        &mut state.amplitude,
        warnings,
    );
    let b_typ = state.amplitude.iter().sum::<f64>() / n_knots as f64;
    let (intercept, r_anchor) = start_phase(
        from.scale_fit,
        &ws.residuals,
        &ws.ext_path,
        &mut ws.resid_knots,
        grid,
        start,
        scale.kappa,
        rad_per_hint_nm,
        &mut state.delta,
    );
    state.intercept = intercept + rad_per_hint_nm * state.hint_ref;
    let r_meas = from
        .noise_ls
        .or(r_anchor)
        .unwrap_or_else(|| estimate_noise_sigma(start.intensity, &mut ws.scratch).powi(2))
        .max((super::config::NOISE_FLOOR_REL * b_typ).powi(2));
    ws.x0.clear();
    ws.x0.extend((0..n_knots).map(|j| Vector3::new(state.delta[j], state.offset[j], state.amplitude[j])));
    let priors = priors(cfg, grid, scale, &state.amplitude, b_typ, from.scale_fit, &mut ws.seg_prec);
    Start { state, knot_model, model_gain, b_typ, r_meas, priors }
}
