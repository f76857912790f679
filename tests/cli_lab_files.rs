//! Folders of CSV traces as other labs' recorders write them, through the path users run:
//! `photorobot calibrate --bench table2-ideal --traces DIR --json`. The same recording written in
//! every style (`lab_files.rs`) calibrates to the same report as in our own format; the styles that
//! cannot be read without guessing are refused with the file, the line and the column.

use photorobot_app::cli::run;
use photorobot_e2e::independent::{lab_records, FileStyle, Record, Recorder};
use serde_json::Value;
use std::path::Path;
use std::sync::OnceLock;

/// A short recording: the independent simulator's lab motions without its rotations at ±3° of
/// the other goniometer (three sweeps, seven translations, rotations of each goniometer, one off
/// centre, and the rotary stage): about five seconds of identification each.
fn records() -> Vec<Record> {
    lab_records()
        .into_iter()
        .filter(|r| !matches!(r, Record::Motion { label, .. } if label.ends_with(" 3") || label.ends_with("-3")))
        .collect()
}

/// Our own format's report of the recording, computed once for every test.
fn ours() -> &'static str {
    static OURS: OnceLock<String> = OnceLock::new();
    OURS.get_or_init(|| {
        let (ok, text) = calibrate(recorded(FileStyle::Ours).path(), &[]);
        assert!(ok, "our format: {text}");
        text
    })
}

/// `calibrate --traces DIR` with `extra` arguments: whether it succeeded and what it printed,
/// then the error.
fn calibrate(traces: &Path, extra: &[&str]) -> (bool, String) {
    let session = tempfile::tempdir().expect("a temporary folder");
    let out = session.path().join("s");
    let mut args = vec!["photorobot", "calibrate", "--bench", "table2-ideal", "--traces", traces.to_str().unwrap()];
    args.extend(["--out", out.to_str().unwrap(), "--json"]);
    args.extend(extra);
    let mut printed = Vec::new();
    let result = run(args, &mut printed);
    let mut text = String::from_utf8_lossy(&printed).into_owned();
    if let Err(e) = &result {
        text += &format!("\nerror: {e}");
    }
    (result.is_ok(), text)
}

/// The recording written in `style` into a new folder.
fn recorded(style: FileStyle) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let mut recorder = Recorder::new(31);
    recorder.style = style;
    recorder.write_folder(&records(), dir.path()).expect("the traces written");
    dir
}

/// The report's extrinsics and each parameter's value and σ.
fn figures(text: &str) -> Vec<(String, f64, f64)> {
    let doc: Value = serde_json::from_str(text).unwrap_or_else(|e| panic!("{e}: {text}"));
    assert_eq!(doc["fit"]["verdict"], "fits", "{}", doc["fit"]["summary"]);
    doc["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (p["name"].as_str().unwrap().to_string(), p["value"].as_f64().unwrap(), p["sigma"].as_f64().unwrap_or(0.0))
        })
        .collect()
}

/// One style against our own format: it calibrates, to the same values and σ.
fn same_as_ours(style: FileStyle) {
    let (ok, theirs) = calibrate(recorded(style).path(), &[]);
    assert!(ok, "{}: {theirs}", style.name());
    for ((name, a, sa), (_, b, sb)) in figures(ours()).into_iter().zip(figures(&theirs)) {
        assert!((a - b).abs() <= 1e-9 * a.abs().max(1.0), "{}: {name} {a} vs {b}", style.name());
        assert!((sa - sb).abs() <= 1e-6 * sa.max(1e-12), "{}: σ of {name} {sa} vs {sb}", style.name());
    }
}

#[test]
fn files_without_comment_lines_calibrate_each_labelled_by_its_name() {
    let dir = recorded(FileStyle::Plain);
    let session = tempfile::tempdir().unwrap();
    let out = session.path().join("s");
    let args = ["photorobot", "calibrate", "--bench", "table2-ideal", "--traces", dir.path().to_str().unwrap()];
    let mut printed = Vec::new();
    run(args.into_iter().chain(["--out", out.to_str().unwrap()]), &mut printed).expect("calibrated");
    let text = std::fs::read_to_string(out.join("session.ron")).unwrap();
    for k in 0..records().len() {
        assert!(text.contains(&format!("label: \"{k:03}\"")), "trace {k} labelled by its file: {text}");
    }
    same_as_ours(FileStyle::Plain);
}

#[test]
fn crlf_line_ends_calibrate_the_same() {
    same_as_ours(FileStyle::Crlf);
}

#[test]
fn semicolons_and_a_decimal_comma_calibrate_the_same() {
    same_as_ours(FileStyle::SemicolonDecimalComma);
}

#[test]
fn columns_in_another_order_with_extra_ones_calibrate_the_same() {
    same_as_ours(FileStyle::Reordered);
}

#[test]
fn time_in_milliseconds_calibrates_the_same() {
    same_as_ours(FileStyle::Milliseconds);
}

#[test]
fn a_wavelength_given_once_calibrates_the_same() {
    same_as_ours(FileStyle::WavelengthOnce);
    // Without the line, the folder's wavelength on the command line.
    let dir = recorded(FileStyle::WavelengthOnce);
    for f in std::fs::read_dir(dir.path()).unwrap() {
        let path = f.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::write(&path, text.replace("# wavelength_nm: 1560.000000\n", "")).unwrap();
    }
    let (ok, text) = calibrate(dir.path(), &[]);
    assert!(!ok && text.contains("001.csv:1: no `wavelength_nm` column"), "{text}");
    let (ok, text) = calibrate(dir.path(), &["--wavelength-nm", "1560"]);
    assert!(ok, "{text}");
}

#[test]
fn upper_case_names_after_a_byte_order_mark_calibrate_the_same() {
    same_as_ours(FileStyle::UpperCaseBom);
}

#[test]
fn what_cannot_be_read_without_guessing_is_refused_with_file_line_and_column() {
    let dir = recorded(FileStyle::Plain);
    let file = dir.path().join("001.csv");
    let text = std::fs::read_to_string(&file).unwrap();
    // A decimal comma with commas between the fields.
    let comma = text.lines().take(2).collect::<Vec<_>>().join("\n").replace('.', ",") + "\n";
    std::fs::write(&file, comma).unwrap();
    let (ok, out) = calibrate(dir.path(), &[]);
    assert!(!ok && out.contains("001.csv:2: expected 9 fields") && out.contains("decimal comma"), "{out}");
    // Time without a unit.
    std::fs::write(&file, text.replacen("t_s", "time", 1)).unwrap();
    let (ok, out) = calibrate(dir.path(), &[]);
    assert!(!ok && out.contains("001.csv:1: header column 1: `time`: no unit in the name"), "{out}");
    // Two decimal marks in one file.
    let semi = text.replace(',', ";");
    let mut lines: Vec<String> = semi.lines().map(str::to_string).collect();
    lines[2] = lines[2].replace('.', ",");
    std::fs::write(&file, lines.join("\n")).unwrap();
    let (ok, out) = calibrate(dir.path(), &[]);
    assert!(!ok && out.contains("001.csv:3: column `") && out.contains("does not use a decimal point"), "{out}");
}
