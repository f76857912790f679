//! `photorobot diagnose <session> [--bench PRESET] [--seed N] [--json]`: the discrepancy workflow on a
//! session written by `photorobot calibrate`. Owns only reading the session folder, choosing the bench and
//! printing; the work is `photorobot_core::diagnose`.
//!
//! The session folder has `traces/*.csv` and `extrinsics.ron`. The bench is the one the traces
//! name (`# bench: virtual bench <preset>`), or `--bench`; discriminating motions run on a fresh
//! virtual bench of that preset (seed `--seed`, default the preset's + 1). With `--bench none`
//! nothing runs: the report says which motions would tell the absorbed candidates apart, and
//! writes them as a plan file (`discriminating-motions.ron` in the session folder) to record on
//! the bench and add to the session's traces.

use super::common::{json_text, timed, CliError};
use photorobot_core::bench::{Bench, BenchPreset, VirtualBench};
use photorobot_core::diagnose::fit::StopCheck;
use photorobot_core::diagnose::motions::{BenchRunner, MotionRunner};
use photorobot_core::diagnose::validation::{validate_with_effects, EffectValidationRow};
use photorobot_core::diagnose::{Diagnosis, DiagnosisResult, Step};
use photorobot_core::files::FileError;
use photorobot_core::model::effects::Effect;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::trace::Trace;
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Arguments of `photorobot diagnose`.
#[derive(Debug, clap::Args)]
pub struct DiagnoseArgs {
    /// Session folder written by `photorobot calibrate` (traces/*.csv, extrinsics.ron).
    pub session: PathBuf,
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
}

/// Where `--bench none` writes the discriminating motions it proposes, in the session folder.
pub const PROPOSED_PLAN_FILE: &str = "discriminating-motions.ron";

fn invalid(file: &Path, field: &str, problem: String) -> CliError {
    CliError::File(FileError::Invalid { file: file.to_path_buf(), field: field.into(), problem })
}

/// Read the session's traces, in file-name order, on every core.
fn read_traces(session: &Path) -> Result<Vec<Trace>, CliError> {
    let dir = session.join("traces");
    if !dir.is_dir() {
        let problem = "not a folder: expected a session written by `photorobot calibrate --out`";
        return Err(invalid(&dir, "traces", problem.into()));
    }
    Ok(photorobot_core::trace::import::read_folder(&dir, None)?)
}

/// Run the workflow and print it.
pub fn diagnose(a: &DiagnoseArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let traces = timed("read_traces", || read_traces(&a.session))?;
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
    let mut bench = preset.as_ref().map(|p| resumed_bench(p, a.seed, &d)).transpose()?;
    let mut runner = bench.as_mut().map(|b| BenchRunner::new(b, 0.0));
    if !a.json {
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
    save_record(&a.session, &result, &effects, &validation)?;
    let proposed = save_proposed_plan(&d, &a.session)?;
    if a.json {
        let text = json_text(&JsonOut {
            result: &result,
            steps: &d.steps,
            skipped_traces: &skipped,
            validation: &validation,
            proposed_plan_file: proposed.as_deref(),
        })?;
        writeln!(out, "{text}")?;
    } else {
        print_validation(&validation, out)?;
        print_result(&result, out)?;
        if let Some(file) = &proposed {
            print_proposed_plan(file, &a.session, out)?;
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
    b.set_clock_s(d.end_time_s() + 60.0);
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
    loop {
        let step = d
            .step(runner.as_mut().map(|r| &mut **r as &mut dyn MotionRunner))
            .map_err(|e| CliError::Failed { what: "diagnosis", problem: e.to_string() })?;
        let Some(step) = step else { break };
        tracing::info!("diagnosis step: {}", step.title());
        progress.stage(&format!("diagnosis: after {}", step.title()));
        if !json {
            writeln!(out, "\n## {}\n{}", step.title(), step.summary())?;
        }
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

/// Write the discriminating motions designed but not run as a plan file in the session folder.
fn save_proposed_plan(d: &Diagnosis, session: &Path) -> Result<Option<PathBuf>, CliError> {
    Ok(match d.proposed_plan() {
        Some(plan) => {
            let file = session.join(PROPOSED_PLAN_FILE);
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
         (e.g. `photorobot simulate --bench PRESET --plan {} --out DIR` on a virtual one), put the traces \
         in {}, and diagnose again",
        file.display(),
        file.display(),
        session.join("traces").display()
    )
}

/// Save the diagnosis, with its extended model and validation, into the folder's `session.ron`
/// when there is one (atomically; a folder of bare traces is left as it is).
fn save_record(
    dir: &Path,
    result: &DiagnosisResult,
    effects: &[Effect],
    validation: &[EffectValidationRow],
) -> Result<(), CliError> {
    use photorobot_core::session::{session_path, DiagnosisRecord, Session};
    if !session_path(dir).exists() {
        return Ok(());
    }
    let mut session = Session::load(dir)?;
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
            "  {} = {:+.4} ± {} {} (F {:.1}){}",
            e.name,
            e.estimate,
            e.sigma.map_or("undetermined".into(), |s| format!("{s:.4}")),
            e.unit,
            e.score,
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
    if !r.not_seen.is_empty() {
        writeln!(out, "no observation can see: {}", r.not_seen.join(", "))?;
    }
    for p in &r.partial {
        writeln!(
            out,
            "partly explained by {} = {:+.4} {} (not named: the residual stays above the noise)",
            p.name, p.estimate, p.unit
        )?;
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
