//! `photorobot simulate --bench PRESET --plan PLAN --out DIR|FILE [--seed N] [--after SESSION]`: run a
//! motion plan on a virtual bench and write the recorded traces as CSV. Owns only argument parsing and
//! printing; the work is `photorobot_core::bench::run_plan`.
//!
//! Files are numbered after the highest number the folder's files start with, so that they sort
//! after any already there. With `--after SESSION` the bench's clock (and its drift) starts a
//! minute after the session's last trace ends, as a bench that goes on recording does.

use super::common::{load_plan, CliError};
use super::progress::{Progress, INTERRUPT};
use photorobot_core::bench::{run_plan_with, Bench, RunControl, VirtualBench};
use photorobot_core::files::FileError;
use photorobot_core::trace::Trace;
use std::cell::RefCell;
use std::io::Write;
use std::path::PathBuf;

/// Arguments of `photorobot simulate`.
#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    /// Bench preset: an embedded name (table2-ideal, femto-lab) or a preset file (RON).
    #[arg(long, value_name = "PRESET")]
    pub bench: String,
    /// Motion plan file (RON), or an embedded plan: strategy1, strategy2.
    #[arg(long, value_name = "PLAN")]
    pub plan: String,
    /// Output: a directory (one CSV per recorded segment) or, for a plan that records one trace, a .csv file.
    #[arg(long, value_name = "DIR|FILE")]
    pub out: PathBuf,
    /// Random seed (default: the preset's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// A session folder this recording continues: the bench's clock starts a minute after its
    /// last trace ends (default: at 0).
    #[arg(long, value_name = "SESSION")]
    pub after: Option<PathBuf>,
}

/// The bench time at which the traces of a session folder end (s): those its `session.ron`
/// references, or every trace of its `traces/`.
fn session_end_s(dir: &std::path::Path) -> Result<f64, CliError> {
    use photorobot_core::session::{session_path, Session, TRACES_DIR};
    let traces = if session_path(dir).exists() {
        Session::load(dir)?.load_traces(dir)?
    } else {
        photorobot_core::trace::import::read_folder(&dir.join(TRACES_DIR), None)?
    };
    Ok(traces.iter().filter_map(|t| t.t_s.last().copied()).fold(0.0, f64::max))
}

/// The first file number after those the `.csv` files of `dir` start with (`002-…`, `017.csv`):
/// 1 in an empty or new folder.
fn next_file_number(dir: &std::path::Path) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else { return 1 };
    entries
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let digits: String = name.chars().take_while(|c| c.is_ascii_digit()).collect();
            (name.to_ascii_lowercase().ends_with(".csv") && !digits.is_empty()).then(|| digits.parse::<usize>().ok())?
        })
        .max()
        .map_or(1, |n| n + 1)
}

/// A file-system-safe name for a trace file.
fn slug(label: &str) -> String {
    let s: String =
        label.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '.' { c } else { '_' }).collect();
    let s = s.trim_matches('_').to_string();
    if s.is_empty() {
        "trace".into()
    } else {
        s.chars().take(60).collect()
    }
}

/// Run the plan and write its traces, even those of a run that stopped early.
pub fn simulate(a: &SimulateArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let mut bench = VirtualBench::from_preset_name(&a.bench, a.seed)?;
    if let Some(session) = &a.after {
        bench.set_clock_s(session_end_s(session)? + photorobot_core::session::LATER_PAUSE_S);
    }
    let plan = load_plan(&a.plan)?;
    // One bar for the plan; Ctrl-C stops it at the segment and the traces so far are written.
    let progress = RefCell::new(Progress::new(vec![(plan.name.clone(), plan.segments.len())]));
    progress.borrow_mut().segment(0, 0);
    let mut on_progress = |done: f64| progress.borrow_mut().fraction(done);
    let mut control = RunControl { cancel: &INTERRUPT, on_samples: &mut |_, _| {}, on_progress: &mut on_progress };
    let run = run_plan_with(&mut bench, &plan, &mut control, &mut |step| {
        progress.borrow_mut().segment(0, step.segment + 1);
        Ok(())
    });
    progress.borrow_mut().finish();
    let single_file = a.out.extension().is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    if single_file && run.traces.len() > 1 {
        return Err(CliError::Argument {
            argument: "--out",
            problem: format!(
                "the plan recorded {} traces: give a directory, not the file {}",
                run.traces.len(),
                a.out.display()
            ),
        });
    }
    // Whatever happened, the traces recorded so far are written first.
    let mut written = Vec::new();
    if single_file {
        if let Some(t) = run.traces.first() {
            t.write_csv(&a.out)?;
            written.push(a.out.clone());
        }
    } else {
        std::fs::create_dir_all(&a.out).map_err(|source| FileError::Io {
            file: a.out.clone(),
            action: "cannot create directory",
            source,
        })?;
        let first = next_file_number(&a.out);
        for (i, t) in run.traces.iter().enumerate() {
            let path = a.out.join(format!("{:03}-{}.csv", first + i, slug(&t.meta.label)));
            t.write_csv(&path)?;
            written.push(path);
        }
    }
    let samples: usize = run.traces.iter().map(Trace::len).sum();
    writeln!(
        out,
        "{}: plan {} ran {:.1} s of bench time; {} traces, {} samples written to {}",
        bench.name(),
        plan.name,
        run.duration_s,
        written.len(),
        samples,
        a.out.display()
    )?;
    run.outcome?;
    Ok(())
}
