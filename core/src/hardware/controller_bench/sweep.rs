//! A wavelength sweep on a bench on controllers: configured before the recorder starts, started
//! right after the stages' trigger, waited for, and its lambda log checked and mapped onto the
//! recorded samples. Where the laser's wavelength monitor is wired to the recorder, its readings
//! stay (they are measured on the recorder's clock); otherwise each sample gets the logged
//! wavelength at its time since the sweep started; a laser without a log leaves the commanded one.

use super::acquisition::Acquisition;
use super::laser::LambdaLog;
use super::ControllerBench;
use crate::hardware::HwError;
use crate::plan::{TimedMotion, TimedSegment};

/// A sweep's speed (nm/s): the planned span over the planned duration.
pub(super) fn sweep_rate(seg: &TimedSegment) -> Option<(f64, f64, f64)> {
    match seg.motion {
        TimedMotion::Sweep { from_nm, to_nm } => {
            Some((from_nm, to_nm, (to_nm - from_nm).abs() / seg.duration_s.max(f64::MIN_POSITIVE)))
        }
        _ => None,
    }
}

impl ControllerBench {
    /// After the sweep's planned time: wait (up to the segment's margin) for the laser to report the
    /// sweep done, then read its log and check that it covers the sweep (a shorter log: the laser
    /// aborted it).
    pub(super) fn finish_sweep(&mut self, seg: &TimedSegment) -> Result<Option<LambdaLog>, HwError> {
        let deadline = self.bench_now() + self.config.timeout_margin_s;
        while self.laser.sweep_running()? {
            if self.bench_now() > deadline {
                return Err(HwError::WaitTimeout {
                    controller: self.laser.name(),
                    axes: "wavelength sweep".into(),
                    timeout_s: seg.duration_s + self.config.timeout_margin_s,
                });
            }
            self.sleep_poll();
        }
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

    /// Give every sample of `a` the logged wavelength at its time since the sweep started at bench
    /// time `t_sweep_s`, unless the wavelength monitor is recorded.
    pub(super) fn apply_lambda_log(&self, a: &mut Acquisition, log: &LambdaLog, t_sweep_s: f64) {
        if self.config.photodiode.wavelength_input.is_some() {
            return;
        }
        for (w, &t) in a.trace.wavelength_nm.iter_mut().zip(&a.trace.t_s) {
            if let Some(logged) = log.wavelength_at(t - t_sweep_s) {
                *w = logged;
            }
        }
    }
}
