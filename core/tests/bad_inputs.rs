//! Every class of bad input (truncated file, wrong version, wrong types, NaN or infinite values,
//! non-monotonic time, mismatched column counts, empty trace, a huge file) for every file the
//! program reads (traces, sessions, column mappings, imported traces): a clear error that names
//! the file and the line or field and says what was expected, never a panic.

use photorobot_core::bench::BenchPreset;
use photorobot_core::files::to_ron_string;
use photorobot_core::plan::Plan;
use photorobot_core::session::{BenchInfo, DiagnosisRecord, EffectFinding, Session};
use photorobot_core::trace::import::{import_file, ColumnMapping};
use photorobot_core::trace::{ReadOptions, Trace};
use std::path::{Path, PathBuf};

const HEADER: &str = "t_s,q1_um,q2_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,irradiance";
const FOREIGN: &str = "time_ms,X_nm,Z_nm,lambda_nm,pd_V";

/// Which reader a case goes through.
#[derive(Debug, Clone, Copy)]
enum Reader {
    Trace,
    Session,
    Mapping,
    Import,
}

/// What the file holds.
enum Content {
    Text(String),
    /// A sparse file of this many bytes (nothing written: a reader that read it would take minutes).
    Huge(u64),
}

/// A column mapping for the foreign format `FOREIGN` (shared with the fuzzing of mappings).
fn mapping_text() -> String {
    include_str!("fixtures/foreign-mapping.ron").to_string()
}

/// A valid session with a plan and a diagnosis, as RON text.
fn session_text() -> String {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let info = BenchInfo {
        name: "virtual bench table2-ideal".into(),
        preset: Some("table2-ideal".into()),
        description: None,
        seed: Some(1),
    };
    let mut session = Session::new(info, preset.robot_description().unwrap());
    session.plans = vec![Plan::strategy2()];
    session.diagnosis = Some(DiagnosisRecord {
        effects: vec![EffectFinding {
            name: "q2 (Y) scale".into(),
            estimate: 800.0,
            unit: "ppm".into(),
            sigma: Some(30.0),
            score: 12.0,
            score_kind: "ΔBIC".into(),
            absorbed_fraction: None,
            note: String::new(),
        }],
        verdict: "q2 scale".into(),
        ..Default::default()
    });
    to_ron_string(&session, Path::new("session.ron")).unwrap()
}

fn read(reader: Reader, path: &Path) -> Result<(), String> {
    let mapping = ColumnMapping::from_ron_str(&mapping_text(), Path::new("mapping.ron")).unwrap();
    match reader {
        Reader::Trace => Trace::read_csv(path).map(drop).map_err(|e| e.to_string()),
        Reader::Session => Session::load(path).map(drop).map_err(|e| e.to_string()),
        Reader::Mapping => ColumnMapping::load(path).map(drop).map_err(|e| e.to_string()),
        Reader::Import => import_file(path, &mapping, &ReadOptions::default()).map(drop).map_err(|e| e.to_string()),
    }
}

/// One bad input: its name, the reader it goes through, the file's content and the pieces the
/// error message must contain.
type BadCase = (&'static str, Reader, Content, Vec<String>);

/// The valid file of each reader that the bad cases are made from.
struct ValidInputs {
    ok_trace: String,
    ok_foreign: String,
    session: String,
    mapping: String,
}

fn valid_inputs() -> ValidInputs {
    ValidInputs {
        ok_trace: format!("# photorobot trace v1\n{HEADER}\n0,0,0,0,0,0,0,1560,0.5\n0.1,0,0,0,0,0,0,1560,0.5\n"),
        ok_foreign: format!("{FOREIGN}\n0,1000,0,1560,0.5\n10,1100,0,1560,0.4\n"),
        session: session_text(),
        mapping: mapping_text(),
    }
}

/// Line of a field in the valid session text (1-based), for the type errors.
fn line_of(session: &str, needle: &str) -> usize {
    session.lines().position(|l| l.contains(needle)).unwrap() + 1
}

/// Write every case to its own folder and read it: each must fail, without panicking and
/// quickly (a huge file is refused unread), with a message that starts with the file and
/// contains every wanted piece.
fn assert_each_case_fails_clearly(cases: Vec<BadCase>) {
    let dir = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    for (k, (name, reader, content, wants)) in cases.into_iter().enumerate() {
        let file = match reader {
            Reader::Session => "session.ron".to_string(),
            Reader::Mapping => "mapping.ron".to_string(),
            _ => format!("case{k}.csv"),
        };
        let case_dir = dir.path().join(format!("case{k}"));
        std::fs::create_dir(&case_dir).unwrap();
        let path: PathBuf = case_dir.join(&file);
        match content {
            Content::Text(t) => std::fs::write(&path, t).unwrap(),
            Content::Huge(n) => std::fs::File::create(&path).unwrap().set_len(n).unwrap(),
        }
        let start = std::time::Instant::now();
        let result = std::panic::catch_unwind(|| read(reader, &path));
        let err = match result {
            Err(_) => panic!("{name}: the reader panicked"),
            Ok(Ok(())) => panic!("{name}: accepted"),
            Ok(Err(e)) => e,
        };
        assert!(
            err.starts_with(&path.display().to_string()),
            "{name}: the message does not start with the file: {err}"
        );
        for want in &wants {
            if !err.contains(want.as_str()) {
                failures.push(format!("{name}: got `{err}`, want `{want}`"));
            }
        }
        assert!(
            start.elapsed().as_secs_f64() < 2.0,
            "{name}: took {:?} (a huge file must be refused unread)",
            start.elapsed()
        );
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Truncated files: a trace cut in its metadata or in a row, a session, a mapping, an import.
fn truncated_files_cases(inputs: &ValidInputs) -> Vec<BadCase> {
    let ok_trace = &inputs.ok_trace;
    let ok_foreign = &inputs.ok_foreign;
    let session = &inputs.session;
    let mapping = &inputs.mapping;
    vec![
        (
            "truncated trace: metadata only",
            Reader::Trace,
            Content::Text("# photorobot trace v1\n# label: x\n".into()),
            vec!["truncated file: no header row".into(), "expected a header line `t_s,q1_um".into()],
        ),
        (
            "truncated trace: cut in a row",
            Reader::Trace,
            Content::Text(ok_trace[..ok_trace.len() - 12].to_string()),
            vec![":4: expected 9 fields (one per header column), found 6 (truncated row?)".into()],
        ),
        (
            "truncated session",
            Reader::Session,
            Content::Text(session[..session.len() / 2].to_string()),
            vec!["expected a Session(format_version: 1".into()],
        ),
        (
            "truncated mapping",
            Reader::Mapping,
            Content::Text(mapping[..mapping.len() / 2].to_string()),
            vec!["expected a ColumnMapping(format_version: 1".into()],
        ),
        (
            "truncated import",
            Reader::Import,
            Content::Text(ok_foreign[..ok_foreign.len() - 6].to_string()),
            vec![":3: expected 5 fields (one per header column), found 4 (truncated row?)".into()],
        ),
    ]
}

/// Format versions this program does not read, or none.
fn wrong_versions_cases(inputs: &ValidInputs) -> Vec<BadCase> {
    let ok_trace = &inputs.ok_trace;
    let session = &inputs.session;
    let mapping = &inputs.mapping;
    vec![
        (
            "newer trace format",
            Reader::Trace,
            Content::Text(ok_trace.replace("trace v1", "trace v2")),
            vec![":1: unsupported format `# photorobot trace v2` (expected `# photorobot trace v1`)".into()],
        ),
        (
            "newer session format",
            Reader::Session,
            Content::Text(session.replace("format_version: 1", "format_version: 2")),
            vec![
                "field `format_version`: found 2, but this program".into(),
                "reads session formats up to 1".into(),
                "open it with that version or newer".into(),
            ],
        ),
        (
            "older session format",
            Reader::Session,
            Content::Text(session.replace("format_version: 1", "format_version: 0")),
            vec!["field `format_version`: found 0, which is older".into(), "photorobot calibrate --traces".into()],
        ),
        (
            "session without a version",
            Reader::Session,
            Content::Text(session.replace("format_version: 1,", "")),
            vec!["field `format_version`: missing; expected `format_version: 1`".into()],
        ),
        (
            "newer mapping format",
            Reader::Mapping,
            Content::Text(mapping.replace("format_version: 1", "format_version: 3")),
            vec!["field `format_version`: expected 1".into(), "found 3".into()],
        ),
    ]
}

/// Values of the wrong type, unknown units, columns and sources.
fn wrong_types_cases(inputs: &ValidInputs) -> Vec<BadCase> {
    let ok_trace = &inputs.ok_trace;
    let session = &inputs.session;
    let mapping = &inputs.mapping;
    let line_of = |needle: &str| line_of(session, needle);
    vec![
        ("text in a trace number", Reader::Trace, Content::Text(ok_trace.replace("0.1,0,0,0", "0.1,0,0,abc")),
            vec![":4: column `q3_um`: expected a number, found `abc`".into()]),
        ("text as the session version", Reader::Session, Content::Text(session.replace("format_version: 1", "format_version: \"one\"")),
            vec![format!("session.ron:{}:", line_of("format_version")), "expected a Session(".into()]),
        ("text as a plan rate", Reader::Session, Content::Text(session.replacen("rate_nm_per_s: ", "rate_nm_per_s: \"fast\" + ", 1)),
            vec![format!("session.ron:{}:", line_of("rate_nm_per_s")), "expected a Session(".into()]),
        ("text as a mapping scale", Reader::Mapping, Content::Text(mapping.replace("unit: \"ms\")", "unit: \"ms\", scale: \"x\")")),
            vec!["mapping.ron:4:62: Expected float".into(), "expected a ColumnMapping(".into()]),
        ("unknown unit in a mapping", Reader::Mapping, Content::Text(mapping.replace("unit: \"nm\"),\n        \"q2_um\"", "unit: \"furlong\"),\n        \"q2_um\"")),
            vec!["field `columns.\"q1_um\".unit`: unknown unit `furlong` for q1_um (expected one of: m, mm, um (µm), nm, pm)".into()]),
        ("unknown column in a mapping", Reader::Mapping, Content::Text(mapping.replace("\"irradiance\": (", "\"power\": (")),
            vec!["field `columns.\"power\"`: not one of our columns (expected one of t_s, q1_um".into()]),
        ("time constant in a mapping", Reader::Mapping, Content::Text(mapping.replace("Column(\"time_ms\")", "Constant(0.0)")),
            vec!["field `columns.\"t_s\".source`: expected Column(\"<time column>\"): time must be recorded".into()]),
    ]
}

/// NaN and infinite values, in the files or after the mapping's scaling.
fn non_finite_values_cases(inputs: &ValidInputs) -> Vec<BadCase> {
    let ok_trace = &inputs.ok_trace;
    let ok_foreign = &inputs.ok_foreign;
    let session = &inputs.session;
    let mapping = &inputs.mapping;
    vec![
        (
            "NaN in a trace",
            Reader::Trace,
            Content::Text(ok_trace.replace("0.1,0,0,0,0,0", "0.1,0,0,0,0,NaN")),
            vec![":4: column `q5_deg`: expected a finite number, found NaN".into()],
        ),
        (
            "infinity in a trace",
            Reader::Trace,
            Content::Text(ok_trace.replace("1560,0.5\n0.1", "inf,0.5\n0.1")),
            vec![":3: column `wavelength_nm`: expected a finite number, found inf".into()],
        ),
        (
            "NaN in a session",
            Reader::Session,
            Content::Text(session.replace("estimate: 800.0", "estimate: NaN")),
            vec!["field `diagnosis.effects[0].estimate`: expected a finite number".into()],
        ),
        (
            "NaN as a mapping scale",
            Reader::Mapping,
            Content::Text(mapping.replace("unit: \"ms\")", "unit: \"ms\", scale: NaN)")),
            vec!["field `columns.\"t_s\".scale`: expected a finite, non-zero factor, found NaN".into()],
        ),
        (
            "infinity in an import",
            Reader::Import,
            Content::Text(ok_foreign.replace("10,1100", "10,-inf")),
            vec![":3: column `X_nm`: expected a finite number, found -inf".into()],
        ),
        (
            "overflow after the mapping",
            Reader::Import,
            Content::Text(ok_foreign.replace("1560,0.4", "1560,1e308")),
            vec!["column `irradiance`, data row 2: inf after the mapping's unit conversion and scale".into()],
        ),
    ]
}

/// Time that goes back, in our format and in an import.
fn non_monotonic_time_cases(inputs: &ValidInputs) -> Vec<BadCase> {
    let ok_trace = &inputs.ok_trace;
    let ok_foreign = &inputs.ok_foreign;
    vec![
        (
            "time goes back in a trace",
            Reader::Trace,
            Content::Text(format!("{ok_trace}0.05,0,0,0,0,0,0,1560,0.5\n")),
            vec![
                ":5: column `t_s`: time 0.05 s is not after 0.1 s on line 4 (expected strictly increasing time)".into()
            ],
        ),
        (
            "time goes back in an import",
            Reader::Import,
            Content::Text(format!("{ok_foreign}5,0,0,1560,0.5\n")),
            vec![":4: column `time_ms`: time 5 is not after 10 on line 3 (expected strictly increasing time)".into()],
        ),
    ]
}

/// Rows and headers whose columns do not match.
fn mismatched_columns_cases(inputs: &ValidInputs) -> Vec<BadCase> {
    let ok_trace = &inputs.ok_trace;
    let ok_foreign = &inputs.ok_foreign;
    vec![
        (
            "extra field in a trace row",
            Reader::Trace,
            Content::Text(format!("{ok_trace}0.2,0,0,0,0,0,0,1560,0.5,9\n")),
            vec![":5: expected 9 fields (one per header column), found 10".into()],
        ),
        (
            "missing required column",
            Reader::Trace,
            Content::Text(ok_trace.replace("q2_um,", "")),
            vec![":2: missing required column(s) `q2_um`".into()],
        ),
        (
            "mapped column absent",
            Reader::Import,
            Content::Text(ok_foreign.replace("X_nm", "Y_nm")),
            vec![":1: no column `X_nm` in the header (the column mapping reads it for `q3_um`)".into()],
        ),
        (
            "short import row",
            Reader::Import,
            Content::Text(format!("{ok_foreign}20,1\n")),
            vec![":4: expected 5 fields (one per header column), found 2".into()],
        ),
    ]
}

/// Empty files and headers without rows.
fn empty_files_cases() -> Vec<BadCase> {
    vec![
        (
            "header without rows",
            Reader::Trace,
            Content::Text(format!("{HEADER}\n")),
            vec!["empty trace: the header is followed by no data rows (expected at least one row)".into()],
        ),
        ("empty trace file", Reader::Trace, Content::Text(String::new()), vec!["truncated file: no header row".into()]),
        ("import without rows", Reader::Import, Content::Text(format!("{FOREIGN}\n")), vec!["empty trace".into()]),
        (
            "empty session file",
            Reader::Session,
            Content::Text(String::new()),
            vec!["session.ron:1:".into(), "expected a Session(".into()],
        ),
    ]
}

/// Files above their size limit, refused from their size alone.
fn huge_files_cases() -> Vec<BadCase> {
    vec![
        (
            "huge trace",
            Reader::Trace,
            Content::Huge(3 << 30),
            vec!["3221225472 bytes, above the limit of 2147483648 bytes for a trace file; refusing to read it".into()],
        ),
        (
            "huge import",
            Reader::Import,
            Content::Huge(3 << 30),
            vec!["above the limit of 2147483648 bytes for a trace file".into()],
        ),
        (
            "huge session",
            Reader::Session,
            Content::Huge(40 << 20),
            vec!["41943040 bytes, above the limit of 33554432 bytes for a session file; refusing to read it".into()],
        ),
        (
            "huge mapping",
            Reader::Mapping,
            Content::Huge(2 << 20),
            vec!["above the limit of 1048576 bytes for a column mapping".into()],
        ),
    ]
}

#[test]
fn truncated_files_say_what_is_missing_and_where() {
    assert_each_case_fails_clearly(truncated_files_cases(&valid_inputs()));
}

#[test]
fn wrong_versions_are_refused_with_advice() {
    assert_each_case_fails_clearly(wrong_versions_cases(&valid_inputs()));
}

#[test]
fn wrong_types_name_the_line_or_field() {
    assert_each_case_fails_clearly(wrong_types_cases(&valid_inputs()));
}

#[test]
fn nan_and_infinite_values_name_the_column_or_field() {
    assert_each_case_fails_clearly(non_finite_values_cases(&valid_inputs()));
}

#[test]
fn non_monotonic_time_names_both_lines() {
    assert_each_case_fails_clearly(non_monotonic_time_cases(&valid_inputs()));
}

#[test]
fn mismatched_column_counts_name_the_line() {
    assert_each_case_fails_clearly(mismatched_columns_cases(&valid_inputs()));
}

#[test]
fn empty_traces_and_files_are_refused() {
    assert_each_case_fails_clearly(empty_files_cases());
}

#[test]
fn huge_files_are_refused_unread() {
    assert_each_case_fails_clearly(huge_files_cases());
}

/// The valid files behind the cases are accepted.
#[test]
fn the_valid_files_behind_the_cases_are_accepted() {
    let inputs = valid_inputs();
    let dir = tempfile::tempdir().unwrap();
    let valid = dir.path().join("valid");
    std::fs::create_dir(&valid).unwrap();
    for (reader, file, text) in [
        (Reader::Trace, "t.csv", &inputs.ok_trace),
        (Reader::Session, "session.ron", &inputs.session),
        (Reader::Mapping, "mapping.ron", &inputs.mapping),
        (Reader::Import, "i.csv", &inputs.ok_foreign),
    ] {
        std::fs::write(valid.join(file), text).unwrap();
        read(reader, &valid.join(file)).unwrap_or_else(|e| panic!("{file}: {e}"));
    }
}
