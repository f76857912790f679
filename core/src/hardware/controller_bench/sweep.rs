//! A wavelength sweep on a bench on controllers: configured and read back before the recorder is
//! armed (the laser's start, speed and step as it will run them), started right after the stages'
//! trigger, followed until the laser reports it done, its lambda log checked, and every recorded
//! sample given its wavelength on the recorder's clock ([`super::sweep_timing`]): from the
//! wavelength monitor, or from the log timed by the laser's trigger output.

use super::acquisition::{keep_range, Acquisition};
use super::laser::{LambdaLog, SweepSetup};
use super::sweep_timing::{from_monitor, from_trigger};
use super::{ControllerBench, SweepTimeBase};
use crate::hardware::{HwError, RecordTrigger};
use crate::plan::{TimedMotion, TimedSegment};

/// Bench time allowed beyond a sweep's start-to-stop time for the laser's start latency, run-up
/// and run-out (s): the recorder is sized for it, and the bench waits for the laser anyway.
pub(super) const SWEEP_ALLOWANCE_S: f64 = 1.0;

/// A sweep's span and speed (nm/s): the planned span over the planned duration.
pub(super) fn sweep_rate(seg: &TimedSegment) -> Option<(f64, f64, f64)> {
    match seg.motion {
        TimedMotion::Sweep { from_nm, to_nm } => {
            Some((from_nm, to_nm, (to_nm - from_nm).abs() / seg.duration_s.max(f64::MIN_POSITIVE)))
        }
        _ => None,
    }
}

impl ControllerBench {
    fn time_base_or_refuse(&self) -> Result<SweepTimeBase, HwError> {
        self.sweep_time_base().ok_or_else(|| HwError::Usage {
            controller: self.laser.name(),
            problem: "this bench cannot time a sweep: wire the laser's wavelength monitor to a recorder input \
                      (`photodiode.wavelength_input`) or its trigger output to a digital input of the recorder's \
                      controller (`photodiode.laser_trigger_input`)"
                .into(),
        })
    }

    /// Configure the sweep of `seg` on the laser and send it to its start (what the laser will
    /// really do, read back).
    pub(super) fn prepare_sweep(&mut self, seg: &TimedSegment) -> Result<Option<SweepSetup>, HwError> {
        let Some((from_nm, to_nm, rate)) = sweep_rate(seg) else { return Ok(None) };
        self.time_base_or_refuse()?;
        let setup = self.laser.prepare_sweep(from_nm, to_nm, rate)?;
        self.laser.set_wavelength(setup.from_nm)?;
        Ok(Some(setup))
    }

    /// What starts the recording of `seg` and how long it may last (s).
    pub(super) fn recording_plan(&self, seg: &TimedSegment, sweep: Option<&SweepSetup>) -> (RecordTrigger, f64) {
        let margin = |d: f64| 1.25 * d + 1.0;
        match (sweep, self.sweep_time_base()) {
            (Some(s), Some(SweepTimeBase::Trigger { line })) => {
                (RecordTrigger::External { line }, margin(s.duration_s() + SWEEP_ALLOWANCE_S))
            }
            (Some(s), _) => (RecordTrigger::NextMove, margin(s.duration_s() + SWEEP_ALLOWANCE_S)),
            (None, _) => (RecordTrigger::NextMove, margin(seg.duration_s)),
        }
    }

    /// After the laser reported the sweep done: its log, checked to cover the sweep (a shorter log
    /// means the laser aborted it).
    pub(super) fn finish_sweep(&mut self) -> Result<Option<LambdaLog>, HwError> {
        let Some(log) = self.laser.lambda_log()? else { return Ok(None) };
        let expected = log.expected_points();
        if log.wavelengths_nm.len() < expected {
            let at =
                log.wavelengths_nm.last().map_or("before its first point".to_string(), |w| format!("at {w:.4} nm"));
            return Err(HwError::Usage {
                controller: self.laser.name(),
                problem: format!(
                    "the sweep {:.4} → {:.4} nm stopped {at} after {} of its {expected} logged points (aborted by the laser)",
                    log.from_nm,
                    log.to_nm,
                    log.wavelengths_nm.len()
                ),
            });
        }
        Ok(Some(log))
    }

    /// Give each recorded sample its wavelength by the bench's time base and keep only the samples
    /// of the sweep at constant speed.
    pub(super) fn apply_sweep(
        &self,
        a: &mut Acquisition,
        setup: &SweepSetup,
        log: Option<&LambdaLog>,
    ) -> Result<(), HwError> {
        let timed = match self.time_base_or_refuse()? {
            SweepTimeBase::Monitor { .. } => from_monitor(&a.trace.t_s, &a.trace.wavelength_nm, setup, log),
            SweepTimeBase::Trigger { .. } => match log {
                Some(log) => from_trigger(a.trace.len(), a.dt_s, log),
                None => Err("the laser keeps no lambda log: its trigger output alone gives no wavelength".into()),
            },
        };
        let timed = timed.map_err(|problem| HwError::Usage { controller: self.laser.name(), problem })?;
        keep_range(&mut a.trace, timed.first, timed.wavelengths_nm.len());
        a.trace.wavelength_nm = timed.wavelengths_nm;
        a.trace.meta.wavelength_scale_sigma_ppm = timed.scale_sigma_ppm;
        Ok(())
    }
}
