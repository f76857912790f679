//! Each recorded sample's wavelength during a laser sweep, on the recorder's clock. The laser's own
//! log holds exact wavelengths but no times; its time base is either the wavelength monitor on a
//! recorder input (noisy, quantised, but timed by the recorder) or the laser's trigger output
//! starting the recorder at the first logged point. Owns both mappings and the trim to the part
//! of the sweep run at constant speed; pure functions of the samples, tested on their own.

use super::laser::{LambdaLog, SweepSetup};

/// The samples of a recording that lie within the sweep, and their wavelengths.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepSamples {
    /// First sample within the sweep.
    pub first: usize,
    /// The wavelength of samples `first..first + wavelengths_nm.len()` (nm), strictly monotonic.
    pub wavelengths_nm: Vec<f64>,
    /// The relative uncertainty (ppm, 1σ) of the sweep's scale these wavelengths carry: the
    /// speed a monitor's line gives is known to its slope's σ, and a gap from the sweep is off by
    /// the same fraction (0 from the laser's own log).
    pub scale_sigma_ppm: f64,
}

/// Fewest samples the monitor must see in the middle of the sweep.
const MIN_CENTRAL_SAMPLES: usize = 16;
/// How far the monitor's speed may differ from the speed the laser reads back (fraction).
const SPEED_TOLERANCE: f64 = 0.05;

/// Least-squares line `p = a + b·t` through `(t, p)`, centred for conditioning: (a, b), and
/// Σ(t - t̄)² (the slope's σ is the residual's over its root).
fn fit_line(t: &[f64], p: &[f64]) -> ((f64, f64), f64) {
    let n = t.len() as f64;
    let (tm, pm) = (t.iter().sum::<f64>() / n, p.iter().sum::<f64>() / n);
    let (mut stt, mut stp) = (0.0, 0.0);
    for (ti, pi) in t.iter().zip(p) {
        stt += (ti - tm) * (ti - tm);
        stp += (ti - tm) * (pi - pm);
    }
    let b = if stt > 0.0 { stp / stt } else { 0.0 };
    ((pm - b * tm, b), stt)
}

/// The wavelengths from the monitor readings `monitor_nm` taken at `t_s`: in the middle of the
/// sweep (15-85 % of its span) the laser runs at constant speed, so a straight line fitted to the
/// readings there times the sweep to a fraction of a sample whatever the monitor's noise and
/// quantisation; the line is followed outward while the readings stay on it (within 6σ of its
/// residual), which leaves out the run-up, the run-out and the rest before and after. Each kept
/// sample gets the line's wavelength, or, with the laser's log, the logged wavelength at the
/// line's position along the sweep (the log's points are evenly spaced in the sweep). The line's
/// slope is known only to its σ from the readings' scatter: that fraction of the sweep's scale is
/// returned, as every gap measured from the sweep is off by it. A recording
/// that ends while the readings are still on the line, short of the stop, lost the sweep's end:
/// refused, not taken for a shorter sweep.
pub fn from_monitor(
    t_s: &[f64],
    monitor_nm: &[f64],
    setup: &SweepSetup,
    log: Option<&LambdaLog>,
) -> Result<SweepSamples, String> {
    let span = (setup.to_nm - setup.from_nm).abs();
    let dir = (setup.to_nm - setup.from_nm).signum();
    let progress: Vec<f64> = monitor_nm.iter().map(|m| dir * (m - setup.from_nm)).collect();
    let central: Vec<usize> = (0..progress.len().min(t_s.len()))
        .filter(|&k| progress[k] >= 0.15 * span && progress[k] <= 0.85 * span)
        .collect();
    if central.len() < MIN_CENTRAL_SAMPLES {
        return Err(format!(
            "the wavelength monitor saw the sweep {:.4} → {:.4} nm in {} samples of its middle, {MIN_CENTRAL_SAMPLES} needed: is it wired, and its scale right?",
            setup.from_nm,
            setup.to_nm,
            central.len()
        ));
    }
    let line_of = |idx: &[usize]| {
        let t: Vec<f64> = idx.iter().map(|&k| t_s[k]).collect();
        let p: Vec<f64> = idx.iter().map(|&k| progress[k]).collect();
        fit_line(&t, &p)
    };
    let rms = |idx: &[usize], (a, b): (f64, f64)| {
        (idx.iter().map(|&k| (progress[k] - a - b * t_s[k]).powi(2)).sum::<f64>() / idx.len() as f64).sqrt()
    };
    // One pass dropping outliers (a glitch of the input), then the line of the rest.
    let (first, _) = line_of(&central);
    let sigma = rms(&central, first);
    let kept: Vec<usize> = central
        .iter()
        .copied()
        .filter(|&k| (progress[k] - first.0 - first.1 * t_s[k]).abs() <= 5.0 * sigma.max(1e-9))
        .collect();
    let used = if kept.len() >= MIN_CENTRAL_SAMPLES { &kept } else { &central };
    let ((a, b), stt) = line_of(used);
    let sigma = rms(used, (a, b));
    // The slope's σ from the readings' scatter about the line (two parameters fitted).
    let dof = (used.len() as f64 - 2.0).max(1.0);
    let slope_sigma = sigma * (used.len() as f64 / dof).sqrt() / stt.max(f64::MIN_POSITIVE).sqrt();
    if (b - setup.rate_nm_per_s).abs() > SPEED_TOLERANCE * setup.rate_nm_per_s {
        return Err(format!(
            "the wavelength monitor sees the sweep run at {b:.4} nm/s, the laser reads back {:.4} nm/s: check the monitor's scale (nm per input unit)",
            setup.rate_nm_per_s
        ));
    }
    let on_line = |k: usize| {
        let p = a + b * t_s[k];
        (0.0..=span).contains(&p) && (progress[k] - p).abs() <= (6.0 * sigma).max(1e-3)
    };
    let n = progress.len().min(t_s.len());
    let (mut lo, mut hi) = (central[0], central[central.len() - 1]);
    while lo > 0 && on_line(lo - 1) {
        lo -= 1;
    }
    while hi + 1 < n && on_line(hi + 1) {
        hi += 1;
    }
    // Still on the line at the recording's last sample, short of the stop by more than two
    // samples' travel and the noise: the recording ended before the sweep did.
    let short_nm = span - (a + b * t_s[hi]);
    if hi + 1 == n && hi > 0 && short_nm > 2.0 * b * (t_s[hi] - t_s[hi - 1]) + 6.0 * sigma {
        return Err(format!(
            "the recording ended {short_nm:.4} nm before the sweep's stop at {:.4} nm: it stopped before the laser did",
            setup.to_nm
        ));
    }
    let wavelengths_nm = (lo..=hi)
        .map(|k| {
            let p = (a + b * t_s[k]).clamp(0.0, span);
            match log.filter(|l| l.step_nm > 0.0 && !l.wavelengths_nm.is_empty()) {
                Some(l) => l.at_index(p / l.step_nm).unwrap_or(setup.from_nm + dir * p),
                None => setup.from_nm + dir * p,
            }
        })
        .collect();
    Ok(SweepSamples { first: lo, wavelengths_nm, scale_sigma_ppm: 1e6 * slope_sigma / b.abs() })
}

/// The wavelengths of a recording the laser's trigger output started at its first logged point:
/// sample `k`, `k·dt` after it, gets the log at that time (its points `step / speed` apart at
/// constant speed); samples after the last logged point are left out.
pub fn from_trigger(samples: usize, dt_s: f64, log: &LambdaLog) -> Result<SweepSamples, String> {
    if log.wavelengths_nm.len() < 2 || log.step_nm.is_nan() || log.step_nm <= 0.0 {
        return Err(format!("the laser logged {} points: no sweep to time", log.wavelengths_nm.len()));
    }
    let end_s = log.duration_s();
    let n = ((end_s / dt_s).floor() as usize + 1).min(samples);
    let wavelengths_nm = (0..n).map(|k| log.wavelength_at(k as f64 * dt_s).unwrap_or(log.from_nm)).collect();
    Ok(SweepSamples { first: 0, wavelengths_nm, scale_sigma_ppm: 0.0 })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::StdRng, Rng, SeedableRng};

    /// A laser that starts 40 ms late, runs up from 0.05 nm before the start at 2000 nm/s², sweeps
    /// 1550 → 1552 nm at 10 nm/s and runs out past the stop: the truth.
    fn truth(t: f64) -> f64 {
        let (t0, v, acc) = (0.040, 10.0, 2000.0);
        let ramp = v / acc;
        let run_up = v * v / (2.0 * acc);
        let t_start = t0 + ramp; // crosses 1550 nm at full speed
        let t_stop = t_start + 2.0 / v;
        if t < t0 {
            1550.0
        } else if t < t_start {
            1550.0 - run_up + 0.5 * acc * (t - t0) * (t - t0)
        } else if t < t_stop {
            1550.0 + v * (t - t_start)
        } else if t < t_stop + ramp {
            let u = t - t_stop;
            1552.0 + v * u - 0.5 * acc * u * u
        } else {
            1552.0 + run_up
        }
    }

    fn setup() -> SweepSetup {
        SweepSetup { from_nm: 1550.0, to_nm: 1552.0, rate_nm_per_s: 10.0, step_nm: 2e-4 }
    }

    /// The truth recovered from a monitor with 3 pm quantisation and 2 pm noise, against the
    /// truth itself (the oracle), to under a pm (a 40 ms latency mistimed would be 400 pm); the
    /// run-up and the rests are left out.
    #[test]
    fn a_noisy_quantised_monitor_times_the_sweep() {
        let mut rng = StdRng::seed_from_u64(3);
        let dt = 5e-4;
        let t: Vec<f64> = (0..600).map(|k| k as f64 * dt).collect();
        let lsb = 0.003;
        let m: Vec<f64> =
            t.iter().map(|&t| ((truth(t) + rng.random_range(-0.0035..0.0035)) / lsb).round() * lsb).collect();
        let got = from_monitor(&t, &m, &setup(), None).unwrap();
        let worst =
            got.wavelengths_nm.iter().enumerate().map(|(i, w)| (w - truth(t[got.first + i])).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-3, "worst {worst} nm");
        assert!(got.wavelengths_nm.windows(2).all(|w| w[1] > w[0]), "strictly monotonic");
        let first_t = t[got.first];
        assert!(
            first_t >= 0.045 - dt && first_t < 0.045 + 3.0 * dt,
            "starts where the laser reaches 1550 nm at speed: {first_t}"
        );
        assert!(got.wavelengths_nm.len() > 380, "{}", got.wavelengths_nm.len());
        // A monitor whose scale is off by 20 % is refused, not believed.
        let scaled: Vec<f64> = m.iter().map(|w| 1550.0 + 1.2 * (w - 1550.0)).collect();
        let e = from_monitor(&t, &scaled, &setup(), None).unwrap_err();
        assert!(e.contains("check the monitor's scale"), "{e}");
        // A recording that ends before the sweep does is refused, not taken for a shorter sweep.
        let cut = (0.045 + 0.16) / dt;
        let e = from_monitor(&t[..cut as usize], &m[..cut as usize], &setup(), None).unwrap_err();
        assert!(e.contains("before the sweep's stop"), "{e}");
        // A monitor that sees nothing is refused.
        assert!(from_monitor(&t, &vec![1550.0; t.len()], &setup(), None).unwrap_err().contains("is it wired"));
    }

    /// The scale σ the monitor's line reports is the scatter of the speed it times, over many
    /// monitors' noise (the oracle: the truth's 10 nm/s).
    #[test]
    fn the_scale_sigma_is_the_scatter_of_the_timed_speed() {
        let dt = 5e-4;
        let t: Vec<f64> = (0..600).map(|k| k as f64 * dt).collect();
        let (mut errs, mut sigmas) = (Vec::new(), Vec::new());
        for seed in 0..200 {
            let mut rng = StdRng::seed_from_u64(100 + seed);
            let m: Vec<f64> = t.iter().map(|&t| truth(t) + rng.random_range(-0.01..0.01)).collect();
            let got = from_monitor(&t, &m, &setup(), None).unwrap();
            let (w, n) = (&got.wavelengths_nm, got.wavelengths_nm.len());
            let speed = (w[n - 1] - w[0]) / (t[got.first + n - 1] - t[got.first]);
            errs.push(1e6 * (speed / 10.0 - 1.0));
            sigmas.push(got.scale_sigma_ppm);
        }
        let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
        let sigma = sigmas.iter().sum::<f64>() / sigmas.len() as f64;
        assert!(rms > 0.8 * sigma && rms < 1.25 * sigma, "speed scatter {rms:.1} ppm, reported {sigma:.1} ppm");
    }

    #[test]
    fn a_trigger_started_recording_reads_the_log_at_its_times() {
        let log = LambdaLog {
            from_nm: 1550.0,
            to_nm: 1551.0,
            step_nm: 0.5,
            rate_nm_per_s: 10.0,
            wavelengths_nm: vec![1550.0, 1550.498, 1551.0],
        };
        let got = from_trigger(1000, 0.025, &log).unwrap();
        assert_eq!(got.wavelengths_nm.len(), 5, "0, 25, 50, 75, 100 ms: the log lasts 100 ms");
        assert!((got.wavelengths_nm[2] - 1550.498).abs() < 1e-12);
        assert!((got.wavelengths_nm[1] - 1550.249).abs() < 1e-12);
    }
}
