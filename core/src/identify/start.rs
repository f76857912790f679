//! A first estimate that does not depend on the plan's layout: the extrinsics that explain what
//! the traces show before any model guides their analysis. Owns the sign-free data and the starts.
//!
//! A single-channel fringe signal is unchanged when the phase runs backwards, so without a model
//! a motion trace says how far its fringe phase travelled, not which way: each extremum is a
//! quarter wavelength of travel. Those travels, the absolute gaps of the sweeps and the
//! geometry of the motions fix the lamella's tilt against the beam (a translation's travel is
//! |v·dp|), where the beam hits the lamella and the fiber's direction (a rotation's travel grows
//! with the tilt either side of where the lamella faces the fiber). The fit of the travels is
//! started from a grid of lamella tilts around the nominal design; each distinct minimum is a
//! branch of the discrete ambiguities (a travel is blind to the sign of each tilt component),
//! and the full identification starts from each one and keeps the one that fits the signed data.

use crate::identify::{parameter_scale, predict, Observation, ObservationKind, N_EXTRINSICS};
use crate::measure::extrema::{detect_extrema, HysteresisConfig};
use crate::model::extrinsics::{Extrinsics, FiberGeometry};
use crate::model::optics::FabryPerot;
use crate::model::phase::PhaseModel;
use crate::trace::Trace;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{storage::Owned, DMatrix, DVector, Dyn, Isometry3};
use std::borrow::Borrow;

/// Points along a motion at which the model's gap is evaluated for its travel.
const TRAVEL_POINTS: usize = 48;

/// Smoothing of |Δgap| per step (nm): `√(Δ² + ε²) − ε`, so that the travel has a derivative
/// where a step's gap change crosses zero (a lateral move of a square lamella).
const TRAVEL_SMOOTHING_NM: f64 = 10.0;

/// How far one motion's fringe phase travelled, read without a model.
#[derive(Debug, Clone)]
pub struct Travel {
    /// The trace's label.
    pub label: String,
    /// Joints (µm, °) at [`TRAVEL_POINTS`] evenly spaced samples, first and last included.
    pub joints_display: Vec<[f64; 6]>,
    /// Phase-equivalent gap travelled (nm, ≥ 0): a quarter wavelength in air per extremum.
    pub travel_nm: f64,
    /// Vacuum wavelength (nm).
    pub wavelength_nm: f64,
}

/// The sign-free travel of each motion trace (sweeps are left out): the number of intensity
/// extrema (adaptive hysteresis) times λ/(4n). A motion without a detectable fringe travelled
/// under a quarter wavelength.
pub fn travels<T: Borrow<Trace>>(motions: &[T], n_air: f64) -> Vec<Travel> {
    motions
        .iter()
        .map(Borrow::borrow)
        .filter(|t| t.len() >= 2 && !crate::trace::is_sweep(t))
        .map(|t| {
            let wavelength_nm = t.wavelength_nm[0];
            let extrema = detect_extrema(&t.irradiance, &HysteresisConfig::default()).map_or(0, |e| e.len());
            let n = t.len();
            let joints_display =
                (0..TRAVEL_POINTS).map(|k| t.joints_display(k * (n - 1) / (TRAVEL_POINTS - 1))).collect();
            Travel {
                label: t.meta.label.clone(),
                joints_display,
                travel_nm: extrema as f64 * wavelength_nm / (4.0 * n_air),
                wavelength_nm,
            }
        })
        .collect()
}

/// The model's sign-free travel along a motion through end-effector `poses` (nm, smoothed) and
/// its number of turning points; `None` where the beam misses the lamella.
fn model_travel(fp: &FabryPerot, geometry: &FiberGeometry, poses: &[Isometry3<f64>]) -> Option<(f64, usize)> {
    let to_nm = fp.wavelength_nm() / (4.0 * std::f64::consts::PI * fp.medium_index());
    let gaps: Vec<f64> = poses
        .iter()
        .map(|wte| {
            geometry
                .gap_and_tilt(wte)
                .map_or(f64::NAN, |(gap_um, tilt_rad)| fp.fundamental_phase_rad(gap_um, tilt_rad) * to_nm)
        })
        .collect();
    if gaps.iter().any(|g| !g.is_finite()) {
        return None;
    }
    let steps: Vec<f64> = gaps.windows(2).map(|w| w[1] - w[0]).collect();
    let travel = steps.iter().map(|d| d.hypot(TRAVEL_SMOOTHING_NM) - TRAVEL_SMOOTHING_NM).sum();
    let turns = steps.windows(2).filter(|w| w[0] * w[1] < 0.0).count();
    Some((travel, turns))
}

/// σ of a travel (nm): the ends of the motion fall anywhere within a quarter fringe, so do the
/// gap's turning points, and the detector may miss an extremum where the fringe fades (2 %).
fn travel_sigma_nm(t: &Travel, n_air: f64, turns: usize) -> f64 {
    let quarter = t.wavelength_nm / (4.0 * n_air);
    (quarter * (0.5 + 0.5 * turns as f64).sqrt()).hypot(0.02 * t.travel_nm)
}

/// Width of the weak priors that keep the start fit away from wandering where the travels see
/// nothing: 3° on the angles, 100 µm on the positions, about the nominal design.
const PRIOR_DEG: f64 = 3.0;
const PRIOR_UM: f64 = 100.0;

/// Smallest σ given to an absolute gap in the start fit (µm): the model has no effect yet that
/// a bench may have, and the gaps must not outweigh the travels.
const START_GAP_SIGMA_UM: f64 = 0.1;

struct StartProblem<'a> {
    model: &'a PhaseModel,
    fp: FabryPerot,
    travels: &'a [Travel],
    /// The end effector's pose at each travel's joints: the extrinsics do not move it.
    poses: &'a [Vec<Isometry3<f64>>],
    gaps: &'a [Observation],
    prior: [f64; N_EXTRINSICS],
    x: DVector<f64>,
}

/// Free in the start fit: every parameter but Z_et (only y_wf − Z_et shows).
const FREE: [usize; 7] = [0, 1, 2, 3, 5, 6, 7];

impl StartProblem<'_> {
    fn extrinsics(&self, x: &DVector<f64>) -> Extrinsics {
        let mut a = self.prior;
        for (k, &i) in FREE.iter().enumerate() {
            a[i] = x[k] * parameter_scale(i);
        }
        Extrinsics::from_array(a)
    }

    /// Normalised residuals: travels, absolute gaps, priors.
    fn residuals_at(&self, x: &DVector<f64>) -> DVector<f64> {
        let e = self.extrinsics(x);
        let n_air = self.model.n_air;
        let mut r = Vec::with_capacity(self.travels.len() + self.gaps.len() + FREE.len());
        let geometry = e.geometry();
        for (t, poses) in self.travels.iter().zip(self.poses) {
            r.push(match model_travel(&self.fp, &geometry, poses) {
                Some((travel, turns)) => (travel - t.travel_nm) / travel_sigma_nm(t, n_air, turns),
                None => 1e3,
            });
        }
        for o in self.gaps {
            let p = predict(self.model, &self.fp, &e, o, 1.0);
            r.push(if p.is_finite() { (p - o.value()) / o.sigma.max(START_GAP_SIGMA_UM) } else { 1e3 });
        }
        let a = e.to_array();
        for &i in &FREE {
            let width = if parameter_scale(i) == 1.0 { PRIOR_UM } else { PRIOR_DEG };
            r.push((a[i] - self.prior[i]) / width);
        }
        DVector::from_vec(r)
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for StartProblem<'_> {
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
        Some(self.residuals_at(&self.x))
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let columns: Vec<DVector<f64>> = (0..self.x.len())
            .map(|c| {
                // 0.01 mrad, 0.01 µm: above the travel's smoothing, far below its features.
                let h = 1e-2;
                let (mut a, mut b) = (self.x.clone(), self.x.clone());
                a[c] += h;
                b[c] -= h;
                (self.residuals_at(&a) - self.residuals_at(&b)) / (2.0 * h)
            })
            .collect();
        Some(DMatrix::from_columns(&columns))
    }
}

/// One minimum of the start fit.
#[derive(Debug, Clone, Copy)]
pub struct StartBranch {
    /// The extrinsics there.
    pub extrinsics: Extrinsics,
    /// Its cost: the sum of squared normalised residuals (travels, gaps, priors).
    pub chi2: f64,
}

/// Lamella tilts (°) added to the nominal design's β_et and θ_et to start the fit from: a grid
/// wide enough for a lamella mounted a few degrees off square.
const TILT_GRID_DEG: [f64; 3] = [-1.5, 0.0, 1.5];

/// Two minima closer than this in every angle (°) and position (µm) are one branch.
const SAME_BRANCH: (f64, f64) = (0.05, 5.0);

/// The distinct minima of the start fit of `travels` and `gaps` (absolute-gap observations),
/// best first, from a grid of lamella tilts around `nominal.extrinsics`; `wavelength_nm` is the
/// motions' laser wavelength.
pub fn start_branches(
    nominal: &PhaseModel,
    travels: &[Travel],
    gaps: &[Observation],
    wavelength_nm: f64,
) -> Vec<StartBranch> {
    use rayon::prelude::*;
    let Ok(fp) = FabryPerot::new(&nominal.optics, wavelength_nm, nominal.n_air) else { return vec![] };
    let gaps: Vec<Observation> =
        gaps.iter().filter(|o| matches!(o.kind, ObservationKind::AbsoluteGap { .. })).cloned().collect();
    let prior = nominal.extrinsics.to_array();
    let chain = &nominal.chain;
    let poses: Vec<Vec<Isometry3<f64>>> = travels
        .iter()
        .map(|t| t.joints_display.iter().map(|q| chain.end_effector(&chain.description().q_from_display(q))).collect())
        .collect();
    let grid: Vec<(f64, f64)> =
        TILT_GRID_DEG.iter().flat_map(|&b| TILT_GRID_DEG.iter().map(move |&t| (b, t))).collect();
    let mut minima: Vec<StartBranch> = grid
        .par_iter()
        .map(|&(db, dt)| {
            let mut start = prior;
            start[0] += db;
            start[1] += dt;
            let x = DVector::from_iterator(FREE.len(), FREE.iter().map(|&i| start[i] / parameter_scale(i)));
            let problem =
                StartProblem { model: nominal, fp: fp.clone(), travels, poses: &poses, gaps: &gaps, prior, x };
            let (problem, _) = LevenbergMarquardt::new().with_patience(60).minimize(problem);
            let chi2 = problem.residuals_at(&problem.x).norm_squared();
            StartBranch { extrinsics: problem.extrinsics(&problem.x), chi2 }
        })
        .filter(|b| b.chi2.is_finite())
        .collect();
    minima.sort_by(|a, b| a.chi2.total_cmp(&b.chi2));
    let mut distinct: Vec<StartBranch> = Vec::new();
    for m in minima {
        if !distinct.iter().any(|d| same_branch(&d.extrinsics, &m.extrinsics)) {
            distinct.push(m);
        }
    }
    distinct
}

/// The first of `estimates[..k]` in the same branch as `estimates[k]`: a branch found again.
pub fn found_before(estimates: &[Extrinsics], k: usize) -> Option<usize> {
    let e = estimates.get(k)?;
    estimates[..k].iter().position(|b| same_branch(b, e))
}

/// Whether two estimates are the same branch ([`SAME_BRANCH`]).
pub fn same_branch(a: &Extrinsics, b: &Extrinsics) -> bool {
    let (a, b) = (a.to_array(), b.to_array());
    (0..N_EXTRINSICS).all(|i| {
        let tol = if parameter_scale(i) == 1.0 { SAME_BRANCH.1 } else { SAME_BRANCH.0 };
        (a[i] - b[i]).abs() <= tol
    })
}
