//! Bench presets: the documented description of a virtual bench (truth, optics, sensors, noise, hidden effects).
//! Owns the preset file format (`assets/benches/*.ron`) and its validation.

use crate::files::{self, FieldError, FileError};
use crate::model::air::AmbientConditions;
use crate::model::effects::Effect;
use crate::model::extrinsics::Extrinsics;
use crate::model::optics::OpticalParams;
use crate::model::robot::RobotDescription;
use crate::plan::MotionLimits;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The presets shipped with the project, embedded so the app runs anywhere.
pub const EMBEDDED: [(&str, &str); 3] = [
    ("table2-ideal", include_str!("../../../assets/benches/table2-ideal.ron")),
    ("femto-lab", include_str!("../../../assets/benches/femto-lab.ron")),
    ("hidden-pivot", include_str!("../../../assets/benches/hidden-pivot.ron")),
];

/// Which robot the bench has.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum RobotRef {
    /// A robot shipped with the project, by name ("femto-6dof").
    Embedded(String),
    /// A robot description file, relative to the preset file.
    File(PathBuf),
}

/// The laser.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Laser {
    /// Vacuum wavelength when not sweeping (nm).
    pub wavelength_nm: f64,
    /// Relative intensity noise, as a fraction of the power (rms per sample).
    #[serde(default)]
    pub rin_rel: f64,
    /// The laser sweeps its wavelength (a tunable laser; the default). `false`: it stays at
    /// `wavelength_nm`, the bench refuses sweeps and calibrations skip them.
    #[serde(default = "tunable_by_default")]
    pub tunable: bool,
}

fn tunable_by_default() -> bool {
    true
}

/// The photodiode and its acquisition.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Detector {
    /// Sampling rate (Hz).
    pub sample_rate_hz: f64,
    /// White detector noise, as a fraction of the two-beam fringe amplitude at the bench's
    /// reference pose (q = 0) (rms per sample).
    pub white_noise_rel_fringe: f64,
    /// Shot noise: rms (mW) for 1 mW of detected power, scaling as √P.
    #[serde(default)]
    pub shot_noise_mw_at_1mw: f64,
    /// ADC resolution (bits); 0 for an ideal converter.
    #[serde(default)]
    pub adc_bits: u32,
    /// ADC full scale (mW of optical power).
    #[serde(default = "default_full_scale")]
    pub adc_full_scale_mw: f64,
    /// Slow drift of the detector gain (fraction per hour).
    #[serde(default)]
    pub gain_drift_per_hour: f64,
}

fn default_full_scale() -> f64 {
    1.0
}

/// Joint encoders and stage jitter.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Stages {
    /// Encoder read noise of the prismatic joints (nm rms).
    pub encoder_noise_nm: f64,
    /// Encoder read noise of the revolute joints (µrad rms).
    pub encoder_noise_urad: f64,
    /// Jitter of the real position of the prismatic stages (nm rms).
    pub stage_noise_nm: f64,
    /// Jitter of the real angle of the revolute stages (µrad rms).
    pub stage_noise_urad: f64,
}

/// A virtual bench: every number with its unit, and the hidden truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BenchPreset {
    /// Preset name.
    pub name: String,
    /// What the preset stands for and where its numbers come from.
    pub description: String,
    /// The robot.
    pub robot: RobotRef,
    /// Hidden truth: the real extrinsic parameters.
    pub truth: Extrinsics,
    /// Optics of fiber and lamella.
    pub optics: OpticalParams,
    /// The laser.
    pub laser: Laser,
    /// Ambient conditions (set the air index).
    pub ambient: AmbientConditions,
    /// The photodiode.
    pub detector: Detector,
    /// Encoders and stage jitter.
    pub stages: Stages,
    /// Motion speeds and accelerations.
    pub motion: MotionLimits,
    /// Hidden effects (intrinsic errors, drift, …), none for an ideal bench.
    #[serde(default)]
    pub effects: Vec<Effect>,
    /// Random seed (overridable per run).
    pub seed: u64,
}

const EXPECTED: &str = "a BenchPreset(name, description, robot, truth, optics, laser, ambient, detector, stages, motion, effects, seed) as in assets/benches/table2-ideal.ron";

impl BenchPreset {
    /// An embedded preset by name, or a preset file by path.
    pub fn resolve(name_or_path: &str) -> Result<Self, FileError> {
        if let Some((name, text)) = EMBEDDED.iter().find(|(n, _)| *n == name_or_path) {
            return Self::from_ron_str(text, Path::new(&format!("assets/benches/{name}.ron")));
        }
        let path = Path::new(name_or_path);
        if !path.exists() {
            return Err(FileError::Invalid {
                file: path.to_path_buf(),
                field: "--bench".into(),
                problem: format!(
                    "no such file, and not an embedded preset (expected one of: {})",
                    EMBEDDED.map(|(n, _)| n).join(", ")
                ),
            });
        }
        Self::load(path)
    }

    /// Load a preset file.
    pub fn load(path: &Path) -> Result<Self, FileError> {
        let text = files::read_text(path)?;
        let mut p = Self::from_ron_str(&text, path)?;
        if let RobotRef::File(f) = &p.robot {
            if f.is_relative() {
                p.robot = RobotRef::File(path.parent().unwrap_or(Path::new(".")).join(f));
            }
        }
        Ok(p)
    }

    /// Parse and validate; `origin` names the text in errors.
    pub fn from_ron_str(text: &str, origin: &Path) -> Result<Self, FileError> {
        let p: Self = files::parse_ron(text, origin, EXPECTED)?;
        p.validate().map_err(|e| e.in_file(origin))?;
        Ok(p)
    }

    /// The same bench without any noise: no detector, shot or intensity noise, no ADC
    /// quantisation, no gain drift, no encoder or stage noise. Hidden effects, drift and the
    /// truth stay. For checks that a difference comes from the model, not the noise.
    pub fn without_noise(mut self) -> Self {
        self.laser.rin_rel = 0.0;
        self.detector.white_noise_rel_fringe = 0.0;
        self.detector.shot_noise_mw_at_1mw = 0.0;
        self.detector.adc_bits = 0;
        self.detector.gain_drift_per_hour = 0.0;
        self.stages =
            Stages { encoder_noise_nm: 0.0, encoder_noise_urad: 0.0, stage_noise_nm: 0.0, stage_noise_urad: 0.0 };
        self
    }

    /// The robot description (truth geometry before hidden effects).
    pub fn robot_description(&self) -> Result<RobotDescription, FileError> {
        match &self.robot {
            RobotRef::Embedded(name) if name == "femto-6dof" => Ok(RobotDescription::femto_6dof()),
            RobotRef::Embedded(name) => Err(FileError::Invalid {
                file: PathBuf::from(&self.name),
                field: "robot".into(),
                problem: format!("no embedded robot `{name}` (expected \"femto-6dof\" or File(\"path.ron\"))"),
            }),
            RobotRef::File(p) => RobotDescription::load(p),
        }
    }

    /// Check the values that the types do not.
    pub fn validate(&self) -> Result<(), FieldError> {
        self.truth.validate().map_err(|e| FieldError::new(format!("truth.{}", e.field), e.problem))?;
        self.optics.validate().map_err(|e| FieldError::new("optics", e.to_string()))?;
        self.ambient.validate().map_err(|e| FieldError::new("ambient", e.to_string()))?;
        let positive = |field: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(FieldError::new(field, format!("expected a positive number, found {v}")))
            }
        };
        let non_negative = |field: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(FieldError::new(field, format!("expected a number ≥ 0, found {v}")))
            }
        };
        positive("detector.sample_rate_hz", self.detector.sample_rate_hz)?;
        non_negative("detector.white_noise_rel_fringe", self.detector.white_noise_rel_fringe)?;
        non_negative("detector.shot_noise_mw_at_1mw", self.detector.shot_noise_mw_at_1mw)?;
        positive("detector.adc_full_scale_mw", self.detector.adc_full_scale_mw)?;
        non_negative("detector.gain_drift_per_hour", self.detector.gain_drift_per_hour.abs())?;
        if self.detector.adc_bits > 32 {
            return Err(FieldError::new(
                "detector.adc_bits",
                format!("expected 0 (ideal) to 32 bits, found {}", self.detector.adc_bits),
            ));
        }
        if !(1500.0..=1630.0).contains(&self.laser.wavelength_nm) {
            return Err(FieldError::new(
                "laser.wavelength_nm",
                format!("expected 1500 to 1630 nm (the tunable laser's range), found {}", self.laser.wavelength_nm),
            ));
        }
        non_negative("laser.rin_rel", self.laser.rin_rel)?;
        non_negative("stages.encoder_noise_nm", self.stages.encoder_noise_nm)?;
        non_negative("stages.encoder_noise_urad", self.stages.encoder_noise_urad)?;
        non_negative("stages.stage_noise_nm", self.stages.stage_noise_nm)?;
        non_negative("stages.stage_noise_urad", self.stages.stage_noise_urad)?;
        Ok(())
    }
}
