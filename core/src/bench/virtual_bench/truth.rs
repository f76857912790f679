//! The hidden truth of the virtual bench: the robot with its hidden effects, the extrinsics, the
//! optics, the air and the noise levels, and the exact path, the reflected power evaluated from
//! scratch at one sample.

use crate::bench::preset::BenchPreset;
use crate::bench::BenchError;
use crate::model::air::air_index_ciddor;
use crate::model::effects::{self, Effect};
use crate::model::extrinsics::{Extrinsics, FiberGeometry};
use crate::model::kinematics::Chain;
use crate::model::optics::{FabryPerot, OpticalParams};
use crate::model::robot::{JointType, RobotDescription};
use nalgebra::Vector3;

/// The hidden part of a virtual bench: the true robot, extrinsics and optics, and the noise levels.
pub(super) struct Truth {
    /// The robot with the hidden effects applied.
    pub(super) chain: Chain,
    pub(super) extrinsics: Extrinsics,
    pub(super) geometry: FiberGeometry,
    /// The preset's optics with the hidden optical effects.
    pub(super) optics: OpticalParams,
    pub(super) n_air: f64,
    pub(super) laser_wavelength_nm: f64,
    /// The cavity at the laser's resting wavelength.
    pub(super) fp: FabryPerot,
    /// The hidden effects that act on the optical path (drift, path scale, fringe nonlinearity).
    pub(super) path_effects: Vec<Effect>,
    /// Play of each stage (display units; hidden reversal errors).
    pub(super) play_width: [f64; 6],
    /// The path effects compiled: gap = scale·|L| + offset(t).
    pub(super) gap_map: GapMap,
    pub(super) joint_is_revolute: [bool; 6],
    /// Detector noise: white (mW), shot (mW at 1 mW) and the laser's relative intensity noise.
    pub(super) white_sigma_mw: f64,
    pub(super) shot_mw_at_1mw: f64,
    pub(super) rin_rel: f64,
    /// Any detector noise at all (a draw per sample).
    pub(super) detector_noise: bool,
    /// The ADC's quantisation step (0: no quantisation).
    pub(super) adc_step_mw: f64,
    /// 1/adc_step_mw and the number of ADC steps over the full scale.
    pub(super) adc_per_mw: f64,
    pub(super) adc_levels: f64,
    pub(super) gain_drift_per_s: f64,
    pub(super) sample_period_s: f64,
    pub(super) stage_sigma: [f64; 6],
    /// The joint noise draws of a sample, in order.
    pub(super) draws: Vec<Draw>,
    /// Optical axis in the world.
    pub(super) n_f: Vector3<f64>,
    /// Lamella normal in the end-effector frame.
    pub(super) n_t_in_ee: Vector3<f64>,
}

/// One joint noise draw: slot i < 6 is the stage jitter of joint i, slot 6 + i its encoder noise.
#[derive(Debug, Clone, Copy)]
pub(super) struct Draw {
    pub(super) slot: usize,
    pub(super) sigma: f64,
}

/// The path effects (drift, path scale) composed in their order into an affine map of the
/// geometric gap: `gap = scale·|L| + per_s·t + per_s2·t²` (µm, t bench time in s).
#[derive(Debug, Clone, Copy)]
pub(super) struct GapMap {
    pub(super) scale: f64,
    pub(super) per_s: f64,
    pub(super) per_s2: f64,
}

impl GapMap {
    pub(super) fn new(effects: &[Effect]) -> Self {
        let mut m = GapMap { scale: 1.0, per_s: 0.0, per_s2: 0.0 };
        for e in effects {
            match e {
                Effect::ThermalDrift { nm_per_s, nm_per_s2 } => {
                    m.per_s += nm_per_s * 1e-3;
                    m.per_s2 += 0.5 * nm_per_s2 * 1e-3;
                }
                Effect::PathScale { ppm } => {
                    let f = 1.0 + ppm * 1e-6;
                    m = GapMap { scale: m.scale * f, per_s: m.per_s * f, per_s2: m.per_s2 * f };
                }
                _ => {}
            }
        }
        m
    }

    #[inline]
    pub(super) fn offset_um(&self, t_s: f64) -> f64 {
        (self.per_s + self.per_s2 * t_s) * t_s
    }

    #[inline]
    pub(super) fn rate_um_per_s(&self, t_s: f64) -> f64 {
        self.per_s + 2.0 * self.per_s2 * t_s
    }
}

impl Truth {
    /// The truth of `preset` around the nominal `robot`: the robot with the hidden effects, the
    /// optics, the air and the noise of the stages and the detector.
    pub(super) fn new(preset: &BenchPreset, robot: &RobotDescription) -> Result<Self, BenchError> {
        let truth_robot = effects::apply_all(&preset.effects, robot)
            .map_err(|e| BenchError::Config(format!("bench {}: {e}", preset.name)))?;
        let n_air = air_index_ciddor(preset.laser.wavelength_nm, &preset.ambient)
            .map_err(|e| BenchError::Config(format!("bench {}: ambient: {e}", preset.name)))?;
        // The truth's optics: the preset's with the hidden optical effects (Gouy phase, back face).
        let optics = effects::apply_optics(&preset.effects, &preset.optics);
        let fp = FabryPerot::new(&optics, preset.laser.wavelength_nm, n_air)
            .map_err(|e| BenchError::Config(format!("bench {}: optics: {e}", preset.name)))?;
        let chain = Chain::new(truth_robot);
        let wte0 = chain.end_effector(&[0.0; 6]);
        let cavity0 = preset
            .truth
            .cavity(&wte0)
            .map_err(|e| BenchError::Config(format!("bench {}: at q = 0: {e}", preset.name)))?;
        let fringe0 = fp.two_beam(cavity0.length_um.abs(), cavity0.tilt_rad);
        let joint_is_revolute: [bool; 6] = std::array::from_fn(|i| robot.links[i].joint == JointType::Revolute);
        let per_joint = |nm: f64, urad: f64| -> [f64; 6] {
            // Display units: µm for prismatic joints, degrees for revolute joints.
            std::array::from_fn(|i| if joint_is_revolute[i] { (urad * 1e-6).to_degrees() } else { nm * 1e-3 })
        };
        let d = &preset.detector;
        let encoder_sigma = per_joint(preset.stages.encoder_noise_nm, preset.stages.encoder_noise_urad);
        let stage_sigma = per_joint(preset.stages.stage_noise_nm, preset.stages.stage_noise_urad);
        let draws = (0..6)
            .flat_map(|i| [Draw { slot: i, sigma: stage_sigma[i] }, Draw { slot: 6 + i, sigma: encoder_sigma[i] }])
            .filter(|d| d.sigma != 0.0)
            .collect();
        let path_effects: Vec<Effect> = preset.effects.iter().filter(|e| e.is_path()).cloned().collect();
        let geometry = preset.truth.geometry();
        let white_sigma_mw = d.white_noise_rel_fringe * fringe0.amplitude_mw;
        Ok(Truth {
            n_f: geometry.n_f(),
            n_t_in_ee: geometry.n_t_in_ee(),
            geometry,
            extrinsics: preset.truth,
            optics,
            n_air,
            laser_wavelength_nm: preset.laser.wavelength_nm,
            fp,
            gap_map: GapMap::new(&path_effects),
            play_width: effects::reversal_play(&preset.effects, robot),
            path_effects,
            joint_is_revolute,
            white_sigma_mw,
            shot_mw_at_1mw: d.shot_noise_mw_at_1mw,
            rin_rel: preset.laser.rin_rel,
            detector_noise: white_sigma_mw != 0.0 || d.shot_noise_mw_at_1mw != 0.0 || preset.laser.rin_rel != 0.0,
            adc_step_mw: if d.adc_bits == 0 { 0.0 } else { d.adc_full_scale_mw / 2f64.powi(d.adc_bits as i32) },
            adc_per_mw: 2f64.powi(d.adc_bits as i32) / d.adc_full_scale_mw,
            adc_levels: 2f64.powi(d.adc_bits as i32),
            gain_drift_per_s: d.gain_drift_per_hour / 3600.0,
            sample_period_s: 1.0 / d.sample_rate_hz,
            stage_sigma,
            draws,
            chain,
        })
    }

    /// Reflected power (mW, before the detector) at bench time `t_s` and real joints
    /// `q_display` (µm, °), evaluated from scratch: the exact path.
    pub(super) fn power_exact(&self, t_s: f64, q_display: &[f64; 6], fp: &FabryPerot) -> f64 {
        let q: [f64; 6] =
            std::array::from_fn(|i| if self.joint_is_revolute[i] { q_display[i].to_radians() } else { q_display[i] });
        let wte = self.chain.end_effector(&q);
        let l_um = self.extrinsics.cavity_length_um(&wte, &self.geometry);
        let n_t = wte.rotation * self.n_t_in_ee;
        let cos_tilt = n_t.dot(&self.n_f).abs().min(1.0);
        let tilt = cos_tilt.acos();
        let mut gap_um = l_um.abs();
        for e in &self.path_effects {
            gap_um += e.gap_change_nm(t_s, gap_um) * 1e-3;
        }
        let phase_rad = 2.0 * std::f64::consts::PI * gap_um / fp.fringe_period_um();
        for e in &self.path_effects {
            gap_um += e.cyclic_error_nm(phase_rad) * 1e-3;
        }
        fp.power(gap_um, tilt)
    }
}
