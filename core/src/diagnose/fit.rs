//! The extended model and its fit: extrinsics + named effects + detector gains, predicted through
//! the same forward model as the identifier ([`crate::identify::predict_with_path`]) and fitted by
//! Gauss-Newton with a truncated-SVD step. Owns the state of the model under diagnosis.
//!
//! The truncated SVD keeps the step out of directions the data do not determine (the split of
//! the gap between y_wf and Z_et): such directions stay at their start values,
//! as in the identifier, instead of wandering.

use crate::diagnose::candidates::Candidate;
use crate::diagnose::projection::{Projector, RANK_TOLERANCE};
use crate::identify::{parameter_scale, predict_with_path, Observation, ObservationKind, N_EXTRINSICS};
use crate::model::effects::{apply_optics, Effect, EffectError};
use crate::model::extrinsics::{Extrinsics, PARAMETER_NAMES};
use crate::model::optics::FabryPerot;
use crate::model::phase::PhaseModel;
use nalgebra::{DMatrix, DVector};

/// The model under diagnosis: extrinsics, the effects added so far with their values (in the
/// candidate's unit), one detector gain per amplitude group.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelState {
    /// Extrinsics.
    pub extrinsics: Extrinsics,
    /// Added effects and their values.
    pub effects: Vec<(Candidate, f64)>,
    /// Detector gain per fringe-amplitude group.
    pub gains: Vec<f64>,
}

impl ModelState {
    /// The library effects of the state (values in their units).
    pub fn library_effects(&self) -> Vec<Effect> {
        self.effects.iter().map(|(c, v)| c.effect(*v)).collect()
    }
}

/// Forward predictions of a set of observations; one optics model per wavelength, built once.
#[derive(Debug, Clone)]
pub struct Predictor {
    base: PhaseModel,
    fps: Vec<(f64, FabryPerot)>,
    stop: StopCheck,
}

/// Asked before every prediction: once it answers true, predictions fail with
/// [`PredictError::Stopped`], so a fit, a scoring or a design in progress ends within one
/// evaluation instead of at the end of its workflow step.
#[derive(Clone, Default)]
pub struct StopCheck(Option<std::sync::Arc<dyn Fn() -> bool + Send + Sync>>);

impl StopCheck {
    /// A check that asks `stopped`.
    pub fn new(stopped: impl Fn() -> bool + Send + Sync + 'static) -> Self {
        StopCheck(Some(std::sync::Arc::new(stopped)))
    }

    /// Whether a stop was asked for.
    pub fn stopped(&self) -> bool {
        self.0.as_ref().is_some_and(|f| f())
    }
}

impl std::fmt::Debug for StopCheck {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.is_some() { "StopCheck(set)" } else { "StopCheck(none)" })
    }
}

/// Why a prediction could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PredictError {
    /// An effect could not be applied to the model.
    #[error(transparent)]
    Effect(#[from] EffectError),
    /// The [`StopCheck`] asked to stop.
    #[error("stopped")]
    Stopped,
}

/// Number of gain groups among the observations.
pub fn gain_groups(obs: &[Observation]) -> usize {
    obs.iter()
        .filter_map(|o| match o.kind {
            ObservationKind::FringeAmplitude { group, .. } => Some(group + 1),
            _ => None,
        })
        .max()
        .unwrap_or(0)
}

impl Predictor {
    /// A predictor on `base` (its robot must be nominal: effects are applied on top) for the
    /// wavelengths of `obs`.
    pub fn new(base: &PhaseModel, obs: &[Observation]) -> Result<Self, String> {
        let mut fps: Vec<(f64, FabryPerot)> = Vec::new();
        for o in obs {
            if !fps.iter().any(|(w, _)| *w == o.wavelength_nm) {
                let fp = FabryPerot::new(&base.optics, o.wavelength_nm, base.n_air)
                    .map_err(|e| format!("observation `{}`: optics at {} nm: {e}", o.label, o.wavelength_nm))?;
                fps.push((o.wavelength_nm, fp));
            }
        }
        Ok(Self { base: base.clone(), fps, stop: StopCheck::default() })
    }

    /// Ask `stop` before every prediction from now on.
    pub fn set_stop(&mut self, stop: StopCheck) {
        self.stop = stop;
    }

    /// Whether the [`StopCheck`] asks to stop.
    pub fn stopped(&self) -> bool {
        self.stop.stopped()
    }

    /// Add the wavelengths of more observations.
    pub fn extend(&mut self, obs: &[Observation]) -> Result<(), String> {
        let more = Self::new(&self.base, obs)?;
        for (w, fp) in more.fps {
            if !self.fps.iter().any(|(v, _)| *v == w) {
                self.fps.push((w, fp));
            }
        }
        Ok(())
    }

    /// The nominal model.
    pub fn base(&self) -> &PhaseModel {
        &self.base
    }

    /// Predictions of every observation with extrinsics `e` and `effects` (NaN where the beam misses).
    pub fn predict(
        &self,
        e: &Extrinsics,
        effects: &[Effect],
        gains: &[f64],
        obs: &[Observation],
    ) -> Result<Vec<f64>, PredictError> {
        if self.stopped() {
            return Err(PredictError::Stopped);
        }
        let model = crate::diagnose::validation::extended_model(&self.base, *e, effects)?;
        let path: Vec<Effect> = effects.iter().filter(|e| e.is_path()).cloned().collect();
        // Optical effects: the optics models rebuilt with them (cheap next to the predictions).
        let optical: Vec<(f64, FabryPerot)>;
        let fps = if effects.iter().any(Effect::is_optical) {
            let params = apply_optics(effects, &self.base.optics);
            optical = self
                .fps
                .iter()
                .map(|(w, _)| {
                    FabryPerot::new(&params, *w, self.base.n_air)
                        .map(|fp| (*w, fp))
                        .map_err(|e| EffectError::Optics(e.to_string()))
                })
                .collect::<Result<_, _>>()?;
            &optical
        } else {
            &self.fps
        };
        // Observations are independent (an amplitude's prediction costs a few hundred of a gap
        // change's): spread them over threads.
        use rayon::prelude::*;
        Ok(obs
            .par_iter()
            .with_min_len(16)
            .map(|o| {
                let gain = match o.kind {
                    ObservationKind::FringeAmplitude { group, .. } => gains.get(group).copied().unwrap_or(1.0),
                    _ => 1.0,
                };
                match fps.iter().find(|(w, _)| *w == o.wavelength_nm) {
                    Some((_, fp)) => predict_with_path(&model, fp, e, o, gain, &path),
                    None => f64::NAN,
                }
            })
            .collect())
    }

    /// Whitened residuals (measured − predicted)/σ of a state.
    pub fn whitened_residuals(&self, state: &ModelState, obs: &[Observation]) -> Result<DVector<f64>, PredictError> {
        let p = self.predict(&state.extrinsics, &state.library_effects(), &state.gains, obs)?;
        Ok(DVector::from_iterator(
            obs.len(),
            obs.iter().zip(&p).map(|(o, p)| if p.is_finite() { (o.value() - p) / o.sigma } else { 1e6 }),
        ))
    }
}

/// The parameter vector of a fit: the free extrinsics (mrad, µm), the effects (in steps), the gains.
#[derive(Debug, Clone)]
struct Layout {
    free: Vec<usize>,
    effects: usize,
    gains: usize,
}

impl Layout {
    fn len(&self) -> usize {
        self.free.len() + self.effects + self.gains
    }

    fn pack(&self, s: &ModelState) -> DVector<f64> {
        let a = s.extrinsics.to_array();
        let mut x = DVector::zeros(self.len());
        for (k, &i) in self.free.iter().enumerate() {
            x[k] = a[i] / parameter_scale(i);
        }
        for (k, (c, v)) in s.effects.iter().enumerate() {
            x[self.free.len() + k] = v / c.step;
        }
        for g in 0..self.gains {
            x[self.free.len() + self.effects + g] = s.gains[g];
        }
        x
    }

    fn unpack(&self, template: &ModelState, x: &DVector<f64>) -> ModelState {
        let mut s = template.clone();
        let mut a = s.extrinsics.to_array();
        for (k, &i) in self.free.iter().enumerate() {
            a[i] = x[k] * parameter_scale(i);
        }
        s.extrinsics = Extrinsics::from_array(a);
        for (k, (c, v)) in s.effects.iter_mut().enumerate() {
            *v = x[self.free.len() + k] * c.step;
        }
        for g in 0..self.gains {
            s.gains[g] = x[self.free.len() + self.effects + g];
        }
        s
    }

    fn names(&self, s: &ModelState) -> Vec<String> {
        let mut n: Vec<String> = self.free.iter().map(|&i| PARAMETER_NAMES[i].0.to_string()).collect();
        n.extend(s.effects.iter().map(|(c, _)| c.name.clone()));
        n.extend((0..self.gains).map(|g| format!("gain[{g}]")));
        n
    }
}

/// A fitted state with its whitened residuals and Jacobian.
#[derive(Debug, Clone)]
pub struct Fit {
    /// The fitted state.
    pub state: ModelState,
    /// Whitened residuals (measured − predicted)/σ, one per observation.
    pub residuals: DVector<f64>,
    /// Whitened Jacobian of the predictions (columns: free extrinsics per mrad or µm, effects
    /// per step, gains).
    pub jacobian: DMatrix<f64>,
    /// Names of the Jacobian's columns.
    pub column_names: Vec<String>,
    /// Standard uncertainty of each added effect (its unit), `None` when the data do not
    /// determine it. Scaled up by the residual rms when that is above 1.
    pub effect_sigma: Vec<Option<f64>>,
    /// Gauss-Newton iterations used.
    pub iterations: usize,
}

impl Fit {
    /// RMS of the whitened residuals (1 = at the noise floor).
    pub fn rms(&self) -> f64 {
        rms(&self.residuals)
    }

    /// χ²: the sum of the squared whitened residuals.
    pub fn chi2(&self) -> f64 {
        self.residuals.norm_squared()
    }

    /// How many σ added effect `k` is from neutral (0 when the data do not determine it).
    pub fn effect_z(&self, k: usize) -> f64 {
        self.effect_sigma[k].map_or(0.0, |s| self.state.effects[k].1.abs() / s)
    }
}

/// RMS of a vector (0 for an empty one).
pub fn rms(v: &DVector<f64>) -> f64 {
    if v.is_empty() {
        0.0
    } else {
        (v.norm_squared() / v.len() as f64).sqrt()
    }
}

/// The whitened Jacobian at `x`. Extrinsic and effect columns by central differences (1e-4
/// mrad or µm, 1e-2 of an effect's step), spread over threads; the gain columns in closed
/// form: a prediction is linear in its group's gain, so its derivative is the prediction
/// divided by the gain (what a central difference gives, without two predictions per gain).
fn jacobian(
    p: &Predictor,
    layout: &Layout,
    template: &ModelState,
    x: &DVector<f64>,
    obs: &[Observation],
) -> Result<DMatrix<f64>, PredictError> {
    use rayon::prelude::*;
    let n_differenced = layout.free.len() + layout.effects;
    let columns: Vec<DVector<f64>> = (0..n_differenced)
        .into_par_iter()
        .map(|c| {
            let h = if c < layout.free.len() { 1e-4 } else { 1e-2 };
            let (mut a, mut b) = (x.clone(), x.clone());
            a[c] += h;
            b[c] -= h;
            // Residuals are measured − predicted: the prediction's derivative is minus theirs.
            let ra = p.whitened_residuals(&layout.unpack(template, &a), obs)?;
            let rb = p.whitened_residuals(&layout.unpack(template, &b), obs)?;
            Ok((rb - ra) / (2.0 * h))
        })
        .collect::<Result<_, PredictError>>()?;
    let mut j = DMatrix::zeros(obs.len(), x.len());
    for (c, col) in columns.iter().enumerate() {
        j.set_column(c, col);
    }
    if layout.gains > 0 {
        let state = layout.unpack(template, x);
        let predicted = p.predict(&state.extrinsics, &state.library_effects(), &state.gains, obs)?;
        for (i, (o, pi)) in obs.iter().zip(&predicted).enumerate() {
            if let ObservationKind::FringeAmplitude { group, .. } = o.kind {
                let gain = state.gains[group];
                // A prediction the beam misses has a constant residual: no derivative.
                if pi.is_finite() && gain != 0.0 {
                    j[(i, n_differenced + group)] = pi / gain / o.sigma;
                }
            }
        }
    }
    Ok(j)
}

/// The whitened Jacobian of the predictions of `obs` at `state` with respect to every
/// extrinsic, the state's effects and the gains of `obs`'s amplitude groups.
pub fn jacobian_of(p: &Predictor, state: &ModelState, obs: &[Observation]) -> Result<DMatrix<f64>, PredictError> {
    let mut template = state.clone();
    let groups = gain_groups(obs);
    template.gains.resize(groups.max(template.gains.len()), 1.0);
    let layout = Layout { free: (0..N_EXTRINSICS).collect(), effects: state.effects.len(), gains: groups };
    let x = layout.pack(&template);
    jacobian(p, &layout, &template, &x, obs)
}

/// Solve `J·dx ≈ r` by the SVD, dropping directions below [`RANK_TOLERANCE`].
fn truncated_solve(j: &DMatrix<f64>, r: &DVector<f64>) -> DVector<f64> {
    let svd = j.clone().svd(true, true);
    let smax = svd.singular_values.max();
    let (Some(u), Some(vt)) = (&svd.u, &svd.v_t) else { return DVector::zeros(j.ncols()) };
    let mut dx = DVector::zeros(j.ncols());
    for (k, &s) in svd.singular_values.iter().enumerate() {
        if s > RANK_TOLERANCE * smax && s > 0.0 {
            let coef = u.column(k).dot(r) / s;
            dx += vt.row(k).transpose() * coef;
        }
    }
    dx
}

/// Fit the free extrinsics (`free`, order of [`PARAMETER_NAMES`]), the effects of `start` and
/// the gains to the observations, from `start`.
pub fn fit(
    p: &Predictor,
    obs: &[Observation],
    start: &ModelState,
    free: &[bool; N_EXTRINSICS],
) -> Result<Fit, PredictError> {
    let groups = gain_groups(obs);
    let mut template = start.clone();
    template.gains.resize(groups, 1.0);
    let layout =
        Layout { free: (0..N_EXTRINSICS).filter(|&i| free[i]).collect(), effects: start.effects.len(), gains: groups };
    let mut x = layout.pack(&template);
    let mut r = p.whitened_residuals(&template, obs)?;
    let mut cost = r.norm_squared();
    let mut iterations = 0;
    let mut j = jacobian(p, &layout, &template, &x, obs)?;
    for _ in 0..12 {
        iterations += 1;
        let dx = truncated_solve(&j, &r);
        let mut accepted = false;
        let mut scale = 1.0;
        for _ in 0..6 {
            let xn = &x + &dx * scale;
            // A step that takes an effect out of its accepted range (a back-face reflectance
            // above 1) is refused like one that raises the cost.
            let rn = match p.whitened_residuals(&layout.unpack(&template, &xn), obs) {
                Ok(rn) => rn,
                Err(PredictError::Stopped) => return Err(PredictError::Stopped),
                Err(PredictError::Effect(_)) => {
                    scale *= 0.5;
                    continue;
                }
            };
            let cn = rn.norm_squared();
            if cn.is_finite() && cn <= cost {
                let gain = cost - cn;
                x = xn;
                r = rn;
                cost = cn;
                accepted = gain > 1e-9 * cost.max(1.0);
                break;
            }
            scale *= 0.5;
        }
        if !accepted {
            break;
        }
        j = jacobian(p, &layout, &template, &x, obs)?;
    }
    let state = layout.unpack(&template, &x);
    let names = layout.names(&state);
    // Effect σ: the effect's column projected off every other column (its Schur complement).
    let n_free = layout.free.len();
    let scale = (cost / (obs.len().saturating_sub(x.len())).max(1) as f64).sqrt().max(1.0);
    let effect_sigma = (0..layout.effects)
        .map(|k| {
            let col = n_free + k;
            let others: Vec<usize> = (0..j.ncols()).filter(|&c| c != col).collect();
            let proj = Projector::new(&j.select_columns(others.iter()));
            let s = proj.orthogonal(&j.column(col).into_owned());
            let n = s.norm();
            (n > 1e-12).then(|| state.effects[k].0.step / n * scale)
        })
        .collect();
    Ok(Fit { state, residuals: r, jacobian: j, column_names: names, effect_sigma, iterations })
}
