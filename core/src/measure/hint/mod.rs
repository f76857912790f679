//! What the phase model predicts along a trace: the motion hint (the phase-equivalent gap
//! change at every sample) and the fringe's shape, and the model of a bench preset.
//! These need a trace or a bench, so they sit here rather than in `model::phase`.

use crate::measure::track::{FringeModel, Harmonic};
use crate::model::extrinsics::Extrinsics;
use crate::model::optics::{FabryPerot, FringeExpansion};
use crate::model::phase::PhaseModel;
use crate::trace::Trace;

mod knots;

impl PhaseModel {
    /// The model of a bench preset (its robot, optics, ambient conditions and laser) with the
    /// given extrinsics.
    pub fn of_preset(preset: &crate::bench::BenchPreset, extrinsics: Extrinsics) -> Result<Self, String> {
        let robot = preset.robot_description().map_err(|e| e.to_string())?;
        Self::new(robot, extrinsics, preset.optics, &preset.ambient, preset.laser.wavelength_nm)
    }

    /// The motion hint of a trace: predicted phase-equivalent gap change (nm) per sample,
    /// relative to the first sample. The model is evaluated at every 16th sample and at each
    /// interval's middle, and interpolated between where the joints are smooth at the sample
    /// scale and the middle agrees within [`HINT_TOL_NM`]; elsewhere at every sample.
    pub fn hint_nm(&self, trace: &Trace, wavelength_nm: f64) -> Result<Vec<f64>, String> {
        let fp = FabryPerot::new(&self.optics, wavelength_nm, self.n_air).map_err(|e| e.to_string())?;
        let geometry = self.extrinsics.geometry();
        let gaps = knots::along_trace(trace, &[HINT_TOL_NM], |i| {
            let g = self.phase_gap_nm_in(&geometry, &fp, &trace.joints_display(i));
            if g.is_finite() {
                Ok([g])
            } else {
                Err(format!("sample {i}: the beam misses the lamella at these joints"))
            }
        })?;
        let g0 = gaps.first().map_or(0.0, |g| g[0]);
        Ok(gaps.iter().map(|g| g[0] - g0).collect())
    }

    /// The cavity's length |L| (µm) at every sample: the model's geometry alone, without the
    /// optics, evaluated and interpolated as [`PhaseModel::hint_nm`] (within [`GAP_TOL_UM`] at
    /// the intervals' middles).
    pub fn gap_um_along(&self, trace: &Trace) -> Result<Vec<f64>, String> {
        let geometry = self.extrinsics.geometry();
        let gaps = knots::along_trace(trace, &[GAP_TOL_UM], |i| {
            self.gap_and_tilt_in(&geometry, &trace.joints_display(i))
                .map(|(gap_um, _)| [gap_um])
                .ok_or_else(|| format!("sample {i}: the beam misses the lamella at these joints"))
        })?;
        Ok(gaps.iter().map(|g| g[0]).collect())
    }

    /// The motion hint ([`PhaseModel::hint_nm`], the same values) and the fringe's shape at
    /// every sample ([`FabryPerot::fringe_shape`] at the sample's gap and tilt, evaluated and
    /// interpolated as the hint, within [`SHAPE_TOL`] at the intervals' middles): what the
    /// shaped tracker takes as its fringe model.
    pub fn hint_and_shape(&self, trace: &Trace, wavelength_nm: f64) -> Result<(Vec<f64>, FringeShapeTrace), String> {
        let fp = FabryPerot::new(&self.optics, wavelength_nm, self.n_air).map_err(|e| e.to_string())?;
        let mut ex = FringeExpansion::default();
        let geometry = self.extrinsics.geometry();
        let misses = |i: usize| format!("sample {i}: the beam misses the lamella at these joints");
        let tol = [HINT_TOL_NM, SHAPE_TOL, SHAPE_TOL, SHAPE_TOL, SHAPE_TOL, SHAPE_TOL, SHAPE_TOL];
        let values = knots::along_trace(trace, &tol, |i| {
            let (gap_um, tilt_rad) =
                self.gap_and_tilt_in(&geometry, &trace.joints_display(i)).ok_or_else(|| misses(i))?;
            let s = fp.fringe_shape(gap_um, tilt_rad, &mut ex);
            // The fundamental's phase as `FabryPerot::fundamental_phase_rad` gives it, to the bit.
            let phase = fp.fringe_phase_rad(gap_um, tilt_rad) + s.pulling_rad;
            let g = phase * fp.wavelength_nm() / (4.0 * std::f64::consts::PI * fp.medium_index());
            if !g.is_finite() {
                return Err(misses(i));
            }
            let h = Harmonic::from_phasors(s.second, s.third);
            Ok([g, h.cos_rel, h.sin_rel, h.cos3_rel, h.sin3_rel, s.offset, s.fundamental.max(f64::MIN_POSITIVE)])
        })?;
        let g0 = values.first().map_or(0.0, |v| v[0]);
        let hint = values.iter().map(|v| v[0] - g0).collect();
        let out = FringeShapeTrace {
            harmonics: values
                .iter()
                .map(|v| Harmonic { cos_rel: v[1], sin_rel: v[2], cos3_rel: v[3], sin3_rel: v[4] })
                .collect(),
            offset: values.iter().map(|v| v[5]).collect(),
            amplitude: values.iter().map(|v| v[6].max(f64::MIN_POSITIVE)).collect(),
        };
        Ok((hint, out))
    }
}

/// How far the interpolated cavity length may be from the model at an interval's middle, µm.
pub const GAP_TOL_UM: f64 = 1e-8;

/// How far the interpolated hint may be from the model at an interval's middle, nm.
pub const HINT_TOL_NM: f64 = 1e-5;

/// How far an interpolated harmonic (relative to the fundamental) or envelope term (relative to
/// the input power) may be from the model at an interval's middle.
pub const SHAPE_TOL: f64 = 1e-9;

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
    use crate::model::optics::FringeShape;
    use crate::plan::{JointTarget, Plan, Segment};
    use rand::{Rng, SeedableRng};

    /// One recorded motion of the virtual bench from the origin to `to`.
    fn motion(preset: &BenchPreset, to: [f64; 6]) -> Trace {
        let mut bench = VirtualBench::new(preset, Some(4)).unwrap();
        let plan = Plan {
            name: "motion".into(),
            description: String::new(),
            segments: vec![Segment::Move {
                to: JointTarget::all(to),
                record: true,
                label: "motion".into(),
                through: false,
            }],
        };
        let cancel = std::sync::atomic::AtomicBool::new(false);
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        run_plan(&mut bench, &plan, &mut control).traces.remove(0)
    }

    /// The model at every sample, one by one: the oracle of the interpolated evaluation.
    fn exact(model: &PhaseModel, trace: &Trace) -> (Vec<f64>, Vec<FringeShape>) {
        let fp = FabryPerot::new(&model.optics, trace.wavelength_nm[0], model.n_air).unwrap();
        let mut ex = FringeExpansion::default();
        let phase_gap = |i: usize| model.phase_gap_nm(&fp, &trace.joints_display(i));
        let hint = (0..trace.len()).map(|i| phase_gap(i) - phase_gap(0)).collect();
        let shapes = (0..trace.len())
            .map(|i| {
                let (gap_um, tilt_rad) = model.gap_and_tilt(&trace.joints_display(i)).unwrap();
                fp.fringe_shape(gap_um, tilt_rad, &mut ex)
            })
            .collect();
        (hint, shapes)
    }

    /// Largest distance of the hint and of the shape from the model at every sample.
    fn worst(model: &PhaseModel, trace: &Trace) -> (f64, f64) {
        let wavelength_nm = trace.wavelength_nm[0];
        let (hint, shape) = model.hint_and_shape(trace, wavelength_nm).unwrap();
        assert_eq!(hint, model.hint_nm(trace, wavelength_nm).unwrap(), "one hint, whichever call");
        let (hint_exact, shapes) = exact(model, trace);
        let hint_err = hint.iter().zip(&hint_exact).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        let mut shape_err = 0.0f64;
        for (i, s) in shapes.iter().enumerate() {
            let h = Harmonic::from_phasors(s.second, s.third);
            let got = shape.harmonics[i];
            for (a, b) in [
                (got.cos_rel, h.cos_rel),
                (got.sin_rel, h.sin_rel),
                (got.cos3_rel, h.cos3_rel),
                (got.sin3_rel, h.sin3_rel),
                (shape.offset[i], s.offset),
                (shape.amplitude[i], s.fundamental),
            ] {
                shape_err = shape_err.max((a - b).abs());
            }
        }
        (hint_err, shape_err)
    }

    /// The hint, the shape and the cavity's length, evaluated at knots and interpolated, are the
    /// model's at every sample within their tolerances, on translations, rotations and a motion
    /// of all six joints (where the tilt, the pulling and the harmonics all move).
    #[test]
    fn the_interpolated_hint_and_shape_are_the_model_at_every_sample() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let model = PhaseModel::of_preset(&preset, preset.truth).unwrap();
        for to in [
            [40.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 1.5, -1.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, 0.0, 3.0],
            [-20.0, 15.0, 30.0, -2.0, 1.0, -2.0],
        ] {
            let trace = motion(&preset, to);
            let (hint_err, shape_err) = worst(&model, &trace);
            assert!(hint_err <= HINT_TOL_NM, "to {to:?}: hint {hint_err:e} nm off the model");
            assert!(shape_err <= SHAPE_TOL, "to {to:?}: shape {shape_err:e} off the model");
            let gaps = model.gap_um_along(&trace).unwrap();
            for (i, g) in gaps.iter().enumerate() {
                let (exact, _) = model.gap_and_tilt(&trace.joints_display(i)).unwrap();
                assert!((g - exact).abs() <= GAP_TOL_UM, "to {to:?}, sample {i}: |L| {g} µm vs {exact} µm");
            }
        }
    }

    /// Joints that are not smooth at the sample scale (an encoder's quantisation, a glitch) are
    /// not interpolated over: the hint and the shape are the model's at every sample, to the bit.
    #[test]
    fn rough_joints_are_evaluated_at_every_sample() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let model = PhaseModel::of_preset(&preset, preset.truth).unwrap();
        let mut trace = motion(&preset, [0.0, 0.0, 0.0, 1.5, -1.0, 0.0]);
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        for q in trace.q4_deg.iter_mut() {
            *q = (*q * 1e5).round() / 1e5; // 0.01 mdeg steps
        }
        let glitch = trace.len() / 3 + 5;
        trace.q1_um[glitch] += 1e-4; // 0.1 nm on one sample
        for q in trace.q2_um.iter_mut() {
            *q += rng.random_range(-1e-6..1e-6);
        }
        let (hint, shape) = model.hint_and_shape(&trace, trace.wavelength_nm[0]).unwrap();
        let (hint_exact, shapes) = exact(&model, &trace);
        assert_eq!(hint, hint_exact);
        for (i, s) in shapes.iter().enumerate() {
            assert_eq!(shape.harmonics[i], Harmonic::from_phasors(s.second, s.third), "sample {i}");
            assert_eq!((shape.offset[i], shape.amplitude[i]), (s.offset, s.fundamental), "sample {i}");
        }
    }

    /// On a smooth motion the model is evaluated at about one sample in eight (knots and
    /// middles, and every sample where the stages' velocity profile has a kink); a value that
    /// cannot be interpolated is evaluated at every sample on its own.
    #[test]
    fn a_smooth_motion_is_evaluated_at_its_knots_and_middles() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let trace = motion(&preset, [40.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
        let n = trace.len();
        let mut calls = 0usize;
        let values = knots::along_trace(&trace, &[1e-9, 1e-9], |i| {
            calls += 1;
            // a smooth value, and one that turns every 7 samples (a harmonic on a fast rotation)
            let x = i as f64 / n as f64;
            Ok::<_, ()>([x * x * (3.0 - 2.0 * x), (0.9 * i as f64).sin()])
        })
        .unwrap();
        let expected = 2 * n / knots::KNOT_SAMPLES;
        assert!(calls < n + expected + 8, "{calls} evaluations of {n} samples");
        for (i, v) in values.iter().enumerate() {
            let x = i as f64 / n as f64;
            assert!((v[0] - x * x * (3.0 - 2.0 * x)).abs() < 1e-12, "sample {i}");
            assert_eq!(v[1], (0.9 * i as f64).sin(), "sample {i}");
        }
        let mut calls = 0usize;
        knots::along_trace(&trace, &[1e-9], |i| {
            calls += 1;
            Ok::<_, ()>([(3.0 * i as f64 / n as f64).sin()])
        })
        .unwrap();
        // the exact ones besides: the intervals where the stages' velocity profile has a kink
        assert!(calls < n / 6, "{calls} evaluations of {n} samples ({expected} knots and middles)");
    }
}
