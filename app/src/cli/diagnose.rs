//! `photorobot diagnose <session> [--add DIR]... [--bench PRESET] [--seed N] [--json]`: the discrepancy
//! workflow on a session written by `photorobot calibrate`. Owns only choosing the bench and
//! printing; the session folder is read and extended by `diagnose_session`, the work is
//! `photorobot_core::diagnose`.
//!
//! The session folder has `session.ron` (the traces it references are diagnosed) and
//! `extrinsics.ron`; a folder of bare `traces/*.csv` without `session.ron` is read whole. The
//! bench is the one the traces name (`# bench: virtual bench <preset>`), or `--bench`;
//! discriminating motions run on a fresh virtual bench of that preset (seed `--seed`, default the
//! preset's + 1). With `--bench none` nothing runs: the report says which motions would tell the
//! absorbed candidates apart, and writes them as a plan file (`discriminating-motions.ron` in the
//! session folder) to record on the bench; `--add DIR` then adds the recorded traces to the session
//! and diagnoses again, which proposes only motions not recorded yet, or says it is settled.

use super::common::{json_text, timed, CliError};
use super::diagnose_session::{self as folder, AddedTraces};
use photorobot_core::bench::{Bench, BenchPreset, VirtualBench};
use photorobot_core::diagnose::fit::StopCheck;
use photorobot_core::diagnose::motions::{BenchRunner, MotionRunner};
use photorobot_core::diagnose::validation::{validate_with_effects, EffectValidationRow};
use photorobot_core::diagnose::{Diagnosis, DiagnosisResult, Step};
use photorobot_core::files::FileError;
use photorobot_core::model::effects::Effect;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::phase::PhaseModel;
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Arguments of `photorobot diagnose`.
#[derive(Debug, clap::Args)]
pub struct DiagnoseArgs {
    /// Session folder written by `photorobot calibrate` (session.ron, traces/, extrinsics.ron).
    pub session: PathBuf,
    /// Add the traces of this folder to the session before diagnosing (repeatable): motions
    /// recorded after it, such as a proposed `discriminating-motions.ron`. Their files are copied
    /// into traces/ and referenced by session.ron; a clock that starts before the session's end
    /// (a recorder started afresh) is moved to continue it.
    #[arg(long, value_name = "DIR")]
    pub add: Vec<PathBuf>,
    /// Bench preset to run discriminating motions on (default: the one the traces name;
    /// `none`: run nothing).
    #[arg(long, value_name = "PRESET")]
    pub bench: Option<String>,
    /// Random seed of that virtual bench (default: the preset's + 1).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Print the result as JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct JsonOut<'a> {
    #[serde(flatten)]
    result: &'a DiagnosisResult,
    steps: &'a [Step],
    skipped_traces: &'a [(String, String)],
    /// The validation motions planned without and with the added effects (empty without a
    /// bench or without added effects).
    validation: &'a [EffectValidationRow],
    /// The plan file of the discriminating motions designed but not run (`--bench none`).
    proposed_plan_file: Option<&'a Path>,
    /// Traces added to the session by `--add`.
    added_traces: &'a [AddedTraces],
    /// What to know before trusting the result (a refused calibration, unreferenced files).
    warnings: &'a [String],
}

pub use folder::PROPOSED_PLAN_FILE;

fn invalid(file: &Path, field: &str, problem: String) -> CliError {
    CliError::File(FileError::Invalid { file: file.to_path_buf(), field: field.into(), problem })
}

/// Run the workflow and print it.
pub fn diagnose(a: &DiagnoseArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let read = timed("read_traces", || folder::read(&a.session, &a.add))?;
    let traces = read.traces;
    if traces.is_empty() {
        return Err(invalid(&a.session.join("session.ron"), "traces", "no complete trace to diagnose".into()));
    }
    let extrinsics = Extrinsics::load(&a.session.join("extrinsics.ron"))?;
    let named = traces[0].meta.bench.trim().trim_start_matches("virtual bench ").to_string();
    let preset = chosen_preset(a, &named)?;
    let base = analysis_model(preset.as_ref(), extrinsics).map_err(|problem| match a.bench {
        Some(_) => CliError::Argument { argument: "--bench", problem },
        None => invalid(&a.session.join("traces"), "# bench", format!("the model of bench `{named}`: {problem}")),
    })?;
    let (mut d, skipped) =
        timed("analyse_traces", || Diagnosis::from_traces(&base, &traces, extrinsics, StopCheck::default()))
            .map_err(|e| invalid(&a.session, "traces", e.to_string()))?;
    if let Some(c) = read.session.as_ref().and_then(|s| s.calibration.as_ref()) {
        d.set_branches(&c.branch_extrinsics());
    }
    // A second pass (traces added since) may start where the first ended.
    if let Some(e) = read.session.as_ref().and_then(|s| s.diagnosis.as_ref()).and_then(|r| r.extrinsics) {
        d.set_earlier(e);
    }
    let mut warnings = read.warnings.clone();
    warnings.extend(d.hint_led.iter().map(|(label, why)| format!("trace `{label}`: {why}")));
    let mut bench = preset.as_ref().map(|p| resumed_bench(p, a.seed, &d)).transpose()?;
    let mut runner = bench.as_mut().map(|b| BenchRunner::new(b, 0.0));
    if !a.json {
        for added in &read.added {
            writeln!(
                out,
                "added {} traces from {} to the session{}",
                added.traces,
                added.from.display(),
                if added.clock_shift_s != 0.0 {
                    format!(" (their clock moved by {:+.1} s to continue the session's)", added.clock_shift_s)
                } else {
                    String::new()
                }
            )?;
        }
        for w in &warnings {
            writeln!(out, "warning: {w}")?;
        }
        writeln!(out, "diagnosis of {} ({} traces, bench {named})", a.session.display(), traces.len())?;
        for (label, why) in &skipped {
            writeln!(out, "trace `{label}` not used: {why}")?;
        }
        match &runner {
            Some(r) => writeln!(out, "discriminating motions run on {}", r.name())?,
            None => writeln!(out, "no bench: discriminating motions are proposed, not run")?,
        }
    }
    timed("diagnose_steps", || run_steps(&mut d, runner.as_mut(), a.json, out))?;
    let result =
        d.result().cloned().ok_or_else(|| CliError::Failed { what: "diagnosis", problem: "no result".into() })?;
    drop(runner);
    let effects = d.state().map(|s| s.library_effects()).unwrap_or_default();
    let validation = timed("validate", || {
        validate_added_effects(bench.as_mut(), &base, &extrinsics, &result, &effects, a.json, out)
    })?;
    save_record(&a.session, read.session, &result, &effects, &validation)?;
    let proposed = save_proposed_plan(&d, &a.session)?;
    if a.json {
        let text = json_text(&JsonOut {
            result: &result,
            steps: &d.steps,
            skipped_traces: &skipped,
            validation: &validation,
            proposed_plan_file: proposed.as_deref(),
            added_traces: &read.added,
            warnings: &warnings,
        })?;
        writeln!(out, "{text}")?;
    } else {
        print_validation(&validation, out)?;
        print_result(&result, out)?;
        match &proposed {
            Some(file) => print_proposed_plan(file, &a.session, out)?,
            None if result.settled => writeln!(
                out,
                "settled: no discriminating motion that these data lack would tell more of a single candidate (each \
                 is named, ruled out at its typical size, equivalent to an extrinsic change, or too small for any \
                 motion){}",
                result.pairs_left_open().map_or(String::new(), |open| format!("\n{open}"))
            )?,
            None => {}
        }
    }
    Ok(())
}

/// The preset of `--bench`, else the one the traces name; `None` for `none` (run nothing).
fn chosen_preset(a: &DiagnoseArgs, named: &str) -> Result<Option<BenchPreset>, CliError> {
    let preset_name = a.bench.clone().unwrap_or(named.to_string());
    Ok(match preset_name.as_str() {
        "none" => None,
        n => Some(BenchPreset::resolve(n).map_err(|e| match a.bench {
            Some(_) => CliError::from(e),
            None => invalid(
                &a.session.join("traces"),
                "# bench",
                format!("the traces name bench `{named}`, which is not a known preset ({e}); give --bench PRESET or --bench none"),
            ),
        })?),
    })
}

/// The software's model: the preset's robot description (nominal), optics and air; without a
/// preset, the embedded reference bench's.
fn analysis_model(preset: Option<&BenchPreset>, extrinsics: Extrinsics) -> Result<PhaseModel, String> {
    let reference = match preset {
        Some(p) => p.clone(),
        None => BenchPreset::resolve("table2-ideal").map_err(|e| e.to_string())?,
    };
    PhaseModel::new(
        reference.robot_description().map_err(|e| e.to_string())?,
        extrinsics,
        reference.optics,
        &reference.ambient,
        reference.laser.wavelength_nm,
    )
}

/// The session's bench, resumed a minute after the session ended: its time (and drift) goes on
/// from the recorded traces', so the observations need no time offset.
fn resumed_bench(preset: &BenchPreset, seed: Option<u64>, d: &Diagnosis) -> Result<VirtualBench, CliError> {
    let mut b = VirtualBench::new(preset, Some(seed.unwrap_or(preset.seed + 1)))?;
    b.set_clock_s(d.end_time_s() + photorobot_core::session::LATER_PAUSE_S);
    Ok(b)
}

/// Step the workflow to its end, printing each step unless the output is JSON.
fn run_steps(
    d: &mut Diagnosis,
    mut runner: Option<&mut BenchRunner<'_>>,
    json: bool,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    // A spinner per workflow step on stderr (the steps have no fraction to show).
    let mut progress = super::progress::Progress::new(Vec::new());
    progress.stage("diagnosis: starting");
    // One call can add several steps (an effect added, then one removed): each is printed.
    let mut shown = d.steps.len();
    loop {
        let more = d
            .step(runner.as_mut().map(|r| &mut **r as &mut dyn MotionRunner))
            .map_err(|e| CliError::Failed { what: "diagnosis", problem: e.to_string() })?
            .is_some();
        if !more {
            break;
        }
        for step in &d.steps[shown..] {
            tracing::info!("diagnosis step: {}\n{}", step.title(), step.summary());
            progress.stage(&format!("diagnosis: after {}", step.title()));
            if !json {
                writeln!(out, "\n## {}\n{}", step.title(), step.summary())?;
            }
        }
        shown = d.steps.len();
    }
    Ok(())
}

/// The extended model in use: the validation motions planned with and without the effects
/// added (named, or tried and kept as partial), on the same bench; empty without a bench or
/// without added effects.
fn validate_added_effects(
    bench: Option<&mut VirtualBench>,
    base: &PhaseModel,
    extrinsics: &Extrinsics,
    result: &DiagnosisResult,
    effects: &[Effect],
    json: bool,
    out: &mut dyn Write,
) -> Result<Vec<EffectValidationRow>, CliError> {
    match bench {
        Some(b) if !effects.is_empty() => {
            if !json {
                writeln!(
                    out,
                    "
## validation with and without the added effects (on {})",
                    b.name()
                )?;
            }
            validate_with_effects(b, base, extrinsics, &result.extrinsics, effects)
                .map_err(|e| CliError::Failed { what: "validation with the named effects", problem: e.to_string() })
        }
        _ => Ok(Vec::new()),
    }
}

/// Write the discriminating motions designed but not run as a new plan file in the session
/// folder (an earlier pass's plan is kept).
fn save_proposed_plan(d: &Diagnosis, session: &Path) -> Result<Option<PathBuf>, CliError> {
    Ok(match d.proposed_plan() {
        Some(plan) => {
            let file = folder::free_plan_file(session);
            photorobot_core::files::save_ron(&file, &plan)?;
            Some(file)
        }
        None => None,
    })
}

/// Where the proposed plan is and what to do with it.
fn print_proposed_plan(file: &Path, session: &Path, out: &mut dyn Write) -> std::io::Result<()> {
    writeln!(
        out,
        "the discriminating motions, as a plan: {}\nrecord it on the bench that recorded these traces \
         (e.g. `photorobot simulate --bench PRESET --plan {} --after {} --out DIR` on a virtual one), then \
         add them and diagnose again: `photorobot diagnose {} --add DIR`",
        file.display(),
        file.display(),
        session.display(),
        session.display()
    )
}

/// Save the diagnosis, with its extended model and validation, into the folder's `session.ron`
/// when there is one (atomically; a folder of bare traces is left as it is).
fn save_record(
    dir: &Path,
    session: Option<photorobot_core::session::Session>,
    result: &DiagnosisResult,
    effects: &[Effect],
    validation: &[EffectValidationRow],
) -> Result<(), CliError> {
    use photorobot_core::session::DiagnosisRecord;
    let Some(mut session) = session else { return Ok(()) };
    session.diagnosis = Some(DiagnosisRecord::with_model(result, effects, validation));
    session.save(dir)?;
    Ok(())
}

fn print_validation(rows: &[EffectValidationRow], out: &mut dyn Write) -> std::io::Result<()> {
    if rows.is_empty() {
        return Ok(());
    }
    let nm = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.1}"));
    writeln!(out, "  {:<52} {:>16} {:>14}", "motion (FP cavity variation, peak to peak)", "without (nm)", "with (nm)")?;
    for r in rows {
        writeln!(out, "  {:<52} {:>16} {:>14}", r.motion, nm(r.without_effect_nm), nm(r.with_effect_nm))?;
        if let Some(n) = &r.note {
            writeln!(out, "    {n}")?;
        }
    }
    Ok(())
}

fn print_result(r: &DiagnosisResult, out: &mut dyn Write) -> std::io::Result<()> {
    writeln!(out, "\nverdict: {}", r.verdict.word())?;
    for e in &r.effects {
        writeln!(
            out,
            "  {} = {:+.4} ± {} {} (F {:.1}{}){}",
            e.name,
            e.estimate,
            e.sigma.map_or("undetermined".into(), |s| format!("{s:.4}")),
            e.unit,
            e.score,
            e.held_out_chi2_gain
                .map_or(String::new(), |g| format!("; traces predicted from the others: χ² {:.1} lower with it", g)),
            if e.ambiguous_with.is_empty() {
                String::new()
            } else {
                format!("; or equivalently {}", e.ambiguous_with.join(", "))
            }
        )?;
    }
    writeln!(
        out,
        "residual rms: {:.2} nm ({:.2}σ) before, {:.2} nm ({:.2}σ) after; held-out motions {:.2}σ → {:.2}σ",
        r.residual_rms_before_nm,
        r.residual_rms_before_sigma,
        r.residual_rms_after_nm,
        r.residual_rms_after_sigma,
        r.held_out_rms_before_sigma,
        r.held_out_rms_after_sigma
    )?;
    if !r.equivalent_to_extrinsics.is_empty() {
        writeln!(
            out,
            "equivalent to an extrinsic change on every available motion: {}",
            r.equivalent_to_extrinsics.join(", ")
        )?;
    }
    if !r.need_motions.is_empty() {
        writeln!(out, "the recorded data cannot tell these from an extrinsic change: {}", r.need_motions.join(", "))?;
        writeln!(out, "motions that would: {}", r.discriminating_motions.join("; "))?;
    }
    if !r.not_detectable.is_empty() {
        writeln!(
            out,
            "not detectable at typical size on the data and motions available ({}): {}",
            r.not_detectable.len(),
            r.not_detectable.join(", ")
        )?;
    }
    if !r.cancelling_pairs.is_empty() {
        let pairs: Vec<String> = r.cancelling_pairs.iter().map(|[a, b]| format!("{a} ↔ {b}")).collect();
        writeln!(
            out,
            "pairs these data cannot tell apart (sizes that cancel would show nothing): {}",
            pairs.join("; ")
        )?;
    }
    if !r.ruled_out_above.is_empty() {
        let bounds: Vec<String> = r.ruled_out_above.iter().map(|b| b.describe()).collect();
        writeln!(out, "not named, each smaller than the data would show (|estimate| + 3σ): {}", bounds.join("; "))?;
    }
    if !r.not_seen.is_empty() {
        writeln!(out, "no observation can see: {}", r.not_seen.join(", "))?;
    }
    let most = r
        .worst_family()
        .map_or(String::new(), |f| format!(", most in the {} ({:.2}σ)", f.family.words(), f.after_sigma));
    for p in &r.partial {
        writeln!(
            out,
            "partly explained by {} = {:+.4} ± {} {} (kept by every check against the other effects; not named: the residual stays at {:.2}σ{most}, above the noise, so the model still lacks something)",
            p.name,
            p.estimate,
            p.sigma.map_or("undetermined".into(), |s| format!("{s:.4}")),
            p.unit,
            r.residual_rms_after_sigma
        )?;
    }
    if let Some(line) = r.family_line() {
        writeln!(out, "{line}")?;
    }
    for g in &r.residual_where {
        writeln!(
            out,
            "  residual by {} `{}`: rms {:.2}σ, mean {:+.2}σ (n = {})",
            g.by, g.key, g.rms_sigma, g.mean_sigma, g.count
        )?;
    }
    Ok(())
}
