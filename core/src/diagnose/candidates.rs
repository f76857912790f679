//! The candidates the diagnosis scores: each effect of the library split into scalar parameters
//! (one joint, one axis), with its unit, typical size and finite-difference step. Owns that list.
//!
//! An effect with several parameters (a pivot offset has three coordinates) becomes several
//! candidates, one per coordinate, so every score is a one-parameter test and every estimate a
//! single number with one unit.

use crate::model::effects::Effect;
use crate::model::optics::BackFace;
use crate::model::robot::{JointType, RobotDescription};
use serde::{Deserialize, Serialize};

/// Which parameter of which effect a candidate is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum CandidateKind {
    /// [`Effect::PathScale`] (ppm).
    PathScale,
    /// [`Effect::ThermalDrift`], linear rate (nm/s).
    DriftRate,
    /// [`Effect::ThermalDrift`], acceleration (nm/s²).
    DriftAcceleration,
    /// [`Effect::JointScale`] of a joint (ppm).
    JointScale(String),
    /// [`Effect::JointZeroOffset`] of a joint (µm or °).
    JointZeroOffset(String),
    /// [`Effect::PivotOffset`] of a joint along world axis 0, 1, 2 (X_w, Y_w, Z_w) (µm).
    PivotOffset(String, usize),
    /// [`Effect::AxisTilt`] of a joint toward the link x (0) or y (1) axis (mrad).
    AxisTilt(String, usize),
    /// [`Effect::ReversalError`] of a joint: its play (µm or °).
    ReversalError(String),
    /// [`Effect::GouyPhase`]: fractional error of the Gouy phase (dimensionless).
    GouyPhase,
    /// [`Effect::LamellaBackFace`] of the nominal lamella ([`BackFace::default`]: 500 µm of
    /// LiNbO3): signed amplitude reflectance √R of the back face (dimensionless), the
    /// parameter the field is linear in.
    BackFaceAmplitude,
    /// [`Effect::FringeNonlinearity`], the cos φ (0) or sin φ (1) term (nm).
    FringeNonlinearity(usize),
}

/// One scalar candidate effect.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// Name for reports, e.g. "pivot offset q4 along Z_w".
    pub name: String,
    /// Unit of the parameter.
    pub unit: String,
    /// Typical size, in `unit`: what the design of discriminating motions aims to see.
    pub typical: f64,
    /// Finite-difference step and internal scale of the parameter, in `unit`.
    pub step: f64,
    /// Which effect parameter.
    pub kind: CandidateKind,
}

const AXES: [&str; 3] = ["X_w", "Y_w", "Z_w"];

impl Candidate {
    /// True when both are parameters of the same library effect (the same kind of effect on
    /// the same joint): thermal drift rate and acceleration, a pivot offset's three
    /// coordinates, an axis tilt's two directions, the fringe nonlinearity's two terms.
    pub fn same_effect(&self, other: &Candidate) -> bool {
        let joint = |k: &CandidateKind| match k {
            CandidateKind::JointScale(j)
            | CandidateKind::JointZeroOffset(j)
            | CandidateKind::PivotOffset(j, _)
            | CandidateKind::AxisTilt(j, _)
            | CandidateKind::ReversalError(j) => Some(j.clone()),
            _ => None,
        };
        std::mem::discriminant(&self.effect(1.0)) == std::mem::discriminant(&other.effect(1.0))
            && joint(&self.kind) == joint(&other.kind)
    }

    /// The library effect with this parameter at `value` (in `unit`), every other parameter neutral.
    pub fn effect(&self, value: f64) -> Effect {
        match &self.kind {
            CandidateKind::PathScale => Effect::PathScale { ppm: value },
            CandidateKind::DriftRate => Effect::ThermalDrift { nm_per_s: value, nm_per_s2: 0.0 },
            CandidateKind::DriftAcceleration => Effect::ThermalDrift { nm_per_s: 0.0, nm_per_s2: value },
            CandidateKind::JointScale(j) => Effect::JointScale { joint: j.clone(), ppm: value },
            CandidateKind::JointZeroOffset(j) => Effect::JointZeroOffset { joint: j.clone(), offset: value },
            CandidateKind::PivotOffset(j, axis) => {
                let mut offset_world_um = [0.0; 3];
                offset_world_um[*axis] = value;
                Effect::PivotOffset { joint: j.clone(), offset_world_um }
            }
            CandidateKind::AxisTilt(j, k) => {
                let mut tilt_mrad = [0.0; 2];
                tilt_mrad[*k] = value;
                Effect::AxisTilt { joint: j.clone(), tilt_mrad }
            }
            CandidateKind::ReversalError(j) => Effect::ReversalError { joint: j.clone(), step: value },
            CandidateKind::GouyPhase => Effect::GouyPhase { scale_error: value },
            CandidateKind::BackFaceAmplitude => {
                let b = BackFace::default();
                Effect::LamellaBackFace {
                    amplitude_reflectance: value,
                    thickness_um: b.thickness_um,
                    phase_index: b.phase_index,
                    group_index: b.group_index,
                }
            }
            CandidateKind::FringeNonlinearity(k) => {
                let (in_phase_nm, quadrature_nm) = if *k == 0 { (value, 0.0) } else { (0.0, value) };
                Effect::FringeNonlinearity { in_phase_nm, quadrature_nm }
            }
        }
    }
}

/// Every scalar candidate of the effect library for a robot: path scale, drift rate and
/// acceleration, Gouy phase, lamella back face, fringe nonlinearity (cos and sin terms), scale
/// errors of the prismatic joints, reversal errors of every joint, zero offsets of the revolute
/// joints (a prismatic zero offset is a translation of the whole tool: always an extrinsic
/// change), pivot offsets of the revolute joints along each world axis, and axis tilts of every
/// joint. Typical sizes as in docs/diagnosis.md.
pub fn library(robot: &RobotDescription) -> Vec<Candidate> {
    let c = |name: String, unit: &str, typical: f64, step: f64, kind| Candidate {
        name,
        unit: unit.to_string(),
        typical,
        step,
        kind,
    };
    let mut out = vec![
        c("optical path scale".into(), "ppm", 268.0, 10.0, CandidateKind::PathScale),
        c("thermal drift rate".into(), "nm/s", 0.5, 0.05, CandidateKind::DriftRate),
        c("thermal drift acceleration".into(), "nm/s²", 5e-4, 5e-5, CandidateKind::DriftAcceleration),
        // The Gouy phase as a switch: ±1 turns it off or on; fractions are a wrong z_R.
        c("Gouy phase scale error".into(), "fraction", 1.0, 0.05, CandidateKind::GouyPhase),
        // √R = 0.2: R = 4 %, a glass lamella's back face or a LiNbO3 one with a poor AR coating.
        // (An uncoated LiNbO3 back face, √R = 0.377, moves the calibration so far that the
        // refit from its extrinsics stops in a local minimum: model such a lamella from the start.)
        c("lamella back face amplitude reflectance".into(), "√R", 0.2, 0.01, CandidateKind::BackFaceAmplitude),
        c("fringe nonlinearity cos φ".into(), "nm", 2.0, 0.1, CandidateKind::FringeNonlinearity(0)),
        c("fringe nonlinearity sin φ".into(), "nm", 2.0, 0.1, CandidateKind::FringeNonlinearity(1)),
    ];
    for l in &robot.links {
        let j = l.name.clone();
        match l.joint {
            JointType::Prismatic => {
                out.push(c(format!("joint scale error {j}"), "ppm", 800.0, 10.0, CandidateKind::JointScale(j.clone())));
                out.push(c(format!("reversal error {j}"), "µm", 1.0, 0.02, CandidateKind::ReversalError(j.clone())));
            }
            JointType::Revolute => {
                // µrad-level: 20 µrad.
                out.push(c(
                    format!("reversal error {j}"),
                    "°",
                    20e-6f64.to_degrees(),
                    1e-6f64.to_degrees(),
                    CandidateKind::ReversalError(j.clone()),
                ));
                out.push(c(
                    format!("joint zero offset {j}"),
                    "°",
                    0.05,
                    0.001,
                    CandidateKind::JointZeroOffset(j.clone()),
                ));
                for (a, axis) in AXES.iter().enumerate() {
                    out.push(c(
                        format!("pivot offset {j} along {axis}"),
                        "µm",
                        20.0,
                        1.0,
                        CandidateKind::PivotOffset(j.clone(), a),
                    ));
                }
            }
        }
        for (k, toward) in ["x", "y"].iter().enumerate() {
            out.push(c(
                format!("axis tilt {j} toward link {toward}"),
                "mrad",
                0.6,
                0.01,
                CandidateKind::AxisTilt(j.clone(), k),
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_library_variant_is_a_candidate_and_neutral_at_zero() {
        let cands = library(&RobotDescription::femto_6dof());
        // 3 path + 4 optical and cyclic + 3 scales + 6 reversal errors + 3 zero offsets + 9 pivot
        // coordinates + 12 tilts.
        assert_eq!(cands.len(), 40);
        for c in &cands {
            let e = c.effect(0.0);
            let r =
                crate::model::effects::apply_all(std::slice::from_ref(&e), &RobotDescription::femto_6dof()).unwrap();
            assert_eq!(r, RobotDescription::femto_6dof(), "{} not neutral at zero", c.name);
            assert_eq!(e.gap_change_nm(100.0, 900.0), 0.0);
            assert_eq!(e.cyclic_error_nm(0.7), 0.0);
            let optics = crate::model::optics::OpticalParams::default();
            assert_eq!(crate::model::effects::apply_optics(std::slice::from_ref(&e), &optics), optics);
        }
        let names: Vec<&str> = cands.iter().map(|c| c.effect(1.0).name()).collect();
        for n in [
            "thermal drift",
            "optical path scale",
            "joint scale error",
            "joint zero offset",
            "pivot offset",
            "axis tilt",
            "reversal error",
            "Gouy phase",
            "lamella back face",
            "fringe nonlinearity",
        ] {
            assert!(names.contains(&n), "{n} missing");
        }
    }
}
