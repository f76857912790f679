//! The crash guarantee of `photorobot calibrate`, checked on the binary: it is killed (SIGKILL)
//! at seeded random moments, and after each kill the folder is held against what the run's log
//! reported; `--resume` then continues, and the finished session is compared with an
//! uninterrupted run of the same seed. Shared by `tests/cli_crash.rs` and
//! `examples/crash_kills.rs`.
//!
//! What "equal to an uninterrupted run" means on the virtual bench: a resumed run builds its bench
//! again from the seed, so the detector noise of the segments it measures is a new draw (as on a
//! real bench, where a segment measured again never repeats its noise). Equal exactly: the steps
//! (plan, segment), labels, kinds and sample counts, in order; every trace recorded before the
//! first kill, byte for byte; every trace the log reported, byte for byte, from then on; the
//! joints and the wavelength of every sample and its time from the segment's start. Equal within
//! the noise: the irradiance of a segment measured after a resume differs from the
//! uninterrupted run's by the detector's white noise alone (RMS √2·σ within 15 %, no offset), and
//! each identified parameter by less than [`PARAMETER_TOLERANCE_SIGMA`] of its σ, with the same
//! parameters determined and the same verdict; when no trace was measured anew, the calibration
//! is the same to the last bit.

#![allow(dead_code)]

use photorobot_core::bench::VirtualBench;
use photorobot_core::calibration::CalibrationReport;
use photorobot_core::session::{autosave_path, session_path, Session, TraceRef};
use photorobot_core::trace::Trace;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A finished session's parameters differ from the uninterrupted run's by less than this many
/// of their σ. The two runs share the noise of the segments measured before the first kill and
/// draw the rest anew: two calibrations of one bench from data that differ by noise alone, which
/// must agree within the uncertainty each states (a resumed session that moved a parameter by
/// its σ would make that σ a false statement). Seen: at most 0.35 σ over 60 kills.
pub const PARAMETER_TOLERANCE_SIGMA: f64 = 1.0;

/// `photorobot calibrate` with its arguments (all but `--out` and `--resume`).
#[derive(Debug, Clone)]
pub struct Calibrate {
    pub bin: PathBuf,
    pub args: Vec<String>,
}

impl Calibrate {
    /// The command into `dir`; resuming, without `--plan` (the plans are in the autosave), as
    /// the command calibrate prints on Ctrl-C.
    pub fn command(&self, dir: &Path, resume: bool) -> Command {
        let mut cmd = Command::new(&self.bin);
        cmd.arg("calibrate");
        let mut args = self.args.iter();
        while let Some(arg) = args.next() {
            if resume && arg == "--plan" {
                args.next();
            } else {
                cmd.arg(arg);
            }
        }
        cmd.arg("--out").arg(dir);
        if resume {
            cmd.arg("--resume");
        }
        cmd.stdout(Stdio::null()).stderr(Stdio::piped());
        cmd
    }

    /// Run to the end; it must succeed.
    pub fn finish(&self, dir: &Path, resume: bool) {
        let out = self.command(dir, resume).output().expect("start photorobot");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "calibrate (resume {resume}) into {}: {}\n{stderr}", dir.display(), out.status);
    }
}

/// A segment the log reported done and autosaved, with where its trace went.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reported {
    pub step: (usize, usize),
    /// File, size (bytes) and CRC-32 of its trace; `None` for a segment that records nothing.
    pub trace: Option<(String, u64, u32)>,
}

/// The number after `key=` in `line`.
fn field<T: std::str::FromStr>(line: &str, key: &str) -> Option<T> {
    let at = line.rfind(&format!(" {key}="))? + key.len() + 2;
    line[at..].split(' ').next()?.trim_matches('"').parse().ok()
}

/// The completed segments a log reports, in order.
pub fn reported(log: &str) -> Vec<Reported> {
    let mut out = Vec::new();
    for line in log.lines().filter(|l| l.contains("segment done, autosaved")) {
        let step = (field(line, "plan_index").expect("plan_index"), field(line, "segment").expect("segment"));
        let trace = field::<String>(line, "file")
            .map(|file| (file, field(line, "bytes").expect("bytes"), field(line, "crc32").expect("crc32")));
        out.push(Reported { step, trace });
    }
    out
}

/// When to kill a run: after its `n`-th completed segment (0: right after it starts), after its
/// measurement is done, or after its validation (while it writes the session); then after
/// `delay`.
#[derive(Debug, Clone, Copy)]
pub enum After {
    Segments(usize),
    MeasurementDone,
    ValidationDone,
}

#[derive(Debug, Clone, Copy)]
pub struct Moment {
    pub after: After,
    pub delay: Duration,
}

/// `count` kill moments within the measurement drawn from `seed`: after 0 to 2 more segments,
/// then up to 80 ms (about one segment); the first, at times, within 15 ms of the start.
pub fn moments(seed: u64, count: usize) -> Vec<Moment> {
    let mut rng = StdRng::seed_from_u64(seed);
    (0..count)
        .map(|k| {
            if k == 0 && rng.random_bool(0.5) {
                return Moment { after: After::Segments(0), delay: Duration::from_millis(rng.random_range(0..15)) };
            }
            let after = After::Segments(rng.random_range(0..=2));
            Moment { after, delay: Duration::from_millis(rng.random_range(0..80)) }
        })
        .collect()
}

/// A kill moment after the measurement drawn from `seed`: within the identification and the
/// validation, or within the writing of the session (after the validation), at 5-80 % of the
/// time the uninterrupted run `reference` took for it. A fixed window (up to 4 s) let the run
/// end first on a fast machine, and no kill fell after the measurement.
pub fn late_moment(seed: u64, writing: bool, reference: &Reference) -> Moment {
    let mut rng = StdRng::seed_from_u64(seed);
    let (after, window) = match writing {
        false => (After::MeasurementDone, reference.identify_and_validate),
        true => (After::ValidationDone, reference.writing),
    };
    Moment { after, delay: window.mul_f64(rng.random_range(0.05..0.8)) }
}

fn read_from(path: &Path, offset: usize) -> String {
    let bytes = std::fs::read(path).unwrap_or_default();
    String::from_utf8_lossy(bytes.get(offset..).unwrap_or_default()).into_owned()
}

pub fn log_path(dir: &Path) -> PathBuf {
    dir.join("photorobot.log")
}

/// Wait for `moment` in the run `child` (its log from `offset`), then SIGKILL it. `false` when
/// the run ended first (it must have succeeded).
fn kill_at(child: &mut Child, dir: &Path, offset: usize, moment: Moment) -> bool {
    let start = Instant::now();
    let mut reached: Option<Instant> = None;
    loop {
        if let Some(status) = child.try_wait().expect("try_wait") {
            let mut err = String::new();
            std::io::Read::read_to_string(child.stderr.as_mut().expect("stderr"), &mut err).ok();
            assert!(status.success(), "calibrate ended by itself with {status}: {err}");
            return false;
        }
        if reached.is_none() {
            let log = read_from(&log_path(dir), offset);
            // A resumed run with nothing left to measure goes on to identify at once.
            let measured = log.contains("measurement done");
            let hit = match moment.after {
                After::Segments(n) => measured || log.matches("segment done, autosaved").count() >= n,
                After::MeasurementDone => measured,
                After::ValidationDone => log.contains("validation done"),
            };
            reached = hit.then(Instant::now);
        }
        if reached.is_some_and(|t| t.elapsed() >= moment.delay) {
            child.kill().expect("SIGKILL"); // no destructor, no flush runs
            child.wait().expect("wait");
            return true;
        }
        assert!(start.elapsed() < Duration::from_secs(300), "no {moment:?} after five minutes");
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// An uninterrupted run: its session and the bytes of its traces, by step.
pub struct Reference {
    pub session: Session,
    pub bytes: BTreeMap<(usize, usize), Vec<u8>>,
    pub traces: Vec<Trace>,
    /// Standard deviation of the bench's white detector noise (mW).
    pub white_sigma_mw: f64,
    /// From the end of the measurement to the end of the validation (its log's lines, polled).
    pub identify_and_validate: Duration,
    /// From the end of the validation to the end of the run (the session written).
    pub writing: Duration,
}

/// Run `calibrate` into `dir` to its end (it must succeed); the times of its log's "measurement
/// done" and "validation done" lines, and of its end, from its start.
fn timed_run(calibrate: &Calibrate, dir: &Path) -> [Duration; 3] {
    let start = Instant::now();
    let mut child = calibrate.command(dir, false).spawn().expect("start photorobot");
    let (mut measured, mut validated) = (None, None);
    loop {
        if let Some(status) = child.try_wait().expect("try_wait") {
            let mut err = String::new();
            std::io::Read::read_to_string(child.stderr.as_mut().expect("stderr"), &mut err).ok();
            assert!(status.success(), "calibrate into {}: {status}\n{err}", dir.display());
            let end = start.elapsed();
            return [measured.unwrap_or(end), validated.unwrap_or(end), end];
        }
        let log = std::fs::read_to_string(log_path(dir)).unwrap_or_default();
        if measured.is_none() && log.contains("measurement done") {
            measured = Some(start.elapsed());
        }
        if validated.is_none() && log.contains("validation done") {
            validated = Some(start.elapsed());
        }
        assert!(start.elapsed() < Duration::from_secs(300), "the reference run took over five minutes");
        std::thread::sleep(Duration::from_millis(2));
    }
}

impl Reference {
    pub fn run(calibrate: &Calibrate, dir: &Path, preset: &str, seed: u64) -> Self {
        let [measured, validated, end] = timed_run(calibrate, dir);
        let session = Session::load(dir).expect("reference session");
        let bytes = session
            .traces
            .iter()
            .map(|r| (r.step.expect("a measured step"), std::fs::read(dir.join(&r.file)).expect("trace")))
            .collect();
        let traces = session.load_traces(dir).expect("reference traces");
        let white_sigma_mw = VirtualBench::from_preset_name(preset, Some(seed)).expect("bench").white_noise_sigma_mw();
        Self {
            session,
            bytes,
            traces,
            white_sigma_mw,
            identify_and_validate: validated.saturating_sub(measured),
            writing: end.saturating_sub(validated),
        }
    }

    fn calibration(&self) -> &CalibrationReport {
        self.session.calibration.as_ref().expect("the reference is calibrated")
    }
}

/// What one chain of kills did.
#[derive(Debug, Default)]
pub struct Chain {
    pub kills: usize,
    /// Kills after which the folder held no autosave yet (nothing measured).
    pub before_any_autosave: usize,
    /// Kills within the identification, validation or writing.
    pub after_measurement: usize,
    /// Segments reported done, over all runs.
    pub reported: usize,
    /// Largest |Δ|/σ of a parameter against the uninterrupted run.
    pub worst_parameter_sigma: f64,
}

/// The state the chain's checks carry from kill to kill.
#[derive(Default)]
pub struct Seen {
    /// Bytes of every trace the log reported, by step.
    bytes: BTreeMap<(usize, usize), Vec<u8>>,
    /// Steps completed in the first run, which must equal the uninterrupted run byte for byte.
    first_run: BTreeSet<(usize, usize)>,
    /// Trace files on disk no session references (segments in hand at a kill).
    unreferenced: usize,
}

/// Kill `calibrate` into `dir` at each of `moments` (each run after the first resumes), check
/// the folder after each kill, finish with `--resume`, and compare with `reference`.
pub fn kill_chain(calibrate: &Calibrate, dir: &Path, moments: &[Moment], reference: &Reference) -> Chain {
    let mut chain = Chain::default();
    let mut seen = Seen::default();
    let mut resume = false;
    for (k, moment) in moments.iter().enumerate() {
        let offset = std::fs::read(log_path(dir)).map_or(0, |b| b.len());
        let mut child = calibrate.command(dir, resume).spawn().expect("start photorobot");
        let context = format!("{} kill {k} at {moment:?}", dir.display());
        if !kill_at(&mut child, dir, offset, *moment) {
            return chain.finished(dir, &seen, reference, true, &context);
        }
        chain.kills += 1;
        chain.after_measurement += usize::from(!matches!(moment.after, After::Segments(_)));
        match check_interrupted(dir, &mut seen, !resume, reference, &context) {
            State::Nothing => {
                chain.before_any_autosave += 1;
                refused_resume(calibrate, dir, "nothing was measured");
                resume = false;
            }
            State::Measuring => resume = true,
            State::Finished => {
                refused_resume(calibrate, dir, "holds a finished session");
                return chain.finished(dir, &seen, reference, false, &context);
            }
        }
    }
    calibrate.finish(dir, resume);
    let context = format!("{} after {} kills", dir.display(), chain.kills);
    chain.finished(dir, &seen, reference, true, &context)
}

impl Chain {
    /// The chain's finished folder checked against `reference`.
    fn finished(mut self, dir: &Path, seen: &Seen, reference: &Reference, cleaned_up: bool, context: &str) -> Self {
        let redrawn = check_finished(dir, seen, reference, cleaned_up, context);
        self.reported = reported(&std::fs::read_to_string(log_path(dir)).unwrap_or_default()).len();
        self.worst_parameter_sigma = compare_calibration(dir, reference, redrawn, context);
        self
    }
}

/// `--resume` on this folder is refused with `why`.
pub fn refused_resume(calibrate: &Calibrate, dir: &Path, why: &str) {
    let out = calibrate.command(dir, true).output().expect("start photorobot");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "--resume on {}: {stderr}", dir.display());
    assert!(stderr.contains(why), "--resume on {}: no `{why}` in {stderr}", dir.display());
}

/// Where a killed run left its folder.
pub enum State {
    /// No autosave: the run was killed before its first one.
    Nothing,
    /// An autosave to resume.
    Measuring,
    /// `session.ron` written: the run was done.
    Finished,
}

/// The trace files of the folder's `traces/`.
fn trace_files(dir: &Path) -> BTreeSet<String> {
    let Ok(entries) = std::fs::read_dir(dir.join("traces")) else { return BTreeSet::new() };
    entries
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".csv") && !n.starts_with('.'))
        .map(|n| format!("traces/{n}"))
        .collect()
}

/// After a kill: every segment the log reported is in the autosave, its trace byte for byte as
/// reported (and as the uninterrupted run's, for the first run's); at most the segment in hand
/// is lost.
pub fn check_interrupted(dir: &Path, seen: &mut Seen, first_run: bool, reference: &Reference, context: &str) -> State {
    let log = std::fs::read_to_string(log_path(dir)).unwrap_or_default();
    let reports = reported(&log);
    if session_path(dir).exists() && !autosave_path(dir).exists() {
        return State::Finished;
    }
    if !autosave_path(dir).exists() {
        assert!(reports.is_empty(), "{context}: the log reported segments but there is no autosave");
        return State::Nothing;
    }
    let session = Session::recover(dir).unwrap_or_else(|e| panic!("{context}: the autosave does not load: {e}"));
    let by_step: BTreeMap<(usize, usize), &TraceRef> =
        session.traces.iter().map(|r| (r.step.expect("measured"), r)).collect();
    for r in &reports {
        let Some((file, bytes, crc32)) = &r.trace else { continue };
        let kept =
            by_step.get(&r.step).unwrap_or_else(|| panic!("{context}: reported {:?} is not in the autosave", r.step));
        assert_eq!((&kept.file, kept.bytes, kept.crc32), (file, *bytes, *crc32), "{context}: {:?}", r.step);
        assert!(kept.complete, "{context}: {:?} kept as partial", r.step);
        let on_disk = std::fs::read(dir.join(file)).expect("reported trace");
        let earlier = seen.bytes.entry(r.step).or_insert_with(|| on_disk.clone());
        assert!(*earlier == on_disk, "{context}: the trace of {:?} changed since it was reported", r.step);
        if first_run {
            seen.first_run.insert(r.step);
        }
        if seen.first_run.contains(&r.step) {
            assert!(
                reference.bytes.get(&r.step) == Some(&on_disk),
                "{context}: {:?} differs from the uninterrupted run",
                r.step
            );
        }
    }
    // The autosave runs ahead of the log by at most the segment whose line the kill cut.
    let recorded_reports = reports.iter().filter(|r| r.trace.is_some()).count();
    assert!(
        session.traces.len() <= recorded_reports + 1,
        "{context}: {} traces, {recorded_reports} reported",
        session.traces.len()
    );
    // At most the segment in hand is lost: its trace written, not yet in the autosave.
    let referenced: BTreeSet<&String> = session.traces.iter().map(|r| &r.file).collect();
    let unreferenced = trace_files(dir).iter().filter(|f| !referenced.contains(f)).count();
    assert!(
        unreferenced <= seen.unreferenced + 1,
        "{context}: {unreferenced} unreferenced trace files, {} before",
        seen.unreferenced
    );
    seen.unreferenced = unreferenced;
    State::Measuring
}

/// The finished folder: the session loads with every trace checked, no autosave, no stray
/// temporary, no unreferenced trace file (but after a kill within the final clean-up, which is
/// best effort); the same steps as the uninterrupted run, every reported trace kept byte for
/// byte, the others equal but for the detector noise. Returns how many traces were measured
/// anew (not byte for byte the uninterrupted run's).
pub fn check_finished(dir: &Path, seen: &Seen, reference: &Reference, cleaned_up: bool, context: &str) -> usize {
    let session = Session::load(dir).unwrap_or_else(|e| panic!("{context}: {e}"));
    let traces = session.load_traces(dir).unwrap_or_else(|e| panic!("{context}: {e}"));
    assert!(!autosave_path(dir).exists(), "{context}: the autosave is left");
    for name in ["extrinsics.ron", "report.json"] {
        assert!(dir.join(name).exists(), "{context}: no {name}");
    }
    let referenced: BTreeSet<String> = session.traces.iter().map(|r| r.file.clone()).collect();
    let files = trace_files(dir);
    assert!(referenced.is_subset(&files), "{context}: trace files missing");
    if cleaned_up {
        assert_eq!(files, referenced, "{context}: trace files beside the session's");
    }
    let stray: Vec<String> = walk(dir).into_iter().filter(|n| n.ends_with(".tmp")).collect();
    assert!(stray.is_empty(), "{context}: temporaries left: {stray:?}");
    let steps = |s: &Session| {
        s.traces.iter().map(|r| (r.step, r.label.clone(), r.kind, r.samples, r.complete)).collect::<Vec<_>>()
    };
    assert_eq!(steps(&session), steps(&reference.session), "{context}: steps");
    let mut redrawn = 0;
    for ((r, trace), expected) in session.traces.iter().zip(&traces).zip(&reference.traces) {
        let step = r.step.expect("measured");
        let bytes = std::fs::read(dir.join(&r.file)).expect("trace");
        if let Some(kept) = seen.bytes.get(&step) {
            assert!(*kept == bytes, "{context}: the reported trace of {step:?} changed");
        }
        if seen.first_run.contains(&step) || reference.bytes[&step] == bytes {
            assert!(reference.bytes[&step] == bytes, "{context}: {step:?} differs from the uninterrupted run");
            continue;
        }
        equal_but_for_noise(trace, expected, reference.white_sigma_mw, &format!("{context}: {step:?}"));
        redrawn += 1;
    }
    redrawn
}

/// Every file under `dir`, as paths relative to it.
fn walk(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap_or(&p).display().to_string());
            }
        }
    }
    out
}

/// A segment measured again after a resume: the same joints, wavelength and times from its
/// start, sample for sample; an irradiance that differs by white noise of RMS √2·σ (each run
/// drew its own) within 15 %, without an offset, or not at all (the same draw).
fn equal_but_for_noise(trace: &Trace, expected: &Trace, white_sigma_mw: f64, context: &str) {
    assert_eq!(trace.len(), expected.len(), "{context}: samples");
    for j in 0..6 {
        assert!(trace.joint_column(j) == expected.joint_column(j), "{context}: joint q{} differs", j + 1);
    }
    assert!(trace.wavelength_nm == expected.wavelength_nm, "{context}: wavelengths differ");
    let (t0, e0) = (trace.t_s[0], expected.t_s[0]);
    let worst_t = trace.t_s.iter().zip(&expected.t_s).map(|(a, b)| ((a - t0) - (b - e0)).abs()).fold(0.0, f64::max);
    assert!(worst_t < 1e-9, "{context}: times from the start differ by {worst_t} s");
    let n = trace.len() as f64;
    let diff: Vec<f64> = trace.irradiance.iter().zip(&expected.irradiance).map(|(a, b)| a - b).collect();
    let mean = diff.iter().sum::<f64>() / n;
    let rms = (diff.iter().map(|d| d * d).sum::<f64>() / n).sqrt();
    if rms == 0.0 {
        // The same draw: a resumed bench's noise starts where the uninterrupted run's did, and
        // the segment is the first it records.
        return;
    }
    let sigma = std::f64::consts::SQRT_2 * white_sigma_mw;
    assert!((rms / sigma - 1.0).abs() < 0.15, "{context}: irradiance differs by {rms} mW RMS, noise √2·σ = {sigma} mW");
    assert!(mean.abs() < 5.0 * sigma / n.sqrt(), "{context}: irradiance offset {mean} mW");
}

/// The finished session's calibration against the uninterrupted run's: the same parameters
/// determined, the same verdict, each value within [`PARAMETER_TOLERANCE_SIGMA`] of its σ, and
/// equal to the last bit when no trace was measured anew (`redrawn`). Returns the largest
/// |Δ|/σ.
pub fn compare_calibration(dir: &Path, reference: &Reference, redrawn: usize, context: &str) -> f64 {
    let session = Session::load(dir).unwrap_or_else(|e| panic!("{context}: {e}"));
    let got = session.calibration.as_ref().unwrap_or_else(|| panic!("{context}: no calibration"));
    let want = reference.calibration();
    let verdict = |c: &CalibrationReport| c.fit.as_ref().map(|f| f.verdict);
    assert_eq!(verdict(got), verdict(want), "{context}: verdict");
    assert_eq!(got.converged, want.converged, "{context}: converged");
    let mut worst: f64 = 0.0;
    for (g, w) in got.parameters.iter().zip(&want.parameters) {
        assert_eq!((&g.name, g.determined), (&w.name, w.determined), "{context}");
        if redrawn == 0 {
            assert_eq!(
                (g.value.to_bits(), g.sigma),
                (w.value.to_bits(), w.sigma),
                "{context}: {} from the same traces",
                g.name
            );
        }
        let (Some(sigma), true) = (w.sigma, w.determined) else { continue };
        let distance = (g.value - w.value).abs() / sigma;
        assert!(
            distance < PARAMETER_TOLERANCE_SIGMA,
            "{context}: {} = {} against {} (σ {sigma}): {distance:.2}σ",
            g.name,
            g.value,
            w.value
        );
        worst = worst.max(distance);
    }
    worst
}
