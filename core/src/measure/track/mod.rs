//! Sub-fringe phase tracking: turns a single-photodiode Fabry-Perot trace into the cavity-length
//! change dL (nm) with its uncertainty, guided by a motion hint.
//!
//! Signal model used here (a local model, independent of `model::optics`):
//! `I = A + B·f(φ) + noise`, `f(φ) = cos φ + 2nd and 3rd harmonics`, with the fringe phase
//! `φ = 4π·n_air·gap/λ - arctan(gap/z_R) + const`. A and B drift slowly with the motion.
//! The harmonics are estimated along the path, or, when the caller has a model of the fringe
//! ([`FringeModel`], e.g. `model::optics` along the recorded joints), taken from it per sample
//! with the envelope's shape: on rotations the multi-beam harmonics turn with the tilt phase
//! and the amplitude changes by up to 50 % per fringe, which only a model can follow.
//!
//! Conventions: lengths in nm (names carry units); the tracked phase increases when the
//! motion hint increases, so `dl_nm` is reported in the hint's sign convention.
//!
//! The stages of one tracking run, in order, each in its file: input checks and scales
//! (`inputs`), the grid pass over the hint (`grid`), the hint scale from the extrema
//! (`hint_scale`), the initial envelope (`envelope`), the harmonics from window fits
//! (`window`), the start phase and priors (`priors`), Gauss-Newton (`gauss_newton`, with the
//! per-sample `kernel` and the block `factor`), and the uncertainty and outputs (`output`).

mod config;
mod coordinates;
mod envelope;
mod factor;
mod gauss_newton;
mod grid;
mod harmonic;
mod hint_scale;
mod inputs;
mod kernel;
mod output;
mod priors;
mod result;
mod window;

#[cfg(test)]
mod reference;
#[cfg(test)]
mod tests;

pub use config::{EnvelopeSource, FringeModel, GouyCorrection, KnownEnvelope, TrackConfig};
pub use harmonic::Harmonic;
pub use result::PhaseTrack;

use envelope::{initial_envelope, Knot};
use factor::{Factor, Sym3};
use gauss_newton::{smooth, Convergence, Smoothing};
use grid::{grid_pass, motion_windows, Grid, GridRecord, PathView};
use hint_scale::hint_scale;
use inputs::{check_inputs, scan_intensity, TrackScale};
use kernel::{Decimated, NormalEq, State};
use output::{apply_gouy, phase_and_dl, reported_harmonic, total_phase_variance, OutputScale};
use priors::{initial_state, Start, StartFrom, StartWindow};
use window::fit_harmonics;

use crate::measure::extrema::{extrema_into_scaled, Extremum};
use crate::measure::signal::{check_optics, FringeError};
use nalgebra::Vector3;

/// Reusable buffers of the phase tracker: after the first trace of a given size, tracking
/// allocates nothing.
#[derive(Default)]
struct Workspace {
    grid: Grid,
    extrema: Vec<Extremum>,
    ext_hint: Vec<f64>,
    ext_path: Vec<f64>,
    ext_offset: Vec<f64>,
    env_r: Vec<f64>,
    env_ca: Vec<f64>,
    scratch: Vec<f64>,
    residuals: Vec<(usize, f64)>,
    points: Vec<(f64, f64, usize)>,
    upper: Vec<Knot>,
    lower: Vec<Knot>,
    resid_knots: Vec<Knot>,
    delta: Vec<f64>,
    offset: Vec<f64>,
    amplitude: Vec<f64>,
    x0: Vec<Vector3<f64>>,
    seg_prec: Vec<Vector3<f64>>,
    decimated: Decimated,
    data: NormalEq,
    diag: Vec<Sym3>,
    off: Vec<Sym3>,
    rhs: Vec<Vector3<f64>>,
    border: Vec<Vector3<f64>>,
    dx: Vec<Vector3<f64>>,
    z_border: Vec<Vector3<f64>>,
    e: Vec<Vector3<f64>>,
    ze: Vec<Vector3<f64>>,
    dvar: Vec<f64>,
    factor: Factor,
    seg_harm: Vec<Harmonic>,
}

/// A phase tracker that keeps its buffers between traces, for streaming many traces (or
/// long ones) without allocating. `track_phase` is the one-shot convenience wrapper.
pub struct PhaseTracker {
    wavelength_nm: f64,
    n_air: f64,
    cfg: TrackConfig,
    ws: Workspace,
    out: PhaseTrack,
}

impl PhaseTracker {
    /// A tracker for a vacuum wavelength (nm), an air index and settings.
    pub fn new(wavelength_nm: f64, n_air: f64, cfg: TrackConfig) -> Result<Self, FringeError> {
        check_optics(wavelength_nm, n_air)?;
        cfg.validate()?;
        Ok(Self { wavelength_nm, n_air, cfg, ws: Workspace::default(), out: PhaseTrack::default() })
    }

    /// Track one trace (see [`track_phase`]); the result stays valid until the next call.
    pub fn track(&mut self, intensity: &[f64], hint_dl_nm: &[f64]) -> Result<&PhaseTrack, FringeError> {
        run_tracker(
            &mut self.ws,
            &mut self.out,
            intensity,
            hint_dl_nm,
            None,
            self.wavelength_nm,
            self.n_air,
            &self.cfg,
        )?;
        Ok(&self.out)
    }

    /// Like [`PhaseTracker::track`], with the fringe's shape predicted per sample by a model
    /// ([`FringeModel`]) instead of estimated along the path. On rotations the multi-beam
    /// harmonics turn against the fundamental as fast as the fringes go by, which no harmonic
    /// profile along the path can follow, and the amplitude changes by up to 50 % per fringe,
    /// which the extrema cannot extrapolate over the trace's first and last partial fringe.
    pub fn track_shaped(
        &mut self,
        intensity: &[f64],
        hint_dl_nm: &[f64],
        model: &FringeModel,
    ) -> Result<&PhaseTrack, FringeError> {
        run_tracker(
            &mut self.ws,
            &mut self.out,
            intensity,
            hint_dl_nm,
            Some(model),
            self.wavelength_nm,
            self.n_air,
            &self.cfg,
        )?;
        Ok(&self.out)
    }

    /// The result of the last successful `track`.
    pub fn result(&self) -> &PhaseTrack {
        &self.out
    }

    /// Take the result of the last successful `track`.
    pub fn into_result(self) -> PhaseTrack {
        self.out
    }
}

/// Track the fringe phase sample by sample, guided by the motion hint.
///
/// `hint_dl_nm` is the predicted optical-path change from the robot model (one value per
/// sample; its rate sign must be right except very near turning points, its scale may be
/// off by a few %). Method:
/// 1. extrema with adaptive hysteresis, their direction from the hint (turning points of
///    the motion excluded), and a regression of their fringe order on the hint phase: the
///    hint scale and a coarse phase ψ₀ = intercept + g·κ·hint;
/// 2. initial envelope from the extremum levels along the motion path; second harmonic and
///    white noise from local least-squares fits over two-fringe windows;
/// 3. a smoother: the phase correction δ = φ - ψ₀ and the envelope A, B are piecewise
///    linear on a grid (one fringe of travel, or 4096 samples of time, per knot) with
///    random-walk priors on their deviation from the initial profiles, plus one global
///    hint-scale correction γ; all fitted to every sample by Gauss-Newton, each step a
///    bordered block-tridiagonal least-squares solve, O(n). Direction survives turning
///    points and pauses because ψ₀ follows the hint; where the intensity carries no phase
///    information (fringe extrema, pauses) the phase follows the hint and the priors
///    instead of an arccos; the envelope and γ are marginalised, so their uncertainty is
///    in `sigma_total_nm`. The noise variance is re-estimated from the residuals.
///
/// Errors: empty or non-finite input, mismatched lengths, no motion, and (with
/// `EnvelopeSource::FromData`) traces covering less than one fringe.
pub fn track_phase(
    intensity: &[f64],
    hint_dl_nm: &[f64],
    wavelength_nm: f64,
    n_air: f64,
    cfg: &TrackConfig,
) -> Result<PhaseTrack, FringeError> {
    check_optics(wavelength_nm, n_air)?;
    cfg.validate()?;
    let mut out = PhaseTrack::default();
    with_spare_workspace(|ws| run_tracker(ws, &mut out, intensity, hint_dl_nm, None, wavelength_nm, n_air, cfg))?;
    Ok(out)
}

/// [`track_phase`] with the fringe's harmonics known per sample ([`PhaseTracker::track_shaped`]).
pub fn track_phase_shaped(
    intensity: &[f64],
    hint_dl_nm: &[f64],
    model: &FringeModel,
    wavelength_nm: f64,
    n_air: f64,
    cfg: &TrackConfig,
) -> Result<PhaseTrack, FringeError> {
    check_optics(wavelength_nm, n_air)?;
    cfg.validate()?;
    let mut out = PhaseTrack::default();
    with_spare_workspace(|ws| {
        run_tracker(ws, &mut out, intensity, hint_dl_nm, Some(model), wavelength_nm, n_air, cfg)
    })?;
    Ok(out)
}

thread_local! {
    /// The one-shot functions' workspace, kept per thread between calls: a fresh one costs
    /// more than the tracking itself on long traces (the kernel zero-fills every new page,
    /// tens of MB for a 1 M-sample trace). It holds no result, only scratch buffers (about
    /// 20 bytes per sample and 600 per fringe of the longest trace tracked on the thread).
    static SPARE_WORKSPACE: std::cell::Cell<Option<Box<Workspace>>> = const { std::cell::Cell::new(None) };
}

/// Runs `f` with this thread's spare workspace (a new one if it is in use).
fn with_spare_workspace<R>(f: impl FnOnce(&mut Workspace) -> R) -> R {
    let mut ws = SPARE_WORKSPACE.take().unwrap_or_default();
    let r = f(&mut ws);
    SPARE_WORKSPACE.set(Some(ws));
    r
}

/// [`run_tracker_impl`], compiled for AVX2 and FMA when the CPU has them: the per-sample
/// passes outside the kernel vectorise four lanes wide. Same results either way (no
/// operation is fused unless written so).
#[allow(clippy::too_many_arguments)] // the tracker's inputs, all sample-aligned or settings
fn run_tracker(
    ws: &mut Workspace,
    out: &mut PhaseTrack,
    intensity: &[f64],
    hint_dl_nm: &[f64],
    model: Option<&FringeModel>,
    wavelength_nm: f64,
    n_air: f64,
    cfg: &TrackConfig,
) -> Result<(), FringeError> {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU features required by `run_tracker_avx2` were detected above.
            return unsafe { run_tracker_avx2(ws, out, intensity, hint_dl_nm, model, wavelength_nm, n_air, cfg) };
        }
    }
    run_tracker_impl(ws, out, intensity, hint_dl_nm, model, wavelength_nm, n_air, cfg)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
fn run_tracker_avx2(
    ws: &mut Workspace,
    out: &mut PhaseTrack,
    intensity: &[f64],
    hint_dl_nm: &[f64],
    model: Option<&FringeModel>,
    wavelength_nm: f64,
    n_air: f64,
    cfg: &TrackConfig,
) -> Result<(), FringeError> {
    run_tracker_impl(ws, out, intensity, hint_dl_nm, model, wavelength_nm, n_air, cfg)
}

/// The tracker: input checks, the grid pass, the hint scale, the initial envelope, the
/// harmonics, the start phase and priors, Gauss-Newton, the uncertainty and the outputs.
/// Every stage is inlined here, so that [`run_tracker_avx2`] compiles them all for AVX2/FMA.
/// On an error the workspace and output buffers are kept for the next trace.
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the tracker's inputs, all sample-aligned or settings
fn run_tracker_impl(
    ws: &mut Workspace,
    out: &mut PhaseTrack,
    intensity: &[f64],
    hint_dl_nm: &[f64],
    model: Option<&FringeModel>,
    wavelength_nm: f64,
    n_air: f64,
    cfg: &TrackConfig,
) -> Result<(), FringeError> {
    // The grid and the envelope's knots stay borrowed while later stages change the rest of
    // the workspace: they are out of it for the run.
    let mut grid = std::mem::take(&mut ws.grid);
    let mut levels = (std::mem::take(&mut ws.upper), std::mem::take(&mut ws.lower));
    let inputs = TrackInputs { intensity, hint_dl_nm, model, wavelength_nm, n_air, cfg };
    let result = run_stages(ws, &mut grid, (&mut levels.0, &mut levels.1), out, &inputs);
    (ws.grid, ws.upper, ws.lower) = (grid, levels.0, levels.1);
    result
}

/// The inputs of one tracking run.
struct TrackInputs<'a> {
    intensity: &'a [f64],
    hint_dl_nm: &'a [f64],
    model: Option<&'a FringeModel<'a>>,
    wavelength_nm: f64,
    n_air: f64,
    cfg: &'a TrackConfig,
}

/// The stages of [`run_tracker_impl`], with the grid and the envelope's extremum levels
/// (upper, lower) outside the workspace.
#[inline(always)]
fn run_stages(
    ws: &mut Workspace,
    grid: &mut Grid,
    levels: (&mut Vec<Knot>, &mut Vec<Knot>),
    out: &mut PhaseTrack,
    inputs: &TrackInputs,
) -> Result<(), FringeError> {
    let TrackInputs { intensity, hint_dl_nm, model, wavelength_nm, n_air, cfg } = *inputs;
    check_inputs(intensity, hint_dl_nm, model)?;
    let scale = TrackScale::new(hint_dl_nm, wavelength_nm, n_air, cfg);
    let (kappa, fringe_nm) = (scale.kappa, scale.fringe_nm);
    let mut warnings = std::mem::take(&mut out.warnings);
    warnings.clear();
    let shape = model.map(|m| m.harmonics);
    ws.decimated.reset(shape.is_some());
    let max_abs = scan_intensity(intensity, scale.decimation, &mut ws.decimated.y)?;

    // The extrema first (one pass over the intensity), then the grid pass. The grid
    // coordinate c = path/Δs + k/T is kept in the phase output buffer until the end.
    extrema_into_scaled(intensity, max_abs, &cfg.hysteresis, &mut ws.scratch, &mut ws.extrema);
    ws.ext_hint.clear();
    ws.ext_path.clear();
    let mut cgrid = std::mem::take(&mut out.phase_rad);
    cgrid.clear();
    let record = GridRecord {
        grid,
        extrema: &ws.extrema,
        ext_hint: &mut ws.ext_hint,
        ext_path: &mut ws.ext_path,
        decimated: &mut ws.decimated,
        cgrid: &mut cgrid,
    };
    let excursion = match grid_pass(record, hint_dl_nm, shape, &scale) {
        Ok(excursion) => excursion,
        Err(err) => {
            out.phase_rad = cgrid;
            return Err(err);
        }
    };
    let grid = &*grid;
    let path = PathView { c: &cgrid, ds: fringe_nm, refine: scale.refine };
    let n_knots = grid.knot_k.len();

    let (scale_fit, counted) = hint_scale(
        &mut ws.extrema,
        &ws.ext_hint,
        &mut ws.ext_offset,
        &mut ws.points,
        &mut ws.residuals,
        hint_dl_nm,
        model,
        &scale,
        &mut warnings,
    );
    let g0 = scale_fit.as_ref().map_or(1.0, |f| f.scale);
    let rad_per_hint_nm = g0 * kappa;

    let envelope = match initial_envelope(&cfg.envelope, &ws.extrema, &path, levels.0, levels.1) {
        Ok(envelope) => envelope,
        Err(err) => {
            out.phase_rad = cgrid;
            return Err(err);
        }
    };
    let (win_s, win_e, iref_s) = motion_windows(&path, 2.0 * fringe_nm);
    let (harm, harm_sigma, noise_ls) = fit_harmonics(
        cfg,
        shape.is_some(),
        &path,
        intensity,
        hint_dl_nm,
        &envelope,
        (win_s, win_e),
        rad_per_hint_nm,
        &scale,
        &mut ws.scratch,
        &mut warnings,
    );
    ws.seg_harm.clear();
    let mut cur = 0usize;
    ws.seg_harm.extend((0..n_knots - 1).map(|j| harm.at(0.5 * (grid.knot_s[j] + grid.knot_s[j + 1]), &mut cur)));

    let start = StartWindow {
        path: &path,
        intensity,
        hint_dl_nm,
        envelope: &envelope,
        harm: &harm,
        window: win_s,
        reference: iref_s,
    };
    let from = StartFrom { grid, cgrid: &cgrid, model, scale_fit: scale_fit.as_ref(), noise_ls, rad_per_hint_nm };
    let Start { mut state, knot_model, model_gain, b_typ, r_meas, priors } =
        initial_state(ws, &from, &start, cfg, &scale, &mut warnings);
    let smoothing = Smoothing { knot_model: &knot_model, model_gain, priors: &priors, b_typ, r_meas, excursion };
    let conv = smooth(ws, grid, &cgrid, &mut state, &smoothing, intensity, hint_dl_nm, model, &scale, cfg);
    let conv = match conv {
        Ok(conv) => conv,
        Err(err) => {
            out.phase_rad = cgrid;
            (ws.delta, ws.offset, ws.amplitude) = (state.delta, state.offset, state.amplitude);
            return Err(err);
        }
    };
    let fit = FitSummary { g0, harm_sigma, harmonic: reported_harmonic(shape, &harm), counted };
    let result = finish(ws, grid, out, cgrid, &state, &conv, &fit, hint_dl_nm, cfg, kappa, warnings);
    (ws.delta, ws.offset, ws.amplitude) = (state.delta, state.offset, state.amplitude);
    result
}

/// What the earlier stages hand to the outputs.
struct FitSummary {
    /// Hint scale from the extrema (1 when they could not give it).
    g0: f64,
    /// Standard uncertainty of one harmonic coefficient.
    harm_sigma: f64,
    /// The harmonic reported.
    harmonic: Harmonic,
    /// Extrema that counted.
    counted: usize,
}

/// Warnings about the fit, the uncertainty of the total and the per-sample outputs; the
/// grid-coordinate buffer `cgrid` becomes φ(t). An error when the result is not finite.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn finish(
    ws: &mut Workspace,
    grid: &Grid,
    out: &mut PhaseTrack,
    cgrid: Vec<f64>,
    state: &State,
    conv: &Convergence,
    fit: &FitSummary,
    hint_dl_nm: &[f64],
    cfg: &TrackConfig,
    kappa: f64,
    mut warnings: Vec<String>,
) -> Result<(), FringeError> {
    let n = hint_dl_nm.len();
    let (iterations, last_update, chi2, schur) = (conv.iterations, conv.last_update, conv.chi2, conv.schur);
    if !conv.converged {
        warnings
            .push(format!("phase fit not converged after {iterations} iterations (last update {last_update:.2e} rad)"));
    }
    if chi2 > 4.0 {
        warnings.push(format!(
            "residuals {:.1}× the noise: the two-beam model does not fit (cycle slip, \
             unmodelled distortion or wrong hint)",
            chi2.sqrt()
        ));
    }
    let e_gamma = state.rad_per_hint_nm * (hint_dl_nm[n - 1] - hint_dl_nm[0]);
    let var_total =
        total_phase_variance(cgrid[n - 1], &mut ws.factor, &ws.z_border, schur, e_gamma, &mut ws.e, &mut ws.ze);
    let inflate = chi2.max(1.0);
    let nm_per_rad = 1.0 / kappa;
    let sigma_fit_nm = (var_total.max(0.0) * inflate).sqrt() * nm_per_rad;
    // four coefficients of σ each, at both ends
    let sigma_harmonic_nm = 4.0 * fit.harm_sigma * nm_per_rad;

    ws.factor.delta_variances_into(&mut ws.dvar);
    let mut phase = cgrid;
    let mut dl = std::mem::take(&mut out.dl_nm);
    dl.clear();
    dl.reserve(n);
    let mut sigma = std::mem::take(&mut out.sigma_dl_nm);
    sigma.clear();
    if cfg.per_sample_sigma {
        sigma.reserve(n);
    }
    let scale = OutputScale { dvar: &ws.dvar, z_border: &ws.z_border, schur, inflate, kappa };
    let per_sample_sigma = cfg.per_sample_sigma.then_some(&mut sigma);
    phase_and_dl(state, grid, hint_dl_nm, &scale, &mut phase, &mut dl, per_sample_sigma);
    if let Some(g) = &cfg.gouy {
        apply_gouy(&mut dl, g, kappa);
    }
    let total = dl[n - 1];
    if !(total.is_finite() && sigma_fit_nm.is_finite()) {
        out.phase_rad = phase;
        out.dl_nm = dl;
        out.sigma_dl_nm = sigma;
        return Err(FringeError::FitDiverged("non-finite result"));
    }
    *out = PhaseTrack {
        phase_rad: phase,
        dl_nm: dl,
        sigma_dl_nm: sigma,
        total_dl_nm: total,
        sigma_total_nm: (sigma_fit_nm.powi(2) + sigma_harmonic_nm.powi(2)).sqrt(),
        sigma_fit_nm,
        sigma_harmonic_nm,
        hint_scale: fit.g0 * (1.0 + state.gamma),
        hint_scale_sigma: fit.g0 * (inflate / schur.max(f64::MIN_POSITIVE)).sqrt(),
        harmonic: fit.harmonic,
        noise_sigma: conv.r_meas.sqrt(),
        normalized_chi2: chi2,
        extrema_used: fit.counted,
        iterations,
        last_update_rad: last_update,
        warnings,
    };
    Ok(())
}
