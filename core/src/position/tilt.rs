//! The lamella's tilt against the beam at the end of a move, measured without the extrinsics:
//! owns the two small rotations about the fiber's transverse axes through P_r that read it from
//! the fringe contrast, and the return to the end pose.
//!
//! Along a rotation by φ about an axis square to the beam, `cos γ(φ) = cos(φ − ψ)` in the plane
//! of the rotation; the contrast along it gives ψ with κ fitted from the data
//! ([`crate::validate::contrast::fit_tilt_term_along`]), and the rotation angle comes from the
//! joints through the robot's geometric model alone. Rotations about X_f and about Z_f give the
//! tilt's two components at the end pose: `tan² γ = tan² γ_x + tan² γ_z`. The extrinsics only
//! aim the rotations: an axis a fraction of a degree off square to the beam, or a pivot off
//! P_r, changes the reading to second order.

use super::Placement;
use crate::bench::{run_plan, Bench, RunControl};
use crate::plan::{JointTarget, Plan, Segment};
use crate::validate::contrast::rotation_angles_rad;
use crate::validate::{record_validation, Compensation, StopSettings, ValidationMotion};
use serde::{Deserialize, Serialize};

/// Stops along each rotation: nine contrast readings with the start, one at the end pose.
const STOPS: usize = 8;
/// The relative error of the tilt beyond the fits' σ: on table2-ideal's virtual bench, 40
/// random targets (`random_moves` seeds 1 and 2) read tilts of 0.4-2.4° up to 0.4 % off the
/// truth, several times their fits' σ at the largest (the contrast's departure from the fitted
/// shape over the rotations' 0-5°).
const TILT_RELATIVE_ERROR: f64 = 0.003;

/// The tilt at the end pose, from the contrast.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TiltMeasurement {
    /// The angle between the lamella's normal and the beam (°).
    pub tilt_deg: f64,
    /// Its standard uncertainty (°).
    pub sigma_deg: f64,
    /// Its components in the planes of the rotations about X_f and Z_f (°, signed).
    pub components_deg: [f64; 2],
    /// Their standard uncertainties (°).
    pub components_sigma_deg: [f64; 2],
    /// The angle the positioning model gives at the end pose (°).
    pub model_deg: f64,
    /// Bench time of the rotations and the return to the end pose (s).
    pub bench_time_s: f64,
}

impl TiltMeasurement {
    /// One line for the user: the tilt, its components and the model's.
    pub fn describe(&self) -> String {
        let [a, b] = self.components_deg;
        let [sa, sb] = self.components_sigma_deg;
        format!(
            "tilt from the fringe contrast: {:.4} ± {:.4}° (about X_f {a:+.4} ± {sa:.4}°, about Z_f {b:+.4} ± {sb:.4}°); \
             the model's {:.4}°",
            self.tilt_deg, self.sigma_deg, self.model_deg
        )
    }

    /// The angle and its σ (rad).
    pub fn rad(&self) -> (f64, f64) {
        (self.tilt_deg.to_radians(), self.sigma_deg.to_radians())
    }
}

/// Measure the tilt at `end` (µm, °; where the bench stands) and bring the stages back there.
/// `Err` names what failed (a rotation out of reach, a contrast that did not fit, a stop).
pub fn measure_at(
    bench: &mut dyn Bench,
    placement: &Placement,
    end: [f64; 6],
    control: &mut RunControl<'_>,
) -> Result<TiltMeasurement, String> {
    let t0 = bench.clock_s();
    let model = &placement.model;
    let compensation = Compensation { play: placement.play, drift: Vec::new() };
    let mut components = [(0.0, 0.0); 2];
    let result = [ValidationMotion::RotationXf, ValidationMotion::RotationZf].into_iter().enumerate().try_for_each(
        |(k, motion)| {
            components[k] = in_plane_component(bench, placement, &compensation, motion, end, control.cancel)?;
            Ok::<(), String>(())
        },
    );
    let back = return_to(bench, end, &placement.play, control);
    result?;
    back?;
    let (tilt, sigma) = combine(components);
    let sigma = sigma.hypot(TILT_RELATIVE_ERROR * tilt);
    Ok(TiltMeasurement {
        tilt_deg: tilt.to_degrees(),
        sigma_deg: sigma.to_degrees(),
        components_deg: components.map(|c| c.0.to_degrees()),
        components_sigma_deg: components.map(|c| c.1.to_degrees()),
        model_deg: model.gap_and_tilt(&end).map_or(f64::NAN, |g| g.1.to_degrees()),
        bench_time_s: bench.clock_s() - t0,
    })
}

/// The tilt (rad, signed) at `end` in the plane of `motion` (a rotation about X_f or Z_f from
/// `end`), and its σ: the rotation run, its contrast fitted, the angle at `end` read from the joints.
fn in_plane_component(
    bench: &mut dyn Bench,
    placement: &Placement,
    compensation: &Compensation,
    motion: ValidationMotion,
    end: [f64; 6],
    cancel: &std::sync::atomic::AtomicBool,
) -> Result<(f64, f64), String> {
    let model = &placement.model;
    let stops = StopSettings { stops: STOPS, sweeps: false };
    let figure = record_validation(bench, model, &model.extrinsics, motion, end, compensation, &stops, cancel)
        .and_then(|r| r.measure(model))
        .map_err(|e| e.to_string())?;
    let term = figure.evidence.tilt_term.as_ref().ok_or_else(|| {
        format!("{}: the contrast along it gives no tilt ({})", motion.name(), figure.evidence.notes.join("; "))
    })?;
    let from = figure.motion_start.min(figure.trace.len().saturating_sub(1));
    let angles = rotation_angles_rad(&model.chain, &figure.trace, from);
    let at_end = nearest_sample(&figure.trace, from, &end);
    let angle = angles.get(at_end - from).ok_or_else(|| format!("{}: nothing recorded", motion.name()))?;
    Ok(term.in_plane_tilt_rad(*angle))
}

/// The tilt and its σ (rad) from its two components and theirs: `tan² γ = tan² a + tan² b`; near
/// normal incidence, where the angle is within its noise, σ is the components' together.
pub(crate) fn combine(c: [(f64, f64); 2]) -> (f64, f64) {
    let [(a, sa), (b, sb)] = c;
    let gamma = a.tan().hypot(b.tan()).atan();
    let floor = sa.hypot(sb);
    let sigma = if gamma > floor { (a * sa).hypot(b * sb) / gamma } else { floor };
    (gamma, sigma)
}

/// The sample of `trace` from `from` on whose joints are nearest `pose` (µm and ° alike).
fn nearest_sample(trace: &crate::trace::Trace, from: usize, pose: &[f64; 6]) -> usize {
    let distance = |i: usize| trace.joints_display(i).iter().zip(pose).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
    (from..trace.len()).min_by(|&a, &b| distance(a).total_cmp(&distance(b))).unwrap_or(from)
}

/// Move back to `end` (unrecorded), stoppable; stages with play (`play`, display units) are
/// commanded half their play beyond it in their direction of travel, as the path's moves are
/// ([`crate::validate::plan_through`]).
fn return_to(
    bench: &mut dyn Bench,
    end: [f64; 6],
    play: &[f64; 6],
    control: &mut RunControl<'_>,
) -> Result<(), String> {
    let from = bench.position_display();
    let end: [f64; 6] = std::array::from_fn(|j| {
        let d = end[j] - from[j];
        if d.abs() > 1e-9 {
            end[j] + 0.5 * play[j].abs() * d.signum()
        } else {
            end[j]
        }
    });
    let plan = Plan {
        name: "position: back to the end pose".into(),
        description: String::new(),
        segments: vec![Segment::Move {
            to: JointTarget::all(end),
            record: false,
            label: "position: back to the end pose".into(),
            through: false,
        }],
    };
    run_plan(bench, &plan, control).outcome.map_err(|e| format!("back to the end pose: {e}"))
}

#[cfg(test)]
mod tests {
    use super::combine;

    #[test]
    fn the_tilt_combines_its_components_as_the_normal_does() {
        // A normal n = (tan a, 1, tan b)/|…| makes an angle γ with the beam (0, 1, 0).
        let (a, b) = (0.03f64, -0.04f64);
        let n = nalgebra::Vector3::new(a.tan(), 1.0, b.tan()).normalize();
        let (gamma, sigma) = combine([(a, 1e-4), (b, 1e-4)]);
        assert!((gamma - n.y.acos()).abs() < 1e-12, "{gamma} vs {}", n.y.acos());
        assert!((sigma - 1e-4).abs() < 1e-6, "{sigma}");
        // Within the noise of normal incidence the σ is the components' together.
        let (g0, s0) = combine([(1e-5, 1e-4), (0.0, 1e-4)]);
        assert!(g0 < 2e-5 && (s0 - 2f64.sqrt() * 1e-4).abs() < 1e-9, "{g0} {s0}");
    }
}
