//! The smoother's starting point and priors: the phase correction at the knots, the noise
//! variance to weigh the samples with, and the random walks between knots.

use super::config::{EnvelopeSource, TrackConfig};
use super::envelope::{knot_value, Envelope, Knot, MAX_EXTRAP};
use super::grid::{Grid, PathView};
use super::harmonic::HarmonicProfile;
use super::hint_scale::ScaleFit;
use super::inputs::TrackScale;
use super::window::{anchor_phase, window_data};
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
