//! The virtual bench: the robot, the optics and the sensors simulated around a hidden truth.
//! Owns the simulation in time (commanded motion → real motion → cavity → light → noisy samples); it writes only what a real bench would record.

use crate::bench::preset::BenchPreset;
use crate::bench::{Bench, BenchError, RunControl};
use crate::files::FileError;
use crate::model::air::{air_index_ciddor, AmbientConditions};
use crate::model::effects::{self, Effect};
use crate::model::extrinsics::{Extrinsics, FiberGeometry};
use crate::model::kinematics::Chain;
use crate::model::optics::FabryPerot;
use crate::model::robot::{JointType, RobotDescription};
use crate::plan::{MotionLimits, TimedSegment};
use crate::trace::{Trace, TraceMeta};
use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// A simulated bench. Its truth (extrinsics, hidden effects, noise) stays inside: the public
/// interface is the [`Bench`] trait, which yields recorded traces only.
pub struct VirtualBench {
    name: String,
    /// What the software believes the robot is (nominal description).
    robot: RobotDescription,
    motion: MotionLimits,
    ambient: AmbientConditions,
    truth: Truth,
    rng: StdRng,
    clock_s: f64,
    q_display: [f64; 6],
    wavelength_nm: f64,
}

/// The hidden part.
struct Truth {
    chain: Chain,
    extrinsics: Extrinsics,
    geometry: FiberGeometry,
    optics: crate::model::optics::OpticalParams,
    n_air: f64,
    laser_wavelength_nm: f64,
    fp: FabryPerot,
    path_effects: Vec<Effect>,
    joint_is_revolute: [bool; 6],
    white_sigma_mw: f64,
    shot_mw_at_1mw: f64,
    rin_rel: f64,
    adc_step_mw: f64,
    adc_full_scale_mw: f64,
    gain_drift_per_s: f64,
    sample_period_s: f64,
    encoder_sigma: [f64; 6],
    stage_sigma: [f64; 6],
}

impl VirtualBench {
    /// Build a bench from a preset; `seed` overrides the preset's seed.
    pub fn new(preset: &BenchPreset, seed: Option<u64>) -> Result<Self, BenchError> {
        let robot = preset.robot_description()?;
        if robot.dof() != 6 {
            return Err(BenchError::Config(format!(
                "bench {}: the virtual bench simulates six-joint robots, this one has {}",
                preset.name,
                robot.dof()
            )));
        }
        let truth_robot = effects::apply_all(&preset.effects, &robot)
            .map_err(|e| BenchError::Config(format!("bench {}: {e}", preset.name)))?;
        let n_air = air_index_ciddor(preset.laser.wavelength_nm, &preset.ambient)
            .map_err(|e| BenchError::Config(format!("bench {}: ambient: {e}", preset.name)))?;
        let fp = FabryPerot::new(&preset.optics, preset.laser.wavelength_nm, n_air)
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
        let truth = Truth {
            geometry: preset.truth.geometry(),
            extrinsics: preset.truth,
            optics: preset.optics,
            n_air,
            laser_wavelength_nm: preset.laser.wavelength_nm,
            fp,
            path_effects: preset
                .effects
                .iter()
                .filter(|e| matches!(e, Effect::ThermalDrift { .. } | Effect::PathScale { .. }))
                .cloned()
                .collect(),
            joint_is_revolute,
            white_sigma_mw: d.white_noise_rel_fringe * fringe0.amplitude_mw,
            shot_mw_at_1mw: d.shot_noise_mw_at_1mw,
            rin_rel: preset.laser.rin_rel,
            adc_step_mw: if d.adc_bits == 0 { 0.0 } else { d.adc_full_scale_mw / 2f64.powi(d.adc_bits as i32) },
            adc_full_scale_mw: d.adc_full_scale_mw,
            gain_drift_per_s: d.gain_drift_per_hour / 3600.0,
            sample_period_s: 1.0 / d.sample_rate_hz,
            encoder_sigma: per_joint(preset.stages.encoder_noise_nm, preset.stages.encoder_noise_urad),
            stage_sigma: per_joint(preset.stages.stage_noise_nm, preset.stages.stage_noise_urad),
            chain,
        };
        Ok(Self {
            name: preset.name.clone(),
            robot,
            motion: preset.motion,
            ambient: preset.ambient,
            truth,
            rng: StdRng::seed_from_u64(seed.unwrap_or(preset.seed)),
            clock_s: 0.0,
            q_display: [0.0; 6],
            wavelength_nm: preset.laser.wavelength_nm,
        })
    }

    /// An embedded preset or a preset file, by name or path.
    pub fn from_preset_name(name_or_path: &str, seed: Option<u64>) -> Result<Self, BenchError> {
        Self::new(&BenchPreset::resolve(name_or_path)?, seed)
    }

    /// Sampling period (s).
    pub fn sample_period_s(&self) -> f64 {
        self.truth.sample_period_s
    }

    /// One sample: the real joints (commanded + stage jitter) give the cavity and the light;
    /// the recorded joints are the encoder readings. Returns (encoder q in µm/°, irradiance mW).
    #[inline]
    fn sample(&mut self, t_s: f64, q_cmd_display: &[f64; 6], fp: Option<&FabryPerot>) -> ([f64; 6], f64) {
        let tr = &self.truth;
        let rng = &mut self.rng;
        let mut normal = |sigma: f64| -> f64 {
            if sigma == 0.0 {
                0.0
            } else {
                sigma * <StandardNormal as Distribution<f64>>::sample(&StandardNormal, rng)
            }
        };
        let mut q = [0.0; 6];
        let mut enc = [0.0; 6];
        for i in 0..6 {
            let real = q_cmd_display[i] + normal(tr.stage_sigma[i]);
            q[i] = if tr.joint_is_revolute[i] { real.to_radians() } else { real };
            enc[i] = real + normal(tr.encoder_sigma[i]);
        }
        let wte = tr.chain.end_effector(&q);
        let l_um = tr.extrinsics.cavity_length_um(&wte, &tr.geometry);
        let n_t = wte.rotation * (tr.geometry_tool_normal());
        let cos_tilt = n_t.dot(&tr.extrinsics.n_f().into_inner()).abs().min(1.0);
        let tilt = cos_tilt.acos();
        let mut gap_um = l_um.abs();
        for e in &tr.path_effects {
            gap_um += e.gap_change_nm(t_s, gap_um) * 1e-3;
        }
        let p = fp.unwrap_or(&tr.fp).power(gap_um, tilt);
        let p = p * (1.0 + tr.gain_drift_per_s * t_s);
        let shot = if tr.shot_mw_at_1mw > 0.0 { tr.shot_mw_at_1mw * p.max(0.0).sqrt() } else { 0.0 };
        let sigma = (tr.white_sigma_mw.powi(2) + shot * shot + (tr.rin_rel * p).powi(2)).sqrt();
        let mut v = p + normal(sigma);
        if tr.adc_step_mw > 0.0 {
            v = ((v / tr.adc_step_mw).round() * tr.adc_step_mw).clamp(0.0, tr.adc_full_scale_mw);
        }
        (enc, v)
    }
}

impl Truth {
    #[inline]
    fn geometry_tool_normal(&self) -> Vector3<f64> {
        self.extrinsics.n_t_in_ee().into_inner()
    }
}

impl Bench for VirtualBench {
    fn name(&self) -> String {
        format!("virtual bench {}", self.name)
    }

    fn robot(&self) -> &RobotDescription {
        &self.robot
    }

    fn motion_limits(&self) -> &MotionLimits {
        &self.motion
    }

    fn position_display(&self) -> [f64; 6] {
        self.q_display
    }

    fn wavelength_nm(&self) -> f64 {
        self.wavelength_nm
    }

    fn ambient(&self) -> AmbientConditions {
        self.ambient
    }

    fn clock_s(&self) -> f64 {
        self.clock_s
    }

    fn run_segment(
        &mut self,
        segment: &TimedSegment,
        meta: TraceMeta,
        control: &mut RunControl<'_>,
    ) -> Result<Option<Trace>, BenchError> {
        let dt = self.truth.sample_period_s;
        let duration = segment.duration_s;
        let n = (duration / dt).floor() as usize + 1;
        let record = segment.record;
        let mut trace = record.then(|| Trace::with_capacity(meta, n));
        let t0 = self.clock_s;
        let chunk = (0.05 / dt).max(1.0) as usize; // report progress every 50 ms of bench time
        let mut reported = 0;
        for k in 0..n {
            let t = k as f64 * dt;
            let q_cmd = segment.position_at(t);
            let wavelength = segment.wavelength_at(t).unwrap_or(self.truth.laser_wavelength_nm);
            if let Some(tr) = trace.as_mut() {
                let swept = (wavelength != self.truth.laser_wavelength_nm)
                    .then(|| FabryPerot::new(&self.truth.optics, wavelength, self.truth.n_air))
                    .transpose()
                    .map_err(|e| BenchError::Config(format!("optics at {wavelength} nm: {e}")))?;
                let (enc, v) = self.sample(t0 + t, &q_cmd, swept.as_ref());
                tr.push_sample(t0 + t, enc, wavelength, v);
            }
            self.q_display = q_cmd;
            self.wavelength_nm = wavelength;
            if (k + 1) % chunk == 0 || k + 1 == n {
                if control.cancelled() {
                    self.clock_s = t0 + t;
                    return Err(BenchError::Cancelled { partial: trace.map(Box::new) });
                }
                if let Some(tr) = trace.as_ref() {
                    (control.on_samples)(tr, reported);
                    reported = tr.len();
                }
                (control.on_progress)(t / duration.max(f64::MIN_POSITIVE));
            }
        }
        self.clock_s = t0 + duration;
        self.wavelength_nm = self.truth.laser_wavelength_nm;
        Ok(trace)
    }
}

impl From<FileError> for BenchError {
    fn from(e: FileError) -> Self {
        BenchError::Config(e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::{run_plan, PlanRun};
    use crate::plan::{JointTarget, Plan, Segment};
    use std::sync::atomic::AtomicBool;

    fn run(bench: &mut VirtualBench, plan: &Plan) -> PlanRun {
        let cancel = AtomicBool::new(false);
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        run_plan(bench, plan, &mut control)
    }

    fn plan(segments: Vec<Segment>) -> Plan {
        Plan { name: "test".into(), description: String::new(), segments }
    }

    fn mv(target: JointTarget, record: bool) -> Segment {
        Segment::Move { to: target, record, label: "move".into() }
    }

    fn dwell(s: f64) -> Segment {
        Segment::Dwell { duration_s: s, record: true, label: "dwell".into() }
    }

    #[test]
    fn same_seed_gives_the_same_trace_and_another_seed_other_noise() {
        let p = plan(vec![mv(JointTarget::default().with(1, 5.0), true)]);
        let a = run(&mut VirtualBench::from_preset_name("table2-ideal", Some(3)).unwrap(), &p);
        let b = run(&mut VirtualBench::from_preset_name("table2-ideal", Some(3)).unwrap(), &p);
        let c = run(&mut VirtualBench::from_preset_name("table2-ideal", Some(4)).unwrap(), &p);
        assert_eq!(a.traces[0].irradiance, b.traces[0].irradiance);
        assert_ne!(a.traces[0].irradiance, c.traces[0].irradiance);
        assert!(a.outcome.is_ok());
    }

    #[test]
    fn a_trace_holds_only_what_a_real_bench_records() {
        let p = plan(vec![mv(JointTarget::default().with(2, 50.0), true)]);
        let r = run(&mut VirtualBench::from_preset_name("femto-lab", None).unwrap(), &p);
        let t = &r.traces[0];
        assert!(t.extra.is_empty(), "no hidden columns");
        let csv = String::from_utf8(t.to_csv_bytes(std::path::Path::new("t.csv")).unwrap()).unwrap();
        for secret in ["112.4", "113.3", "0.744", "ThermalDrift", "PivotOffset", "truth"] {
            assert!(!csv.contains(secret), "the trace leaks `{secret}`");
        }
        // Encoders read the joints with noise (femto-lab): the recorded q3 is near, not at, the command.
        let last = t.q3_um.last().unwrap();
        assert!((last - 50.0).abs() < 0.02 && *last != 50.0, "q3 = {last}");
    }

    #[test]
    fn motion_is_velocity_limited_and_sampled_at_the_preset_rate() {
        let mut b = VirtualBench::from_preset_name("table2-ideal", None).unwrap();
        let p = plan(vec![mv(JointTarget::default().with(2, 100.0), true)]);
        let r = run(&mut b, &p);
        let t = &r.traces[0];
        let dt = t.t_s[1] - t.t_s[0];
        assert!((dt - 1e-4).abs() < 1e-12, "10 kHz");
        // 100 µm at 100 µm/s with 1000 µm/s² ramps: 1.1 s, plus 0.05 s settling.
        let span = t.t_s.last().unwrap() - t.t_s[0];
        assert!((span - 1.15).abs() < 2e-4, "duration {span}");
        let max_speed = t.q3_um.windows(2).map(|w| (w[1] - w[0]) / dt).fold(0.0, f64::max);
        assert!(max_speed <= 100.0 + 1e-6, "max speed {max_speed} µm/s");
        assert_eq!(b.position_display()[2], 100.0);
    }

    /// Fringe count of a 20 µm move along the beam against the truth computed independently
    /// from the extrinsics: 2·n·Δd/λ fringes, with d the perpendicular gap.
    #[test]
    fn fringes_of_an_axial_move_match_the_truth() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let mut b = VirtualBench::new(&preset, None).unwrap();
        let p = plan(vec![
            mv(JointTarget::default().with(1, -10.0), false),
            mv(JointTarget::default().with(1, 10.0), true),
        ]);
        let r = run(&mut b, &p);
        let t = &r.traces[0];
        let chain = Chain::femto_6dof();
        let d = |q2: f64| {
            let c = preset.truth.cavity(&chain.end_effector(&[0.0, q2, 0.0, 0.0, 0.0, 0.0])).unwrap();
            c.length_um.abs() * c.tilt_rad.cos()
        };
        let n = air_index_ciddor(1560.0, &preset.ambient).unwrap();
        let fringes = 2.0 * n * (d(10.0) - d(-10.0)).abs() / 1.560;
        // Count maxima crossing the mean: each fringe gives one upward crossing.
        let mean = t.irradiance.iter().sum::<f64>() / t.len() as f64;
        let crossings = t.irradiance.windows(2).filter(|w| w[0] < mean && w[1] >= mean).count();
        assert!((crossings as f64 - fringes).abs() <= 1.0, "{crossings} crossings, {fringes:.2} fringes expected");
        assert!(fringes > 25.0);
    }

    #[test]
    fn detector_noise_is_the_preset_fraction_of_the_fringe_amplitude() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let mut b = VirtualBench::new(&preset, Some(11)).unwrap();
        let r = run(&mut b, &plan(vec![dwell(1.0)]));
        let v = &r.traces[0].irradiance;
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt();
        let c = preset.truth.cavity(&Chain::femto_6dof().end_effector(&[0.0; 6])).unwrap();
        let n = air_index_ciddor(1560.0, &preset.ambient).unwrap();
        let b_amp =
            FabryPerot::new(&preset.optics, 1560.0, n).unwrap().two_beam(c.length_um.abs(), c.tilt_rad).amplitude_mw;
        assert!((sd / b_amp - 1e-3).abs() < 0.05e-3, "σ/B = {}", sd / b_amp);
    }

    #[test]
    fn hidden_thermal_drift_moves_the_fringes_at_rest() {
        let mut preset = BenchPreset::resolve("table2-ideal").unwrap();
        preset.effects = vec![Effect::ThermalDrift { nm_per_s: 200.0, nm_per_s2: 0.0 }];
        let mut b = VirtualBench::new(&preset, None).unwrap();
        let r = run(&mut b, &plan(vec![dwell(8.0)]));
        // A 50 ms boxcar (the fringe period here is ~3.9 s) removes the noise chatter.
        let v: Vec<f64> = r.traces[0].irradiance.chunks(500).map(|c| c.iter().sum::<f64>() / c.len() as f64).collect();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let crossings = v.windows(2).filter(|w| (w[0] < mean) != (w[1] < mean)).count();
        // 1.6 µm of drift = 2·1.6/1.56 ≈ 2.05 fringes: about 4 mean crossings.
        assert!((3..=5).contains(&crossings), "{crossings} crossings");
    }

    #[test]
    fn cancelling_keeps_the_samples_recorded_so_far() {
        let mut b = VirtualBench::from_preset_name("table2-ideal", None).unwrap();
        let p = plan(vec![dwell(0.5), dwell(2.0)]);
        let cancel = AtomicBool::new(false);
        let mut seen = 0usize;
        let mut on_samples = |t: &Trace, _from: usize| {
            seen = t.len();
            if t.t_s.last().copied().unwrap_or(0.0) > 1.0 {
                cancel.store(true, std::sync::atomic::Ordering::Relaxed);
            }
        };
        let mut control = RunControl { cancel: &cancel, on_samples: &mut on_samples, on_progress: &mut |_| {} };
        let r = run_plan(&mut b, &p, &mut control);
        assert!(matches!(
            r.outcome,
            Err(crate::bench::RunError::Segment { segment: 1, error: BenchError::Cancelled { .. }, .. })
        ));
        assert_eq!(r.traces.len(), 2, "the finished dwell and the partial one");
        assert!(r.traces[1].len() > 1000 && r.traces[1].len() < 20001);
        assert!(seen > 0);
    }

    #[test]
    fn a_plan_out_of_limits_moves_nothing() {
        let mut b = VirtualBench::from_preset_name("table2-ideal", None).unwrap();
        let p =
            plan(vec![mv(JointTarget::default().with(2, 50.0), true), mv(JointTarget::default().with(3, 12.0), true)]);
        let r = run(&mut b, &p);
        assert!(r.traces.is_empty());
        assert_eq!(b.position_display(), [0.0; 6]);
        let msg = r.outcome.unwrap_err().to_string();
        assert!(msg.contains("q4 = 12.000 ° is 2.000 ° above its upper limit 10.000 °"), "{msg}");
    }

    #[test]
    fn presets_are_valid_and_errors_name_fields() {
        for (name, _) in crate::bench::preset::EMBEDDED {
            VirtualBench::from_preset_name(name, None).unwrap();
        }
        let text = crate::bench::preset::EMBEDDED[0].1.replace("sample_rate_hz: 10000.0", "sample_rate_hz: -1.0");
        let err = BenchPreset::from_ron_str(&text, std::path::Path::new("b.ron")).unwrap_err().to_string();
        assert_eq!(err, "b.ron: field `detector.sample_rate_hz`: expected a positive number, found -1");
        let err = BenchPreset::resolve("no-such-bench").unwrap_err().to_string();
        assert!(err.contains("expected one of: table2-ideal, femto-lab"), "{err}");
    }
}
