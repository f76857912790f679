//! End to end: traces written by the virtual bench identify through `photorobot
//! calibrate --traces` into a session; the session loads and re-identifies to identical results;
//! the same traces renamed and re-mapped into another acquisition system's columns and units
//! identify to the same results; `photorobot report` turns the session into one self-contained
//! HTML file. A short plan keeps the three identifications cheap.

use photorobot_app::cli::{run, Outcome};
use photorobot_core::calibration::{report_from_traces, CalibrationReport, Mode};
use photorobot_core::model::extrinsics::{Extrinsics, PARAMETER_NAMES};
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::session::Session;
use photorobot_core::trace::Trace;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// Run the CLI with `args`; it must finish. Returns what it printed.
fn cli(args: &[&str]) -> String {
    let mut out = Vec::new();
    let argv: Vec<String> = std::iter::once("photorobot").chain(args.iter().copied()).map(String::from).collect();
    let outcome = run(argv, &mut out).unwrap_or_else(|e| panic!("photorobot {}: {e}", args.join(" ")));
    assert_eq!(outcome, Outcome::Done);
    String::from_utf8(out).unwrap()
}

/// `photorobot calibrate` in paper mode on `table2-ideal` into `out`, with `extra` arguments;
/// returns its JSON output.
fn calibrate(extra: &[&str], out: &Path) -> Value {
    let out = out.display().to_string();
    let mut args =
        vec!["calibrate", "--bench", "table2-ideal", "--seed", "7", "--mode", "paper", "--json", "--out", &out];
    args.extend_from_slice(extra);
    serde_json::from_str(&cli(&args)).unwrap()
}

/// The parameter values of a calibration's JSON output.
fn values(doc: &Value) -> Vec<f64> {
    doc["parameters"].as_array().unwrap().iter().map(|p| p["value"].as_f64().unwrap()).collect()
}

/// Write the traces as another acquisition system would: other names, order and units, no
/// metadata (labels only in the file names), and a mapping back.
fn write_foreign(traces: &[Trace], dir: &Path) -> PathBuf {
    std::fs::create_dir_all(dir.join("run")).unwrap();
    for (i, t) in traces.iter().enumerate() {
        let mut csv = String::from("pd_mW,time_ms,Z_nm,Y_nm,X_nm,a_mrad,b_mrad,c_deg,lambda_um,temp_C\n");
        for k in 0..t.len() {
            let q = t.joints_display(k);
            csv.push_str(&format!(
                "{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{:?},21.5\n",
                t.irradiance[k],
                t.t_s[k] * 1e3,
                q[0] * 1e3,
                q[1] * 1e3,
                q[2] * 1e3,
                q[3].to_radians() * 1e3,
                q[4].to_radians() * 1e3,
                q[5],
                t.wavelength_nm[k] * 1e-3,
            ));
        }
        let name = format!("rec {i:03} {}.csv", t.meta.label.replace(['/', ':', '>', '\\'], "_"));
        std::fs::write(dir.join("run").join(name), csv).unwrap();
    }
    let mapping = r#"ColumnMapping(
        format_version: 1,
        columns: {
            "t_s": (source: Column("time_ms"), unit: "ms"),
            "q1_um": (source: Column("Z_nm"), unit: "nm"),
            "q2_um": (source: Column("Y_nm"), unit: "nm"),
            "q3_um": (source: Column("X_nm"), unit: "nm"),
            "q4_deg": (source: Column("a_mrad"), unit: "mrad"),
            "q5_deg": (source: Column("b_mrad"), unit: "mrad"),
            "q6_deg": (source: Column("c_deg"), unit: "deg"),
            "wavelength_nm": (source: Column("lambda_um"), unit: "um"),
            "irradiance": (source: Column("pd_mW"), unit: "mW"),
        },
    )"#;
    let path = dir.join("mapping.ron");
    std::fs::write(&path, mapping).unwrap();
    path
}

/// The virtual bench's traces of the small plan, written to `root/sim` by `photorobot simulate`.
fn simulate_traces(root: &Path) -> (PathBuf, Vec<Trace>) {
    let sim = root.join("sim");
    let plan = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/small-plan.ron");
    cli(&["simulate", "--bench", "table2-ideal", "--seed", "7", "--plan", plan, "--out", &sim.display().to_string()]);
    let sim_traces = photorobot_core::trace::import::read_folder(&sim, None).unwrap();
    assert_eq!(sim_traces.len(), 9);
    (sim, sim_traces)
}

/// A folder holding a session is never overwritten; a folder holding an unfinished
/// measurement is offered for --resume, not overwritten.
fn assert_occupied_folders_are_refused(root: &Path, sim_dir: &str, session_dir: &Path) {
    let mut sink = Vec::new();
    let argv = ["photorobot", "calibrate", "--bench", "table2-ideal", "--traces", sim_dir, "--out"];
    let mut argv: Vec<String> = argv.iter().map(|s| s.to_string()).collect();
    argv.push(session_dir.display().to_string());
    let err = run(argv, &mut sink).unwrap_err().to_string();
    assert!(err.contains("already holds a session (session.ron); choose another folder"), "{err}");

    let unfinished = root.join("unfinished");
    let mut partial = Session::load(session_dir).unwrap();
    partial.calibration = None;
    partial.autosave(&unfinished).unwrap();
    let argv = ["photorobot", "calibrate", "--bench", "table2-ideal", "--mode", "paper", "--out"];
    let mut argv: Vec<String> = argv.iter().map(|s| s.to_string()).collect();
    argv.push(unfinished.display().to_string());
    let err = run(argv, &mut sink).unwrap_err().to_string();
    assert!(
        err.contains("holds an unfinished measurement (session.autosave.ron); add --resume to continue it"),
        "{err}"
    );
}

/// The session file: bench, robot, every trace referenced, the calibration as printed.
/// Returns the calibration.
fn assert_session_holds_the_calibration(
    session: &Session,
    session_dir: &Path,
    measured: &Value,
    trace_count: usize,
) -> CalibrationReport {
    assert_eq!(session.format_version, 1);
    assert_eq!(session.bench.preset.as_deref(), Some("table2-ideal"));
    assert_eq!(session.traces.len(), trace_count);
    assert!(session.traces.iter().all(|r| r.step.is_none() && r.complete));
    let calibration = session.calibration.clone().expect("a calibration in the session");
    // As printed (serde_json reads floats to within an ulp or two, not bit for bit).
    assert_eq!(values(measured).len(), calibration.parameters.len());
    for (p, printed) in calibration.parameters.iter().zip(values(measured)) {
        assert!((p.value - printed).abs() <= 1e-14 * p.value.abs().max(1e-12), "{}: {} vs {printed}", p.name, p.value);
    }
    assert!(session_dir.join("extrinsics.ron").exists() && session_dir.join("report.json").exists());
    calibration
}

/// Round trip: load the traces, re-identify: identical results (bit for bit), the same
/// traces; saving what was loaded writes the same file. Returns the loaded traces.
fn assert_reidentify_is_bit_identical(
    root: &Path,
    session: &Session,
    session_dir: &Path,
    sim_traces: &[Trace],
    calibration: &CalibrationReport,
) -> Vec<Trace> {
    let reidentify_started = std::time::Instant::now();
    let traces = session.load_traces(session_dir).unwrap();
    assert_eq!(traces, sim_traces);
    let preset = session.bench.description.clone().unwrap();
    let nominal = PhaseModel::new(
        session.robot.clone(),
        Extrinsics::nominal_design(),
        preset.optics,
        &preset.ambient,
        preset.laser.wavelength_nm,
    )
    .unwrap();
    let again = report_from_traces(traces.clone(), 0.0, "again".into(), &nominal, Mode::Paper).unwrap();
    eprintln!("re-identify: {:.1} s", reidentify_started.elapsed().as_secs_f64());
    assert_eq!(again.extrinsics, calibration.extrinsics);
    assert_eq!(again.parameters, calibration.parameters);
    assert_eq!(again.identifiability, calibration.identifiability);
    assert_eq!(again.residuals, calibration.residuals);
    let copy = root.join("copy");
    session.save(&copy).unwrap();
    assert_eq!(
        std::fs::read(copy.join("session.ron")).unwrap(),
        std::fs::read(session_dir.join("session.ron")).unwrap()
    );
    traces
}

/// Re-mapped and renamed, as another acquisition system writes them: the same results to
/// rounding (ms → s and nm → µm are not exact in binary), far inside σ; labels from the file
/// names, sweeps recognised from the data.
fn assert_remapped_traces_identify_alike(root: &Path, traces: &[Trace], measured: &Value, session: &Session) {
    let remap_started = std::time::Instant::now();
    let mapping = write_foreign(traces, &root.join("foreign"));
    let foreign_session_dir = root.join("from-foreign");
    let foreign_dir = root.join("foreign/run").display().to_string();
    let mapping = mapping.display().to_string();
    let remapped = calibrate(&["--traces", &foreign_dir, "--mapping", &mapping, "--before"], &foreign_session_dir);
    // With --before the prediction plans each motion with the nominal extrinsics as well.
    for v in remapped["validation"].as_array().unwrap() {
        assert!(v["before_nm"].is_f64() && v["after_nm"].is_f64(), "{v}");
    }
    eprintln!("--traces --mapping: {:.1} s", remap_started.elapsed().as_secs_f64());
    for (k, p) in measured["parameters"].as_array().unwrap().iter().enumerate() {
        let (a, b) = (p["value"].as_f64().unwrap(), remapped["parameters"][k]["value"].as_f64().unwrap());
        let sigma = p["sigma"].as_f64().unwrap_or(1.0);
        assert!((a - b).abs() <= 1e-3 * sigma + 1e-9 * a.abs(), "{}: {a} vs {b} (σ {sigma})", PARAMETER_NAMES[k].0);
        assert_eq!(p["determined"], remapped["parameters"][k]["determined"]);
    }
    let foreign_session = Session::load(&foreign_session_dir).unwrap();
    let labels: Vec<&str> = foreign_session.traces.iter().map(|r| r.label.as_str()).collect();
    assert!(labels[0].starts_with("rec 000 "), "labels from file names: {labels:?}");
    let kinds: Vec<_> = foreign_session.traces.iter().map(|r| r.kind).collect();
    let original: Vec<_> = session.traces.iter().map(|r| r.kind).collect();
    assert_eq!(kinds, original, "sweeps recognised from the data");
}

/// The report: one self-contained HTML file with a row per parameter, the residual and
/// validation plots, and the notes a reader needs.
fn assert_report_is_self_contained(root: &Path, session_dir: &Path, calibration: &CalibrationReport) {
    let html_path = root.join("report.html");
    cli(&["report", &session_dir.display().to_string(), "--out", &html_path.display().to_string()]);
    let html = std::fs::read_to_string(&html_path).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>") && html.trim_end().ends_with("</html>"));
    assert!(!html.contains("http://") && !html.contains("https://"), "no external reference");
    assert!(!html.contains("<script") && !html.contains("<link") && !html.contains("src="), "nothing loaded");
    for p in &calibration.parameters {
        assert!(html.contains(&format!("<tr><td>{}</td>", p.name)), "a row for {}", p.name);
        if !p.determined {
            let row = html.lines().find(|l| l.starts_with(&format!("<tr><td>{}</td>", p.name))).unwrap();
            assert!(row.contains("<td class=\"muted\">not determined</td>"), "{row}");
            assert!(!row.contains(&format!("{:.4}", p.value)), "no bare number for an undetermined parameter: {row}");
        }
    }
    let svgs = html.matches("<svg ").count();
    let curves = calibration
        .validation
        .iter()
        .filter(|v| !(v.before_curve_nm.is_empty() && v.after_curve_nm.is_empty()))
        .count();
    assert!(curves > 0, "validation curves recorded");
    assert_eq!(svgs, 1 + curves, "residual + validation plots");
    assert!(html.matches("<circle ").count() >= calibration.residuals.len() / 2, "residual markers");
    assert!(html.contains("<polyline "), "validation curves");
    assert!(html.contains("PREDICTED, not measured"));
    assert!(html.contains(env!("CARGO_PKG_VERSION")), "software version");
    assert!(html.contains("No diagnosis was run"));
    for w in &calibration.warnings {
        assert!(html.contains(&photorobot_core::report::escape(w)), "warning shown: {w}");
    }
}

#[test]
fn session_round_trip_import_and_report() {
    let root = tempfile::tempdir().unwrap();
    let started = std::time::Instant::now();
    // Traces written by the virtual bench (a short plan: the identification is the cost here).
    let (sim, sim_traces) = simulate_traces(root.path());

    // 3a. `calibrate --traces`: the virtual bench's traces through the identifier, a session written.
    let traces_session_dir = root.path().join("from-traces");
    let sim_dir = sim.display().to_string();
    let measured = calibrate(&["--traces", &sim_dir], &traces_session_dir);
    eprintln!("--traces (identify + predicted validation): {:.1} s", started.elapsed().as_secs_f64());
    assert_eq!(measured["validation_predicted"], true);
    // Predicted as a bench runs it by default: planned with the identified extrinsics only.
    let rows = measured["validation"].as_array().unwrap();
    assert_eq!(rows.len(), 4);
    assert!(rows.iter().all(|v| v["before_nm"].is_null() && v["after_nm"].is_f64()), "{rows:?}");
    assert_eq!(measured["observations"].as_u64().unwrap() as usize, measured["residuals"].as_array().unwrap().len());

    assert_occupied_folders_are_refused(root.path(), &sim_dir, &traces_session_dir);

    // 1. The session file.
    let session = Session::load(&traces_session_dir).unwrap();
    let calibration = assert_session_holds_the_calibration(&session, &traces_session_dir, &measured, sim_traces.len());

    // 6. Round trip.
    let traces =
        assert_reidentify_is_bit_identical(root.path(), &session, &traces_session_dir, &sim_traces, &calibration);

    // 3b. Another acquisition system's columns and units.
    assert_remapped_traces_identify_alike(root.path(), &traces, &measured, &session);

    // 7. The report.
    assert_report_is_self_contained(root.path(), &traces_session_dir, &calibration);
    eprintln!("total: {:.1} s", started.elapsed().as_secs_f64());
}

/// `calibrate --resume` on a folder the workbench autosaved with its first step not measured
/// and its second measured whole: the second is skipped, its traces kept as they are, and the
/// calibration equals the one measured in one run (the virtual bench's noise starts anew with
/// its seed). With the second step begun and the first not: both measured, the second first.
/// With the second step measured in part, the folder is refused, the plan named: it would be
/// measured again from its start and its traces counted twice.
#[test]
fn resume_skips_a_step_the_workbench_measured_and_refuses_one_it_stopped() {
    use photorobot_core::bench::{Bench, BenchPreset, VirtualBench};
    use photorobot_core::session::{Progress, TraceRef};
    let root = tempfile::tempdir().unwrap();
    let full_dir = root.path().join("full");
    // The measurement steps are what is resumed: the validation is not run (paper mode leaves
    // β_wf and θ_wf undetermined, and its validation is refused).
    let full = calibrate(&["--no-validation"], &full_dir);
    let measured = Session::load(&full_dir).unwrap();
    let second: Vec<TraceRef> = measured.traces.iter().filter(|t| t.step.is_some_and(|s| s.0 == 1)).cloned().collect();
    assert!(second.len() >= 2 && second.len() < measured.traces.len());
    let start = VirtualBench::new(&BenchPreset::resolve("table2-ideal").unwrap(), Some(7)).unwrap().position_display();
    let workbench_folder = |name: &str, traces: &[TraceRef]| -> PathBuf {
        let dir = root.path().join(name);
        std::fs::create_dir_all(dir.join("traces")).unwrap();
        for t in traces {
            std::fs::copy(full_dir.join(&t.file), dir.join(&t.file)).unwrap();
        }
        let mut autosaved = measured.clone();
        autosaved.calibration = None;
        autosaved.traces = traces.to_vec();
        autosaved.progress = Some(Progress { plan: 0, next_segment: 0, plan_start_display: start });
        autosaved.autosave(&dir).unwrap();
        dir
    };

    let dir = workbench_folder("second-whole", &second);
    let resumed = calibrate(&["--resume", "--no-validation"], &dir);
    let session = Session::load(&dir).unwrap();
    let kept: Vec<&TraceRef> = session.traces.iter().filter(|t| t.step.is_some_and(|s| s.0 == 1)).collect();
    let files = |refs: &[&TraceRef]| refs.iter().map(|t| t.file.clone()).collect::<Vec<_>>();
    assert_eq!(files(&kept), files(&second.iter().collect::<Vec<_>>()), "the second step, not measured again");
    assert!(kept.iter().zip(&second).all(|(a, b)| *a == b), "its references as they were");
    assert_eq!(session.traces.len(), measured.traces.len(), "the first step measured once");
    // As measured in one run, to rounding (the traces are identified in another order).
    for (p, q) in resumed["parameters"].as_array().unwrap().iter().zip(full["parameters"].as_array().unwrap()) {
        let (a, b) = (p["value"].as_f64().unwrap(), q["value"].as_f64().unwrap());
        let sigma = q["sigma"].as_f64().unwrap_or(1.0);
        assert!((a - b).abs() < 1e-3 * sigma, "{}: {a} resumed, {b} in one run (σ {sigma})", p["name"]);
    }

    // The second step begun (its progress autosaved, no segment done), the first not at all:
    // the second is measured, then the first, each recorded segment once.
    let dir = workbench_folder("first-unmeasured", &[]);
    let mut autosaved = Session::recover(&dir).unwrap();
    autosaved.progress = Some(Progress { plan: 1, next_segment: 0, plan_start_display: start });
    autosaved.autosave(&dir).unwrap();
    let resumed = calibrate(&["--resume", "--no-validation"], &dir);
    let session = Session::load(&dir).unwrap();
    let steps: Vec<(usize, usize)> = session.traces.iter().map(|t| t.step.unwrap()).collect();
    let mut in_plan_order = steps.clone();
    in_plan_order.sort();
    let expected: Vec<(usize, usize)> = measured.traces.iter().map(|t| t.step.unwrap()).collect();
    assert_eq!(in_plan_order, expected, "every recorded segment once");
    assert_eq!(steps[0].0, 1, "the step the progress names first");
    let truth = BenchPreset::resolve("table2-ideal").unwrap().truth.to_array();
    for (p, truth) in resumed["parameters"].as_array().unwrap().iter().zip(truth) {
        if p["determined"] == true {
            let (value, sigma) = (p["value"].as_f64().unwrap(), p["sigma"].as_f64().unwrap());
            assert!((value - truth).abs() < 3.0 * sigma, "{}: {value}, truth {truth}, σ {sigma}", p["name"]);
        }
    }

    let dir = workbench_folder("second-stopped", &second[..second.len() - 1]);
    let argv = ["photorobot", "calibrate", "--bench", "table2-ideal", "--seed", "7", "--mode", "paper", "--resume"];
    let mut argv: Vec<String> = argv.iter().map(|s| s.to_string()).collect();
    argv.extend(["--out".to_string(), dir.display().to_string()]);
    let err = run(argv, &mut Vec::new()).unwrap_err();
    let expected = format!(
        "session.autosave.ron: field `traces`: plan 2 ({}) has whole traces for {} of its {} recorded segments",
        measured.plans[1].name,
        second.len() - 1,
        second.len()
    );
    assert!(err.to_string().contains(&expected), "{err}");
    assert_eq!(err.exit_code(), 3);
    assert_eq!(Session::recover(&dir).unwrap().traces.len(), second.len() - 1, "the autosave as it was");
}
