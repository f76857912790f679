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
        let geometry = self.extrinsics.geometry();
        let mut out = Vec::with_capacity(trace.len());
        let mut first = None;
        for i in 0..trace.len() {
            let g = self.phase_gap_nm_in(&geometry, &fp, &trace.joints_display(i));
            if !g.is_finite() {
                return Err(format!("sample {i}: the beam misses the lamella at these joints"));
            }
            let g0 = *first.get_or_insert(g);
            out.push(g - g0);
        }
        Ok(out)
    }

    /// The motion hint ([`PhaseModel::hint_nm`], the same values) and the fringe's shape at
    /// every sample of a trace (`FabryPerot::fringe_shape` at the model's gap and tilt:
    /// harmonics relative to the fundamental, offset and amplitude relative to the input
    /// power), each sample's pose computed once for both. On rotations the tilt phase turns the
    /// multi-beam harmonics against the fundamental and the tilt coupling changes the amplitude
    /// by up to 50 % per fringe; the model knows both at every joint position.
    pub fn hint_and_shape(&self, trace: &Trace, wavelength_nm: f64) -> Result<(Vec<f64>, FringeShapeTrace), String> {
        let fp = FabryPerot::new(&self.optics, wavelength_nm, self.n_air).map_err(|e| e.to_string())?;
        let mut ex = FringeExpansion::default();
        let n = trace.len();
        let mut hint = Vec::with_capacity(n);
        let mut out = FringeShapeTrace {
            harmonics: Vec::with_capacity(n),
            offset: Vec::with_capacity(n),
            amplitude: Vec::with_capacity(n),
        };
        let mut first = None;
        let geometry = self.extrinsics.geometry();
        for i in 0..n {
            let (gap_um, tilt_rad) = self
                .gap_and_tilt_in(&geometry, &trace.joints_display(i))
                .ok_or_else(|| format!("sample {i}: the beam misses the lamella at these joints"))?;
            let s = fp.fringe_shape(gap_um, tilt_rad, &mut ex);
            // The fundamental's phase as `FabryPerot::fundamental_phase_rad` gives it, to the bit.
            let phase = fp.fringe_phase_rad(gap_um, tilt_rad) + s.pulling_rad;
            let g = phase * fp.wavelength_nm() / (4.0 * std::f64::consts::PI * fp.medium_index());
            if !g.is_finite() {
                return Err(format!("sample {i}: the beam misses the lamella at these joints"));
            }
            hint.push(g - *first.get_or_insert(g));
            out.harmonics.push(Harmonic::from_phasors(s.second, s.third));
            out.offset.push(s.offset);
            out.amplitude.push(s.fundamental.max(f64::MIN_POSITIVE));
        }
        Ok((hint, out))
    }
}

/// The optics model's fringe along a trace ([`PhaseModel::hint_and_shape`]).
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::{run_plan, BenchPreset, RunControl, VirtualBench};
    use crate::plan::{JointTarget, Plan, Segment};

    /// The one pass gives, to the bit, the hint of [`PhaseModel::hint_nm`] and the shape of
    /// `FabryPerot::fringe_shape` at each sample's gap and tilt, on a rotation (where the
    /// tilt, the pulling and the harmonics all move).
    #[test]
    fn hint_and_shape_are_the_hint_and_the_optics_shape_to_the_bit() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let mut bench = VirtualBench::new(&preset, Some(4)).unwrap();
        let to = JointTarget::all([0.0, 0.0, 0.0, 1.5, -1.0, 0.0]);
        let plan = Plan {
            name: "rotation".into(),
            description: String::new(),
            segments: vec![Segment::Move { to, record: true, label: "q4, q5".into() }],
        };
        let cancel = std::sync::atomic::AtomicBool::new(false);
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        let trace = run_plan(&mut bench, &plan, &mut control).traces.remove(0);
        let model = PhaseModel::of_preset(&preset, preset.truth).unwrap();
        let wavelength_nm = trace.wavelength_nm[0];
        let (hint, shape) = model.hint_and_shape(&trace, wavelength_nm).unwrap();
        assert_eq!(hint, model.hint_nm(&trace, wavelength_nm).unwrap());
        let fp = FabryPerot::new(&model.optics, wavelength_nm, model.n_air).unwrap();
        let mut ex = FringeExpansion::default();
        for i in (0..trace.len()).step_by(97) {
            let (gap_um, tilt_rad) = model.gap_and_tilt(&trace.joints_display(i)).unwrap();
            let s = fp.fringe_shape(gap_um, tilt_rad, &mut ex);
            assert_eq!(shape.harmonics[i], Harmonic::from_phasors(s.second, s.third), "sample {i}");
            assert_eq!((shape.offset[i], shape.amplitude[i]), (s.offset, s.fundamental), "sample {i}");
        }
        assert!(hint.last().unwrap().abs() > 1000.0, "the rotation moves the gap by fringes");
    }
}
