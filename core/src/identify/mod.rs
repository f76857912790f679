//! Identification: measurements → extrinsic parameters with uncertainties (paper mode, joint estimate),
//! identifiability, experiment design. Owns the observation types and the forward prediction shared by every estimator.
//!
//! Every observation is predicted by the same forward model the virtual bench uses
//! ([`crate::model::phase::PhaseModel`]): phase-equivalent gap changes from the fringes, absolute
//! gaps from sweeps, fringe amplitudes (reflected power) from tilt scans.

mod approach;
pub mod design;
pub mod discrepancy;
pub mod joint;
pub mod measurements;
pub mod multistart;
pub mod observability;
pub mod paper;
pub mod signs;
pub mod start;
pub mod sweep_cost;
pub mod verdict;

use crate::model::effects::Effect;
use crate::model::extrinsics::{Extrinsics, PARAMETER_NAMES};
use crate::model::optics::FabryPerot;
use crate::model::phase::{PathForward, PhaseModel};
use serde::{Deserialize, Serialize};

/// Number of extrinsic parameters.
pub const N_EXTRINSICS: usize = 8;

/// Scale of each parameter in the estimators' internal units: angles in mrad, lengths in µm,
/// so the Jacobian columns are comparable. `internal = value / scale`
/// with values in ° and µm.
pub fn parameter_scale(i: usize) -> f64 {
    if PARAMETER_NAMES[i].1 == "°" {
        0.001f64.to_degrees() // 1 mrad in degrees
    } else {
        1.0
    }
}

/// What was observed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum ObservationKind {
    /// Phase-equivalent gap change from one pose to another (nm), from the fringes.
    GapChange {
        /// Joints at the start (µm, °).
        from_display: [f64; 6],
        /// Joints at the end (µm, °).
        to_display: [f64; 6],
        /// Measured change (nm).
        dl_nm: f64,
    },
    /// Phase-equivalent (perpendicular) gap at a pose (µm), from a wavelength sweep.
    AbsoluteGap {
        /// Joints (µm, °).
        at_display: [f64; 6],
        /// Measured gap (µm).
        gap_um: f64,
        /// Rate of the sweep's wavelength (nm/s; 0 when unknown): a gap that moves during the
        /// sweep (drift) reads off by whole fringe orders of its rate times λ over this
        /// ([`crate::model::effects::sweep_reading_nm`]).
        #[serde(default)]
        sweep_nm_per_s: f64,
    },
    /// Fringe amplitude at a pose (mW), from a tilt scan; `group` shares one unknown detector
    /// gain between the observations of one scan.
    FringeAmplitude {
        /// Joints (µm, °).
        at_display: [f64; 6],
        /// Measured half peak-to-peak fringe amplitude (mW).
        amplitude_mw: f64,
        /// Gain group.
        group: usize,
        /// When the amplitude comes from three extrema in a row: where the outer two were.
        /// The model then predicts the same combination of the three extrema, so that a fringe
        /// level and amplitude that curve along the scan (the tilt's Gaussian) do not bias it.
        /// `None`: the half peak-to-peak at `at_display` (older files, designed templates).
        #[serde(default)]
        neighbours: Option<AmplitudeNeighbours>,
    },
}

/// The outer extrema of a fringe amplitude measured from three extrema in a row: the middle
/// one (at [`ObservationKind::FringeAmplitude::at_display`]) against the mean of its
/// neighbours, `|(E₀ + E₂)/2 − E₁| / 2` (mW).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AmplitudeNeighbours {
    /// Joints at the extremum before the middle one (µm, °).
    pub before_display: [f64; 6],
    /// Joints at the extremum after it (µm, °).
    pub after_display: [f64; 6],
    /// The middle extremum is a maximum of the reflected power (its neighbours are minima).
    pub middle_is_max: bool,
    /// Where each extremum's value was read (before, middle, after): the joints at the first
    /// and the last sample of the window its parabola was fitted in (µm, °). The model then
    /// fits the same parabola to its own power along the path between them, so that the tilt
    /// and the gap moving together through the window count as they did on the bench.
    /// `None` (older files): each extremum is the fixed-tilt fringe's at its pose.
    #[serde(default)]
    pub windows_display: Option<Box<[[[f64; 6]; 2]; 3]>>,
}

/// One observation with its standard uncertainty (in the observation's unit: nm, µm or mW).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Observation {
    /// Which motion or measurement it comes from (for residual reports).
    pub label: String,
    /// What was observed.
    pub kind: ObservationKind,
    /// Standard uncertainty (nm for gap changes, µm for gaps, mW for amplitudes).
    pub sigma: f64,
    /// Vacuum wavelength (nm).
    pub wavelength_nm: f64,
    /// Bench time (s) of the start and end of the observation (a gap change's two poses; a
    /// pose measurement's start and end): what time-dependent effects (drift) act on.
    #[serde(default)]
    pub time_s: [f64; 2],
    /// The direction each joint q1..q6 last moved in before the start pose and before the end
    /// pose (+1, −1; 0 when unknown or never moved): what a reversal error acts on.
    #[serde(default)]
    pub approach: [[i8; 6]; 2],
}

impl Observation {
    /// The unit of the observation's value and σ.
    pub fn unit(&self) -> &'static str {
        match self.kind {
            ObservationKind::GapChange { .. } => "nm",
            ObservationKind::AbsoluteGap { .. } => "µm",
            ObservationKind::FringeAmplitude { .. } => "mW",
        }
    }

    /// The measured value.
    pub fn value(&self) -> f64 {
        match self.kind {
            ObservationKind::GapChange { dl_nm, .. } => dl_nm,
            ObservationKind::AbsoluteGap { gap_um, .. } => gap_um,
            ObservationKind::FringeAmplitude { amplitude_mw, .. } => amplitude_mw,
        }
    }
}

/// Half the peak-to-peak reflected power over one fringe at gap `gap_um` and tilt `tilt_rad`
/// (mW), from the full multi-beam model: what [`ObservationKind::FringeAmplitude`] measures.
/// The coupling barely changes over one fringe (λ/2 ≪ z_R), so the gap is stepped through one
/// fringe period and the extremes found on the trigonometric interpolant of the samples.
pub fn half_peak_to_peak_mw(fp: &FabryPerot, gap_um: f64, tilt_rad: f64) -> f64 {
    let (max, min) = fringe_extremes_mw(fp, gap_um, tilt_rad);
    (max - min) / 2.0
}

/// The largest and the smallest reflected power over one fringe at gap `gap_um` and tilt
/// `tilt_rad` (mW), from the full multi-beam model (see [`half_peak_to_peak_mw`]).
pub fn fringe_extremes_mw(fp: &FabryPerot, gap_um: f64, tilt_rad: f64) -> (f64, f64) {
    use std::f64::consts::TAU;
    const N: usize = 32;
    const H: usize = 6; // harmonics kept: R ≤ 0.3 puts the 7th below 1e-4 of the fundamental
    let period = fp.fringe_period_um();
    let p: Vec<f64> = (0..N).map(|k| fp.power(gap_um + period * k as f64 / N as f64, tilt_rad)).collect();
    // Trigonometric interpolant over one fringe, then Newton on its derivative from the best
    // sample: smooth in the gap and tilt (no arg-max jumps), so finite differences behave.
    let mut c = [(0.0f64, 0.0f64); H + 1];
    for (h, ch) in c.iter_mut().enumerate().skip(1) {
        for (k, pk) in p.iter().enumerate() {
            let a = TAU * (h * k) as f64 / N as f64;
            ch.0 += 2.0 / N as f64 * pk * a.cos();
            ch.1 += 2.0 / N as f64 * pk * a.sin();
        }
    }
    let deriv = |x: f64, order: u32| -> f64 {
        (1..=H)
            .map(|h| {
                let (a, b) = c[h];
                let w = h as f64;
                let (s, co) = (w * x).sin_cos();
                match order {
                    0 => a * co + b * s,
                    1 => w * (-a * s + b * co),
                    _ => -w * w * (a * co + b * s),
                }
            })
            .sum()
    };
    let extreme = |sign: f64| {
        let k = (0..N).max_by(|&i, &j| (sign * p[i]).total_cmp(&(sign * p[j]))).unwrap_or(0);
        let mut x = TAU * k as f64 / N as f64;
        for _ in 0..6 {
            let d2 = deriv(x, 2);
            if d2 == 0.0 {
                break;
            }
            x -= (deriv(x, 1) / d2).clamp(-0.2, 0.2);
        }
        // What the fringe analysis measures: the top of a least-squares parabola through the
        // fringe within ±VERTEX_WINDOW_HALF_FRINGE of a half fringe (π) of it, the window
        // centred on that top (see `measurements::vertex_value`). Not the fringe's own
        // extreme: for a cosine 0.05 % of the amplitude lower, more as the harmonics grow.
        let w = VERTEX_WINDOW_HALF_FRINGE * std::f64::consts::PI;
        let xs = unit_grid::<33>();
        let mut top = (deriv(x, 0), x);
        for _ in 0..3 {
            let ys = xs.map(|u| deriv(top.1 + u * w, 0));
            match parabola_top(&xs, &ys) {
                Some((value, u, curvature)) if sign * curvature < 0.0 => top = (value, top.1 + u * w),
                _ => break,
            }
        }
        top.0
    };
    (extreme(1.0), extreme(-1.0))
}

/// What `measurements::vertex_value` reads from the samples of one window: the top of the
/// least-squares parabola through the power across the window. The tilt follows the straight
/// joint path from `window[0]` to `window[1]` (the samples are evenly spaced in time and the
/// joints move at a steady speed through one window); the gap runs evenly over the window's
/// width on the tracked gap, ±[`VERTEX_WINDOW_HALF_FRINGE`] of a half fringe, as measured,
/// not as the model would move it (a model that misses an effect can miss the gap's rate by a
/// lot). The fringe's phase is not the bench's (the absolute gap is known to far less than a
/// fringe), so the gap is shifted until the model's top of the wanted kind (`max`: a maximum)
/// sits at the window's centre, as the samples' does by construction. NaN when the beam
/// misses the lamella or the parabola curves the wrong way.
fn windowed_top(
    fp: &FabryPerot,
    window: [[f64; 6]; 2],
    max: bool,
    gap_tilt: impl Fn(&[f64; 6]) -> Option<(f64, f64)>,
) -> f64 {
    const K: usize = 17;
    let sign = if max { 1.0 } else { -1.0 };
    let xs = unit_grid::<K>();
    // The window is a fraction of a fringe of motion: the model is evaluated at five of its
    // points and carried to the others by the quartic through them ([`on_grid`]).
    let nodes: Option<Vec<(f64, f64)>> = (0..NODES)
        .map(|j| {
            let f = j as f64 / (NODES - 1) as f64;
            gap_tilt(&std::array::from_fn(|i| window[0][i] + f * (window[1][i] - window[0][i])))
        })
        .collect();
    let Some(nodes) = nodes else {
        return f64::NAN;
    };
    let gaps = on_grid::<K>(std::array::from_fn(|j| nodes[j].0));
    let tilts = on_grid::<K>(std::array::from_fn(|j| nodes[j].1));
    let path: [(f64, f64); K] = std::array::from_fn(|k| (gaps[k], tilts[k]));
    let period = fp.fringe_period_um();
    let half_width_um = VERTEX_WINDOW_HALF_FRINGE * period / 2.0;
    // The gap runs the way the model moves it from window[0] to window[1] (a turning point
    // inside a window gives no amplitude): with the tilt moving too, the direction counts.
    let run = (path[K - 1].0 - path[0].0).signum();
    // The window's width is on the tracked phase, which the tilt moves too (the Gouy phase, a
    // back face's second fringe): the gap takes up what the tilt adds, so that the phase runs
    // evenly over ±half_width_um.
    let (g_c, t_c) = path[K / 2];
    let phase_c = fp.fundamental_phase_rad(g_c, t_c);
    let phases = on_grid::<K>(std::array::from_fn(|j| fp.fundamental_phase_rad(g_c, nodes[j].1)));
    let tilt_um: [f64; K] = std::array::from_fn(|k| (phases[k] - phase_c) * period / std::f64::consts::TAU);
    let gap = |k: usize, shift_um: f64| g_c + shift_um + run * xs[k] * half_width_um - tilt_um[k];
    // Start at the fundamental's extreme of the wanted kind nearest the centre (its phase runs
    // with the gap: a maximum where it is a whole number of turns), then move the fringe until
    // the parabola's top is at the centre. The higher harmonics can move the top off the
    // fundamental's: should the parabola then curve the wrong way, start from the best of a
    // scan over one fringe at fixed tilt.
    let turns = (phase_c / std::f64::consts::TAU) + if max { 0.0 } else { 0.5 };
    let fundamental_top_um = -(turns - turns.round()) * period;
    // The parabola's top through the window's points, the fringe moved until that top sits at
    // the window's centre; `None` when the parabola curves the wrong way.
    let top = |mut shift_um: f64| -> Option<f64> {
        let mut value = f64::NAN;
        for _ in 0..4 {
            let ys = fp.powers(&std::array::from_fn(|k| gap(k, shift_um)), &tilts);
            let (v, x, _) = parabola_top(&xs, &ys).filter(|t| sign * t.2 < 0.0)?;
            value = v;
            let step_um = run * x * half_width_um;
            shift_um += step_um;
            // Settled: stopping at 0.1 nm rather than 1 pm moves the identified extrinsics of
            // a joint session by under 0.01σ and saves a parabola on most tops.
            if step_um.abs() < 1e-4 {
                break;
            }
        }
        Some(value)
    };
    top(fundamental_top_um)
        .or_else(|| {
            let scan = (0..32)
                .map(|k| {
                    let shift_um = (k as f64 / 32.0 - 0.5) * period;
                    (shift_um, sign * fp.power(gap(K / 2, shift_um), t_c))
                })
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .map_or(0.0, |(shift_um, _)| shift_um);
            top(scan)
        })
        .unwrap_or(f64::NAN)
}

/// Poses of a window at which [`windowed_top`] evaluates the model: the first, every quarter, the
/// last.
const NODES: usize = 5;

/// Values at the `NODES` evenly spread nodes of [0, 1], carried to the `K` points of the window's
/// grid by the quartic through them (Lagrange): exact at the nodes, which are grid points
/// (K − 1 a multiple of 4). A window moves the gap by a fifth of a half fringe and the tilt by
/// at most a few mrad: the quartic holds the gap to a femtometre and the tilt to 1e-8 rad.
fn on_grid<const K: usize>(values: [f64; NODES]) -> [f64; K] {
    let node = |j: usize| j as f64 / (NODES - 1) as f64;
    std::array::from_fn(|k| {
        let f = k as f64 / (K - 1) as f64;
        if (k * (NODES - 1)) % (K - 1) == 0 {
            return values[k * (NODES - 1) / (K - 1)];
        }
        (0..NODES)
            .map(|j| {
                let basis: f64 = (0..NODES).filter(|&i| i != j).map(|i| (f - node(i)) / (node(j) - node(i))).product();
                values[j] * basis
            })
            .sum()
    })
}

/// `K` points evenly spread over [−1, 1].
fn unit_grid<const K: usize>() -> [f64; K] {
    std::array::from_fn(|i| -1.0 + 2.0 * i as f64 / (K - 1) as f64)
}

/// Half-width of the window around an intensity extremum in which its value is read from a
/// least-squares parabola, as a fraction of a half fringe (0.2: ±0.63 rad of fringe phase,
/// where a cosine departs from its parabola by under 0.2 % of the amplitude).
pub const VERTEX_WINDOW_HALF_FRINGE: f64 = 0.2;

/// Least-squares parabola y = c₀ + c₁x + c₂x² through the points (x in about ±1): its
/// coefficients, or `None` when the normal equations are singular.
fn parabola(xs: &[f64], ys: &[f64]) -> Option<nalgebra::Vector3<f64>> {
    let mut a = nalgebra::Matrix3::<f64>::zeros();
    let mut b = nalgebra::Vector3::<f64>::zeros();
    for (&x, &y) in xs.iter().zip(ys) {
        let row = nalgebra::Vector3::new(1.0, x, x * x);
        a += row * row.transpose();
        b += row * y;
    }
    a.lu().solve(&b)
}

/// The top of the least-squares parabola through the points: its value, where it is (clamped
/// to the points' range) and its curvature c₂ (negative for a maximum). `None` when the
/// parabola is singular or flat.
pub(crate) fn parabola_top(xs: &[f64], ys: &[f64]) -> Option<(f64, f64, f64)> {
    let c = parabola(xs, ys)?;
    if c[2] == 0.0 {
        return None;
    }
    let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let x = (-c[1] / (2.0 * c[2])).clamp(lo, hi);
    Some((c[0] + c[1] * x + c[2] * x * x, x, c[2]))
}

/// Predict an observation from extrinsics `e` and the gain of its amplitude group (ignored for
/// other kinds). NaN when the beam misses the lamella.
pub fn predict(model: &PhaseModel, fp: &FabryPerot, e: &Extrinsics, obs: &Observation, gain: f64) -> f64 {
    predict_with_path(model, fp, e, obs, gain, &[])
}

/// [`predict`] with path effects (drift, path scale, cyclic errors, reversal play) acting
/// as the virtual bench applies them ([`PathForward`]).
pub fn predict_with_path(
    model: &PhaseModel,
    fp: &FabryPerot,
    e: &Extrinsics,
    obs: &Observation,
    gain: f64,
    path: &[Effect],
) -> f64 {
    let forward = PathForward::new(model, fp, e, path);
    let optical_gap_um = |length_um: f64, t_s: f64| forward.optical_gap_um(length_um, t_s);
    let t_mid = 0.5 * (obs.time_s[0] + obs.time_s[1]);
    // The end poses' real joints: the reading moved by any reversal error (start, end).
    let real = |q: &[f64; 6], end: usize| forward.real_joints(q, &obs.approach[end]);
    let cavity = |q: &[f64; 6]| forward.cavity(q);
    let phase_gap_nm = |q: &[f64; 6], t_s: f64| forward.phase_gap_nm(q, t_s);
    match &obs.kind {
        ObservationKind::GapChange { from_display, to_display, .. } => {
            phase_gap_nm(&real(to_display, 1), obs.time_s[1]) - phase_gap_nm(&real(from_display, 0), obs.time_s[0])
        }
        ObservationKind::AbsoluteGap { at_display, sweep_nm_per_s, .. } => {
            cavity(&real(at_display, 1)).map_or(f64::NAN, |c| {
                optical_gap_um(c.length_um, t_mid) * (1.0 - c.tilt_rad * c.tilt_rad / 2.0)
                    + forward.sweep_reading_um(t_mid, obs.wavelength_nm, *sweep_nm_per_s)
            })
        }
        ObservationKind::FringeAmplitude { at_display, neighbours: None, .. } => cavity(&real(at_display, 1))
            .map_or(f64::NAN, |c| gain * half_peak_to_peak_mw(fp, optical_gap_um(c.length_um, t_mid), c.tilt_rad)),
        ObservationKind::FringeAmplitude { at_display, neighbours: Some(n), .. } => {
            let gap_tilt = |q: &[f64; 6]| cavity(&real(q, 1)).map(|c| (optical_gap_um(c.length_um, t_mid), c.tilt_rad));
            // The value read at each extremum (middle, before, after): a maximum for the middle
            // one when `middle_is_max`, minima for its neighbours, and the other way round.
            let kinds = [n.middle_is_max, !n.middle_is_max, !n.middle_is_max];
            let tops: [f64; 3] = match &n.windows_display {
                // Windows are stored before, middle, after.
                Some(w) => std::array::from_fn(|j| windowed_top(fp, w[[1, 0, 2][j]], kinds[j], gap_tilt)),
                None => {
                    let poses = [at_display, &n.before_display, &n.after_display];
                    std::array::from_fn(|j| {
                        gap_tilt(poses[j]).map_or(f64::NAN, |(gap_um, tilt_rad)| {
                            let (max, min) = fringe_extremes_mw(fp, gap_um, tilt_rad);
                            if kinds[j] {
                                max
                            } else {
                                min
                            }
                        })
                    })
                }
            };
            let combined =
                if n.middle_is_max { tops[0] - 0.5 * (tops[1] + tops[2]) } else { 0.5 * (tops[1] + tops[2]) - tops[0] };
            gain * combined / 2.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::BenchPreset;
    use crate::model::robot::RobotDescription;

    /// The quartic through the nodes reproduces any quartic, and the nodes' values exactly.
    #[test]
    fn the_window_grid_carries_a_quartic_exactly() {
        let quartic = |f: f64| 3.0 - 2.0 * f + 0.5 * f * f - 7.0 * f.powi(3) + 1.25 * f.powi(4);
        let values: [f64; NODES] = std::array::from_fn(|j| quartic(j as f64 / (NODES - 1) as f64));
        let grid = on_grid::<17>(values);
        for (k, v) in grid.iter().enumerate() {
            assert!((v - quartic(k as f64 / 16.0)).abs() < 1e-13, "point {k}: {v}");
        }
        assert_eq!(grid[0].to_bits(), values[0].to_bits());
        assert_eq!(grid[8].to_bits(), values[2].to_bits());
    }

    /// Against the kinematics at every point of a window: a rotation's window at the top of a
    /// tilt scan (the gap stationary, the widest a window gets in tilt: ±0.2°), and a
    /// translation's. The gap within a femtometre, the tilt within 1e-8 rad (the coupling then
    /// moves by 2e-8 of itself, the phase by 3e-7 rad).
    #[test]
    fn the_window_grid_is_the_kinematics_to_a_femtometre() {
        let preset = BenchPreset::resolve("table2-ideal").unwrap();
        let model =
            PhaseModel::new(RobotDescription::femto_6dof(), preset.truth, preset.optics, &preset.ambient, 1560.0)
                .unwrap();
        let windows = [
            [[0.0, 0.0, 0.0, -0.2, 0.0, 0.0], [0.0, 0.0, 0.0, 0.2, 0.0, 0.0]],
            [[0.0, 0.0, 0.0, 0.0, 2.8, 0.0], [0.0, 0.0, 0.0, 0.0, 3.2, 0.0]],
            [[-50.0, 0.0, 0.0, 0.0, 0.0, 0.0], [-49.92, 0.0, 0.0, 0.0, 0.0, 0.0]],
        ];
        for w in windows {
            let pose = |f: f64| -> [f64; 6] { std::array::from_fn(|i| w[0][i] + f * (w[1][i] - w[0][i])) };
            let nodes: [(f64, f64); NODES] =
                std::array::from_fn(|j| model.gap_and_tilt(&pose(j as f64 / (NODES - 1) as f64)).unwrap());
            let gaps = on_grid::<17>(nodes.map(|n| n.0));
            let tilts = on_grid::<17>(nodes.map(|n| n.1));
            let (mut gap_off, mut tilt_off) = (0.0f64, 0.0f64);
            for k in 0..17 {
                let (g, t) = model.gap_and_tilt(&pose(k as f64 / 16.0)).unwrap();
                gap_off = gap_off.max((gaps[k] - g).abs());
                tilt_off = tilt_off.max((tilts[k] - t).abs());
            }
            eprintln!("{w:?}: gap within {gap_off:.1e} µm, tilt within {tilt_off:.1e} rad");
            assert!(gap_off < 1e-9 && tilt_off < 1e-8, "{w:?}: gap off by {gap_off} µm, tilt by {tilt_off} rad");
        }
    }
}
