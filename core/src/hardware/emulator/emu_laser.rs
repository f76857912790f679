//! The emulated tunable laser's wavelength on the emulator clock, shared by the laser emulator that
//! commands it, the photodiode that sees it, the wavelength monitor that reads it, and the
//! recorder's digital input that sees its trigger output. Owns the sweep's profile: the start
//! latency, the run-up before the start wavelength, the constant-speed sweep, the run-out, and the
//! trigger edges at every log step.

use super::EmuClock;
use std::sync::{Arc, Mutex};

/// How a commanded sweep unfolds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepProfile {
    /// From the start command to the beginning of the run-up (s).
    pub latency_s: f64,
    /// Acceleration of the run-up and run-out (nm/s²; infinite: none).
    pub accel_nm_per_s2: f64,
}

impl SweepProfile {
    /// A sweep that starts at once at full speed.
    pub const INSTANT: SweepProfile = SweepProfile { latency_s: 0.0, accel_nm_per_s2: f64::INFINITY };
}

/// One leg of the laser's schedule.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Leg {
    /// At rest at a wavelength from `t0`.
    Rest { t0: f64, nm: f64 },
    /// A sweep commanded at `t_cmd`.
    Sweep { t_cmd: f64, from: f64, to: f64, rate: f64, profile: SweepProfile, trigger_step_nm: Option<f64> },
}

impl Leg {
    fn t0(&self) -> f64 {
        match *self {
            Leg::Rest { t0, .. } => t0,
            Leg::Sweep { t_cmd, .. } => t_cmd,
        }
    }
}

/// The times of a sweep leg: (run-up starts, start wavelength reached at speed, stop reached,
/// run-out ends), and the run-up distance (nm).
fn sweep_times(t_cmd: f64, from: f64, to: f64, rate: f64, p: SweepProfile) -> (f64, f64, f64, f64, f64) {
    let ramp_s = if p.accel_nm_per_s2.is_finite() { rate / p.accel_nm_per_s2 } else { 0.0 };
    let run_up_nm = 0.5 * rate * ramp_s;
    let t_go = t_cmd + p.latency_s;
    let t_from = t_go + ramp_s;
    let t_to = t_from + (to - from).abs() / rate;
    (t_go, t_from, t_to, t_to + ramp_s, run_up_nm)
}

/// An emulated tunable laser on the emulator clock: a fixed wavelength or a sweep.
#[derive(Debug)]
pub struct EmuLaser {
    clock: Arc<EmuClock>,
    schedule: Mutex<Vec<Leg>>,
}

impl EmuLaser {
    /// A laser at `wavelength_nm`.
    pub fn new(clock: Arc<EmuClock>, wavelength_nm: f64) -> Arc<Self> {
        Arc::new(EmuLaser { clock, schedule: Mutex::new(vec![Leg::Rest { t0: f64::NEG_INFINITY, nm: wavelength_nm }]) })
    }

    fn legs(&self) -> std::sync::MutexGuard<'_, Vec<Leg>> {
        self.schedule.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Wavelength (nm) at emulated time `t_s`.
    pub fn wavelength_at(&self, t_s: f64) -> f64 {
        let s = self.legs();
        let k = s.partition_point(|l| l.t0() <= t_s).saturating_sub(1);
        match s[k] {
            Leg::Rest { nm, .. } => nm,
            Leg::Sweep { t_cmd, from, to, rate, profile, .. } => {
                let d = (to - from).signum();
                let (t_go, t_from, t_to, t_end, run_up) = sweep_times(t_cmd, from, to, rate, profile);
                let a = profile.accel_nm_per_s2;
                if t_s < t_go {
                    from
                } else if t_s < t_from {
                    let u = t_s - t_go;
                    from - d * run_up + d * 0.5 * a * u * u
                } else if t_s < t_to {
                    from + d * rate * (t_s - t_from)
                } else if t_s < t_end {
                    let u = t_s - t_to;
                    to + d * (rate * u - 0.5 * a * u * u)
                } else {
                    to + d * run_up
                }
            }
        }
    }

    /// Command a sweep now (the laser goes through `profile`); `trigger_step_nm` is the step of
    /// its trigger output, if on. Returns the emulated time the start wavelength is reached at
    /// speed (the first logged point) and the time the stop is reached.
    pub fn sweep_with(
        &self,
        from_nm: f64,
        to_nm: f64,
        rate_nm_per_s: f64,
        profile: SweepProfile,
        trigger_step_nm: Option<f64>,
    ) -> (f64, f64) {
        let t = self.clock.now_s();
        let rate = rate_nm_per_s.abs();
        self.legs().push(Leg::Sweep { t_cmd: t, from: from_nm, to: to_nm, rate, profile, trigger_step_nm });
        let (_, t_from, t_to, _, _) = sweep_times(t, from_nm, to_nm, rate, profile);
        (t_from, t_to)
    }

    /// Start a sweep now, at once at full speed; returns the emulated start time.
    pub fn sweep(&self, from_nm: f64, to_nm: f64, rate_nm_per_s: f64) -> f64 {
        self.sweep_with(from_nm, to_nm, rate_nm_per_s, SweepProfile::INSTANT, None).0
    }

    /// Set a fixed wavelength now.
    pub fn set(&self, wavelength_nm: f64) {
        let t = self.clock.now_s();
        self.rest_from(t, wavelength_nm);
    }

    /// Rest at `nm` from emulated time `t_s` (an abort at a past time).
    pub(crate) fn rest_from(&self, t_s: f64, nm: f64) {
        let mut s = self.legs();
        let k = s.partition_point(|l| l.t0() <= t_s);
        s.truncate(k);
        s.push(Leg::Rest { t0: t_s, nm });
    }

    /// The first rising edge of the trigger output after emulated time `after_s`: a log step of a
    /// sweep whose trigger output is on, from the start wavelength to the stop.
    pub fn trigger_edge_after(&self, after_s: f64) -> Option<f64> {
        let s = self.legs();
        let mut best: Option<f64> = None;
        for (i, leg) in s.iter().enumerate() {
            let Leg::Sweep { t_cmd, from, to, rate, profile, trigger_step_nm: Some(step) } = *leg else { continue };
            let (_, t_from, t_to, _, _) = sweep_times(t_cmd, from, to, rate, profile);
            // A later leg (an abort, a new command) ends this one.
            let end = s.get(i + 1).map_or(t_to, |next| next.t0().min(t_to));
            let period = step / rate;
            let k = ((after_s - t_from) / period).floor().max(-1.0) + 1.0;
            let edge = t_from + k * period;
            if edge <= end + 1e-12 && edge > after_s {
                best = Some(best.map_or(edge, |b: f64| b.min(edge)));
            }
        }
        best
    }

    /// The clock.
    pub fn clock(&self) -> &Arc<EmuClock> {
        &self.clock
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The profile against its closed form: latency, a run-up of v²/(2a) before the start, the
    /// start crossed at full speed, constant speed to the stop, edges every step from the start.
    #[test]
    fn a_sweep_runs_up_crosses_the_start_at_speed_and_triggers_every_step() {
        let clock = EmuClock::new(1e-9); // frozen: the sweep is commanded at t ≈ 0
        let laser = EmuLaser::new(clock, 1550.0);
        let p = SweepProfile { latency_s: 0.04, accel_nm_per_s2: 1000.0 };
        let (t_from, t_to) = laser.sweep_with(1550.0, 1552.0, 10.0, p, Some(0.001));
        assert!((t_from - 0.05).abs() < 1e-6 && (t_to - 0.25).abs() < 1e-6, "{t_from} {t_to}");
        assert_eq!(laser.wavelength_at(0.03), 1550.0, "latency");
        assert!((laser.wavelength_at(0.045) - 1549.9625).abs() < 1e-9, "run-up from v²/2a = 0.05 nm before");
        assert!((laser.wavelength_at(0.05) - 1550.0).abs() < 1e-9);
        assert!((laser.wavelength_at(0.15) - 1551.0).abs() < 1e-9);
        assert!((laser.wavelength_at(1.0) - 1552.05).abs() < 1e-9, "run-out past the stop");
        let first = laser.trigger_edge_after(0.0).unwrap();
        assert!((first - t_from).abs() < 1e-9);
        let next = laser.trigger_edge_after(first).unwrap();
        assert!((next - first - 1e-4).abs() < 1e-9, "an edge every step / speed");
        assert_eq!(laser.trigger_edge_after(0.3), None, "no edge after the stop");
    }
}
