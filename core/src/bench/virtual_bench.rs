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
//! - fast (the default): the same model, rearranged for dense sampling. The field is
//!   E = Σ_m B_m·u^m·w^(e_m) ([`FringeExpansion`]) with two phasors computed exactly per
//!   sample, u = exp(-i·k·g·(2 - θ²)) and w = exp(i·k·g·θ²) (g the optical gap, |L| with the
//!   drift and path-scale effects), and coefficients B_m that vary slowly (on the scales of
//!   z_R in gap and of 1/(m·k·w0)² in θ²). Within a segment the commanded joints follow
//!   q(s) = from + s·(to - from) and the wavelength is linear in time, so the noise-free gap
//!   without the drift, g_geo, and θ² are smooth functions of the path fraction s (not of
//!   time during accelerations, where a translation times a rotation is quartic in t), and
//!   the B_m smooth functions of time. All are computed exactly at nodes, with their
//!   derivatives (the geometric Jacobian for g_geo and θ², the analytic partial derivatives
//!   of the expansion for B_m), and interpolated between nodes by cubic Hermite polynomials,
//!   in s for g_geo and θ², in t for B_m; the drift is added exactly per sample. Nodes sit on
//!   the kinks of the velocity profile and are adaptive between them: each interval is
//!   checked at its midpoint against an exact node and halved until a bound on the
//!   irradiance error there is below [`FAST_PATH_TOLERANCE`] of the fringe amplitude (at
//!   most [`MAX_NODE_INTERVAL`] samples per interval). Samples are computed in blocks of 32,
//!   stage by stage, two at a time, so that the processor overlaps independent samples.
//!
//!   Stage jitter δq (nm, µrad) is applied per sample through the jitter gradients at the
//!   nodes (interpolated linearly along the path): to first order δg = Σ ∂g/∂q_i·δq_i,
//!   δθ² = Σ ∂θ²/∂q_i·δq_i and B_m += ∂B_m/∂g·δg + ∂B_m/∂θ²·δθ²; the phasors use g + δg and
//!   θ² + δθ² exactly. Second-order terms that matter are kept: the bilinear term δn_t·δO_t
//!   of L (a rotation jitter times a translation jitter: up to 3e-7 of the fringe amplitude
//!   otherwise), the transverse term |δn_t|² - (δn_t·n_f)² of θ² (k·|L|·δθ² ≈ 3600·δθ² rad
//!   of tilt phase) and ½·∂²B_m/∂(θ²)²·(δθ²)². What is left is of the order of the rotations'
//!   own second-order terms (θ·δφ² ≈ 1e-12 rad² for µrad jitter) and of (δg/z_R)² ≈ 1e-7 of
//!   the higher beams' coefficients, below 1e-9 of the fringe amplitude at Table II's gap.
//!   The interpolation error bounds take the jitter as Gaussian, at six standard deviations.
//!
//!   The test `fast_path_matches_the_exact_path` compares both paths sample by sample on
//!   strategy-1 and strategy-2 moves, a 45° turn of q6, a move of all joints, a sweep and a
//!   dwell, on both presets: the difference stays below 3e-8 of the fringe amplitude.

use crate::bench::preset::BenchPreset;
use crate::bench::{Bench, BenchError, RunControl};
use crate::model::air::{air_index_ciddor, AmbientConditions};
use crate::model::effects::{self, Effect};
use crate::model::extrinsics::{Extrinsics, FiberGeometry};
use crate::model::kinematics::{sin_cos_2, Chain};
use crate::model::optics::{tilt_phase_order, FabryPerot, FringeExpansion};
use crate::model::robot::{JointType, RobotDescription};
use crate::plan::{MotionLimits, TimedMotion, TimedSegment};
use crate::trace::{Trace, TraceMeta};
use nalgebra::{Complex, Point3, Vector3};
use std::f64::consts::PI;

/// Largest irradiance error of the fast path's interpolation, as a fraction of the fringe
/// amplitude, estimated at the midpoint of every node interval.
pub const FAST_PATH_TOLERANCE: f64 = 3e-8;

/// Longest node interval of the fast path, in samples.
pub const MAX_NODE_INTERVAL: usize = 2048;

/// Highest beam order the fast path handles (more beams fall back to the exact path).
const MAX_FAST_ORDER: usize = 32;

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
    /// Play of each stage (display units; hidden reversal errors).
    play_width: [f64; 6],
    /// The path effects compiled: gap = scale·|L| + offset(t).
    gap_map: GapMap,
    joint_is_revolute: [bool; 6],
    white_sigma_mw: f64,
    shot_mw_at_1mw: f64,
    rin_rel: f64,
    /// Any detector noise at all (a draw per sample).
    detector_noise: bool,
    adc_step_mw: f64,
    /// 1/adc_step_mw and the number of ADC steps over the full scale.
    adc_per_mw: f64,
    adc_levels: f64,
    gain_drift_per_s: f64,
    sample_period_s: f64,
    stage_sigma: [f64; 6],
    /// The joint noise draws of a sample, in order.
    draws: Vec<Draw>,
    /// Optical axis in the world.
    n_f: Vector3<f64>,
    /// Lamella normal in the end-effector frame.
    n_t_in_ee: Vector3<f64>,
}

/// One joint noise draw: slot i < 6 is the stage jitter of joint i, slot 6 + i its encoder noise.
#[derive(Debug, Clone, Copy)]
struct Draw {
    slot: usize,
    sigma: f64,
}

/// The path effects (drift, path scale) composed in their order into an affine map of the
/// geometric gap: `gap = scale·|L| + per_s·t + per_s2·t²` (µm, t bench time in s).
#[derive(Debug, Clone, Copy)]
struct GapMap {
    scale: f64,
    per_s: f64,
    per_s2: f64,
}

impl GapMap {
    fn new(effects: &[Effect]) -> Self {
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
    fn offset_um(&self, t_s: f64) -> f64 {
        (self.per_s + self.per_s2 * t_s) * t_s
    }

    #[inline]
    fn rate_um_per_s(&self, t_s: f64) -> f64 {
        self.per_s + 2.0 * self.per_s2 * t_s
    }
}

/// xoshiro256++ (Blackman and Vigna, 2019), its state filled by SplitMix64 from a 64-bit seed:
/// fast, statistically sound for simulation, and fixed here so a seed gives the same noise on
/// every platform and with every version of `rand`.
#[derive(Debug, Clone)]
struct Xoshiro256PlusPlus {
    s: [u64; 4],
}

impl Xoshiro256PlusPlus {
    fn seed_from_u64(mut x: u64) -> Self {
        let mut split_mix = || {
            x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = x;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        };
        Self { s: [split_mix(), split_mix(), split_mix(), split_mix()] }
    }

    #[inline(always)]
    fn next_u64(&mut self) -> u64 {
        let s = &mut self.s;
        let result = s[0].wrapping_add(s[3]).rotate_left(23).wrapping_add(s[0]);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        result
    }

    /// Uniform in (0, 1]: 53 random bits.
    #[inline]
    fn uniform_open0(&mut self) -> f64 {
        ((self.next_u64() >> 11) + 1) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

/// Standard normal deviates by the ziggurat method (Marsaglia and Tsang, J. Stat. Softw. 5(8),
/// 2000) with 128 layers, on xoshiro256++. Each deviate takes 32 random bits, two per 64-bit
/// draw: 7 bits choose the layer and the other 25, independent of them (Doornik 2005), give a
/// signed value; 98.8 % of the deviates are accepted on that alone (a compare and a
/// product), the rest go through the exact wedge and tail tests with fresh uniforms. A
/// deviate is a multiple of 2^-24 of its layer's width (at most 3.7·2^-24 ≈ 2e-7): finer than
/// anything the simulated noise is compared with.
#[derive(Debug, Clone)]
struct Gaussian {
    rng: Xoshiro256PlusPlus,
    /// Unused 32-bit half of the last draw, if any.
    spare: Option<u32>,
}

/// The ziggurat's tables, per layer i (1 the top, 127 the lowest rectangle, 0 the base strip
/// with the tail): the accept bound k_i = 2^24·x_(i-1)/x_i, the width w_i = x_i/2^24 (for the
/// base, its equivalent width V/f(R)) and f_i = exp(-x_i²/2), x_i the layer's right edge.
struct ZigguratTables {
    k: [u32; 128],
    w: [f64; 128],
    f: [f64; 128],
}

/// Right edge of the bottom layer (128 layers, Marsaglia and Tsang).
const ZIGGURAT_R: f64 = 3.442_619_855_899;
/// Area of every layer.
const ZIGGURAT_V: f64 = 9.912_563_035_262_17e-3;
const ZIGGURAT_SCALE: f64 = (1u64 << 24) as f64;

fn ziggurat_tables() -> &'static ZigguratTables {
    static TABLES: std::sync::OnceLock<ZigguratTables> = std::sync::OnceLock::new();
    TABLES.get_or_init(|| {
        // Marsaglia and Tsang's zigset, with 2^24 in place of 2^31.
        let (mut k, mut w, mut f) = ([0u32; 128], [0.0; 128], [0.0; 128]);
        let mut dn = ZIGGURAT_R;
        let mut tn = dn;
        let q = ZIGGURAT_V / (-0.5 * dn * dn).exp();
        k[0] = (dn / q * ZIGGURAT_SCALE) as u32;
        k[1] = 0;
        w[0] = q / ZIGGURAT_SCALE;
        w[127] = dn / ZIGGURAT_SCALE;
        f[0] = 1.0;
        f[127] = (-0.5 * dn * dn).exp();
        for i in (1..=126).rev() {
            dn = (-2.0 * (ZIGGURAT_V / dn + (-0.5 * dn * dn).exp()).ln()).sqrt();
            k[i + 1] = (dn / tn * ZIGGURAT_SCALE) as u32;
            tn = dn;
            f[i] = (-0.5 * dn * dn).exp();
            w[i] = dn / ZIGGURAT_SCALE;
        }
        ZigguratTables { k, w, f }
    })
}

impl Gaussian {
    fn seed_from_u64(seed: u64) -> Self {
        ziggurat_tables();
        Self { rng: Xoshiro256PlusPlus::seed_from_u64(seed), spare: None }
    }

    #[inline(always)]
    fn bits32(&mut self) -> u32 {
        match self.spare.take() {
            Some(b) => b,
            None => {
                let b = self.rng.next_u64();
                self.spare = Some((b >> 32) as u32);
                b as u32
            }
        }
    }

    /// Fills `out` with standard normal deviates: the same sequence as calling
    /// [`Gaussian::sample`] for each, with the 64-bit draws split in place.
    fn fill(&mut self, tables: &ZigguratTables, out: &mut [f64]) {
        let mut rest = out;
        if !rest.is_empty() && self.spare.is_some() {
            rest[0] = self.sample(tables);
            rest = &mut rest[1..];
        }
        let mut pairs = rest.chunks_exact_mut(2);
        for pair in &mut pairs {
            let b = self.rng.next_u64();
            pair[0] = self.deviate(tables, b as u32);
            pair[1] = self.deviate(tables, (b >> 32) as u32);
        }
        for x in pairs.into_remainder() {
            *x = self.sample(tables);
        }
    }

    /// The deviate of 32 random bits (fresh draws only if they fall outside the fast region).
    #[inline(always)]
    fn deviate(&mut self, tables: &ZigguratTables, bits: u32) -> f64 {
        let i = (bits & 127) as usize;
        let h = (bits as i32) >> 7; // signed, 25 bits, independent of i
        if h.unsigned_abs() < tables.k[i] {
            return f64::from(h) * tables.w[i];
        }
        self.sample_slow(tables, i, h)
    }

    /// One standard normal deviate.
    #[inline(always)]
    fn sample(&mut self, tables: &ZigguratTables) -> f64 {
        let bits = self.bits32();
        self.deviate(tables, bits)
    }

    #[cold]
    fn sample_slow(&mut self, tables: &ZigguratTables, mut i: usize, mut h: i32) -> f64 {
        loop {
            let x = f64::from(h) * tables.w[i];
            if i == 0 {
                // The tail beyond R (Marsaglia's method).
                loop {
                    let x = -self.rng.uniform_open0().ln() / ZIGGURAT_R;
                    let y = -self.rng.uniform_open0().ln();
                    if y + y >= x * x {
                        return if h > 0 { ZIGGURAT_R + x } else { -ZIGGURAT_R - x };
                    }
                }
            }
            let u = 1.0 - self.rng.uniform_open0(); // [0, 1)
            if tables.f[i] + u * (tables.f[i - 1] - tables.f[i]) < (-0.5 * x * x).exp() {
                return x;
            }
            // A fresh draw (its other half unused), so that the sequence does not depend on
            // how deviates are grouped (`fill`).
            let bits = self.rng.next_u64() as u32;
            i = (bits & 127) as usize;
            h = (bits as i32) >> 7;
            if h.unsigned_abs() < tables.k[i] {
                return f64::from(h) * tables.w[i];
            }
        }
    }
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
        let truth = Truth {
            n_f: geometry.n_f(),
            n_t_in_ee: geometry.n_t_in_ee(),
            geometry,
            extrinsics: preset.truth,
            optics,
            n_air,
            laser_wavelength_nm: preset.laser.wavelength_nm,
            fp,
            gap_map: GapMap::new(&path_effects),
            play_width: effects::reversal_play(&preset.effects, &robot),
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
        };
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

impl Truth {
    /// Reflected power (mW, before the detector) at bench time `t_s` and real joints
    /// `q_display` (µm, °), evaluated from scratch: the exact path.
    fn power_exact(&self, t_s: f64, q_display: &[f64; 6], fp: &FabryPerot) -> f64 {
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

    /// The fast path's node at segment time `t`: the interpolated quantities and their
    /// derivatives (in s for the geometry, in t for the coefficients), exactly, and the jitter
    /// gradients.
    fn node(
        &self,
        seg: &TimedSegment,
        t0: f64,
        t: f64,
        expansion: &mut FringeExpansion,
        node: &mut Node,
    ) -> Result<(), BenchError> {
        let (q_display, s) = command(seg, t);
        // The path q(s) = from + s·(to - from) and ds/dt.
        let (path, s_rate) = match seg.motion {
            TimedMotion::Move { profile, .. } => {
                (std::array::from_fn(|j| seg.to_display[j] - seg.from_display[j]), profile.rate_at(t))
            }
            TimedMotion::Sweep { .. } | TimedMotion::Dwell => ([0.0; 6], 0.0),
        };
        let (wavelength, wavelength_rate) = match seg.motion {
            TimedMotion::Sweep { from_nm, to_nm } => (
                seg.wavelength_at(t).unwrap_or(self.laser_wavelength_nm),
                if seg.duration_s > 0.0 { (to_nm - from_nm) / seg.duration_s } else { 0.0 },
            ),
            _ => (self.laser_wavelength_nm, 0.0),
        };
        let swept;
        let fp = if wavelength == self.laser_wavelength_nm {
            &self.fp
        } else {
            swept = FabryPerot::new(&self.optics, wavelength, self.n_air)
                .map_err(|e| BenchError::Config(format!("optics at {wavelength} nm: {e}")))?;
            &swept
        };
        let k = fp.wavenumber_per_um();
        let k_rate = -k * wavelength_rate / wavelength;

        let unit: [f64; 6] = std::array::from_fn(|i| if self.joint_is_revolute[i] { PI / 180.0 } else { 1.0 });
        let q: [f64; 6] = std::array::from_fn(|i| q_display[i] * unit[i]);
        let mut cols = [(Vector3::zeros(), Vector3::zeros()); 6];
        let wte = self.chain.end_effector_with_jacobian(&q, &mut cols);
        let l = self.extrinsics.cavity_length_um(&wte, &self.geometry);
        let n_t = wte.rotation * self.n_t_in_ee;
        let o_t = wte * Point3::from(self.geometry.ee_to_tool().translation.vector);
        let from_fiber = o_t - self.geometry.origin();
        let to_tool = o_t.coords - wte.translation.vector;
        let den = n_t.dot(&self.n_f);
        let theta = den.abs().min(1.0).acos();
        // d(θ²)/d|cos θ| = -2θ/sin θ, → -2 as θ → 0.
        let dtsq_dc = if theta > 1e-4 { -2.0 * theta / theta.sin() } else { -2.0 * (1.0 + theta * theta / 6.0) };
        let gap_slope = self.gap_map.scale * l.signum();
        let (mut grad_g, mut grad_t) = ([0.0; 6], [0.0; 6]);
        let so = &mut node.second;
        // θ² = asin(|v|)², v the part of n_t across n_f: dθ²/d|v|² = θ/(sin θ·cos θ).
        so.tilt_curvature = if theta > 1e-4 { theta / (theta.sin() * theta.cos()) } else { 1.0 };
        so.inv_den = 1.0 / den;
        so.cross_gain = gap_slope / den;
        for i in 0..6 {
            let (v, w) = cols[i];
            let dn = w.cross(&n_t);
            let d_ot = v + w.cross(&to_tool);
            let dl = (dn.dot(&from_fiber) + n_t.dot(&d_ot) - l * dn.dot(&self.n_f)) / den;
            grad_g[i] = gap_slope * dl * unit[i];
            grad_t[i] = dtsq_dc * den.signum() * dn.dot(&self.n_f) * unit[i];
            so.dn_dq[i] = (dn * unit[i]).into();
            so.dot_dq[i] = (d_ot * unit[i]).into();
        }
        let t_bench = t0 + t;
        let g_geo = self.gap_map.scale * l.abs();
        let g = g_geo + self.gap_map.offset_um(t_bench);
        let tsq = theta * theta;
        let dot6 = |a: &[f64; 6], b: &[f64; 6]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let (g_per_s, tsq_per_s) = (dot6(&grad_g, &path), dot6(&grad_t, &path));
        let g_rate = g_per_s * s_rate + self.gap_map.rate_um_per_s(t_bench);
        let tsq_rate = tsq_per_s * s_rate;
        fp.expansion(g, tsq, expansion);

        node.t = t;
        node.s = s;
        node.k = k;
        node.y.clear();
        node.dy.clear();
        node.lin.clear();
        node.y.extend([g_geo, tsq, expansion.coefficients[0].re]);
        node.dy.extend([g_per_s, tsq_per_s, expansion.d_wavenumber[0].re * k_rate]);
        for m in 1..expansion.coefficients.len() {
            let c = expansion.coefficients[m];
            let dc =
                expansion.d_gap[m] * g_rate + expansion.d_tilt_sq[m] * tsq_rate + expansion.d_wavenumber[m] * k_rate;
            node.y.extend([c.re, c.im]);
            node.dy.extend([dc.re, dc.im]);
        }
        node.lin.extend(grad_g);
        node.lin.extend(grad_t);
        for d in [&expansion.d_gap, &expansion.d_tilt_sq] {
            for c in &d[1..] {
                node.lin.extend([c.re, c.im]);
            }
        }
        node.half_d2_tilt_sq.clear();
        node.half_d2_tilt_sq.extend(expansion.d2_tilt_sq[1..].iter().map(|c| 0.5 * c));
        Ok(())
    }
}

/// What the second-order jitter terms need (see [`FastSegment::power_block_with`]), at one node.
#[derive(Debug, Clone, Copy, Default)]
struct SecondOrder {
    /// dθ²/d|v|², v the part of n_t across n_f.
    tilt_curvature: f64,
    /// 1/d, d = n_t·n_f.
    inv_den: f64,
    /// scale·sign(L)/d: the gap's bilinear term per δn_t·δO_t.
    cross_gain: f64,
    /// ∂n_t/∂q_i per display unit.
    dn_dq: [[f64; 3]; 6],
    /// ∂O_t/∂q_i per display unit (µm).
    dot_dq: [[f64; 3]; 6],
}

/// Exact state of the fast path at one time (see [`Truth::node`]).
#[derive(Debug, Clone, Default)]
struct Node {
    /// Segment time (s).
    t: f64,
    /// Path fraction of a move (0 for other segments).
    s: f64,
    /// Wavenumber (rad/µm).
    k: f64,
    /// Interpolated by cubic Hermite polynomials: the gap without the drift, g_geo (µm), and
    /// θ² (rad²), functions of the path fraction s; then B_0, Re B_m and Im B_m (m ≥ 1,
    /// [`FringeExpansion`]), functions of time. Along a move the gap and the tilt are smooth
    /// in s, but not polynomial in t during accelerations (a translation times a rotation is
    /// quartic in t there); the drift, a function of t, is added exactly per sample.
    y: Vec<f64>,
    /// Derivatives of `y`: in s for g_geo and θ², in t for the others.
    dy: Vec<f64>,
    /// Interpolated linearly along the path (in s during a move, in time otherwise): ∂g/∂q_i
    /// and ∂θ²/∂q_i per display unit (6 + 6), then Re, Im of ∂B_m/∂g, then of ∂B_m/∂θ², m ≥ 1.
    lin: Vec<f64>,
    second: SecondOrder,
    /// ½·∂²B_m/∂(θ²)², m ≥ 1: the second-order amplitude change of the tilted beams.
    half_d2_tilt_sq: Vec<Complex<f64>>,
}

/// The fast path through one recorded segment: the current node interval and its polynomials.
struct FastSegment {
    segment: TimedSegment,
    t0: f64,
    dt: f64,
    /// Kinks of the motion profile and the last sample time, increasing.
    breakpoints: Vec<f64>,
    /// Beam order M.
    order: usize,
    /// Stage jitter present: the jitter terms are evaluated.
    jitter: bool,
    /// Six standard deviations of the stage jitter per joint (display units), for error bounds.
    jitter_bound: [f64; 6],
    sweep: bool,
    gap_map: GapMap,
    n_air: f64,
    /// Optical axis in the world.
    n_f: [f64; 3],
    input_power_mw: f64,
    /// Wavenumber outside sweeps, rad/µm.
    k: f64,
    a: Node,
    b: Node,
    mid: Node,
    expansion: FringeExpansion,
    /// Current interval [ta, tb] and 1/(tb - ta) (0 for an empty interval).
    ta: f64,
    tb: f64,
    inv_h: f64,
    /// Cubics for g_geo and θ² in σ (below), for B_0 in τ = (t - ta)/(tb - ta).
    base: [[f64; 4]; 3],
    /// Per beam m ≥ 1: cubics for B_m and the jitter terms.
    beams: Vec<BeamInterpolant>,
    /// Path coordinate σ = lin_s·s + lin_t·t + lin_0, 0 at ta and 1 at tb: (s - s_a)/(s_b - s_a)
    /// while the joints move, τ otherwise.
    lin_s: f64,
    lin_t: f64,
    lin_0: f64,
    /// The jitter's linear map, one column per joint (display units): rows 0, 1 are ∂g/∂q_i at
    /// σ = 0 and its change to σ = 1; rows 2, 3 the same for ∂θ²/∂q_i; rows 4..7 ∂n_t/∂q_i and
    /// rows 7..10 ∂O_t/∂q_i at ta (`SecondOrder`). Column-major so that the products vectorise.
    jitter_map: [[f64; 10]; 6],
    /// `SecondOrder` at ta.
    tilt_curvature: f64,
    inv_den: f64,
    cross_gain: f64,
    /// Scratch: the Horner factors of two samples.
    factors: Vec<Complex2>,
    /// Next interval length to try (s).
    h_next: f64,
    /// The last interval is built.
    done: bool,
}

/// One beam's interpolants over a node interval.
#[derive(Debug, Clone, Copy, Default)]
struct BeamInterpolant {
    /// Cubics in τ for Re B_m and Im B_m.
    re: [f64; 4],
    im: [f64; 4],
    /// ∂B_m/∂g and ∂B_m/∂θ²: value at σ = 0 and change to σ = 1.
    d_gap: [Complex<f64>; 2],
    d_tilt_sq: [Complex<f64>; 2],
    /// ½·∂²B_m/∂(θ²)² at ta.
    half_d2_tilt_sq: Complex<f64>,
}

impl FastSegment {
    /// `None` when the bench's optics need more beams than the fast path handles.
    fn new(truth: &Truth, segment: &TimedSegment, t0: f64, samples: usize) -> Result<Option<Self>, BenchError> {
        let order = truth.fp.expansion_order();
        if order > MAX_FAST_ORDER {
            return Ok(None);
        }
        let dt = truth.sample_period_s;
        let t_last = (samples.max(1) - 1) as f64 * dt;
        let mut breakpoints = match segment.motion {
            TimedMotion::Move { profile, .. } => {
                vec![profile.accel_time_s, profile.accel_time_s + profile.cruise_time_s, profile.duration_s]
            }
            _ => vec![],
        };
        breakpoints.retain(|&b| b > 0.0 && b < t_last);
        breakpoints.push(t_last);
        breakpoints.sort_by(f64::total_cmp);
        breakpoints.dedup();
        let mut f = FastSegment {
            segment: segment.clone(),
            t0,
            dt,
            breakpoints,
            order,
            jitter: truth.stage_sigma.iter().any(|&s| s != 0.0),
            jitter_bound: truth.stage_sigma.map(|s| 6.0 * s),
            sweep: matches!(segment.motion, TimedMotion::Sweep { .. }),
            gap_map: truth.gap_map,
            n_air: truth.n_air,
            n_f: truth.n_f.into(),
            input_power_mw: truth.fp.input_power_mw(),
            k: truth.fp.wavenumber_per_um(),
            a: Node::default(),
            b: Node::default(),
            mid: Node::default(),
            expansion: FringeExpansion::default(),
            ta: 0.0,
            tb: 0.0,
            inv_h: 0.0,
            base: [[0.0; 4]; 3],
            beams: Vec::new(),
            lin_s: 0.0,
            lin_t: 0.0,
            lin_0: 0.0,
            jitter_map: [[0.0; 10]; 6],
            tilt_curvature: 0.0,
            inv_den: 0.0,
            cross_gain: 0.0,
            factors: vec![Complex2::default(); order],
            h_next: MAX_NODE_INTERVAL as f64 * dt,
            done: t_last == 0.0,
        };
        truth.node(&f.segment, t0, 0.0, &mut f.expansion, &mut f.b)?;
        // The first sample, at t = 0, sits on this node: a constant interval.
        f.a.clone_from(&f.b);
        f.build_polynomials();
        Ok(Some(f))
    }

    /// Builds the interpolants of [a, b].
    fn build_polynomials(&mut self) {
        let (a, b) = (&self.a, &self.b);
        let h = b.t - a.t;
        self.ta = a.t;
        self.tb = b.t;
        self.inv_h = if h > 0.0 { 1.0 / h } else { 0.0 };
        let ds = b.s - a.s;
        let cubic = |j: usize| -> [f64; 4] {
            let step = if j < 2 { ds } else { h };
            let (ya, yb) = (a.y[j], b.y[j]);
            let (da, db) = (a.dy[j] * step, b.dy[j] * step);
            let delta = yb - ya;
            [ya, da, 3.0 * delta - 2.0 * da - db, -2.0 * delta + da + db]
        };
        let linear = |j: usize| -> [f64; 2] { [a.lin[j], b.lin[j] - a.lin[j]] };
        let complex_linear = |j: usize| -> [Complex<f64>; 2] {
            let ([re0, re1], [im0, im1]) = (linear(j), linear(j + 1));
            [Complex::new(re0, im0), Complex::new(re1, im1)]
        };
        self.base = [cubic(0), cubic(1), cubic(2)];
        let m = self.order;
        self.beams.clear();
        for j in 0..m {
            self.beams.push(BeamInterpolant {
                re: cubic(3 + 2 * j),
                im: cubic(4 + 2 * j),
                d_gap: complex_linear(12 + 2 * j),
                d_tilt_sq: complex_linear(12 + 2 * m + 2 * j),
                half_d2_tilt_sq: a.half_d2_tilt_sq[j],
            });
        }
        for i in 0..6 {
            let ([g0, g1], [t0, t1]) = (linear(i), linear(6 + i));
            let (dn, dot) = (a.second.dn_dq[i], a.second.dot_dq[i]);
            self.jitter_map[i] = [g0, g1, t0, t1, dn[0], dn[1], dn[2], dot[0], dot[1], dot[2]];
        }
        (self.lin_s, self.lin_t, self.lin_0) =
            if ds > 0.0 { (1.0 / ds, 0.0, -a.s / ds) } else { (0.0, self.inv_h, -a.t * self.inv_h) };
        self.tilt_curvature = a.second.tilt_curvature;
        self.inv_den = a.second.inv_den;
        self.cross_gain = a.second.cross_gain;
    }

    /// Moves to the next node interval, sized so that its midpoint error is within tolerance.
    fn next_interval(&mut self, truth: &Truth) -> Result<(), BenchError> {
        std::mem::swap(&mut self.a, &mut self.b);
        let ta = self.a.t;
        let end = self.breakpoints.iter().copied().find(|&b| b > ta).unwrap_or(ta);
        let mut h = self.h_next.min(end - ta);
        if end - ta - h < 0.5 * self.dt {
            h = end - ta; // no sliver before a breakpoint
        }
        let mut tb = if h == end - ta { end } else { ta + h };
        truth.node(&self.segment, self.t0, tb, &mut self.expansion, &mut self.b)?;
        loop {
            truth.node(&self.segment, self.t0, ta + 0.5 * h, &mut self.expansion, &mut self.mid)?;
            self.build_polynomials();
            let err = self.midpoint_error();
            if err <= FAST_PATH_TOLERANCE || h <= 2.0 * self.dt {
                let growth =
                    if err > 0.0 { (0.8 * (FAST_PATH_TOLERANCE / err).powf(0.25)).clamp(0.5, 2.0) } else { 2.0 };
                self.h_next = (h * growth).clamp(self.dt, MAX_NODE_INTERVAL as f64 * self.dt);
                break;
            }
            // Halve: the midpoint becomes the end.
            std::mem::swap(&mut self.b, &mut self.mid);
            h *= 0.5;
            tb = ta + h;
        }
        self.done = tb >= *self.breakpoints.last().unwrap_or(&0.0);
        Ok(())
    }

    /// Irradiance error of the current interval at its midpoint (against the exact node
    /// `mid`), as a fraction of the fringe amplitude: a bound on the field error over |B_1|.
    fn midpoint_error(&self) -> f64 {
        let mid = &self.mid;
        let half = |p: &[f64; 4]| p[0] + 0.5 * (p[1] + 0.5 * (p[2] + 0.5 * p[3]));
        let sigma = self.lin_s * mid.s + self.lin_t * mid.t + self.lin_0;
        let at_sigma = |p: &[f64; 4]| p[0] + sigma * (p[1] + sigma * (p[2] + sigma * p[3]));
        let at_half = |j: usize| match j {
            0 | 1 => at_sigma(&self.base[j]),
            2 => half(&self.base[j]),
            _ if j % 2 == 1 => half(&self.beams[(j - 3) / 2].re),
            _ => half(&self.beams[(j - 4) / 2].im),
        };
        let (g, tsq, k) = (mid.y[0], mid.y[1], mid.k);
        let b_norm = |m: usize| -> f64 {
            if m == 0 {
                mid.y[2].abs()
            } else {
                mid.y[1 + 2 * m].hypot(mid.y[2 + 2 * m])
            }
        };
        // A gap error δg and a θ² error δt move beam m's phase m·Φ - e_m·ψ by at most
        // gain_g·δg + gain_t·δt (summed over the beams, weighted by |B_m|).
        let (mut gain_g, mut gain_t) = (0.0, 0.0);
        for m in 1..=self.order {
            let (mf, em) = (m as f64, tilt_phase_order(m) as f64);
            gain_g += b_norm(m) * k * (mf * (2.0 - tsq) + em * tsq);
            gain_t += b_norm(m) * k * g * (mf + em);
        }
        let mut err = (at_half(2) - mid.y[2]).abs();
        for j in 3..mid.y.len() {
            err += (at_half(j) - mid.y[j]).abs();
        }
        err += gain_g * (at_half(0) - g).abs() + gain_t * (at_half(1) - tsq).abs();
        if self.jitter {
            let m2 = 2 * self.order;
            let lin = |j: usize| {
                let [v0, v1] = match j {
                    0..=5 => [self.jitter_map[j][0], self.jitter_map[j][1]],
                    6..=11 => [self.jitter_map[j - 6][2], self.jitter_map[j - 6][3]],
                    _ => {
                        let (k, im) = ((j - 12) % m2, (j - 12) % 2 == 1);
                        let d = if j - 12 < m2 { self.beams[k / 2].d_gap } else { self.beams[k / 2].d_tilt_sq };
                        if im {
                            [d[0].im, d[1].im]
                        } else {
                            [d[0].re, d[1].re]
                        }
                    }
                };
                (v0 + sigma * v1 - mid.lin[j]).abs()
            };
            // The jitter is Gaussian and independent per joint: a term Σ_i a_i·δq_i is bounded
            // by six of its standard deviations, √Σ (a_i·6σ_i)².
            let six_sigma = |a: &dyn Fn(usize) -> f64| -> f64 {
                (0..6).map(|i| (a(i) * self.jitter_bound[i]).powi(2)).sum::<f64>().sqrt()
            };
            let (dg_bound, dt_bound) = (six_sigma(&|i| mid.lin[i]), six_sigma(&|i| mid.lin[6 + i]));
            let (grad_g_err, grad_t_err) = (six_sigma(&|i| lin(i)), six_sigma(&|i| lin(6 + i)));
            err += gain_g * grad_g_err + gain_t * grad_t_err;
            err += (0..m2).map(|j| lin(12 + j) * dg_bound + lin(12 + m2 + j) * dt_bound).sum::<f64>();
        }
        // Relative to the first beam, or to the fiber face when the lamella reflects nothing.
        err / b_norm(self.order.min(1)).max(1e-30)
    }

    /// Makes the current interval the one holding segment time `t`.
    fn cover(&mut self, truth: &Truth, t: f64) -> Result<(), BenchError> {
        while t > self.tb && !self.done {
            self.next_interval(truth)?;
        }
        Ok(())
    }

    /// Reflected power (mW) of the first `n` samples of `block`, all in the current interval.
    fn power_block(&mut self, block: &mut Block, n: usize) {
        if self.jitter {
            self.power_block_with::<true>(block, n)
        } else {
            self.power_block_with::<false>(block, n)
        }
    }

    #[inline(always)]
    fn power_block_with<const JITTER: bool>(&mut self, block: &mut Block, n: usize) {
        let (mut phi, mut psi) = ([0.0; BLOCK], [0.0; BLOCK]);
        let (mut dg_all, mut dtsq_all, mut tau_all, mut sigma_all) =
            ([0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK]);
        // Stage 1: gap and tilt (with the jitter), the two phases; two samples at a time.
        let mut j = 0;
        while j < n {
            let l = [j, (j + 1).min(n - 1)]; // an odd last sample fills both lanes
            let t: Pair = [block.t[l[0]], block.t[l[1]]];
            let s: Pair = [block.s[l[0]], block.s[l[1]]];
            let tau: Pair = std::array::from_fn(|i| (t[i] - self.ta) * self.inv_h);
            let sigma: Pair = std::array::from_fn(|i| self.lin_s * s[i] + self.lin_t * t[i] + self.lin_0);
            let poly_s = |p: &[f64; 4]| -> Pair {
                std::array::from_fn(|i| p[0] + sigma[i] * (p[1] + sigma[i] * (p[2] + sigma[i] * p[3])))
            };
            let (g0, tsq0) = (poly_s(&self.base[0]), poly_s(&self.base[1]));
            let mut g: Pair = std::array::from_fn(|i| g0[i] + self.gap_map.offset_um(self.t0 + t[i]));
            let mut tsq = tsq0;
            if JITTER {
                // First order from the interpolated gradients. Second order from the linearised
                // vectors δn_t = Σ ∂n_t/∂q_i·δq_i and δO_t = Σ ∂O_t/∂q_i·δq_i: the cavity length
                // n_t·(O_t - O_f)/(n_t·n_f) gives exactly δL = (d·δL₁ + δn_t·δO_t)/(d + δn_t·n_f)
                // (d = n_t·n_f), and |v|² (θ = asin|v|) moves by |δn_t|² - (δn_t·n_f)². Left out:
                // the second-order terms of the rotations themselves, ~θ·δφ² (1e-12 rad² for µrad).
                let (x0, x1) = (&block.noise[l[0]], &block.noise[l[1]]);
                // r = jitter_map·δq, column by column, both samples in lanes.
                let mut r = [[0.0; 2]; 10];
                for (i, column) in self.jitter_map.iter().enumerate() {
                    let x = [x0[i], x1[i]];
                    for (ri, ci) in r.iter_mut().zip(column) {
                        *ri = [ri[0] + ci * x[0], ri[1] + ci * x[1]];
                    }
                }
                let (nf, inv_den, cross, curv) = (self.n_f, self.inv_den, self.cross_gain, self.tilt_curvature);
                let dg: Pair = std::array::from_fn(|i| {
                    let g1 = r[0][i] + sigma[i] * r[1][i];
                    let along = r[4][i] * nf[0] + r[5][i] * nf[1] + r[6][i] * nf[2];
                    let dn_dot = r[4][i] * r[7][i] + r[5][i] * r[8][i] + r[6][i] * r[9][i];
                    // 1/(1 + ε) = 1 - ε to 1e-13: ε = δn_t·n_f/d ≲ θ·δφ ≈ 1e-7.
                    (g1 + cross * dn_dot) * (1.0 - along * inv_den)
                });
                let dtsq: Pair = std::array::from_fn(|i| {
                    let t1 = r[2][i] + sigma[i] * r[3][i];
                    let along = r[4][i] * nf[0] + r[5][i] * nf[1] + r[6][i] * nf[2];
                    let dn_sq = r[4][i] * r[4][i] + r[5][i] * r[5][i] + r[6][i] * r[6][i];
                    t1 + curv * (dn_sq - along * along)
                });
                g = [g[0] + dg[0], g[1] + dg[1]];
                tsq = [tsq[0] + dtsq[0], tsq[1] + dtsq[1]];
                for (lane, &k) in l.iter().enumerate() {
                    dg_all[k] = dg[lane];
                    dtsq_all[k] = dtsq[lane];
                }
            }
            for (lane, &k) in l.iter().enumerate() {
                let wavenumber = if self.sweep { 2.0 * PI / (block.wavelength[k] * 1e-3) * self.n_air } else { self.k };
                let kg = wavenumber * g[lane];
                phi[k] = kg * (2.0 - tsq[lane]);
                psi[k] = kg * tsq[lane];
                tau_all[k] = tau[lane];
                sigma_all[k] = sigma[lane];
            }
            j += 2;
        }
        // Stage 2: the phasors u = exp(-iΦ), w = exp(iψ).
        let (mut u_all, mut w_all) = ([Complex::new(0.0, 0.0); BLOCK], [Complex::new(0.0, 0.0); BLOCK]);
        for j in 0..n {
            let ([sin_phi, sin_psi], [cos_phi, cos_psi]) = sin_cos_2([phi[j], psi[j]]);
            u_all[j] = Complex::new(cos_phi, -sin_phi);
            w_all[j] = Complex::new(cos_psi, sin_psi);
        }
        // Stage 3: the beams, two samples at a time (lanes of `Pair`, packed arithmetic).
        let beams = &self.beams[..];
        let factors = &mut self.factors[..beams.len()];
        let mut j = 0;
        while j < n {
            let l = [j, (j + 1).min(n - 1)]; // an odd last sample fills both lanes
            let lanes = |a: &[f64; BLOCK]| -> Pair { [a[l[0]], a[l[1]]] };
            let (tau, sigma) = (lanes(&tau_all), lanes(&sigma_all));
            let u = Complex2 { re: [u_all[l[0]].re, u_all[l[1]].re], im: [u_all[l[0]].im, u_all[l[1]].im] };
            let w = Complex2 { re: [w_all[l[0]].re, w_all[l[1]].re], im: [w_all[l[0]].im, w_all[l[1]].im] };
            let (dg, dtsq) = (lanes(&dg_all), lanes(&dtsq_all));
            let (dg_s, dtsq_s, dtsq2) = (mul2(dg, sigma), mul2(dtsq, sigma), mul2(dtsq, dtsq));
            let poly = |p: &[f64; 4]| -> Pair {
                std::array::from_fn(|i| p[0] + tau[i] * (p[1] + tau[i] * (p[2] + tau[i] * p[3])))
            };
            // E = B_0 + f_1·(B_1 + f_2·(B_2 + f_3·(B_3 + …))) with f_m = u·w^(m(m-1)): beam m
            // then carries u^m·w^(e_m), e_m = Σ_{j≤m} j(j-1) = m(m² - 1)/3. f_{m+1} = f_m·w^(2m).
            let w2 = w.mul(w);
            let (mut f, mut w_2m) = (u, w2);
            for fm in factors.iter_mut() {
                *fm = f;
                f = f.mul(w_2m);
                w_2m = w_2m.mul(w2);
            }
            let mut acc = Complex2 { re: [0.0; 2], im: [0.0; 2] };
            for (beam, f) in beams.iter().zip(factors.iter()).rev() {
                let mut b = Complex2 { re: poly(&beam.re), im: poly(&beam.im) };
                if JITTER {
                    // Jitter terms: dg·∂B/∂g + dtsq·(∂B/∂θ² + ½·dtsq·∂²B/∂θ²²), the first
                    // derivatives linear in σ.
                    b = b
                        .add_scaled(beam.d_gap[0], dg)
                        .add_scaled(beam.d_gap[1], dg_s)
                        .add_scaled(beam.d_tilt_sq[0], dtsq)
                        .add_scaled(beam.d_tilt_sq[1], dtsq_s)
                        .add_scaled(beam.half_d2_tilt_sq, dtsq2);
                }
                acc = acc.add(b).mul(*f);
            }
            let b0 = poly(&self.base[2]);
            for (lane, &k) in l.iter().enumerate() {
                let (re, im) = (acc.re[lane] + b0[lane], acc.im[lane]);
                block.power[k] = self.input_power_mw * (re * re + im * im);
            }
            j += 2;
        }
    }
}

/// Two lanes, one sample each.
type Pair = [f64; 2];

#[inline(always)]
fn mul2(a: Pair, b: Pair) -> Pair {
    [a[0] * b[0], a[1] * b[1]]
}

/// Complex numbers of two samples, real and imaginary parts in lanes.
#[derive(Debug, Clone, Copy, Default)]
struct Complex2 {
    re: Pair,
    im: Pair,
}

impl Complex2 {
    #[inline(always)]
    fn mul(self, o: Complex2) -> Complex2 {
        Complex2 {
            re: [self.re[0] * o.re[0] - self.im[0] * o.im[0], self.re[1] * o.re[1] - self.im[1] * o.im[1]],
            im: [self.re[0] * o.im[0] + self.im[0] * o.re[0], self.re[1] * o.im[1] + self.im[1] * o.re[1]],
        }
    }

    #[inline(always)]
    fn add(self, o: Complex2) -> Complex2 {
        Complex2 { re: [self.re[0] + o.re[0], self.re[1] + o.re[1]], im: [self.im[0] + o.im[0], self.im[1] + o.im[1]] }
    }

    /// self + c·x, one c for both lanes.
    #[inline(always)]
    fn add_scaled(self, c: Complex<f64>, x: Pair) -> Complex2 {
        Complex2 {
            re: [self.re[0] + c.re * x[0], self.re[1] + c.re * x[1]],
            im: [self.im[0] + c.im * x[0], self.im[1] + c.im * x[1]],
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::{run_plan, PlanRun};
    use crate::model::optics::OpticalParams;
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
        // Text (header, metadata) must not contain a secret; a number may by chance start with
        // the digits of one (q3 passing 0.7440… µm), so numeric fields must just differ from it.
        let is_number = |f: &str| f.trim().parse::<f64>().is_ok();
        for secret in ["112.4", "113.3", "0.744", "ThermalDrift", "PivotOffset", "truth"] {
            for line in csv.lines() {
                let fields: Vec<&str> = line.split(',').collect();
                if fields.iter().all(|f| is_number(f)) {
                    assert!(fields.iter().all(|f| f.trim() != secret), "the trace leaks `{secret}`: {line}");
                } else {
                    assert!(!line.contains(secret), "the trace leaks `{secret}`: {line}");
                }
            }
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

    /// Hidden optical effects are the optics they describe: a bench hiding "no Gouy phase" and a
    /// back face gives the power of a bench whose optics have them; a hidden cyclic error moves
    /// the gap by a·cos φ, as a drift of that much at the same instant does.
    #[test]
    fn hidden_optical_and_cyclic_effects_act_on_the_signal() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let back = crate::model::optics::BackFace { reflectance: 0.04, inverted: true, ..Default::default() };
        let mut hidden = preset.clone();
        hidden.effects = vec![
            Effect::GouyPhase { scale_error: -1.0 },
            Effect::LamellaBackFace {
                amplitude_reflectance: -0.2,
                thickness_um: back.thickness_um,
                phase_index: back.phase_index,
                group_index: back.group_index,
            },
        ];
        let mut explicit = preset.clone();
        explicit.optics.gouy_phase = false;
        explicit.optics.back_face = Some(back);
        let (a, b) = (VirtualBench::new(&hidden, None).unwrap(), VirtualBench::new(&explicit, None).unwrap());
        let plain = VirtualBench::new(&preset, None).unwrap();
        let chain = Chain::new(preset.robot_description().unwrap());
        for q in [[0.0; 6], [30.0, -40.0, 120.0, 2.0, -3.0, 10.0], [-150.0, 150.0, 0.0, -4.0, 4.0, -45.0]] {
            let (pa, pb) =
                (a.reflected_power_mw(3.0, &q, 1560.0).unwrap(), b.reflected_power_mw(3.0, &q, 1560.0).unwrap());
            assert!((pa - pb).abs() < 1e-12, "{q:?}: {pa} vs {pb}");
            let p0 = plain.reflected_power_mw(3.0, &q, 1560.0).unwrap();
            assert!((pa - p0).abs() > 1e-4 * p0, "{q:?}: the effects change nothing");

            // The cyclic error against a drift of the same size at t = 2 s.
            let (t_s, amplitude_nm) = (2.0, 3.0);
            let q_rad: Vec<f64> = (0..6).map(|i| if i >= 3 { q[i].to_radians() } else { q[i] }).collect();
            let gap_um = preset.truth.cavity(&chain.end_effector(&q_rad)).unwrap().length_um.abs();
            let phase = 2.0 * std::f64::consts::PI * gap_um / plain.truth.fp.fringe_period_um();
            let mut cyclic = preset.clone();
            cyclic.effects = vec![Effect::FringeNonlinearity { in_phase_nm: amplitude_nm, quadrature_nm: 0.0 }];
            let mut drift = preset.clone();
            drift.effects = vec![Effect::ThermalDrift { nm_per_s: amplitude_nm * phase.cos() / t_s, nm_per_s2: 0.0 }];
            let pc = VirtualBench::new(&cyclic, None).unwrap().reflected_power_mw(t_s, &q, 1560.0).unwrap();
            let pd = VirtualBench::new(&drift, None).unwrap().reflected_power_mw(t_s, &q, 1560.0).unwrap();
            assert!((pc - pd).abs() < 1e-12, "{q:?}: {pc} vs {pd}");
        }
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

    /// Largest |fast - exact| irradiance over every recorded sample of `plan`, as a fraction of
    /// the local two-beam fringe amplitude, with the detector noise and the ADC off (the
    /// stage jitter, encoder noise, drift, intrinsic errors and gain drift stay).
    fn fast_vs_exact(preset_name: &str, plan: &Plan) -> Vec<(String, f64)> {
        fast_vs_exact_with(preset_name, plan, |_| {})
    }

    fn fast_vs_exact_with(preset_name: &str, plan: &Plan, modify: impl Fn(&mut BenchPreset)) -> Vec<(String, f64)> {
        let mut preset = BenchPreset::resolve(preset_name).unwrap();
        modify(&mut preset);
        preset.detector.white_noise_rel_fringe = 0.0;
        preset.detector.shot_noise_mw_at_1mw = 0.0;
        preset.detector.adc_bits = 0;
        preset.laser.rin_rel = 0.0;
        let mut fast = VirtualBench::new(&preset, Some(5)).unwrap();
        let mut exact = VirtualBench::new(&preset, Some(5)).unwrap();
        exact.set_exact(true);
        let (a, b) = (run(&mut fast, plan), run(&mut exact, plan));
        assert!(a.outcome.is_ok() && b.outcome.is_ok());
        assert_eq!(a.traces.len(), b.traces.len());
        let chain = Chain::new(effects::apply_all(&preset.effects, &preset.robot_description().unwrap()).unwrap());
        let rev = |i: usize| chain.description().links[i].joint == JointType::Revolute;
        let fp = &exact.truth.fp;
        a.traces
            .iter()
            .zip(&b.traces)
            .map(|(ta, tb)| {
                assert_eq!(ta.len(), tb.len());
                assert_eq!(ta.q6_deg, tb.q6_deg, "same noise draws");
                let mut worst: f64 = 0.0;
                for j in 0..ta.len() {
                    let q_display = [ta.q1_um[j], ta.q2_um[j], ta.q3_um[j], ta.q4_deg[j], ta.q5_deg[j], ta.q6_deg[j]];
                    let q: Vec<f64> =
                        (0..6).map(|i| if rev(i) { q_display[i].to_radians() } else { q_display[i] }).collect();
                    let c = preset.truth.cavity(&chain.end_effector(&q)).unwrap();
                    // With no lamella reflection there is no fringe: relative to the power.
                    let amplitude = fp.two_beam(c.length_um, c.tilt_rad).amplitude_mw.max(1e-3 * tb.irradiance[j]);
                    worst = worst.max((ta.irradiance[j] - tb.irradiance[j]).abs() / amplitude);
                }
                (ta.meta.label.clone(), worst)
            })
            .collect()
    }

    /// The fast path against the exact per-sample model on strategy-1 moves (300 µm
    /// translations across and along the beam, 20 µm along it), strategy-2 rotations (±4°),
    /// a 45° turn of q6, a move of all joints and a wavelength sweep, on both presets
    /// (femto-lab: stage jitter, drift, intrinsic errors, cleave angle).
    #[test]
    fn fast_path_matches_the_exact_path() {
        let at = |q: [f64; 6]| JointTarget::all(q);
        let labelled =
            |target: JointTarget, label: &str| Segment::Move { to: target, record: true, label: label.into() };
        let p = plan(vec![
            mv(at([150.0, 0.0, -150.0, 0.0, 0.0, 0.0]), false),
            labelled(JointTarget::default().with(2, 150.0), "S1 X_w 300 µm at q1 = 150"),
            mv(at([-150.0, -150.0, 0.0, 0.0, 0.0, 0.0]), false),
            labelled(JointTarget::default().with(0, 150.0), "S1 Z_w 300 µm at q2 = -150"),
            mv(at([0.0, -150.0, 0.0, 0.0, 0.0, 0.0]), false),
            labelled(JointTarget::default().with(1, 150.0), "Y_w 300 µm along the beam"),
            mv(at([0.0, -10.0, 150.0, 0.0, 0.0, 0.0]), false),
            labelled(JointTarget::default().with(1, 10.0), "S1 Y_w 20 µm at q3 = 150"),
            mv(at([0.0, 0.0, 0.0, -4.0, -4.0, 0.0]), false),
            labelled(JointTarget::default().with(3, 4.0), "S2 q4 -4 -> 4° at q5 = -4°"),
            mv(at([0.0, 0.0, 0.0, 4.0, -4.0, 0.0]), false),
            labelled(JointTarget::default().with(4, 4.0), "S2 q5 -4 -> 4° at q4 = 4°"),
            mv(at([0.0; 6]), false),
            labelled(JointTarget::default().with(5, 45.0), "q6 0 -> 45°"),
            labelled(at([100.0, 20.0, 100.0, 3.0, -3.0, 10.0]), "all joints"),
            Segment::Sweep { from_nm: 1555.0, to_nm: 1565.0, rate_nm_per_s: 2.0, label: "sweep 10 nm".into() },
            dwell(2.0),
        ]);
        for preset in ["table2-ideal", "femto-lab"] {
            for (label, worst) in fast_vs_exact(preset, &p) {
                eprintln!("{preset}: {label}: max |fast - exact| = {worst:.2e} of the fringe amplitude");
                // 1e-6 is required; FAST_PATH_TOLERANCE (3e-8) gives at most ~2e-8.
                assert!(worst < 1e-7, "{preset}: {label}: {worst:e}");
            }
        }
    }

    /// Other optics on the fast path: no lamella reflection (no beam), one beam, a back face,
    /// many beams of a silicon lamella, no Gouy phase.
    #[test]
    fn fast_path_matches_the_exact_path_for_other_optics() {
        let p = plan(vec![
            mv(JointTarget::all([0.0, -20.0, 30.0, -2.0, 1.0, 0.0]), false),
            mv(JointTarget::all([10.0, 20.0, -30.0, 2.0, -1.0, 20.0]), true),
            Segment::Sweep { from_nm: 1555.0, to_nm: 1557.0, rate_nm_per_s: 2.0, label: "sweep".into() },
        ]);
        type Change = fn(&mut OpticalParams);
        let cases: [(&str, Change); 6] = [
            ("no reflection", |o| o.lamella_reflectance = 0.0),
            ("half the Gouy phase", |o| o.gouy_scale_error = -0.5),
            ("one beam", |o| o.beams = 1),
            ("back face", |o| o.back_face = Some(crate::model::optics::BackFace::default())),
            ("silicon, 40 beams", |o| {
                o.lamella_reflectance = 0.306;
                o.beams = 40
            }),
            ("no Gouy phase", |o| o.gouy_phase = false),
        ];
        for (name, change) in cases {
            for (label, worst) in fast_vs_exact_with("femto-lab", &p, |preset| change(&mut preset.optics)) {
                eprintln!("{name}: {label}: max |fast - exact| = {worst:.2e} of the fringe amplitude");
                assert!(worst < 1e-7, "{name}: {label}: {worst:e}");
            }
        }
    }

    /// `fill` gives the deviates of successive `sample` calls, however they are grouped.
    #[test]
    fn gaussian_fill_equals_successive_samples() {
        let tables = ziggurat_tables();
        let mut a = Gaussian::seed_from_u64(9);
        let mut b = Gaussian::seed_from_u64(9);
        let one_by_one: Vec<f64> = (0..100_000).map(|_| a.sample(tables)).collect();
        let mut filled = vec![0.0; 100_000];
        let mut at = 0;
        for size in (1..).cycle() {
            let end = (at + size % 37).min(filled.len());
            b.fill(tables, &mut filled[at..end]);
            at = end;
            if at == filled.len() {
                break;
            }
        }
        assert_eq!(one_by_one, filled);
    }

    /// erfc to a relative 1.2e-7 (Numerical Recipes' erfcc), for the test below.
    fn erfc(x: f64) -> f64 {
        let z = x.abs();
        let t = 1.0 / (1.0 + 0.5 * z);
        let p = -1.26551223
            + t * (1.00002368
                + t * (0.37409196
                    + t * (0.09678418
                        + t * (-0.18628806
                            + t * (0.27886807
                                + t * (-1.13520398 + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277))))))));
        let ans = t * (-z * z + p).exp();
        if x >= 0.0 {
            ans
        } else {
            2.0 - ans
        }
    }

    /// The ziggurat deviates against the standard normal: moments, a χ² over 72 bins, the tails
    /// out to 4.5σ (the slow paths) and the correlation of the two deviates of a 64-bit draw.
    #[test]
    fn gaussian_deviates_follow_the_standard_normal_distribution() {
        let tables = ziggurat_tables();
        for seed in [1, 987_654_321] {
            let mut g = Gaussian::seed_from_u64(seed);
            let n = 4_000_000;
            let (width, half) = (0.125, 36usize); // bins over [-4.5, 4.5]
            let mut bins = vec![0u64; 2 * half + 2];
            let (mut s1, mut s2, mut s3, mut s4, mut lag, mut prev) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
            let (mut beyond_3_5, mut beyond_4_5) = (0u64, 0u64);
            for _ in 0..n {
                let x = g.sample(tables);
                let x2 = x * x;
                (s1, s2, s3, s4) = (s1 + x, s2 + x2, s3 + x2 * x, s4 + x2 * x2);
                lag += x * prev;
                prev = x;
                beyond_3_5 += u64::from(x.abs() > 3.5);
                beyond_4_5 += u64::from(x.abs() > 4.5);
                let b = ((x / width).floor() + half as f64).clamp(-1.0, 2.0 * half as f64) + 1.0;
                bins[b as usize] += 1;
            }
            let nf = n as f64;
            let (mean, var) = (s1 / nf, s2 / nf - (s1 / nf).powi(2));
            assert!(mean.abs() < 5.0 / nf.sqrt(), "mean {mean}");
            assert!((var - 1.0).abs() < 5.0 * (2.0 / nf).sqrt(), "variance {var}");
            assert!((s3 / nf).abs() < 5.0 * (15.0 / nf).sqrt(), "third moment {}", s3 / nf);
            assert!((s4 / nf - 3.0).abs() < 5.0 * (96.0 / nf).sqrt(), "fourth moment {}", s4 / nf);
            assert!((lag / nf).abs() < 5.0 / nf.sqrt(), "lag-1 correlation {}", lag / nf);
            let cdf = |x: f64| 0.5 * erfc(-x / std::f64::consts::SQRT_2);
            let mut chi2 = 0.0;
            for (b, &count) in bins.iter().enumerate() {
                let lo = if b == 0 { f64::NEG_INFINITY } else { (b as f64 - 1.0 - half as f64) * width };
                let hi = if b == bins.len() - 1 { f64::INFINITY } else { (b as f64 - half as f64) * width };
                let expected = nf * (cdf(hi) - cdf(lo));
                chi2 += (count as f64 - expected).powi(2) / expected;
            }
            let dof = (bins.len() - 1) as f64;
            eprintln!("seed {seed}: mean {mean:.2e} var-1 {:.2e} m3 {:.2e} m4-3 {:.2e} lag {:.2e} χ² {chi2:.1}/{dof} tails {beyond_3_5} {beyond_4_5}", var - 1.0, s3 / nf, s4 / nf - 3.0, lag / nf);
            assert!(chi2 < dof + 6.0 * (2.0 * dof).sqrt(), "χ² = {chi2} for {dof} degrees of freedom");
            for (count, p) in
                [(beyond_3_5, erfc(3.5 / std::f64::consts::SQRT_2)), (beyond_4_5, erfc(4.5 / std::f64::consts::SQRT_2))]
            {
                let expected = nf * p;
                assert!((count as f64 - expected).abs() < 5.0 * expected.sqrt(), "{count} beyond, {expected} expected");
            }
        }
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
