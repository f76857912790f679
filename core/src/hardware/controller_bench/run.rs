//! Running one segment on the controllers: speeds, the motion started on every controller (the
//! recorder's first), following it to its end while streaming the samples, checking that every
//! joint got there, and stopping everything after a fault.

use super::acquisition::Acquisition;
use super::laser::SweepSetup;
use super::sweep::SWEEP_ALLOWANCE_S;
use super::ControllerBench;
use crate::bench::RunControl;
use crate::hardware::HwError;
use crate::model::robot::JointType;
use crate::plan::{TimedMotion, TimedSegment};
use crate::trace::TraceMeta;
use std::time::Duration;

/// The part of its travel a joint may still have to go when a move it runs through ends.
const THROUGH_SHORTFALL: f64 = 0.01;

/// Most recorder rows read per turn of the loop that follows a segment.
const READ_ROWS_WHILE_MOVING: usize = 10_000;

/// The slowest speed a joint is commanded, as a fraction of its limit: controllers print speeds
/// with six decimals and refuse 0 (PI GCS error 8).
const MIN_SPEED_FRACTION: f64 = 1e-4;

/// Where the segment running is, in bench time (s): its start, its motion command, the end the
/// controllers reported.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Marks {
    pub(super) start_s: f64,
    pub(super) motion_s: Option<f64>,
    pub(super) end_s: Option<f64>,
}

/// How a segment that met no fault ended.
pub(super) enum Stop {
    /// It ran to its end.
    Done,
    /// The user cancelled it.
    Cancelled,
}

impl ControllerBench {
    /// Run the segment; on a fault return it with what was acquired.
    pub(super) fn run_inner(
        &mut self,
        seg: &TimedSegment,
        meta: &TraceMeta,
        acq: &mut Option<Acquisition>,
        control: &mut RunControl<'_>,
    ) -> Result<Stop, HwError> {
        self.set_speeds(seg)?;
        let sweep = self.prepare_sweep(seg)?;
        if seg.record {
            let (trigger, duration_s) = self.recording_plan(seg, sweep.as_ref());
            *acq = Some(self.arm_recorder(meta, trigger, duration_s)?);
            if let Some(a) = acq.as_mut() {
                self.poll(a, true)?;
            }
        }
        let t_start = self.bench_now();
        self.marks.motion_s = Some(t_start);
        let (t_trigger, trigger_rtt_s, spread_s) = self.start_motion(seg)?;
        self.breakdown.start_spread_s = spread_s;
        if let Some(a) = acq.as_mut() {
            if !a.external {
                a.t_trigger_s = t_trigger;
                a.t_trigger_known = true;
            }
            a.timing.trigger_rtt_s = trigger_rtt_s;
        }
        // A sweep's time runs from its start command, sent after the stages' (a laser without a
        // state query is taken as done when that time is up).
        let t_start = match &sweep {
            Some(s) => {
                self.laser.start_sweep(s.from_nm, s.to_nm, s.rate_nm_per_s)?;
                self.bench_now()
            }
            None => t_start,
        };
        let Some(done_at) = self.follow_motion(seg, acq, control, t_start, sweep.as_ref())? else {
            return Ok(Stop::Cancelled);
        };
        self.marks.end_s = Some(done_at.max(self.bench_now()));
        let log = if sweep.is_some() { self.finish_sweep()? } else { None };
        if matches!(seg.motion, TimedMotion::Move { .. }) {
            self.check_arrival(seg)?;
        }
        if let Some(a) = acq.as_mut() {
            self.finish_acquisition(a, seg, done_at)?;
            if let Some(s) = &sweep {
                self.apply_sweep(a, s, log.as_ref())?;
            }
        }
        if sweep.is_some() {
            let nominal = self.laser.nominal_nm();
            self.laser.set_wavelength(nominal)?;
        }
        Ok(Stop::Done)
    }

    /// Follow the motion started at bench time `t_start` until it has ended and settled (a sweep:
    /// until the laser reports it done, at its real speed and latency), streaming the samples and
    /// the progress: the bench time it ended at, or `None` when the user cancelled.
    fn follow_motion(
        &mut self,
        seg: &TimedSegment,
        acq: &mut Option<Acquisition>,
        control: &mut RunControl<'_>,
        t_start: f64,
        sweep: Option<&SweepSetup>,
    ) -> Result<Option<f64>, HwError> {
        let settle_s = match seg.motion {
            TimedMotion::Move { settle_s, .. } => settle_s,
            _ => 0.0,
        };
        let expected_s = sweep.map_or(seg.duration_s, |s| s.duration_s());
        let deadline =
            t_start + 2.0 * (expected_s + sweep.map_or(0.0, |_| SWEEP_ALLOWANCE_S)) + self.config.timeout_margin_s;
        let mut done_at: Option<f64> = None;
        let mut reported = 0;
        let mut laser_asked = std::time::Instant::now();
        loop {
            let now = self.bench_now();
            if control.cancelled() {
                return Ok(None);
            }
            if let Some(a) = acq.as_mut() {
                self.poll(a, false)?;
                self.read_recorder(a, None, READ_ROWS_WHILE_MOVING)?;
                self.emit(a, seg, false);
                if a.trace.len() > reported {
                    (control.on_samples)(&a.trace, reported);
                    reported = a.trace.len();
                }
            }
            (control.on_progress)(((now - t_start) / expected_s.max(1e-9)).clamp(0.0, 1.0));
            match done_at {
                Some(t) if now >= t => return Ok(Some(t)),
                Some(_) => {}
                None => {
                    // Bench time at which the segment is known to be still running if it is not
                    // finished: when its controller or laser was asked, else its planned end.
                    let mut running_at = self.bench_now();
                    let finished = match seg.motion {
                        TimedMotion::Move { .. } => self.all_on_target()?,
                        TimedMotion::Sweep { .. } => {
                            // The laser's state, asked every 10 ms of real time once its time is up.
                            let ask = now >= t_start + expected_s && laser_asked.elapsed().as_secs_f64() >= 0.01;
                            if !ask {
                                running_at = running_at.min(t_start + expected_s);
                            }
                            ask && {
                                laser_asked = std::time::Instant::now();
                                !self.laser.sweep_running()?
                            }
                        }
                        TimedMotion::Dwell => {
                            running_at = running_at.min(t_start + seg.duration_s);
                            now >= t_start + seg.duration_s
                        }
                    };
                    if !finished {
                        // Still running with the recorder full: the rest of the segment is lost.
                        if let Some(a) = acq.as_ref() {
                            self.check_capacity(a, &seg.label, running_at)?;
                        }
                    }
                    if finished {
                        // The motion ended before the controller (or the laser) said so: its end is
                        // stamped after the answer. `now` was read before this turn's polls and
                        // reads, which on a busy host or a fast clock last longer than the settling
                        // time: stamped there, the recording lost the end of the motion.
                        let answered_s = self.bench_now();
                        // The stages stand still from here: a poll now is exact whatever its round
                        // trip, and bounds the interpolation at the end of the motion (polls during
                        // the motion may all have been dropped on a busy host).
                        if let Some(a) = acq.as_mut() {
                            self.poll(a, true)?;
                        }
                        // A dwell ends on time, however late the loop notices.
                        done_at = Some(match seg.motion {
                            TimedMotion::Dwell => t_start + seg.duration_s,
                            _ => answered_s + settle_s,
                        });
                    } else if now > deadline {
                        return Err(self.overdue(seg, sweep.is_some(), deadline - t_start));
                    }
                }
            }
            self.sleep_poll();
        }
    }

    /// The segment's breakdown from its marks, now that it has ended (a fault or a cancel: as far
    /// as it got).
    pub(super) fn close_breakdown(&mut self) {
        let now = self.bench_now();
        let m = self.marks;
        let motion = m.motion_s.unwrap_or(now);
        let end = m.end_s.unwrap_or(now);
        let b = &mut self.breakdown;
        b.setup_s = motion - m.start_s;
        b.motion_s = end - motion;
        b.finish_s = now - end;
    }

    /// The segment ran past its deadline: the axes (or the sweep) that did not finish.
    fn overdue(&self, seg: &TimedSegment, sweep: bool, timeout_s: f64) -> HwError {
        if sweep {
            return HwError::WaitTimeout { controller: self.laser.name(), axes: "wavelength sweep".into(), timeout_s };
        }
        HwError::WaitTimeout {
            controller: self.config.name.clone(),
            axes: (0..6)
                .filter(|&j| seg.to_display[j] != seg.from_display[j])
                .map(|j| self.robot.links[j].name.clone())
                .collect::<Vec<_>>()
                .join(","),
            timeout_s,
        }
    }

    /// How far from its target joint `j` may stand once arrived, and the unit it is read in.
    pub(super) fn arrival_tolerance(&self, j: usize) -> (f64, &'static str) {
        match self.robot.links[j].joint {
            JointType::Prismatic => (0.01, "µm"),
            JointType::Revolute => (1e-4, "°"),
        }
    }

    /// [`Self::arrival_tolerance`] at the end of `seg`: a move the stages run through without
    /// settling may end still closing in on its target (the E-712 says on target within its
    /// window), so there it is also 1 % of the joint's travel; a lost command leaves all of it.
    pub(super) fn end_tolerance(&self, j: usize, seg: &TimedSegment) -> (f64, &'static str) {
        let (tol, unit) = self.arrival_tolerance(j);
        match seg.motion {
            TimedMotion::Move { through: true, .. } => {
                (tol.max(THROUGH_SHORTFALL * (seg.to_display[j] - seg.from_display[j]).abs()), unit)
            }
            _ => (tol, unit),
        }
    }

    /// After a move: every joint at its target. A lost command looks like a finished move.
    fn check_arrival(&mut self, seg: &TimedSegment) -> Result<(), HwError> {
        let q = self.read_joints()?;
        for (j, &qj) in q.iter().enumerate() {
            let (tol, unit) = self.end_tolerance(j, seg);
            if (qj - seg.to_display[j]).abs() > tol {
                let m = self.joints[j];
                return Err(HwError::LimitReached {
                    controller: self.config.controllers[m.controller].name.clone(),
                    axis: format!(
                        "{} (joint {})",
                        self.controllers[m.controller].axes()[m.axis].id,
                        self.robot.links[j].name
                    ),
                    position: qj,
                    target: seg.to_display[j],
                    unit,
                    reason: "the move ended off its target: a lost command, an end stop or a limit".into(),
                });
            }
        }
        Ok(())
    }

    fn to_controller(&self, j: usize, q: f64) -> f64 {
        self.joints[j].zero + self.joints[j].sign * q
    }

    /// The time (s) of a move's straight ramp: every joint arrives with the slowest, which moves
    /// at its speed limit.
    pub(super) fn ramp_s(&self, seg: &TimedSegment) -> f64 {
        (0..6).map(|j| (seg.to_display[j] - seg.from_display[j]).abs() / self.speed_limit(j)).fold(0.0, f64::max)
    }

    /// Joint `j`'s speed limit (µm/s or °/s): its own from the robot file, else its type's.
    fn speed_limit(&self, j: usize) -> f64 {
        self.motion.for_link(&self.robot.links[j]).0
    }

    fn set_speeds(&mut self, seg: &TimedSegment) -> Result<(), HwError> {
        let d: [f64; 6] = std::array::from_fn(|j| (seg.to_display[j] - seg.from_display[j]).abs());
        // All joints arrive together: the slowest sets the time.
        let time = self.ramp_s(seg);
        for (j, &dj) in d.iter().enumerate() {
            let limit = self.speed_limit(j);
            // A joint that moves by rounding noise still gets a speed the controller can express.
            let v = if dj > 0.0 && time > 0.0 { (dj / time).max(MIN_SPEED_FRACTION * limit) } else { limit };
            if (v - self.velocities[j]).abs() > 1e-9 * v || self.velocities[j].is_nan() {
                let m = self.joints[j];
                self.controllers[m.controller].set_velocity(m.axis, v)?;
                self.velocities[j] = v;
            }
        }
        Ok(())
    }

    /// Start the segment's motion: the recorder's controller first (its move command triggers the
    /// recorder, even when it does not move), then the others. Returns the bench time at which the
    /// recorder started (when the move command was sent) and the real duration of that exchange
    /// (s). The polls of the other axes are stamped
    /// when their request is sent too, so the one-way latency to the controllers cancels; stamping
    /// at the reply would add whatever delay the host takes to read it (measured: under load,
    /// stamps at the middle of the exchange put q4/q5 several nm of dL off). Last, the bench time
    /// from the first command to a moving joint to the last one's answer when the joints moving
    /// are on several controllers, else 0 (one controller starts its axes together).
    fn start_motion(&mut self, seg: &TimedSegment) -> Result<(f64, f64, f64), HwError> {
        let n = self.controllers.len();
        let mut t_trigger = self.bench_now();
        let mut trigger_rtt_s = 0.0;
        let moving =
            |c: usize| (0..6).any(|j| self.joints[j].controller == c && seg.to_display[j] != seg.from_display[j]);
        let moving: Vec<bool> = (0..n).map(moving).collect();
        let mut first_sent: Option<f64> = None;
        let order = std::iter::once(self.recorder_controller).chain((0..n).filter(|&c| c != self.recorder_controller));
        for c in order {
            let targets: Vec<(usize, f64)> = (0..6)
                .filter(|&j| self.joints[j].controller == c)
                .filter(|&j| c == self.recorder_controller || seg.to_display[j] != seg.from_display[j])
                .map(|j| (self.joints[j].axis, self.to_controller(j, seg.to_display[j])))
                .collect();
            if c == self.recorder_controller {
                // Travel limits are cached after the first move: only the move command is timed.
                for &(a, _) in &targets {
                    self.controllers[c].travel_limits(a)?;
                }
                t_trigger = self.bench_now();
                self.controllers[c].move_absolute(&targets)?;
                trigger_rtt_s = (self.bench_now() - t_trigger) / self.clock.scale();
                if moving[c] {
                    first_sent = Some(t_trigger);
                }
            } else {
                let sent = self.bench_now();
                self.controllers[c].move_absolute(&targets)?;
                if moving[c] {
                    first_sent.get_or_insert(sent);
                }
            }
        }
        let spread_s = match first_sent {
            Some(t) if moving.iter().filter(|m| **m).count() > 1 => self.bench_now() - t,
            _ => 0.0,
        };
        Ok((t_trigger, trigger_rtt_s, spread_s))
    }

    fn all_on_target(&mut self) -> Result<bool, HwError> {
        for c in 0..self.controllers.len() {
            let axes: Vec<usize> =
                (0..6).filter(|&j| self.joints[j].controller == c).map(|j| self.joints[j].axis).collect();
            if !axes.is_empty() && !self.controllers[c].on_target(&axes)?.iter().all(|&t| t) {
                return Ok(false);
            }
        }
        Ok(true)
    }

    pub(super) fn bench_now(&self) -> f64 {
        self.clock.now_s()
    }

    /// Wait one polling period (real time, whatever the clock's scale: on a faster emulated
    /// clock, polls as often in bench time load the host, and a poll's latency, not their
    /// cadence, bounds the interpolation of the polled joints).
    pub(super) fn sleep_poll(&self) {
        std::thread::sleep(Duration::from_secs_f64(self.config.poll_period_s));
    }

    /// Stop everything after a fault; say what was done.
    pub(super) fn stop_all(&mut self) -> String {
        let mut said = Vec::new();
        for (c, cfg) in self.controllers.iter_mut().zip(&self.config.controllers) {
            let outcome = match c.stop() {
                Ok(()) => "stopped".to_string(),
                Err(e) if e.needs_reconnect() => match c.reconnect().and_then(|()| c.stop()) {
                    Ok(()) => "reconnected and stopped".to_string(),
                    Err(e2) => format!("NOT stopped ({e2})"),
                },
                Err(e) => format!("NOT stopped ({e})"),
            };
            said.push(format!("{}: {outcome}", cfg.name));
        }
        let laser_stop = match self.laser.stop_sweep() {
            Err(e) if e.needs_reconnect() => self.laser.reconnect().and_then(|()| self.laser.stop_sweep()),
            other => other,
        };
        if let Err(e) = laser_stop {
            said.push(format!("{}: sweep NOT stopped ({e})", self.laser.name()));
        }
        let nominal = self.laser.nominal_nm();
        if self.laser.set_wavelength(nominal).is_err() {
            said.push("laser: could not return to its nominal wavelength".into());
        }
        said.join(", ")
    }
}
