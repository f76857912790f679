//! The effect library: named, parametrised extensions of the bench model, neutral at zero.
//! Owns how each effect acts on the forward model; the virtual bench hides effects and the diagnosis fits them with this same code.
//!
//! An effect acts in one of four places: on the robot's intrinsic geometry (through
//! [`crate::model::robot::JointErrors`]), on the cavity length over time (drift, index scale),
//! on the optics (Gouy phase, lamella back face), or on the measured phase (cyclic error). The diagnosis workflow extends this list; bench files name effects by
//! these variants, with units in every field name.

use crate::model::optics::{BackFace, OpticalParams};
use crate::model::robot::RobotDescription;
use serde::{Deserialize, Serialize};

/// One effect with its parameters. Every field is zero (or absent) at its neutral value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Effect {
    /// Thermal drift of the cavity: the gap grows by `nm_per_s·t + ½·nm_per_s2·t²` (t from the
    /// start of the session).
    ThermalDrift {
        /// Drift rate (nm/s).
        nm_per_s: f64,
        /// Drift acceleration (nm/s²).
        #[serde(default)]
        nm_per_s2: f64,
    },
    /// Optical path scale error (ppm), e.g. the air index left out (268 ppm) or a wavelength
    /// error: the optical gap is the geometric gap × (1 + ppm·1e-6).
    PathScale {
        /// Scale error (ppm).
        ppm: f64,
    },
    /// Scale (gain) error of a joint (ppm).
    JointScale {
        /// Joint name, e.g. "q2".
        joint: String,
        /// Scale error (ppm).
        ppm: f64,
    },
    /// Zero offset of a joint, in its display unit (µm or °).
    JointZeroOffset {
        /// Joint name.
        joint: String,
        /// Offset (µm or °).
        offset: f64,
    },
    /// A revolute joint's axis misses the common origin: it passes through this point, given in
    /// world coordinates at q = 0 (µm).
    PivotOffset {
        /// Joint name, e.g. "q4".
        joint: String,
        /// Offset of the axis, world X, Y, Z at q = 0 (µm).
        offset_world_um: [f64; 3],
    },
    /// A joint's axis is tilted toward the link frame's x and y axes (mrad).
    AxisTilt {
        /// Joint name.
        joint: String,
        /// Tilt toward the link x and y axes (mrad).
        tilt_mrad: [f64; 2],
    },
    /// Reversal error of a stick-slip stage: the stage lags its reading by half `step` in the
    /// direction it last moved (a play of `step` between the sensor and the platform), so a pose
    /// approached from opposite sides differs by `step`.
    ReversalError {
        /// Joint name.
        joint: String,
        /// Width of the play, in the joint's display unit (µm or °).
        step: f64,
    },
    /// The beam's Gouy phase differs from the model's: each returning beam's Gouy phase is
    /// scaled by (1 + `scale_error`) when the model has one (−1: the beam has none), or by
    /// `scale_error` when the model has none (+1: the switch the model left off).
    GouyPhase {
        /// Fractional error of the Gouy phase (dimensionless).
        scale_error: f64,
    },
    /// The lamella's back face reflects: a second cavity behind the first, `thickness_um`
    /// deeper at the lamella's index.
    LamellaBackFace {
        /// Amplitude reflectance of the back face seen from inside the lamella (dimensionless,
        /// √R; negative for a π phase shift on reflection, as from a high-index coating).
        amplitude_reflectance: f64,
        /// Lamella thickness (µm).
        thickness_um: f64,
        /// Phase index of the lamella at the laser wavelength (dimensionless).
        phase_index: f64,
        /// Group index of the lamella (dimensionless).
        group_index: f64,
    },
    /// A cyclic error of the measured phase, periodic over one fringe: the gap reads
    /// `in_phase_nm·cos φ + quadrature_nm·sin φ` more than it is, φ = 4π·n·gap/λ. What a fringe
    /// analysis that assumes a pure cosine leaves when the fringe carries a 2nd harmonic (the
    /// paper's counting, dL imported from another system).
    FringeNonlinearity {
        /// Amplitude of the cos φ term (nm).
        in_phase_nm: f64,
        /// Amplitude of the sin φ term (nm).
        quadrature_nm: f64,
    },
}

/// Why an effect cannot be applied.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EffectError {
    /// The effect names a joint the robot does not have.
    #[error("effect {effect}: no joint named `{joint}` (the robot has {known})")]
    UnknownJoint {
        /// The effect's name.
        effect: &'static str,
        /// The joint it names.
        joint: String,
        /// The joints the robot has.
        known: String,
    },
    /// An optical effect takes the optics out of their accepted range.
    #[error("optical effects: {0}")]
    Optics(String),
}

impl Effect {
    /// The effect's name, as used in reports.
    pub fn name(&self) -> &'static str {
        match self {
            Effect::ThermalDrift { .. } => "thermal drift",
            Effect::PathScale { .. } => "optical path scale",
            Effect::JointScale { .. } => "joint scale error",
            Effect::JointZeroOffset { .. } => "joint zero offset",
            Effect::PivotOffset { .. } => "pivot offset",
            Effect::AxisTilt { .. } => "axis tilt",
            Effect::ReversalError { .. } => "reversal error",
            Effect::GouyPhase { .. } => "Gouy phase",
            Effect::LamellaBackFace { .. } => "lamella back face",
            Effect::FringeNonlinearity { .. } => "fringe nonlinearity",
        }
    }

    /// A one-line physical description.
    pub fn description(&self) -> &'static str {
        match self {
            Effect::ThermalDrift { .. } => "the mechanical loop expands with temperature: the gap drifts in time",
            Effect::PathScale { .. } => {
                "the optical path differs from the geometric one by a constant factor (air index, wavelength error)"
            }
            Effect::JointScale { .. } => "a stage moves more or less than commanded, in proportion",
            Effect::JointZeroOffset { .. } => "a stage's zero is not where the model puts it",
            Effect::PivotOffset { .. } => "a goniometer's rotation axis misses the common rotation centre",
            Effect::AxisTilt { .. } => "a stage's axis is not along its nominal direction",
            Effect::ReversalError { .. } => {
                "a stage stops short of its reading by half its play, on the side it came from: poses depend on the approach"
            }
            Effect::GouyPhase { .. } => {
                "the beam's Gouy phase is not the model's: the fringe phase departs from 2k·L near the Rayleigh range"
            }
            Effect::LamellaBackFace { .. } => {
                "the lamella's back face reflects: a second cavity pulls the fringe phase and amplitude with tilt and gap"
            }
            Effect::FringeNonlinearity { .. } => {
                "the fringe analysis reads the phase with a cyclic error of one fringe's period (unmodelled harmonics)"
            }
        }
    }

    /// Apply the geometric part of the effect to a robot description (intrinsic errors add).
    pub fn apply_to_robot(&self, robot: &mut RobotDescription) -> Result<(), EffectError> {
        let index = |joint: &str| {
            robot.links.iter().position(|l| l.name == joint).ok_or_else(|| EffectError::UnknownJoint {
                effect: self.name(),
                joint: joint.to_string(),
                known: robot.joint_names().join(", "),
            })
        };
        match self {
            Effect::JointScale { joint, ppm } => {
                let i = index(joint)?;
                robot.links[i].errors.scale_ppm += ppm;
            }
            Effect::JointZeroOffset { joint, offset } => {
                let i = index(joint)?;
                robot.links[i].errors.zero_offset += offset;
            }
            Effect::AxisTilt { joint, tilt_mrad } => {
                let i = index(joint)?;
                robot.links[i].errors.axis_tilt_mrad[0] += tilt_mrad[0];
                robot.links[i].errors.axis_tilt_mrad[1] += tilt_mrad[1];
            }
            Effect::PivotOffset { joint, offset_world_um } => {
                let i = index(joint)?;
                // Express the world offset in the joint's frame at q = 0 (nominal chain).
                let mut nominal = robot.clone();
                for l in &mut nominal.links {
                    l.errors = Default::default();
                }
                let chain = crate::model::kinematics::Chain::new(nominal);
                let q0 = vec![0.0; chain.dof()];
                let frame = if i == 0 { nalgebra::Isometry3::identity() } else { chain.frames(&q0)[i - 1] };
                let before = frame * chain.link_transform(i, 0.0);
                let local = before.rotation.inverse() * nalgebra::Vector3::from(*offset_world_um);
                for k in 0..3 {
                    robot.links[i].errors.axis_offset_um[k] += local[k];
                }
            }
            Effect::ReversalError { joint, .. } => {
                index(joint)?;
            }
            Effect::ThermalDrift { .. }
            | Effect::PathScale { .. }
            | Effect::GouyPhase { .. }
            | Effect::LamellaBackFace { .. }
            | Effect::FringeNonlinearity { .. } => {}
        }
        Ok(())
    }

    /// Apply the optical part of the effect to the optical parameters (Gouy phase, back face).
    pub fn apply_to_optics(&self, optics: &mut OpticalParams) {
        match self {
            Effect::GouyPhase { scale_error } => optics.gouy_scale_error += scale_error,
            Effect::LamellaBackFace { amplitude_reflectance, thickness_um, phase_index, group_index }
                if *amplitude_reflectance != 0.0 =>
            {
                optics.back_face = Some(BackFace {
                    thickness_um: *thickness_um,
                    phase_index: *phase_index,
                    group_index: *group_index,
                    reference_wavelength_nm: optics.back_face.map_or(1560.0, |b| b.reference_wavelength_nm),
                    reflectance: amplitude_reflectance * amplitude_reflectance,
                    inverted: *amplitude_reflectance < 0.0,
                });
            }
            _ => {}
        }
    }

    /// True for the effects that act on each observation's own conditions (time, gap, fringe
    /// phase, approach directions) rather than on the model: drift, path scale, cyclic error
    /// ([`Effect::gap_change_nm`], [`Effect::cyclic_error_nm`]) and reversal errors
    /// ([`reversal_play`]).
    pub fn is_path(&self) -> bool {
        matches!(
            self,
            Effect::ThermalDrift { .. }
                | Effect::PathScale { .. }
                | Effect::FringeNonlinearity { .. }
                | Effect::ReversalError { .. }
        )
    }

    /// True for the effects that act on the optical parameters ([`Effect::apply_to_optics`]).
    pub fn is_optical(&self) -> bool {
        matches!(self, Effect::GouyPhase { .. } | Effect::LamellaBackFace { .. })
    }

    /// Cyclic error (nm) the effect adds to the phase-equivalent gap at fringe phase
    /// `phase_rad` = 4π·n·gap/λ.
    #[inline]
    pub fn cyclic_error_nm(&self, phase_rad: f64) -> f64 {
        match self {
            Effect::FringeNonlinearity { in_phase_nm, quadrature_nm } => {
                let (s, c) = phase_rad.sin_cos();
                in_phase_nm * c + quadrature_nm * s
            }
            _ => 0.0,
        }
    }

    /// Change of the optical gap (nm) at time `t_s` caused by the effect, for a geometric gap
    /// `gap_um`.
    #[inline]
    pub fn gap_change_nm(&self, t_s: f64, gap_um: f64) -> f64 {
        match self {
            Effect::ThermalDrift { nm_per_s, nm_per_s2 } => nm_per_s * t_s + 0.5 * nm_per_s2 * t_s * t_s,
            Effect::PathScale { ppm } => gap_um * ppm * 1e-3,
            _ => 0.0,
        }
    }

    /// Rate of the optical gap's change (nm/s) at time `t_s` caused by the effect: the drift's
    /// derivative. A wavelength sweep reads a gap that moves at this rate off by whole orders
    /// of −rate·λ/(dλ/dt) ([`sweep_reading_nm`]).
    #[inline]
    pub fn gap_rate_nm_per_s(&self, t_s: f64) -> f64 {
        match self {
            Effect::ThermalDrift { nm_per_s, nm_per_s2 } => nm_per_s + nm_per_s2 * t_s,
            _ => 0.0,
        }
    }
}

/// How far a wavelength sweep's gap reads off (nm) when the gap moves at `rate_nm_per_s` during
/// it, at vacuum wavelength `wavelength_nm` in a medium of index `index`. The gap comes in two
/// steps ([`crate::measure::analyse_sweep`]): the fringe frequency in wavenumber (dφ/dk = 2n·L)
/// seeds it, and a fit of the full multi-beam field refines it. With the gap moving, dφ/dt =
/// 2n·(L·dk/dt + k·dL/dt), so the frequency reads L + k·(dL/dt)/(dk/dt) = L − λ·(dL/dt)/(dλ/dt)
/// at the sweep's middle: a 0.5 nm/s drift during a 1 nm/s sweep at 1560 nm reads 780 nm short.
/// The refinement reads the gap's absolute phase (the beams' mutual interference does not depend
/// on the fit's free phase), which does not move with the sweep: it takes the gap at the sweep's
/// middle, in the fringe order nearest the seed. So the reading is off by whole orders of
/// λ/(2n): the frequency's error rounded to the nearest order. On table2-ideal with 0.5 nm/s
/// (`fringes` on `simulate`d sweeps, against the same seed without drift): 20 nm in 20 s reads
/// 775 nm short (the model: 780 − 5 nm of drift to mid-sweep), 40 nm in 20 s 754 nm short (the
/// frequency's 390 nm, half an order, went to the lower one), 40 nm in 4 s (78 nm by the
/// frequency) −5 nm and 40 nm down in 4 s +5 nm, where the model says 0: the refinement keeps a
/// few % of the frequency's error. Zero when the sweep rate is unknown.
#[inline]
pub fn sweep_reading_nm(rate_nm_per_s: f64, wavelength_nm: f64, sweep_nm_per_s: f64, index: f64) -> f64 {
    if sweep_nm_per_s == 0.0 || !sweep_nm_per_s.is_finite() || index.is_nan() || index <= 0.0 {
        return 0.0;
    }
    let frequency_nm = -rate_nm_per_s * wavelength_nm / sweep_nm_per_s;
    let order_nm = wavelength_nm / (2.0 * index);
    order_nm * (frequency_nm / order_nm).round()
}

/// Stages with play (reversal errors) as a backlash: each stage sits `offset` from its command
/// (display units), within ± half its play, dragged by the command: after a move longer than
/// the play the stage lags the command by half of it. The virtual bench moves its hidden
/// stages so; the validation plans its commands and models its traces' real joints with it.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Backlash {
    /// Where each stage sits relative to its command (display units).
    pub offset: [f64; 6],
    /// The last command followed (display units).
    pub command: [f64; 6],
}

impl Backlash {
    /// Follow the command to `q` (a straight move), for stages of play `width` (display units).
    #[inline]
    pub fn follow(&mut self, q: &[f64; 6], width: &[f64; 6]) {
        for j in 0..6 {
            if width[j] != 0.0 {
                let half = 0.5 * width[j].abs();
                self.offset[j] = (self.offset[j] - (q[j] - self.command[j])).clamp(-half, half);
            }
            self.command[j] = q[j];
        }
    }

    /// Where the stages are: the command plus the offset.
    pub fn real(&self) -> [f64; 6] {
        std::array::from_fn(|j| self.command[j] + self.offset[j])
    }
}

/// The play of each joint of `robot` (display units, µm or °) from the reversal errors of a
/// list; joints the robot does not have are ignored ([`Effect::apply_to_robot`] refuses them).
pub fn reversal_play(effects: &[Effect], robot: &RobotDescription) -> [f64; 6] {
    let mut play = [0.0; 6];
    for e in effects {
        if let Effect::ReversalError { joint, step } = e {
            if let Some(i) = robot.links.iter().position(|l| &l.name == joint).filter(|&i| i < 6) {
                play[i] += step;
            }
        }
    }
    play
}

/// Update the directions each joint last moved in after a straight move `from` → `to`
/// (display units): joints that moved more than `min_move` take the move's sign.
#[inline]
pub fn update_approach(approach: &mut [i8; 6], from: &[f64; 6], to: &[f64; 6], min_move: &[f64; 6]) {
    for j in 0..6 {
        if (to[j] - from[j]).abs() > min_move[j] {
            approach[j] = if to[j] > from[j] { 1 } else { -1 };
        }
    }
}

/// A pose's real joints from its reading (display units) and the directions each joint last
/// moved in: the stage lags by half its play.
#[inline]
pub fn real_joints(display: &[f64; 6], approach: &[i8; 6], play: &[f64; 6]) -> [f64; 6] {
    std::array::from_fn(|j| display[j] - 0.5 * f64::from(approach[j]) * play[j])
}

/// Apply the optical effects of a list to optical parameters.
pub fn apply_optics(effects: &[Effect], optics: &OpticalParams) -> OpticalParams {
    let mut o = *optics;
    for e in effects {
        e.apply_to_optics(&mut o);
    }
    o
}

/// Apply a list of effects to a robot description.
pub fn apply_all(effects: &[Effect], robot: &RobotDescription) -> Result<RobotDescription, EffectError> {
    let mut r = robot.clone();
    for e in effects {
        e.apply_to_robot(&mut r)?;
    }
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::kinematics::Chain;
    use approx::assert_relative_eq;
    use nalgebra::Vector3;

    #[test]
    fn pivot_offset_in_world_terms_moves_the_rotation_centre() {
        // Joint 4 (about X_w at q = 0) with its axis 20 µm off along Y_w (a typical size).
        let e = Effect::PivotOffset { joint: "q4".into(), offset_world_um: [0.0, 20.0, 0.0] };
        let robot = apply_all(&[e], &RobotDescription::femto_6dof()).unwrap();
        let c = Chain::new(robot);
        let phi = 2f64.to_radians();
        let p = c.end_effector(&[0.0, 0.0, 0.0, phi, 0.0, 0.0]).translation.vector;
        assert_relative_eq!(p, Vector3::new(0.0, 20.0 - 20.0 * phi.cos(), -20.0 * phi.sin()), epsilon = 1e-9);
    }

    /// Joint 6's link frame is joint 5's turned −90° about x, so a turn of joint 6's axis toward
    /// its link x (about its link y) is a turn about joint 5's axis before joint 6 turns, and
    /// one of the tool after: R_x(−90°)·R_y(ε) = R_z(−ε)·R_x(−90°). With a q6 tilt of ε toward
    /// link x and a q5 zero offset of −ε the end effector is at the same point at any joint
    /// values, turned by the same ε about its own −y: a fixed turn of the tool, which the
    /// lamella's tilt extrinsics carry. With +ε the turn between the two changes with the joints.
    #[test]
    fn a_joint6_tilt_toward_link_x_is_a_joint5_zero_offset_and_a_turn_of_the_tool() {
        let eps_mrad = 0.6;
        let zero = |sign: f64| Effect::JointZeroOffset {
            joint: "q5".into(),
            offset: sign * (eps_mrad * 1e-3f64).to_degrees(),
        };
        let tilt = Effect::AxisTilt { joint: "q6".into(), tilt_mrad: [eps_mrad, 0.0] };
        let chain =
            |e: &Effect| Chain::new(apply_all(std::slice::from_ref(e), &RobotDescription::femto_6dof()).unwrap());
        let (tilted, offset, wrong) = (chain(&tilt), chain(&zero(-1.0)), chain(&zero(1.0)));
        let mut wrong_angles = Vec::new();
        for k in 0..20 {
            let u = |i: usize| ((k * 6 + i) as f64 * 0.618_034).fract() * 2.0 - 1.0;
            let q = [150.0 * u(0), 150.0 * u(1), 150.0 * u(2), 0.17 * u(3), 0.17 * u(4), 3.1 * u(5)];
            let (a, b, c) = (tilted.end_effector(&q), offset.end_effector(&q), wrong.end_effector(&q));
            assert_relative_eq!(a.translation.vector, b.translation.vector, epsilon = 1e-9);
            let turn = b.rotation.inverse() * a.rotation;
            assert_relative_eq!(turn.scaled_axis(), Vector3::new(0.0, -eps_mrad * 1e-3, 0.0), epsilon = 1e-12);
            wrong_angles.push((c.rotation.inverse() * a.rotation).angle());
        }
        let spread =
            wrong_angles.iter().fold(0.0f64, |m, v| m.max(*v)) - wrong_angles.iter().fold(1.0f64, |m, v| m.min(*v));
        assert!(spread > 5e-4, "{wrong_angles:?}");
    }

    #[test]
    fn unknown_joint_is_named() {
        let e = Effect::JointScale { joint: "q9".into(), ppm: 1.0 };
        let err = apply_all(&[e], &RobotDescription::femto_6dof()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "effect joint scale error: no joint named `q9` (the robot has q1, q2, q3, q4, q5, q6)"
        );
    }

    #[test]
    fn drift_and_path_scale_change_the_gap() {
        let d = Effect::ThermalDrift { nm_per_s: 0.1, nm_per_s2: 0.002 };
        assert_relative_eq!(d.gap_change_nm(10.0, 900.0), 1.0 + 0.1, epsilon = 1e-12);
        let s = Effect::PathScale { ppm: 268.0 };
        assert_relative_eq!(s.gap_change_nm(0.0, 300.0), 80.4, epsilon = 1e-9);
    }

    /// The frequency's error against a brute-force fit (the fringe phase 4π·n·L(t)/λ(t) of a gap
    /// drifting during a linear sweep, its slope in wavenumber fitted by least squares: the
    /// closed form L(t_mid) − λ·(dL/dt)/(dλ/dt)), and the reading: that error in whole orders.
    #[test]
    fn a_gap_drifting_during_a_sweep_reads_off_by_whole_orders_of_the_frequencys_error() {
        let d = Effect::ThermalDrift { nm_per_s: 0.5, nm_per_s2: 0.001 };
        let (l0_nm, t0, duration, from_nm, to_nm, n_air) = (898_830.0, 100.0, 20.0, 1550.0, 1570.0, 1.000268);
        let n = 2001;
        let (mut sk, mut sp, mut skk, mut skp) = (0.0, 0.0, 0.0, 0.0);
        for i in 0..n {
            let f = i as f64 / (n - 1) as f64;
            let t = t0 + f * duration;
            let k = std::f64::consts::TAU / (from_nm + f * (to_nm - from_nm));
            let phase = 2.0 * n_air * k * (l0_nm + d.gap_change_nm(t, 0.0));
            sk += k;
            sp += phase;
            skk += k * k;
            skp += k * phase;
        }
        let nf = n as f64;
        let frequency_nm = (nf * skp - sk * sp) / (nf * skk - sk * sk) / (2.0 * n_air);
        let t_mid = t0 + duration / 2.0;
        let rate = d.gap_rate_nm_per_s(t_mid);
        let sweep_rate = (to_nm - from_nm) / duration;
        let want = l0_nm + d.gap_change_nm(t_mid, 0.0) - rate * 1560.0 / sweep_rate;
        assert!((frequency_nm - want).abs() < 1.0, "frequency {frequency_nm} nm, closed form {want} nm");
        // 0.61 nm/s at 1 nm/s: 952 nm by the frequency, one order (779.9 nm) by the reading.
        let order = 1560.0 / (2.0 * n_air);
        assert!((sweep_reading_nm(rate, 1560.0, sweep_rate, n_air) + order).abs() < 1e-9);
        assert_eq!(sweep_reading_nm(rate, 1560.0, 10.0, n_air), 0.0, "95 nm by the frequency: no order");
        assert!((sweep_reading_nm(-rate, 1560.0, 1.0, n_air) - order).abs() < 1e-9);
        assert_eq!(sweep_reading_nm(0.5, 1560.0, 0.0, n_air), 0.0, "unknown sweep rate");
    }

    #[test]
    fn optical_effects_set_the_optics_and_the_cyclic_error_is_one_fringe_periodic() {
        let base = OpticalParams::default();
        let o = apply_optics(&[Effect::GouyPhase { scale_error: -1.0 }], &base);
        assert_eq!(o.gouy_scale_error, -1.0);
        let e = Effect::LamellaBackFace {
            amplitude_reflectance: -0.2,
            thickness_um: 300.0,
            phase_index: 1.5,
            group_index: 1.52,
        };
        let b = apply_optics(&[e], &base).back_face.unwrap();
        assert_relative_eq!(b.reflectance, 0.04, epsilon = 1e-15);
        assert!(b.inverted && b.thickness_um == 300.0 && b.phase_index == 1.5 && b.group_index == 1.52);
        assert!(e_is_neither_path_nor_geometric(&Effect::GouyPhase { scale_error: 0.3 }));
        let c = Effect::FringeNonlinearity { in_phase_nm: 2.0, quadrature_nm: -1.0 };
        assert!(c.is_path() && !c.is_optical());
        for phi in [0.0, 0.4, 2.0, -3.0] {
            assert_relative_eq!(c.cyclic_error_nm(phi), 2.0 * phi.cos() - phi.sin(), epsilon = 1e-12);
            assert_relative_eq!(
                c.cyclic_error_nm(phi + 2.0 * std::f64::consts::PI),
                c.cyclic_error_nm(phi),
                epsilon = 1e-12
            );
        }
    }

    fn e_is_neither_path_nor_geometric(e: &Effect) -> bool {
        let robot = RobotDescription::femto_6dof();
        e.is_optical() && !e.is_path() && apply_all(std::slice::from_ref(e), &robot).unwrap() == robot
    }
}
