//! Progress on stderr for the commands that take minutes, and the Ctrl-C that stops a run at
//! the segment. Bars are drawn only when stderr is a terminal and `--quiet` is not given, so
//! pipes and logs get no escape codes. Owns no science: it is fed by the core's callbacks.

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

static QUIET: AtomicBool = AtomicBool::new(false);

/// The cancel flag of the run in progress, set by the first Ctrl-C (see [`install_ctrl_c`]).
pub static INTERRUPT: AtomicBool = AtomicBool::new(false);

/// The exit code of a run stopped by Ctrl-C (128 + SIGINT, the shell's convention).
pub const INTERRUPTED_EXIT_CODE: u8 = 130;

/// `--quiet`: no progress display.
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

/// True when progress is drawn: stderr is a terminal and `--quiet` was not given.
pub fn enabled() -> bool {
    !QUIET.load(Ordering::Relaxed) && std::io::stderr().is_terminal()
}

/// The first Ctrl-C sets [`INTERRUPT`] (the run stops after the segment in hand, its session
/// saved); a second one exits at once with [`INTERRUPTED_EXIT_CODE`].
pub fn install_ctrl_c() {
    let result = ctrlc::set_handler(|| {
        if INTERRUPT.swap(true, Ordering::SeqCst) {
            eprintln!("\ninterrupted again: exiting at once");
            std::process::exit(i32::from(INTERRUPTED_EXIT_CODE));
        }
        eprintln!("\ninterrupted: stopping at the current segment and saving (Ctrl-C again to quit at once)");
    });
    if let Err(e) = result {
        tracing::warn!("Ctrl-C will not stop runs cleanly: {e}");
    }
}

fn bar_style() -> ProgressStyle {
    ProgressStyle::with_template("{prefix:>22} [{bar:30}] {percent:>3}% {msg}")
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ")
}

/// One bar per plan (filled segment by segment and within a segment) and a spinner per stage
/// after the measurement; hidden when [`enabled`] is false.
pub struct Progress {
    multi: MultiProgress,
    plans: Vec<(String, usize)>,
    bar: Option<(usize, ProgressBar)>,
    segment: usize,
    stage: Option<ProgressBar>,
}

/// Units of a bar per segment: the fraction within a segment moves the bar too.
const PER_SEGMENT: u64 = 100;

impl Progress {
    /// A display for these plans (name, number of segments).
    pub fn new(plans: Vec<(String, usize)>) -> Self {
        let target = if enabled() { ProgressDrawTarget::stderr() } else { ProgressDrawTarget::hidden() };
        Progress { multi: MultiProgress::with_draw_target(target), plans, bar: None, segment: 0, stage: None }
    }

    /// Segment `segment` of plan `plan` is about to run.
    pub fn segment(&mut self, plan: usize, segment: usize) {
        if self.bar.as_ref().is_none_or(|(p, _)| *p != plan) {
            if let Some((_, old)) = self.bar.take() {
                old.finish();
            }
            let (name, count) = self.plans.get(plan).cloned().unwrap_or_else(|| (format!("plan {}", plan + 1), 1));
            let bar = self.multi.add(ProgressBar::new(count.max(1) as u64 * PER_SEGMENT));
            bar.set_style(bar_style());
            bar.set_prefix(name);
            self.bar = Some((plan, bar));
        }
        self.segment = segment;
        if let Some((_, bar)) = &self.bar {
            let count = self.plans.get(plan).map_or(1, |p| p.1);
            bar.set_message(format!("segment {}/{count}", (segment + 1).min(count)));
            bar.set_position(segment as u64 * PER_SEGMENT);
        }
    }

    /// The fraction (0..1) of the segment in hand that is done.
    pub fn fraction(&mut self, done: f64) {
        if let Some((_, bar)) = &self.bar {
            let within = (done.clamp(0.0, 1.0) * PER_SEGMENT as f64) as u64;
            bar.set_position(self.segment as u64 * PER_SEGMENT + within.min(PER_SEGMENT - 1));
        }
    }

    /// A stage after the measurement starts (identification, validation): a spinner with its name.
    pub fn stage(&mut self, name: &str) {
        if let Some((_, bar)) = self.bar.take() {
            bar.finish();
        }
        if let Some(old) = self.stage.take() {
            old.finish();
        }
        let spinner = self.multi.add(ProgressBar::new_spinner());
        spinner.set_message(name.to_string());
        spinner.enable_steady_tick(Duration::from_millis(120));
        self.stage = Some(spinner);
    }

    /// Remove every bar from the terminal.
    pub fn finish(&mut self) {
        if let Some((_, bar)) = self.bar.take() {
            bar.finish_and_clear();
        }
        if let Some(s) = self.stage.take() {
            s.finish_and_clear();
        }
        let _ = self.multi.clear();
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.finish();
    }
}
