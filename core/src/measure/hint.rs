//! What the phase model predicts along a trace: the motion hint (the phase-equivalent gap
//! change at every sample) and the fringe's shape, and the model of a bench preset.
//! These need a trace or a bench, so they sit here rather than in `model::phase`.

use crate::measure::track::{FringeModel, Harmonic};
use crate::model::extrinsics::Extrinsics;
use crate::model::optics::{FabryPerot, FringeExpansion};
use crate::model::phase::PhaseModel;
use crate::trace::Trace;

impl PhaseModel {
    /// The model of a bench preset (its robot, optics, ambient conditions and laser) with the
    /// given extrinsics.
    pub fn of_preset(preset: &crate::bench::BenchPreset, extrinsics: Extrinsics) -> Result<Self, String> {
        let robot = preset.robot_description().map_err(|e| e.to_string())?;
        Self::new(robot, extrinsics, preset.optics, &preset.ambient, preset.laser.wavelength_nm)
    }

    /// The motion hint of a trace: predicted phase-equivalent gap change (nm) per sample,
    /// relative to the first sample.
    pub fn hint_nm(&self, trace: &Trace, wavelength_nm: f64) -> Result<Vec<f64>, String> {
        let fp = FabryPerot::new(&self.optics, wavelength_nm, self.n_air).map_err(|e| e.to_string())?;
        let mut out = Vec::with_capacity(trace.len());
        let mut first = None;
        for i in 0..trace.len() {
            let g = self.phase_gap_nm(&fp, &trace.joints_display(i));
            if !g.is_finite() {
                return Err(format!("sample {i}: the beam misses the lamella at these joints"));
            }
            let g0 = *first.get_or_insert(g);
            out.push(g - g0);
        }
        Ok(out)
    }

    /// The fringe's shape at every sample of a trace (`FabryPerot::fringe_shape` at the
    /// model's gap and tilt): harmonics relative to the fundamental, offset and amplitude
    /// (relative to the input power). On rotations the tilt phase turns the multi-beam
    /// harmonics against the fundamental and the tilt coupling changes the amplitude by up
    /// to 50 % per fringe; the model knows both at every joint position.
    pub fn fringe_shape(&self, trace: &Trace, wavelength_nm: f64) -> Result<FringeShapeTrace, String> {
        let fp = FabryPerot::new(&self.optics, wavelength_nm, self.n_air).map_err(|e| e.to_string())?;
        let mut ex = FringeExpansion::default();
        let n = trace.len();
        let mut out = FringeShapeTrace {
            harmonics: Vec::with_capacity(n),
            offset: Vec::with_capacity(n),
            amplitude: Vec::with_capacity(n),
        };
        for i in 0..n {
            let (gap_um, tilt_rad) = self
                .gap_and_tilt(&trace.joints_display(i))
                .ok_or_else(|| format!("sample {i}: the beam misses the lamella at these joints"))?;
            let s = fp.fringe_shape(gap_um, tilt_rad, &mut ex);
            out.harmonics.push(Harmonic::from_phasors(s.second, s.third));
            out.offset.push(s.offset);
            out.amplitude.push(s.fundamental.max(f64::MIN_POSITIVE));
        }
        Ok(out)
    }
}

/// The optics model's fringe along a trace ([`PhaseModel::fringe_shape`]).
#[derive(Debug, Clone, Default)]
pub struct FringeShapeTrace {
    /// Harmonics relative to the fundamental, per sample.
    pub harmonics: Vec<Harmonic>,
    /// Fringe offset / input power, per sample.
    pub offset: Vec<f64>,
    /// Fundamental's amplitude / input power, per sample.
    pub amplitude: Vec<f64>,
}

impl FringeShapeTrace {
    /// The view the phase tracker takes.
    pub fn as_model(&self) -> FringeModel<'_> {
        FringeModel { harmonics: &self.harmonics, offset: &self.offset, amplitude: &self.amplitude }
    }
}
