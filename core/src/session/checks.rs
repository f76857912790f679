//! Checks of a session beyond the syntax: the version, the robot, the plans, trace references
//! inside `traces/`, progress within the plans and finite results.

use super::{Session, FORMAT_VERSION, TRACES_DIR};
use crate::files::FieldError;
use std::path::{Component, Path};

impl Session {
    /// Checks beyond the syntax: version, robot, plans, trace references inside `traces/`,
    /// unique and consistent, progress within the plans, finite results.
    pub fn validate(&self) -> Result<(), FieldError> {
        if self.format_version != FORMAT_VERSION {
            return Err(FieldError::new(
                "format_version",
                format!("expected {FORMAT_VERSION}, found {}", self.format_version),
            ));
        }
        self.robot.validate().map_err(|e| FieldError::new(format!("robot.{}", e.field), e.problem))?;
        if let Some(preset) = &self.bench.description {
            preset.validate().map_err(|e| FieldError::new(format!("bench.description.{}", e.field), e.problem))?;
        }
        for (index, plan) in self.plans.iter().enumerate() {
            plan.validate().map_err(|e| {
                FieldError::new(
                    format!("plans[{index}].{}", e.field_path().unwrap_or_else(|| "segments".into())),
                    e.labelled_problem(),
                )
            })?;
        }
        self.lab.validate()?;
        self.check_trace_refs()?;
        self.check_progress()?;
        self.check_results()
    }

    /// Every trace reference names a file `traces/<name>.csv`, once, and a step of the plans.
    fn check_trace_refs(&self) -> Result<(), FieldError> {
        for (index, reference) in self.traces.iter().enumerate() {
            let field = |f: &str| format!("traces[{index}].{f}");
            if !is_trace_path(&reference.file) {
                return Err(FieldError::new(
                    field("file"),
                    format!(
                        "expected a path `{TRACES_DIR}/<name>.csv` inside the session folder, found `{}`",
                        reference.file
                    ),
                ));
            }
            if let Some(earlier) = self.traces[..index].iter().position(|o| o.file == reference.file) {
                return Err(FieldError::new(
                    field("file"),
                    format!("`{}` is also traces[{earlier}]; expected each file once", reference.file),
                ));
            }
            if let Some((plan, segment)) = reference.step {
                let segments = self.plans.get(plan).map(|p| p.segments.len());
                if segments.is_none_or(|n| segment >= n) {
                    return Err(FieldError::new(
                        field("step"),
                        format!("({plan}, {segment}) is not a segment of the session's {} plan(s)", self.plans.len()),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The progress lies within the plans and its start joint vector is finite.
    fn check_progress(&self) -> Result<(), FieldError> {
        if let Some(p) = &self.progress {
            let beyond = p.plan > self.plans.len()
                || self.plans.get(p.plan).is_some_and(|plan| p.next_segment > plan.segments.len());
            if beyond {
                return Err(FieldError::new(
                    "progress",
                    format!(
                        "plan {} segment {} is beyond the session's {} plan(s)",
                        p.plan,
                        p.next_segment,
                        self.plans.len()
                    ),
                ));
            }
            if let Some(j) = p.plan_start_display.iter().position(|v| !v.is_finite()) {
                return Err(FieldError::new(format!("progress.plan_start_display[{j}]"), "expected a finite number"));
            }
        }
        Ok(())
    }

    /// The calibration's parameters and extrinsics and the diagnosis's numbers are finite.
    fn check_results(&self) -> Result<(), FieldError> {
        if let Some(calibration) = &self.calibration {
            for (index, parameter) in calibration.parameters.iter().enumerate() {
                if !parameter.value.is_finite() {
                    return Err(FieldError::new(
                        format!("calibration.parameters[{index}].value"),
                        "expected a finite number",
                    ));
                }
                if parameter.sigma.is_some_and(|s| !(s.is_finite() && s >= 0.0)) {
                    return Err(FieldError::new(
                        format!("calibration.parameters[{index}].sigma"),
                        "expected a finite, non-negative number or None",
                    ));
                }
            }
            calibration
                .extrinsics
                .validate_within(180.0)
                .map_err(|e| FieldError::new(format!("calibration.extrinsics.{}", e.field), e.problem))?;
        }
        if let Some(diagnosis) = &self.diagnosis {
            for (index, effect) in diagnosis.effects.iter().enumerate() {
                let numbers =
                    [("estimate", Some(effect.estimate)), ("sigma", effect.sigma), ("score", Some(effect.score))];
                for (name, value) in numbers {
                    if value.is_some_and(|v| !v.is_finite()) {
                        return Err(FieldError::new(
                            format!("diagnosis.effects[{index}].{name}"),
                            "expected a finite number",
                        ));
                    }
                }
            }
        }
        Ok(())
    }
}

/// A path `traces/<name>.csv` inside the session folder, with forward slashes only.
fn is_trace_path(file: &str) -> bool {
    let p = Path::new(file);
    let mut parts = p.components();
    matches!(parts.next(), Some(Component::Normal(d)) if d == TRACES_DIR)
        && matches!(parts.next(), Some(Component::Normal(_)))
        && parts.next().is_none()
        && p.extension().is_some_and(|e| e == "csv")
        && !file.contains('\\')
}
