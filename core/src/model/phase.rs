//! The phase model: from the joints to the phase-equivalent gap the fringes measure, shared by
//! the analysis (its motion hints) and the identifier (its predicted observations).
//!
//! Phase convention: every length measured from fringes is *phase-equivalent*:
//! `Δφ·λ/(4π·n_air)`, with φ the phase of the fringe's fundamental
//! ([`FabryPerot::fundamental_phase_rad`]: the first beam's phase pulled by the higher beams),
//! which includes the tilt path term (the fringes follow the perpendicular fiber-to-lamella
//! distance, `L·cos γ`) and the Gouy phase.
//!
//! What needs a trace or a bench preset (`PhaseModel::hint_nm`, `PhaseModel::hint_and_shape`,
//! `PhaseModel::of_preset`) is implemented in `crate::measure::hint`, above this layer.

use crate::model::air::{air_index_ciddor, AmbientConditions};
use crate::model::effects::{real_joints, reversal_play, Effect};
use crate::model::extrinsics::{Cavity, Extrinsics, FiberGeometry};
use crate::model::kinematics::Chain;
use crate::model::optics::{FabryPerot, OpticalParams};
use crate::model::robot::RobotDescription;
use std::f64::consts::PI;

/// The model the analysis uses to predict the phase from the joints: the nominal (or current
/// best) robot and extrinsics, the optics and the air.
#[derive(Debug, Clone)]
pub struct PhaseModel {
    /// Robot chain.
    pub chain: Chain,
    /// Extrinsics (nominal before calibration).
    pub extrinsics: Extrinsics,
    /// Optics.
    pub optics: OpticalParams,
    /// Air index.
    pub n_air: f64,
}

impl PhaseModel {
    /// The model with the given parts; the air index from the ambient conditions at `wavelength_nm`.
    pub fn new(
        robot: RobotDescription,
        extrinsics: Extrinsics,
        optics: OpticalParams,
        ambient: &AmbientConditions,
        wavelength_nm: f64,
    ) -> Result<Self, String> {
        let n_air = air_index_ciddor(wavelength_nm, ambient).map_err(|e| format!("ambient conditions: {e}"))?;
        Ok(Self { chain: Chain::new(robot), extrinsics, optics, n_air })
    }

    /// The phase-equivalent gap (nm) at joints `q_display` (µm, °) and vacuum wavelength
    /// `wavelength_nm`: `φ·λ/(4π·n)`.
    pub fn phase_gap_nm(&self, fp: &FabryPerot, q_display: &[f64; 6]) -> f64 {
        self.phase_gap_nm_in(&self.extrinsics.geometry(), fp, q_display)
    }

    /// [`PhaseModel::phase_gap_nm`] with the extrinsics' `geometry` computed once for many poses.
    pub fn phase_gap_nm_in(&self, geometry: &FiberGeometry, fp: &FabryPerot, q_display: &[f64; 6]) -> f64 {
        match self.gap_and_tilt_in(geometry, q_display) {
            Some((gap_um, tilt_rad)) => {
                fp.fundamental_phase_rad(gap_um, tilt_rad) * fp.wavelength_nm() / (4.0 * PI * fp.medium_index())
            }
            None => f64::NAN,
        }
    }

    /// |L| (µm) and the tilt (rad) of the cavity at joints `q_display` (µm, °); None when the
    /// beam misses the lamella.
    pub fn gap_and_tilt(&self, q_display: &[f64; 6]) -> Option<(f64, f64)> {
        self.gap_and_tilt_in(&self.extrinsics.geometry(), q_display)
    }

    /// [`PhaseModel::gap_and_tilt`] with the extrinsics' `geometry` ([`Extrinsics::geometry`])
    /// computed once for many poses.
    pub fn gap_and_tilt_in(&self, geometry: &FiberGeometry, q_display: &[f64; 6]) -> Option<(f64, f64)> {
        let q = self.chain.description().q_from_display(q_display);
        geometry.gap_and_tilt(&self.chain.end_effector(&q))
    }
}

/// The forward model with extrinsics `extrinsics` (in place of the model's) and path effects
/// acting as the virtual bench applies them: drift and path scale
/// ([`Effect::gap_change_nm`]) on the gap at a time, in the order given; cyclic errors
/// ([`Effect::cyclic_error_nm`]) on the phase-equivalent gap; reversal play on the joints.
/// Geometric effects act through `model.chain` (see [`crate::model::effects::apply_all`]),
/// optical ones through `fp` (see [`crate::model::effects::apply_optics`]).
pub struct PathForward<'a> {
    model: &'a PhaseModel,
    fp: &'a FabryPerot,
    extrinsics: &'a Extrinsics,
    path: &'a [Effect],
    /// Reversal play of each joint (display units).
    play: [f64; 6],
    /// Whether any joint has play.
    reversal: bool,
}

impl<'a> PathForward<'a> {
    /// The forward model of `model`'s chain with `extrinsics`, the optics `fp` and the effects `path`.
    pub fn new(model: &'a PhaseModel, fp: &'a FabryPerot, extrinsics: &'a Extrinsics, path: &'a [Effect]) -> Self {
        let play = reversal_play(path, model.chain.description());
        let reversal = play.iter().any(|p| *p != 0.0);
        Self { model, fp, extrinsics, path, play, reversal }
    }

    /// The gap (µm) at time `t_s` of a cavity of length `length_um`, with the path effects.
    pub fn optical_gap_um(&self, length_um: f64, t_s: f64) -> f64 {
        let mut gap_um = length_um.abs();
        for p in self.path {
            gap_um += p.gap_change_nm(t_s, gap_um) * 1e-3;
        }
        gap_um
    }

    /// How far a wavelength sweep at time `t_s` reads the gap off (µm) when the path effects move
    /// it during the sweep (drift): [`crate::model::effects::sweep_reading_nm`] of their rate,
    /// whole orders of the fringe.
    pub fn sweep_reading_um(&self, t_s: f64, wavelength_nm: f64, sweep_nm_per_s: f64) -> f64 {
        let rate: f64 = self.path.iter().map(|p| p.gap_rate_nm_per_s(t_s)).sum();
        if rate == 0.0 {
            return 0.0;
        }
        crate::model::effects::sweep_reading_nm(rate, wavelength_nm, sweep_nm_per_s, self.fp.medium_index()) * 1e-3
    }

    /// The real joints at a pose read as `q_display`, approached in the directions
    /// `approach`: the reading moved by any reversal error.
    pub fn real_joints(&self, q_display: &[f64; 6], approach: &[i8; 6]) -> [f64; 6] {
        if self.reversal {
            real_joints(q_display, approach, &self.play)
        } else {
            *q_display
        }
    }

    /// The cavity at joints `q_display`; None when the beam misses the lamella.
    pub fn cavity(&self, q_display: &[f64; 6]) -> Option<Cavity> {
        let q = self.model.chain.description().q_from_display(q_display);
        self.extrinsics.cavity(&self.model.chain.end_effector(&q)).ok()
    }

    /// The phase-equivalent gap (nm) at joints `q_display` and time `t_s`, with the path
    /// effects and cyclic errors; NaN when the beam misses the lamella.
    pub fn phase_gap_nm(&self, q_display: &[f64; 6], t_s: f64) -> f64 {
        let fp = self.fp;
        match self.cavity(q_display) {
            Some(c) => {
                let gap_um = self.optical_gap_um(c.length_um, t_s);
                let mut gap_nm = fp.fundamental_phase_rad(gap_um, c.tilt_rad) * fp.wavelength_nm()
                    / (4.0 * std::f64::consts::PI * fp.medium_index());
                let phase_rad = 2.0 * std::f64::consts::PI * gap_um / fp.fringe_period_um();
                for p in self.path {
                    gap_nm += p.cyclic_error_nm(phase_rad);
                }
                gap_nm
            }
            None => f64::NAN,
        }
    }
}
