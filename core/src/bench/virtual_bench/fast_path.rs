//! The fast path of the virtual bench: the exact path's model ([`Truth::power_exact`]),
//! rearranged for dense sampling. The field is E = Σ_m B_m·u^m·w^(e_m) ([`FringeExpansion`])
//! with two phasors computed exactly per sample, u = exp(-i·k·g·(2 - θ²)) and w = exp(i·k·g·θ²) (g the optical gap, |L| with the
//! drift and path-scale effects), and coefficients B_m that vary slowly (on the scales of
//! z_R in gap and of 1/(m·k·w0)² in θ²). Within a segment the commanded joints follow
//! q(s) = from + s·(to - from) and the wavelength is linear in time, so the noise-free gap
//! without the drift, g_geo, and θ² are smooth functions of the path fraction s (not of
//! time during accelerations, where a translation times a rotation is quartic in t), and
//! the B_m smooth functions of time. All are computed exactly at nodes, with their
//! derivatives (the geometric Jacobian for g_geo and θ², the analytic partial derivatives
//! of the expansion for B_m), and interpolated between nodes by cubic Hermite polynomials,
//! in s for g_geo and θ², in t for B_m; the drift is added exactly per sample. Nodes sit on
//! the kinks of the velocity profile and are adaptive between them: each interval is
//! checked at its midpoint against an exact node and halved until a bound on the
//! irradiance error there is below [`FAST_PATH_TOLERANCE`] of the fringe amplitude (at
//! most [`MAX_NODE_INTERVAL`] samples per interval). Samples are computed in blocks of 32,
//! stage by stage, two at a time, so that the processor overlaps independent samples.
//!
//! Stage jitter δq (nm, µrad) is applied per sample through the jitter gradients at the
//! nodes (interpolated linearly along the path): to first order δg = Σ ∂g/∂q_i·δq_i,
//! δθ² = Σ ∂θ²/∂q_i·δq_i and B_m += ∂B_m/∂g·δg + ∂B_m/∂θ²·δθ²; the phasors use g + δg and
//! θ² + δθ² exactly. Second-order terms that matter are kept: the bilinear term δn_t·δO_t
//! of L (a rotation jitter times a translation jitter: up to 3e-7 of the fringe amplitude
//! otherwise), the transverse term |δn_t|² - (δn_t·n_f)² of θ² (k·|L|·δθ² ≈ 3600·δθ² rad
//! of tilt phase) and ½·∂²B_m/∂(θ²)²·(δθ²)². What is left is of the order of the rotations'
//! own second-order terms (θ·δφ² ≈ 1e-12 rad² for µrad jitter) and of (δg/z_R)² ≈ 1e-7 of
//! the higher beams' coefficients, below 1e-9 of the fringe amplitude at Table II's gap.
//! The interpolation error bounds take the jitter as Gaussian, at six standard deviations.
//!
//! The test `fast_path_matches_the_exact_path` compares both paths sample by sample on
//! strategy-1 and strategy-2 moves, a 45° turn of q6, a move of all joints, a sweep and a
//! dwell, on both presets: the difference stays below 3e-8 of the fringe amplitude.

use super::truth::{GapMap, Truth};
use super::{command, Block, BLOCK};
use crate::bench::BenchError;
use crate::model::kinematics::sin_cos_2;
use crate::model::optics::{tilt_phase_order, FabryPerot, FringeExpansion};
use crate::plan::{TimedMotion, TimedSegment};
use nalgebra::{Complex, Point3, Vector3};
use std::f64::consts::PI;

/// Largest irradiance error of the fast path's interpolation, as a fraction of the fringe
/// amplitude, estimated at the midpoint of every node interval.
pub const FAST_PATH_TOLERANCE: f64 = 3e-8;

/// Longest node interval of the fast path, in samples.
pub const MAX_NODE_INTERVAL: usize = 2048;

/// Highest beam order the fast path handles (more beams fall back to the exact path).
const MAX_FAST_ORDER: usize = 32;

impl Truth {
    /// The fast path's node at segment time `t`: the interpolated quantities and their
    /// derivatives (in s for the geometry, in t for the coefficients), exactly, and the jitter
    /// gradients.
    pub(super) fn node(
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
pub(super) struct Node {
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
pub(super) struct FastSegment {
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
    pub(super) tb: f64,
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
    pub(super) done: bool,
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
    pub(super) fn new(
        truth: &Truth,
        segment: &TimedSegment,
        t0: f64,
        samples: usize,
    ) -> Result<Option<Self>, BenchError> {
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
    pub(super) fn cover(&mut self, truth: &Truth, t: f64) -> Result<(), BenchError> {
        while t > self.tb && !self.done {
            self.next_interval(truth)?;
        }
        Ok(())
    }

    /// Reflected power (mW) of the first `n` samples of `block`, all in the current interval.
    pub(super) fn power_block(&mut self, block: &mut Block, n: usize) {
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
