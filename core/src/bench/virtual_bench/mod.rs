//! The virtual bench: the robot, the optics and the sensors simulated around a hidden truth.
//! Owns the simulation in time (commanded motion → real motion → cavity → light → noisy samples); it writes only what a real bench would record.
//!
//! # A sample
//!
//! Each sample draws, joint by joint, the stage jitter then the encoder noise (zero sigmas are
//! skipped), then the detector noise: standard normal deviates of a 128-layer ziggurat on
//! xoshiro256++ seeded (through SplitMix64) by the preset's seed or the run's, so a run is
//! reproducible from its seed on any platform. The real joints are the commanded ones plus
//! the jitter; the recorded joints are the real ones plus the encoder noise; the recorded
//! irradiance is the reflected power (times the detector gain drift) plus white, shot and RIN
//! noise, quantised by the ADC.
//!
//! The reflected power is computed on one of two paths, which draw the same noise:
//! - exact ([`VirtualBench::set_exact`]): per sample, the DGM at the real joints, the cavity
//!   length L, the tilt θ = acos|n_t·n_f|, the path effects and the multi-beam
//!   [`FabryPerot::power`] (at the swept wavelength during a sweep);
//! - fast (the default): the same model, rearranged for dense sampling (the `fast_path` module).

mod fast_path;
mod noise;
#[cfg(test)]
mod tests;
mod truth;

use crate::bench::preset::BenchPreset;
use crate::bench::{Bench, BenchError, RunControl};
use crate::model::air::AmbientConditions;
use crate::model::effects::{self, Effect};
use crate::model::optics::FabryPerot;
use crate::model::robot::RobotDescription;
use crate::plan::{MotionLimits, TimedMotion, TimedSegment};
use crate::trace::{Trace, TraceMeta};
use fast_path::FastSegment;
use noise::{ziggurat_tables, Gaussian};
use truth::Truth;

pub use fast_path::{FAST_PATH_TOLERANCE, MAX_NODE_INTERVAL};

/// A simulated bench. Its truth (extrinsics, hidden effects, noise) stays inside: the public
/// interface is the [`Bench`] trait, which yields recorded traces only.
pub struct VirtualBench {
    name: String,
    /// What the software believes the robot is (nominal description).
    robot: RobotDescription,
    motion: MotionLimits,
    ambient: AmbientConditions,
    truth: Truth,
    rng: Gaussian,
    clock_s: f64,
    q_display: [f64; 6],
    wavelength_nm: f64,
    /// Evaluate every sample on the exact path.
    exact: bool,
    /// Where each stage sits in its play (hidden reversal errors).
    play: effects::Backlash,
    /// The preset's laser sweeps (`laser.tunable`).
    tunable: bool,
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
        let truth = Truth::new(preset, &robot)?;
        Ok(Self {
            name: preset.name.clone(),
            robot,
            motion: preset.motion,
            ambient: preset.ambient,
            truth,
            rng: Gaussian::seed_from_u64(seed.unwrap_or(preset.seed)),
            clock_s: 0.0,
            q_display: [0.0; 6],
            wavelength_nm: preset.laser.wavelength_nm,
            exact: false,
            play: effects::Backlash::default(),
            tunable: preset.laser.tunable,
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

    /// Resume the bench at bench time `t_s` (s): what a bench that kept running since a
    /// recorded session would show (its drift goes on from there). A diagnosis that runs
    /// motions after a session recorded earlier on this bench starts it at the session's end.
    pub fn set_clock_s(&mut self, t_s: f64) {
        if t_s.is_finite() {
            self.clock_s = t_s;
        }
    }

    /// Compute every sample on the exact path (true) or on the fast path (false, the default);
    /// see the module documentation. Both draw the same noise: a seed gives the same trace on
    /// either path to within the fast path's tolerance.
    pub fn set_exact(&mut self, exact: bool) {
        self.exact = exact;
    }

    /// The noise-free reflected power (mW) the truth gives at bench time `t_s`, real joints
    /// `q_display` (µm, °) and vacuum wavelength `wavelength_nm`: what an emulated photodiode sees
    /// (the hardware emulators' optics). Detector noise is not added (see [`Self::white_noise_sigma_mw`]).
    pub fn reflected_power_mw(&self, t_s: f64, q_display: &[f64; 6], wavelength_nm: f64) -> Result<f64, String> {
        let tr = &self.truth;
        if wavelength_nm == tr.laser_wavelength_nm {
            return Ok(tr.power_exact(t_s, q_display, &tr.fp));
        }
        let fp = FabryPerot::new(&tr.optics, wavelength_nm, tr.n_air)
            .map_err(|e| format!("optics at {wavelength_nm} nm: {e}"))?;
        Ok(tr.power_exact(t_s, q_display, &fp))
    }

    /// Standard deviation (mW) of the white detector noise of a sample.
    pub fn white_noise_sigma_mw(&self) -> f64 {
        self.truth.white_sigma_mw
    }

    /// Record samples `range` of `segment` (started at bench time `t0`) into `trace`, block by
    /// block ([`Block`]).
    fn record_samples(
        &mut self,
        segment: &TimedSegment,
        t0: f64,
        range: std::ops::Range<usize>,
        trace: &mut Trace,
        mut fast: Option<&mut FastSegment>,
    ) -> Result<(), BenchError> {
        let tr = &self.truth;
        let rng = &mut self.rng;
        let play = &mut self.play;
        let zig = ziggurat_tables();
        let dt = tr.sample_period_s;
        let laser = tr.laser_wavelength_nm;
        let mut block = Block::default();
        let mut k = range.start;
        while k < range.end {
            let mut n = BLOCK.min(range.end - k);
            if let Some(f) = fast.as_deref_mut() {
                // A block stays within one node interval.
                f.cover(tr, k as f64 * dt)?;
                if !f.done {
                    n = (0..n).take_while(|&j| (k + j) as f64 * dt <= f.tb).count().max(1);
                }
            }
            // Commands, then the noise: per sample the joint draws in order, then the detector's.
            for j in 0..n {
                let t = (k + j) as f64 * dt;
                let (q, s) = command(segment, t);
                block.t[j] = t;
                block.s[j] = s;
                block.q[j] = q;
                block.wavelength[j] = segment.wavelength_at(t).unwrap_or(laser);
            }
            let per_sample = tr.draws.len() + usize::from(tr.detector_noise);
            let deviates = &mut block.deviates[..n * per_sample];
            rng.fill(zig, deviates);
            for j in 0..n {
                let drawn = &deviates[j * per_sample..(j + 1) * per_sample];
                let noise = &mut block.noise[j];
                if tr.draws.len() < 12 {
                    *noise = [0.0; 12];
                }
                for (d, x) in tr.draws.iter().zip(drawn) {
                    noise[d.slot] = d.sigma * x;
                }
                block.detector[j] = if tr.detector_noise { drawn[per_sample - 1] } else { 0.0 };
            }
            // The light.
            match fast.as_deref_mut() {
                Some(f) => f.power_block(&mut block, n),
                None => {
                    for j in 0..n {
                        play.follow(&block.q[j], &tr.play_width);
                        let real: [f64; 6] =
                            std::array::from_fn(|i| block.q[j][i] + play.offset[i] + block.noise[j][i]);
                        let wavelength = block.wavelength[j];
                        let p = if wavelength == laser {
                            Ok(tr.power_exact(t0 + block.t[j], &real, &tr.fp))
                        } else {
                            FabryPerot::new(&tr.optics, wavelength, tr.n_air)
                                .map_err(|e| BenchError::Config(format!("optics at {wavelength} nm: {e}")))
                                .map(|fp| tr.power_exact(t0 + block.t[j], &real, &fp))
                        };
                        block.power[j] = p?;
                    }
                }
            }
            // The detector and the recorded row.
            for j in 0..n {
                let t_bench = t0 + block.t[j];
                let p = block.power[j] * (1.0 + tr.gain_drift_per_s * t_bench);
                let var = tr.white_sigma_mw * tr.white_sigma_mw
                    + tr.shot_mw_at_1mw * tr.shot_mw_at_1mw * p.max(0.0)
                    + (tr.rin_rel * p) * (tr.rin_rel * p);
                let mut v = p + var.sqrt() * block.detector[j];
                if tr.adc_step_mw > 0.0 {
                    // Nearest level (ties to even) of the converter's range: adding 1.5·2^52
                    // rounds a number below 2^51 to an integer, without a library call.
                    const SHIFT: f64 = 6_755_399_441_055_744.0;
                    let level = (v * tr.adc_per_mw).clamp(0.0, tr.adc_levels);
                    v = ((level + SHIFT) - SHIFT) * tr.adc_step_mw;
                }
                let (q, noise) = (&block.q[j], &block.noise[j]);
                for i in 0..6 {
                    block.encoder[i][j] = (q[i] + noise[i]) + noise[6 + i];
                }
                block.t_bench[j] = t_bench;
                block.power[j] = v;
            }
            trace.t_s.extend_from_slice(&block.t_bench[..n]);
            let [q1, q2, q3, q4, q5, q6] = &block.encoder;
            trace.q1_um.extend_from_slice(&q1[..n]);
            trace.q2_um.extend_from_slice(&q2[..n]);
            trace.q3_um.extend_from_slice(&q3[..n]);
            trace.q4_deg.extend_from_slice(&q4[..n]);
            trace.q5_deg.extend_from_slice(&q5[..n]);
            trace.q6_deg.extend_from_slice(&q6[..n]);
            trace.wavelength_nm.extend_from_slice(&block.wavelength[..n]);
            trace.irradiance.extend_from_slice(&block.power[..n]);
            k += n;
        }
        Ok(())
    }
}

/// Samples computed together: each stage (commands and noise, light, detector) runs over the
/// whole block, so the processor overlaps independent samples instead of waiting on the long
/// chain of dependencies inside one sample.
const BLOCK: usize = 32;

/// The per-sample data of one block.
struct Block {
    t: [f64; BLOCK],
    s: [f64; BLOCK],
    q: [[f64; 6]; BLOCK],
    wavelength: [f64; BLOCK],
    /// Stage jitter (0..6) and encoder noise (6..12), display units.
    noise: [[f64; 12]; BLOCK],
    /// Standard normal draw of the detector noise.
    detector: [f64; BLOCK],
    /// The block's standard normal deviates, in the order drawn (at most 13 per sample).
    deviates: [f64; 13 * BLOCK],
    /// Reflected power, mW; then the recorded irradiance.
    power: [f64; BLOCK],
    /// Recorded encoder readings, per joint.
    encoder: [[f64; BLOCK]; 6],
    /// Bench time of each sample.
    t_bench: [f64; BLOCK],
}

impl Default for Block {
    fn default() -> Self {
        Block {
            t: [0.0; BLOCK],
            s: [0.0; BLOCK],
            q: [[0.0; 6]; BLOCK],
            wavelength: [0.0; BLOCK],
            noise: [[0.0; 12]; BLOCK],
            detector: [0.0; BLOCK],
            deviates: [0.0; 13 * BLOCK],
            power: [0.0; BLOCK],
            encoder: [[0.0; BLOCK]; 6],
            t_bench: [0.0; BLOCK],
        }
    }
}

/// The commanded joints (µm, °) at segment time `t` and the path fraction s of a move (0 for
/// other segments): the values of [`TimedSegment::position_at`], with s.
#[inline]
fn command(segment: &TimedSegment, t: f64) -> ([f64; 6], f64) {
    match segment.motion {
        TimedMotion::Move { profile, .. } => {
            let s = profile.fraction_at(t);
            let (from, to) = (&segment.from_display, &segment.to_display);
            let q = if s >= 1.0 { *to } else { std::array::from_fn(|j| from[j] + s * (to[j] - from[j])) };
            (q, s)
        }
        TimedMotion::Sweep { .. } | TimedMotion::Dwell => (segment.from_display, 0.0),
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

    fn tunable_laser(&self) -> bool {
        self.tunable
    }

    fn run_segment(
        &mut self,
        segment: &TimedSegment,
        meta: TraceMeta,
        control: &mut RunControl<'_>,
    ) -> Result<Option<Trace>, BenchError> {
        if !self.tunable && matches!(segment.motion, TimedMotion::Sweep { .. }) {
            return Err(BenchError::Config(format!(
                "bench {}: its laser is not tunable (laser.tunable: false): the sweep `{}` cannot run",
                self.name, meta.label
            )));
        }
        let dt = self.truth.sample_period_s;
        let duration = segment.duration_s;
        let n = (duration / dt).floor() as usize + 1;
        let record = segment.record;
        let mut trace = record.then(|| Trace::with_capacity(meta, n));
        let t0 = self.clock_s;
        // Report progress every 50 ms of bench time.
        let chunk = (0.05 / dt).max(1.0) as usize;
        // A cyclic error of the phase (a hidden fringe nonlinearity) and the stages' play (hidden
        // reversal errors) are applied on the exact path only.
        let exact = self.exact
            || self.truth.play_width.iter().any(|w| *w != 0.0)
            || self.truth.path_effects.iter().any(|e| matches!(e, Effect::FringeNonlinearity { .. }));
        let mut fast = match (record, exact) {
            (true, false) => FastSegment::new(&self.truth, segment, t0, n)?,
            _ => None,
        };
        let laser = self.truth.laser_wavelength_nm;
        let mut reported = 0;
        let mut start = 0;
        while start < n {
            let end = (start + chunk).min(n);
            if let Some(tr) = trace.as_mut() {
                self.record_samples(segment, t0, start..end, tr, fast.as_mut())?;
            }
            let t = (end - 1) as f64 * dt;
            self.q_display = segment.position_at(t);
            // Unrecorded moves drag the stages through their play too.
            self.play.follow(&self.q_display, &self.truth.play_width);
            self.wavelength_nm = segment.wavelength_at(t).unwrap_or(laser);
            if control.cancelled() {
                self.clock_s = t0 + t;
                return Err(BenchError::Cancelled { partial: trace.map(Box::new) });
            }
            if let Some(tr) = trace.as_ref() {
                (control.on_samples)(tr, reported);
                reported = tr.len();
            }
            (control.on_progress)(t / duration.max(f64::MIN_POSITIVE));
            start = end;
        }
        self.clock_s = t0 + duration;
        self.wavelength_nm = laser;
        Ok(trace)
    }
}
