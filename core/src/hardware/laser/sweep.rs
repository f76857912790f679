//! A laser sweep's set-up by the rules of each family: the direction it can sweep, the speeds it
//! accepts, a log step within its trigger rate, the commands, and every setting read back from the
//! laser before the sweep may start (what it will really do, not what was asked).

use super::{keysight, same_word, santec, ScpiLaser};
use crate::hardware::controller_bench::SweepSetup;
use crate::hardware::HwError;

/// A laser family's sweep: its configuring commands, the numbers and words to read back, and
/// its speed query.
type SweepDialect = (Vec<String>, [(&'static str, f64); 3], &'static [(&'static str, &'static str)], &'static str);

/// Most points a sweep logs: the step is the sweep's span over this less one (at least 0.1 pm).
pub const LOG_POINTS_MAX: usize = 10_001;

/// A read-back wavelength may differ from the one set by this much (nm): the lasers' 0.1 pm grid.
const READBACK_TOLERANCE_NM: f64 = 1.5e-4;

/// The log step (nm) of a sweep over `span_nm` at `rate_nm_per_s`: at most [`LOG_POINTS_MAX`]
/// points, a trigger rate at most `max_trigger_hz`, in whole 0.1 pm.
pub(super) fn log_step_nm(span_nm: f64, rate_nm_per_s: f64, max_trigger_hz: f64) -> f64 {
    let step = (span_nm.abs() / (LOG_POINTS_MAX - 1) as f64).max(rate_nm_per_s / max_trigger_hz);
    ((step / 1e-4 - 1e-9).ceil() * 1e-4).max(1e-4)
}

impl ScpiLaser {
    /// The module's sweep speed range (nm/s): Keysight `:WAV:SWE:SPE? MIN` and `MAX` (m/s), read once.
    fn speed_range(&mut self) -> Result<(f64, f64), HwError> {
        if let Some(r) = self.speed_range {
            return Ok(r);
        }
        let [min_q, max_q] = keysight::SPEED_LIMITS;
        let range = (self.query_f64(min_q)? * 1e9, self.query_f64(max_q)? * 1e9);
        if !(range.0 > 0.0 && range.1 >= range.0) {
            return Err(HwError::bad_reply(&self.name, max_q, &format!("{range:?} nm/s"), "0 < MIN ≤ MAX"));
        }
        self.speed_range = Some(range);
        Ok(range)
    }

    /// What the family will be asked for: its direction rule and accepted speeds applied.
    fn plan(&mut self, from_nm: f64, to_nm: f64, rate_nm_per_s: f64) -> Result<SweepSetup, HwError> {
        let usage = |problem: String| HwError::Usage { controller: self.name.clone(), problem };
        if !(from_nm.is_finite() && to_nm.is_finite() && rate_nm_per_s.is_finite() && rate_nm_per_s > 0.0)
            || from_nm == to_nm
        {
            return Err(usage(format!("cannot sweep {from_nm} → {to_nm} nm at {rate_nm_per_s} nm/s")));
        }
        let (from_nm, to_nm, rate, max_trigger_hz) = if self.keysight() {
            // "A continuous sweep can only be started if … the start wavelength is less than the
            // stop wavelength": the span is swept upwards.
            let (lo, hi) = (from_nm.min(to_nm), from_nm.max(to_nm));
            let (min, max) = self.speed_range()?;
            (lo, hi, rate_nm_per_s.clamp(min, max), keysight::MAX_TRIGGER_HZ)
        } else {
            (from_nm, to_nm, santec::allowed_speed(rate_nm_per_s), santec::MAX_TRIGGER_HZ)
        };
        if (rate - rate_nm_per_s).abs() > 1e-9 * rate_nm_per_s {
            tracing::info!(laser = %self.name, asked = rate_nm_per_s, "sweeping at {rate} nm/s, the speed the laser accepts");
        }
        let step_nm = log_step_nm(to_nm - from_nm, rate, max_trigger_hz);
        Ok(SweepSetup { from_nm, to_nm, rate_nm_per_s: rate, step_nm })
    }

    /// Configure the sweep (not started), read every setting back, and (Keysight) ask the laser
    /// whether the set is consistent (`:WAV:SWE:CHEC?`). Returns the sweep as read back.
    pub(super) fn configure_sweep(
        &mut self,
        from_nm: f64,
        to_nm: f64,
        rate_nm_per_s: f64,
    ) -> Result<SweepSetup, HwError> {
        let want = self.plan(from_nm, to_nm, rate_nm_per_s)?;
        let (commands, numbers, words, speed_q): SweepDialect = if self.keysight() {
            (
                keysight::configure_sweep(want.from_nm, want.to_nm, want.rate_nm_per_s, want.step_nm),
                keysight::readback(want.from_nm, want.to_nm, want.step_nm),
                &keysight::STATE_READBACK,
                keysight::SPEED_QUERY,
            )
        } else {
            (
                santec::configure_sweep(want.from_nm, want.to_nm, want.rate_nm_per_s, want.step_nm),
                santec::readback(want.from_nm, want.to_nm, want.step_nm),
                &santec::STATE_READBACK,
                santec::SPEED_QUERY,
            )
        };
        for c in commands {
            self.command(&c)?;
        }
        let unit = self.nm_per_reply_unit();
        let mut read = [0.0; 3];
        for (k, (query, set)) in numbers.iter().enumerate() {
            read[k] = self.query_f64(query)? * unit;
            if (read[k] - set).abs() > READBACK_TOLERANCE_NM {
                return Err(HwError::bad_reply(
                    &self.name,
                    query,
                    &format!("{:.4} nm", read[k]),
                    &format!("{set:.4} nm, as just set"),
                ));
            }
        }
        for (query, expected) in words {
            let reply = self.query(query)?;
            if !same_word(&reply, expected) {
                return Err(HwError::bad_reply(&self.name, query, &reply, &format!("{expected}, as just set")));
            }
        }
        let rate = self.query_f64(speed_q)? * unit;
        if rate.is_nan() || rate <= 0.0 || (rate - want.rate_nm_per_s).abs() > 0.01 * want.rate_nm_per_s {
            return Err(HwError::bad_reply(
                &self.name,
                speed_q,
                &format!("{rate} nm/s"),
                &format!("{} nm/s, as just set", want.rate_nm_per_s),
            ));
        }
        if self.keysight() {
            let check = self.query(keysight::CHECK_PARAMS)?;
            let (code, message) = super::scpi::parse_error_reply(&check)
                .map_err(|e| HwError::bad_reply(&self.name, keysight::CHECK_PARAMS, &check, &e))?;
            if code != 0 {
                return Err(HwError::Usage {
                    controller: self.name.clone(),
                    problem: format!(
                        "the laser finds the sweep's settings inconsistent: `{}` answers {code}, \"{message}\"",
                        keysight::CHECK_PARAMS
                    ),
                });
            }
        }
        Ok(SweepSetup { from_nm: read[0], to_nm: read[1], rate_nm_per_s: rate, step_nm: read[2] })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_log_step_keeps_the_points_and_the_trigger_rate_within_bounds() {
        // 40 nm at 10 nm/s: 10 001 points of 4 pm, 2.5 kHz of triggers.
        assert!((log_step_nm(40.0, 10.0, 40e3) - 0.004).abs() < 1e-12);
        // 1 nm at 10 nm/s: 0.1 pm would trigger at 100 kHz; the step grows to 0.3 pm (33 kHz).
        let step = log_step_nm(1.0, 10.0, 40e3);
        assert!((step - 0.0003).abs() < 1e-12 && 10.0 / step <= 40e3, "{step}");
        assert_eq!(log_step_nm(1e-6, 0.0, f64::INFINITY), 1e-4);
        assert_eq!(santec::allowed_speed(10.0), 10.0);
        assert_eq!(santec::allowed_speed(13.0), 10.0);
        assert_eq!(santec::allowed_speed(0.5), 1.0);
    }
}
