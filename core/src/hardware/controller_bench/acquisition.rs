//! Recording during a segment: the recorder of the photodiode's controller samples its joints and
//! the photodiode, the other controllers' joints are polled and interpolated at the sample times;
//! a recorder that fills its tables before the segment ends is a fault, and each recording's cost
//! on the wire and its timing are logged once, at its end.

use super::ControllerBench;
use crate::hardware::{HwError, RecordTrigger, RecorderRequest, Traffic};
use crate::plan::{TimedMotion, TimedSegment};
use crate::trace::{Trace, TraceMeta};

/// Longest round trip (s, real time) of a position poll kept in a recording.
const MAX_POLL_RTT_S: f64 = 0.002;

/// Samples read from the recorder, not yet turned into trace rows.
pub(super) struct Acquisition {
    pub(super) t_trigger_s: f64,
    /// The trigger's bench time is known: at the move command, or (an external trigger) from the
    /// first samples recorded.
    pub(super) t_trigger_known: bool,
    /// Started by an external trigger (the laser's trigger output), not by the move command.
    pub(super) external: bool,
    /// Bench time the recorder was armed.
    pub(super) t_armed_s: f64,
    pub(super) dt_s: f64,
    /// Samples each table holds.
    pub(super) capacity: Option<usize>,
    /// `read` calls made.
    pub(super) reads: usize,
    /// Each controller's and the laser's link traffic when the recorder was armed.
    pub(super) traffic_at_arm: Vec<Option<Traffic>>,
    pub(super) read: usize,
    /// Recorder joints (joint index, column).
    pub(super) recorded_joints: Vec<usize>,
    pub(super) columns: Vec<Vec<f64>>,
    pub(super) inputs: Vec<Vec<f64>>,
    /// Polls of the other joints: per joint the bench time its position was asked for and its
    /// display value.
    pub(super) polls: Vec<Poll>,
    pub(super) emitted: usize,
    pub(super) trace: Trace,
    /// How well the polls were timed (for the log).
    pub(super) timing: PollTiming,
}

impl Acquisition {
    /// Samples recorded from the trigger up to bench time `end_s`.
    fn samples_to(&self, end_s: f64) -> usize {
        ((end_s - self.t_trigger_s) / self.dt_s).floor().max(0.0) as usize + 1
    }
}

/// How well a recording's polls were timed, logged at its end: long exchanges mean a busy host,
/// and a polled joint's position error of its speed times the exchange.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct PollTiming {
    /// Real time of the recorder's trigger exchange (s).
    pub(super) trigger_rtt_s: f64,
    /// Polls kept and dropped.
    pub(super) kept: usize,
    pub(super) dropped: usize,
    /// Longest exchange of a kept poll (s, real time).
    pub(super) worst_kept_rtt_s: f64,
    /// Longest bench time between two kept polls (s).
    pub(super) longest_gap_s: f64,
}

/// One poll of the joints not on the recorder: each read in its own exchange, so each has its
/// own time (a joint read third in a poll is read two exchanges after the first).
#[derive(Debug, Clone, Copy)]
pub(super) struct Poll {
    /// Bench time each joint's position was asked for (s; unused for the recorder's joints).
    pub(super) t_s: [f64; 6],
    /// Display value of each joint (µm, °).
    pub(super) q: [f64; 6],
}

impl ControllerBench {
    /// Joints on the recorder's controller (recorded), the others polled.
    fn recorded_joints(&self) -> Vec<usize> {
        (0..6).filter(|&j| self.joints[j].controller == self.recorder_controller).collect()
    }

    /// Each controller's and the laser's traffic now.
    pub(super) fn traffic_now(&self) -> Vec<Option<Traffic>> {
        self.controllers.iter().map(|c| c.traffic()).chain(std::iter::once(self.laser.traffic())).collect()
    }

    /// Arm the recorder of the photodiode's controller for the recorded joints and the inputs
    /// (photodiode, then the wavelength monitor if wired), started by `trigger`, for a recording
    /// of at most `duration_s`; the acquisition starts empty.
    pub(super) fn arm_recorder(
        &mut self,
        meta: &TraceMeta,
        trigger: RecordTrigger,
        duration_s: f64,
    ) -> Result<Acquisition, HwError> {
        let recorded_joints = self.recorded_joints();
        let axes: Vec<usize> = recorded_joints.iter().map(|&j| self.joints[j].axis).collect();
        let mut inputs = vec![self.config.photodiode.input.clone()];
        inputs.extend(self.config.photodiode.wavelength_input.clone());
        let external = matches!(trigger, RecordTrigger::External { .. });
        let request =
            RecorderRequest { axes, inputs, sample_period_s: self.config.sample_period_s, duration_s, trigger };
        let traffic_at_arm = self.traffic_now();
        let rec = self.controllers[self.recorder_controller].recorder().ok_or_else(|| HwError::Usage {
            controller: self.config.photodiode.controller.clone(),
            problem: "no data recorder".into(),
        })?;
        let setup = rec.arm(&request)?;
        let inputs = request.inputs;
        Ok(Acquisition {
            t_trigger_s: 0.0,
            t_trigger_known: false,
            external,
            t_armed_s: self.bench_now(),
            dt_s: setup.sample_period_s,
            capacity: setup.capacity,
            reads: 0,
            traffic_at_arm,
            read: 0,
            columns: vec![vec![]; recorded_joints.len()],
            inputs: vec![vec![]; inputs.len()],
            recorded_joints,
            polls: vec![],
            emitted: 0,
            trace: Trace::new(meta.clone()),
            timing: PollTiming::default(),
        })
    }

    pub(super) fn poll(&mut self, acq: &mut Acquisition, keep: bool) -> Result<(), HwError> {
        let polled: Vec<usize> = (0..6).filter(|j| !acq.recorded_joints.contains(j)).collect();
        if polled.is_empty() {
            return Ok(());
        }
        let t_before = self.bench_now();
        let mut poll = Poll { t_s: [t_before; 6], q: [0.0; 6] };
        let mut sent = t_before;
        for &j in &polled {
            let m = self.joints[j];
            let p = self.controllers[m.controller].positions(&[m.axis])?;
            // Stamped when its request was sent, as the recorder's trigger is: the one-way
            // latency of both cancels. Each joint its own stamp: the third is asked two
            // exchanges after the first.
            poll.t_s[j] = sent;
            poll.q[j] = (p[0] - m.zero) * m.sign;
            sent = self.bench_now();
        }
        // A poll whose exchanges took long (the host was busy) may have been read late: drop
        // it, unless it is the first or `keep` (at rest, where the time does not matter).
        let rtt_real_s = (sent - t_before) / self.clock.scale();
        if keep || rtt_real_s <= MAX_POLL_RTT_S || acq.polls.is_empty() {
            let timing = &mut acq.timing;
            timing.kept += 1;
            timing.worst_kept_rtt_s = timing.worst_kept_rtt_s.max(rtt_real_s);
            if let Some(last) = acq.polls.last() {
                timing.longest_gap_s = timing.longest_gap_s.max(t_before - last.t_s[polled[0]]);
            }
            acq.polls.push(poll);
        } else {
            acq.timing.dropped += 1;
        }
        Ok(())
    }

    /// Read what the recorder holds (up to bench time `up_to_s`), at most `max_rows` rows: while
    /// the segment runs, the reads stay short so that the polls and the progress keep their pace.
    /// The time it takes counts in the segment's breakdown.
    pub(super) fn read_recorder(
        &mut self,
        acq: &mut Acquisition,
        up_to_s: Option<f64>,
        max_rows: usize,
    ) -> Result<(), HwError> {
        let t0 = self.bench_now();
        let out = self.read_recorder_rows(acq, up_to_s, max_rows);
        let spent = self.bench_now() - t0;
        self.breakdown.recorder_s += spent;
        if self.marks.end_s.is_some() {
            self.breakdown.recorder_after_s += spent;
        }
        out
    }

    fn read_recorder_rows(
        &mut self,
        acq: &mut Acquisition,
        up_to_s: Option<f64>,
        max_rows: usize,
    ) -> Result<(), HwError> {
        let asked_s = self.bench_now();
        let Some(rec) = self.controllers[self.recorder_controller].recorder() else { return Ok(()) };
        let mut available = rec.recorded_len()?;
        if !acq.t_trigger_known {
            if available == 0 {
                return Ok(());
            }
            // Started by an external edge: its samples, counted when asked, date it to a sample
            // and an exchange (the sweeps it times run at rest).
            acq.t_trigger_s = (asked_s - (available - 1) as f64 * acq.dt_s).max(acq.t_armed_s);
            acq.t_trigger_known = true;
        }
        if let Some(end) = up_to_s {
            let last = acq.samples_to(end);
            available = available.min(last);
        }
        let available = available.min(acq.read.saturating_add(max_rows));
        while acq.read < available {
            let count = (available - acq.read).min(50_000);
            let block = rec.read(acq.read, count)?;
            acq.reads += 1;
            for (col, new) in acq.columns.iter_mut().zip(block.axes) {
                col.extend(new);
            }
            for (col, new) in acq.inputs.iter_mut().zip(block.inputs) {
                col.extend(new);
            }
            acq.read += count;
        }
        Ok(())
    }

    /// Turn recorded samples into trace rows, up to the last poll (or all of them with `all`).
    pub(super) fn emit(&self, acq: &mut Acquisition, seg: &TimedSegment, all: bool) {
        if !acq.t_trigger_known {
            return;
        }
        // Samples up to the earliest reading of the last poll: every polled joint is known there.
        let polled: Vec<usize> = (0..6).filter(|j| !acq.recorded_joints.contains(j)).collect();
        let last_poll = acq.polls.last().map(|p| polled.iter().map(|&j| p.t_s[j]).fold(f64::INFINITY, f64::min));
        let pd = &self.config.photodiode;
        let wavelength_recorded = pd.wavelength_input.is_some();
        let (mw, nm_per_unit, offset_nm) = (pd.mw_per_unit, pd.wavelength_nm_per_unit, pd.wavelength_offset_nm);
        while acq.emitted < acq.read {
            let k = acq.emitted;
            let t = acq.t_trigger_s + k as f64 * acq.dt_s;
            if !all && acq.recorded_joints.len() < 6 && last_poll.is_none_or(|lp| t > lp) {
                break;
            }
            let mut q = seg.to_display;
            // Polled joints: linear interpolation between polls (clamped at the ends).
            for &j in &polled {
                q[j] = interpolate(&acq.polls, j, t).unwrap_or(seg.from_display[j]);
            }
            for (c, &j) in acq.recorded_joints.iter().enumerate() {
                let m = self.joints[j];
                q[j] = (acq.columns[c][k] - m.zero) * m.sign;
            }
            let wavelength = if wavelength_recorded {
                offset_nm + nm_per_unit * acq.inputs[1][k]
            } else {
                seg.wavelength_at(t - acq.t_trigger_s).unwrap_or(self.laser.nominal_nm())
            };
            acq.trace.push_sample(t, q, wavelength, acq.inputs[0][k] * mw);
            acq.emitted += 1;
        }
    }

    /// After the motion ended at bench time `end`: a last poll, then every sample up to `end`
    /// (waiting up to 1 s of bench time for the recorder, which may lag a poll behind).
    pub(super) fn finish_acquisition(
        &mut self,
        a: &mut Acquisition,
        seg: &TimedSegment,
        end: f64,
    ) -> Result<(), HwError> {
        self.poll(a, true)?;
        // The recorder may lag a poll behind (it started when the move command arrived, after the
        // bench's stamp): wait for the last samples, a second of bench time and at least 0.2 s of
        // real time (on a fast clock a second is a few of the host's scheduling delays).
        let wait_until = self.bench_now() + 1.0f64.max(0.2 * self.clock.scale());
        loop {
            self.read_recorder(a, Some(end), usize::MAX)?;
            let have_all = a.t_trigger_known && a.read >= a.samples_to(end).min(a.capacity.unwrap_or(usize::MAX));
            if have_all || self.bench_now() > wait_until {
                break;
            }
            self.sleep_poll();
        }
        if !a.t_trigger_known {
            return Err(HwError::Usage {
                controller: self.config.photodiode.controller.clone(),
                problem: format!(
                    "the data recorder was never started by the laser's trigger output (digital input {}): is it wired, and the laser's trigger output on?",
                    self.config.photodiode.laser_trigger_input.as_deref().unwrap_or("?")
                ),
            });
        }
        self.emit(a, seg, true);
        // Rows read while the loop had not yet noticed the end belong to no segment.
        let keep = a.trace.t_s.partition_point(|&t| t <= end + 1e-9);
        keep_range(&mut a.trace, 0, keep);
        refit_polled_ramps(a, seg);
        self.log_recording(a);
        self.check_recorded_end(a, seg)
    }

    /// A move's recording ends with its recorded joints on their targets (within the tolerance
    /// `check_arrival` uses, at rest or going through): one that ends short lost the motion's end.
    fn check_recorded_end(&self, a: &Acquisition, seg: &TimedSegment) -> Result<(), HwError> {
        if !matches!(seg.motion, TimedMotion::Move { .. }) {
            return Ok(());
        }
        for &j in &a.recorded_joints {
            let Some(&last) = a.trace.joint_column(j).last() else { continue };
            let (tol, unit) = self.end_tolerance(j, seg);
            if (last - seg.to_display[j]).abs() > tol {
                return Err(HwError::Usage {
                    controller: self.config.photodiode.controller.clone(),
                    problem: format!(
                        "the recording of `{}` ended with joint {} at {last:.4} {unit}, short of its target {:.4} {unit}: it stopped before the motion did",
                        seg.label, self.robot.links[j].name, seg.to_display[j]
                    ),
                });
            }
        }
        Ok(())
    }

    /// A recorder that had filled its tables when the segment was seen still running (the
    /// question asked at bench time `asked_s`) lost the rest: a fault. Its samples are read behind
    /// time, so its tables are judged full by the time they last, not by the samples read.
    pub(super) fn check_capacity(&self, a: &Acquisition, label: &str, asked_s: f64) -> Result<(), HwError> {
        let full = |c: usize| a.read >= c || (a.t_trigger_known && asked_s > a.t_trigger_s + c as f64 * a.dt_s);
        match a.capacity {
            Some(c) if full(c) => Err(HwError::Usage {
                controller: self.config.photodiode.controller.clone(),
                problem: format!(
                    "the data recorder filled its {c} samples per table ({:.1} s at {:.2} ms) before segment `{label}` ended: the segment ran longer than planned",
                    c as f64 * a.dt_s,
                    a.dt_s * 1e3
                ),
            }),
            _ => Ok(()),
        }
    }

    /// One debug line per recording: its samples and reads, what it cost on each link, and how
    /// well its polls were timed (the rows themselves are at trace level).
    fn log_recording(&self, a: &Acquisition) {
        let now = self.traffic_now();
        let names = self.config.controllers.iter().map(|c| c.name.clone()).chain(std::iter::once(self.laser.name()));
        let links: Vec<String> = names
            .zip(now.iter().zip(&a.traffic_at_arm))
            .filter_map(|(name, (now, then))| {
                let d = now.as_ref()?.since(then.as_ref()?);
                Some(format!(
                    "{name}: {} commands, {} B out, {} B in, {} lines",
                    d.commands, d.bytes_out, d.bytes_in, d.lines_in
                ))
            })
            .collect();
        let t = a.timing;
        tracing::debug!(
            label = %a.trace.meta.label,
            rows = a.trace.len(),
            samples_read = a.read,
            recorder_reads = a.reads,
            sample_ms = a.dt_s * 1e3,
            duration_s = a.trace.len() as f64 * a.dt_s,
            trigger_ms = t.trigger_rtt_s * 1e3,
            polls_kept = t.kept,
            polls_dropped = t.dropped,
            worst_kept_poll_ms = t.worst_kept_rtt_s * 1e3,
            longest_gap_ms = t.longest_gap_s * 1e3,
            "recording: {}",
            links.join("; ")
        );
    }
}

/// Keep samples `first..first + len` of a trace (every column).
pub(super) fn keep_range(t: &mut Trace, first: usize, len: usize) {
    let end = (first + len).min(t.len());
    let first = first.min(end);
    let keep = |c: &mut Vec<f64>| {
        c.truncate(end);
        c.drain(..first);
    };
    keep(&mut t.t_s);
    keep(&mut t.q1_um);
    keep(&mut t.q2_um);
    keep(&mut t.q3_um);
    keep(&mut t.q4_deg);
    keep(&mut t.q5_deg);
    keep(&mut t.q6_deg);
    keep(&mut t.wavelength_nm);
    keep(&mut t.irradiance);
    for e in &mut t.extra {
        keep(&mut e.values);
    }
}

/// A polled joint's move as a ramp: `q = a + b·t` clamped between the move's ends (display
/// units, bench time in s).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Ramp {
    a: f64,
    b: f64,
    lo: f64,
    hi: f64,
}

impl Ramp {
    fn at(&self, t: f64) -> f64 {
        (self.a + self.b * t).clamp(self.lo, self.hi)
    }
}

/// Fewest polls in the middle of a move for its ramp to replace the interpolation.
const MIN_RAMP_POLLS: usize = 8;

/// Joint `j`'s move from `from` to `to` as a ramp, fitted by least squares to the polls in the
/// middle 90 % of its travel; `None` when it does not move or too few polls fall there. A wrist
/// stage with its acceleration control off runs a move at its set speed (`:SCLA<ch>,0`, MCS
/// manual), so each poll's position is the ramp at the time it was read; a poll stamped when its
/// request was sent but read later (a busy host: up to the 2 ms a poll may take) is off by the
/// speed times that delay, and between two such polls the interpolation follows the error (1-5
/// mdeg on a goniometer at 2°/s, 3-8 nm of a rotation's gap correction). The fit averages it
/// over every poll of the move.
fn ramp_fit(polls: &[Poll], j: usize, from: f64, to: f64) -> Option<Ramp> {
    let travel = to - from;
    if travel.abs() < 1e-9 {
        return None;
    }
    let inside = |q: f64| {
        let u = (q - from) / travel;
        (0.05..=0.95).contains(&u)
    };
    let pts: Vec<(f64, f64)> = polls.iter().filter(|p| inside(p.q[j])).map(|p| (p.t_s[j], p.q[j])).collect();
    if pts.len() < MIN_RAMP_POLLS {
        return None;
    }
    let n = pts.len() as f64;
    let (tm, qm) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
    let stt: f64 = pts.iter().map(|p| (p.0 - tm).powi(2)).sum();
    let stq: f64 = pts.iter().map(|p| (p.0 - tm) * (p.1 - qm)).sum();
    if stt <= 0.0 {
        return None;
    }
    let b = stq / stt;
    // It rests at the commanded ends: a closed-loop stage holds its target within its
    // tolerance, which `check_arrival` holds it to.
    Some(Ramp { a: qm - b * tm, b, lo: from.min(to), hi: from.max(to) })
}

/// A finished move's polled joints on their fitted ramps ([`ramp_fit`]) instead of the
/// interpolation between polls; a joint that did not move, or moved with too few polls, keeps it.
fn refit_polled_ramps(a: &mut Acquisition, seg: &TimedSegment) {
    if !matches!(seg.motion, TimedMotion::Move { .. }) {
        return;
    }
    for j in (0..6).filter(|j| !a.recorded_joints.contains(j)) {
        if let Some(r) = ramp_fit(&a.polls, j, seg.from_display[j], seg.to_display[j]) {
            let t = a.trace.t_s.clone();
            for (q, t) in a.trace.joint_column_mut(j).iter_mut().zip(t) {
                *q = r.at(t);
            }
        }
    }
}

/// Joint `j` at bench time `t` (s): linear between the polls that bracket it, clamped at the ends;
/// `None` without a poll.
fn interpolate(polls: &[Poll], j: usize, t: f64) -> Option<f64> {
    let i = polls.partition_point(|p| p.t_s[j] <= t);
    match (i.checked_sub(1).and_then(|a| polls.get(a)), polls.get(i)) {
        (Some(a), Some(b)) if b.t_s[j] > a.t_s[j] => {
            Some(a.q[j] + (b.q[j] - a.q[j]) * (t - a.t_s[j]) / (b.t_s[j] - a.t_s[j]))
        }
        (Some(a), _) => Some(a.q[j]),
        (None, Some(b)) => Some(b.q[j]),
        (None, None) => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_range_of_samples_is_kept_in_every_column() {
        let mut t = Trace::new(TraceMeta::default());
        for (i, w) in [1550.0, 1550.0, 1550.0, 1550.5, 1551.0, 1551.5, 1552.0, 1552.0].iter().enumerate() {
            t.push_sample(i as f64, [i as f64; 6], *w, i as f64);
        }
        keep_range(&mut t, 2, 5);
        assert_eq!(t.wavelength_nm, [1550.0, 1550.5, 1551.0, 1551.5, 1552.0]);
        assert_eq!(t.irradiance, [2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(t.q6_deg, [2.0, 3.0, 4.0, 5.0, 6.0]);
    }

    /// A move's polls read late by random delays (a busy host): the fitted ramp is far closer to
    /// the truth than the interpolation between them, and rests at the move's ends.
    #[test]
    fn a_polled_move_is_a_ramp_fitted_through_its_late_polls() {
        use rand::{rngs::StdRng, Rng, SeedableRng};
        let mut rng = StdRng::seed_from_u64(4);
        // q5 from 0 to 0.5° at 2°/s, starting at 10 ms; polls every 2 ms, read 0-2 ms late.
        let truth = |t: f64| (2.0 * (t - 0.010)).clamp(0.0, 0.5);
        let polls: Vec<Poll> = (0..150)
            .map(|k| {
                let sent = k as f64 * 2e-3;
                let read = sent + rng.random_range(0.0..2e-3);
                Poll { t_s: [sent; 6], q: std::array::from_fn(|j| if j == 4 { truth(read) } else { 0.0 }) }
            })
            .collect();
        let ramp = ramp_fit(&polls, 4, 0.0, 0.5).unwrap();
        let (mut worst_ramp, mut worst_interp) = (0f64, 0f64);
        for i in 0..3000 {
            let t = i as f64 * 1e-4;
            worst_ramp = worst_ramp.max((ramp.at(t) - truth(t + 1e-3)).abs());
            worst_interp = worst_interp.max((interpolate(&polls, 4, t).unwrap() - truth(t + 1e-3)).abs());
        }
        // The mean delay (1 ms) stays, as with the interpolation; the jitter about it goes.
        assert!(worst_ramp < 0.4e-3, "ramp off by {worst_ramp}° at worst: {ramp:?}");
        assert!(worst_interp > 1.5e-3, "interpolation off by {worst_interp}° at worst");
        assert_eq!((ramp.lo, ramp.hi), (0.0, 0.5));
        assert_eq!(ramp_fit(&polls, 3, 0.0, 0.0), None, "a joint that does not move keeps its polls");
    }

    /// Each joint is interpolated on its own stamps: two joints moving at constant speed, read
    /// 0.4 ms apart in every poll, come back exactly at any time between polls (a common stamp
    /// would put the second 0.4 ms of motion off).
    #[test]
    fn each_polled_joint_is_interpolated_on_its_own_stamps() {
        let speed = [0.0, 0.0, 0.0, 2.0, -3.0, 0.0];
        let polls: Vec<Poll> = (0..5)
            .map(|k| {
                let t0 = k as f64 * 1e-3;
                let t_s = [t0, t0, t0, t0, t0 + 4e-4, t0 + 8e-4];
                Poll { t_s, q: std::array::from_fn(|j| speed[j] * t_s[j]) }
            })
            .collect();
        for t in [5e-4, 1.25e-3, 3.9e-3] {
            for j in [3, 4] {
                let q = interpolate(&polls, j, t).unwrap();
                assert!((q - speed[j] * t).abs() < 1e-12, "q{} at {t}: {q}", j + 1);
            }
        }
        assert_eq!(interpolate(&polls, 4, -1.0), Some(polls[0].q[4]), "clamped before the first poll");
        assert_eq!(interpolate(&[], 4, 0.0), None);
    }
}
