//! Experiment: which half of the model (the hint in time or the fringe shape) biases the
//! tracked gap of a validation motion planned with wrong extrinsics.
use super::*;
use crate::bench::{BenchPreset, VirtualBench};
use crate::measure::track::{track_phase_shaped, TrackConfig};
use crate::model::extrinsics::PARAMETER_NAMES;

fn cfg(free: bool) -> TrackConfig {
    TrackConfig {
        per_sample_sigma: true,
        envelope_walk_per_sqrt_fringe: 0.003,
        phase_walk_rad_per_sqrt_fringe: 0.005,
        start_walk_rad: 0.0,
        phase_noise_rad_per_sqrt_sample: if free {
            measure::FREE_PHASE_RAD_PER_SQRT_SAMPLE
        } else {
            TrackConfig::default().phase_noise_rad_per_sqrt_sample
        },
        ..TrackConfig::default()
    }
}

#[test]
#[ignore = "an experiment that prints which half of the model biases the tracked gap: run with --ignored --nocapture"]
fn which_half_biases() {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let truth_m = PhaseModel::of_preset(&preset, preset.truth).unwrap();
    for (name, d) in [("theta_wf", 1.0), ("theta_wf", 0.1), ("theta_et", 0.1), ("beta_et", 1.0)] {
        let mut a = preset.truth.to_array();
        a[PARAMETER_NAMES.iter().position(|p| p.0 == name).unwrap()] += d;
        let e = Extrinsics::from_array(a);
        let model = PhaseModel::of_preset(&preset, e).unwrap();
        for motion in
            [ValidationMotion::RotationXf, ValidationMotion::RotationZf, ValidationMotion::RotationOpticalAxis]
        {
            let mut bench = VirtualBench::new(&preset, Some(5)).unwrap();
            let r = record_validation(
                &mut bench,
                &model,
                &e,
                motion,
                [0.0; 6],
                &Compensation::default(),
                &StopSettings::default(),
                &AtomicBool::new(false),
            )
            .unwrap();
            let t = &r.trace;
            let s = r.dither_end;
            let w = t.wavelength_nm[0];
            let (hint_e, shape_e) = model.hint_and_shape(t, w).unwrap();
            let (hint_t, shape_t) = truth_m.hint_and_shape(t, w).unwrap();
            let fringe = w / (2.0 * model.n_air);
            let travel: f64 = hint_e[s..].windows(2).map(|x| (x[1] - x[0]).abs()).sum();
            let free = travel < 2.0 * fringe;
            let ptp_err = |dl: &[f64]| {
                let v: Vec<f64> = (s..t.len()).map(|i| (dl[i] - dl[s]) - (hint_t[i] - hint_t[s])).collect();
                v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min)
            };
            let mut line = format!("{name} {d:+}: {}: free {free}", motion.name());
            for (lab, h, sh) in [
                ("e/e", &hint_e, &shape_e),
                ("t/e", &hint_t, &shape_e),
                ("e/t", &hint_e, &shape_t),
                ("t/t", &hint_t, &shape_t),
            ] {
                for fr in [free, true] {
                    let tr = track_phase_shaped(&t.irradiance, h, &sh.as_model(), w, model.n_air, &cfg(fr)).unwrap();
                    line += &format!(" | {lab}{} {:.1}", if fr { "F" } else { "" }, ptp_err(&tr.dl_nm));
                }
            }
            let mut mix_h = shape_e.clone();
            mix_h.harmonics = shape_t.harmonics.clone();
            let mut mix_a = shape_e.clone();
            mix_a.amplitude = shape_t.amplitude.clone();
            mix_a.offset = shape_t.offset.clone();
            for (lab, sh) in [("harm_t", &mix_h), ("amp_t", &mix_a)] {
                let tr =
                    track_phase_shaped(&t.irradiance, &hint_e, &sh.as_model(), w, model.n_air, &cfg(free)).unwrap();
                line += &format!(" | {lab} {:.1}", ptp_err(&tr.dl_nm));
            }
            let flat: Vec<f64> = (0..t.len()).map(|i| if i < s { hint_e[i] } else { hint_e[s] }).collect();
            let tr = track_phase_shaped(&t.irradiance, &flat, &shape_e.as_model(), w, model.n_air, &cfg(true)).unwrap();
            line += &format!(" | flat/e F {:.1}", ptp_err(&tr.dl_nm));
            eprintln!("{line}");
        }
    }
}

/// The tracker's χ² against the tilt the shape is computed at: γ_e + s·(γ_t − γ_e).
#[test]
#[ignore = "an experiment that prints the tracker's χ² against the tilt of the fringe shape: run with --ignored --nocapture"]
fn chi2_against_tilt() {
    use crate::measure::hint::FringeShapeTrace;
    use crate::measure::track::Harmonic;
    use crate::model::optics::FabryPerot;
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let truth_m = PhaseModel::of_preset(&preset, preset.truth).unwrap();
    for (name, d) in [("theta_wf", 0.1), ("theta_wf", 1.0), ("beta_et", 1.0)] {
        let mut a = preset.truth.to_array();
        a[PARAMETER_NAMES.iter().position(|p| p.0 == name).unwrap()] += d;
        let e = Extrinsics::from_array(a);
        let model = PhaseModel::of_preset(&preset, e).unwrap();
        for motion in [ValidationMotion::RotationXf, ValidationMotion::RotationZf] {
            let mut bench = VirtualBench::new(&preset, Some(5)).unwrap();
            let r = record_validation(
                &mut bench,
                &model,
                &e,
                motion,
                [0.0; 6],
                &Compensation::default(),
                &StopSettings::default(),
                &AtomicBool::new(false),
            )
            .unwrap();
            let t = &r.trace;
            let s = r.dither_end;
            let w = t.wavelength_nm[0];
            let (hint_e, _) = model.hint_and_shape(t, w).unwrap();
            let (hint_t, _) = truth_m.hint_and_shape(t, w).unwrap();
            let fp = FabryPerot::new(&model.optics, w, model.n_air).unwrap();
            let step = 20;
            let ge: Vec<(f64, f64)> =
                (0..t.len()).step_by(step).map(|i| model.gap_and_tilt(&t.joints_display(i)).unwrap()).collect();
            let gt: Vec<(f64, f64)> =
                (0..t.len()).step_by(step).map(|i| truth_m.gap_and_tilt(&t.joints_display(i)).unwrap()).collect();
            let ptp_err = |dl: &[f64]| {
                let v: Vec<f64> = (s..t.len()).map(|i| (dl[i] - dl[s]) - (hint_t[i] - hint_t[s])).collect();
                v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min)
            };
            let mut line = format!(
                "{name} {d:+}: {}: tilt e {:.3}..{:.3}° t {:.3}..{:.3}°",
                motion.name(),
                ge.iter().map(|g| g.1.to_degrees()).fold(f64::MAX, f64::min),
                ge.iter().map(|g| g.1.to_degrees()).fold(f64::MIN, f64::max),
                gt.iter().map(|g| g.1.to_degrees()).fold(f64::MAX, f64::min),
                gt.iter().map(|g| g.1.to_degrees()).fold(f64::MIN, f64::max)
            );
            for sfac in [0.0, 0.5, 0.9, 1.0, 1.1, 1.5] {
                let mut ex = Default::default();
                let knots: Vec<_> =
                    ge.iter().zip(&gt).map(|(a, b)| fp.fringe_shape(a.0, a.1 + sfac * (b.1 - a.1), &mut ex)).collect();
                let at = |i: usize| &knots[(i / step).min(knots.len() - 1)];
                let sh = FringeShapeTrace {
                    harmonics: (0..t.len()).map(|i| Harmonic::from_phasors(at(i).second, at(i).third)).collect(),
                    offset: (0..t.len()).map(|i| at(i).offset).collect(),
                    amplitude: (0..t.len()).map(|i| at(i).fundamental.max(f64::MIN_POSITIVE)).collect(),
                };
                let tr =
                    track_phase_shaped(&t.irradiance, &hint_e, &sh.as_model(), w, model.n_air, &cfg(false)).unwrap();
                line += &format!(" | s={sfac}: err {:.1} χ² {:.4}", ptp_err(&tr.dl_nm), tr.normalized_chi2);
            }
            eprintln!("{line}");
        }
    }
}
