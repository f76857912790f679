//! Files as other labs write them: each variant read as the same trace as our format, or refused
//! with the file, the line and the column; labels and kinds of a folder.

use super::*;
use crate::trace::TraceMeta;

const OURS: &str = "t_s,q1_um,q2_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,irradiance";

/// Three samples of a motion: our header and rows, as text.
const ROWS: [&str; 3] = [
    "0.000250,-120.5,0,30.25,0.0001,-2,0,1560.000000,0.4132501",
    "0.000500,-120.25,0,30.25,0.0002,-2,0,1560.000000,0.4098",
    "0.000750,-120,0,30.25,0.0003,-2,0,1560.000000,0.40125",
];

fn ours_text() -> String {
    format!("{OURS}\n{}\n", ROWS.join("\n"))
}

/// Write `files` (name, bytes) in a new folder and read it.
fn folder(files: &[(&str, Vec<u8>)], constants: Constants) -> (tempfile::TempDir, Result<Sourced, TraceError>) {
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in files {
        std::fs::write(dir.path().join(name), bytes).unwrap();
    }
    let read = read_folder_with(dir.path(), &FolderOptions { mapping: None, constants });
    (dir, read)
}

fn one(text: &str) -> Result<Trace, TraceError> {
    let (_dir, read) = folder(&[("m.csv", text.as_bytes().to_vec())], Constants::default());
    read.map(|s| s.traces.into_iter().next().unwrap())
}

fn reference() -> Trace {
    one(&ours_text()).unwrap()
}

/// The required columns of two traces, bit for bit (the metadata and extra columns aside).
fn same_samples(a: &Trace, b: &Trace) {
    for ((name, x), (_, y)) in a.required_columns().iter().zip(b.required_columns().iter()) {
        let (x, y): (Vec<u64>, Vec<u64>) =
            (x.iter().map(|v| v.to_bits()).collect(), y.iter().map(|v| v.to_bits()).collect());
        assert_eq!(x, y, "column {name}");
    }
}

#[test]
fn a_file_without_comment_lines_is_labelled_by_its_name() {
    let t = reference();
    assert_eq!(t.meta.label, "m");
    assert_eq!(t.meta.kind, TraceKind::Motion);
    assert_eq!(t.len(), 3);
    assert_eq!(t.q1_um, [-120.5, -120.25, -120.0]);
}

#[test]
fn crlf_line_ends_read_the_same() {
    same_samples(&one(&ours_text().replace('\n', "\r\n")).unwrap(), &reference());
}

#[test]
fn semicolons_with_a_decimal_comma_read_the_same() {
    let text = ours_text().replace(',', ";").replace('.', ",");
    same_samples(&one(&text).unwrap(), &reference());
    let tabs = ours_text().replace(',', "\t");
    same_samples(&one(&tabs).unwrap(), &reference());
}

#[test]
fn columns_in_another_order_with_extra_ones_read_the_same() {
    let order = [8, 0, 6, 2, 1, 7, 5, 4, 3];
    let names: Vec<&str> = OURS.split(',').collect();
    let mut text = order.iter().map(|&i| names[i]).collect::<Vec<_>>().join(",") + ",temperature_C\n";
    for row in ROWS {
        let f: Vec<&str> = row.split(',').collect();
        text += &(order.iter().map(|&i| f[i]).collect::<Vec<_>>().join(",") + ",21.5\n");
    }
    let t = one(&text).unwrap();
    same_samples(&t, &reference());
    assert_eq!(t.extra.len(), 1);
    assert_eq!(t.extra[0].name, "temperature_C");
}

#[test]
fn time_in_milliseconds_and_other_units_are_converted() {
    let text = ours_text().replacen("t_s", "time [ms]", 1).replacen("q1_um", "q1 (nm)", 1);
    let text = text.replace("0.000250,-120.5", "0.25,-120500").replace("0.000500,-120.25", "0.5,-120250");
    let text = text.replace("0.000750,-120,", "0.75,-120000,");
    let t = one(&text).unwrap();
    for (a, b) in t.t_s.iter().zip(&reference().t_s) {
        assert!((a - b).abs() < 1e-15, "{a} vs {b}");
    }
    assert_eq!(t.q1_um, [-120.5, -120.25, -120.0]);
}

#[test]
fn a_wavelength_given_once_replaces_the_column() {
    let without = |text: &str| -> String {
        text.lines()
            .map(|l| {
                let mut f: Vec<&str> = l.split(',').collect();
                f.remove(7);
                f.join(",")
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    let body = without(&ours_text());
    same_samples(&one(&format!("# wavelength_nm: 1560\n{body}")).unwrap(), &reference());
    same_samples(&one(&format!("# wavelength: 1.56 um\n{body}")).unwrap(), &reference());
    // Given for the whole folder instead.
    let (_dir, read) = folder(&[("m.csv", body.clone().into_bytes())], Constants { wavelength_nm: Some(1560.0) });
    same_samples(&read.unwrap().traces[0], &reference());
    // Given nowhere: refused at the header, naming the column and the ways to give it.
    let e = one(&body).unwrap_err().to_string();
    assert!(e.contains("m.csv:1: no `wavelength_nm` column") && e.contains("# wavelength_nm:"), "{e}");
    assert!(e.contains("--wavelength-nm"), "{e}");
    // Given twice, as a column and a line: refused at the line.
    let e = one(&format!(
        "# comment\n# wavelength_nm: 1550\n{}",
        ours_text().replacen(OURS, &OURS.replace("t_s", "T_S"), 1)
    ))
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("m.csv:2: metadata `wavelength_nm`: expected either a wavelength_nm column or this line"),
        "{e}"
    );
}

#[test]
fn upper_case_names_after_a_byte_order_mark_read_the_same() {
    let text = format!("\u{feff}{}", ours_text().replacen(OURS, &OURS.to_uppercase(), 1));
    same_samples(&one(&text).unwrap(), &reference());
    // Our own header after a byte-order mark is our format, its bytes kept.
    let (_dir, read) =
        folder(&[("m.csv", format!("\u{feff}# label: x\n{}", ours_text()).into_bytes())], Constants::default());
    assert!(read.unwrap().files[0].native.is_some());
}

#[test]
fn a_decimal_comma_with_comma_separators_is_refused_at_its_line() {
    let text = format!("{OURS}\n0,00025,-120,5,0,30,25,0,0001,-2,0,1560,0,0,4132501\n");
    let e = one(&text).unwrap_err().to_string();
    assert!(e.contains("m.csv:2: expected 9 fields") && e.contains("found 15"), "{e}");
    assert!(e.contains("decimal comma with `,` as the separator"), "{e}");
}

#[test]
fn mixed_decimal_marks_are_refused_with_line_and_column() {
    let text = ours_text().replace(',', ";").replacen(".", ",", 1);
    let e = one(&text).unwrap_err().to_string();
    assert!(e.contains("m.csv:2: column `q1_um`: `-120.5` does not use a decimal comma"), "{e}");
    let e = one(&format!("{}\n1.5;2,5;0;0;0;0;0;1560;0,5\n", OURS.replace(',', ";"))).unwrap_err().to_string();
    assert!(e.contains("m.csv:2: column `q1_um`: `2,5` does not use a decimal point"), "{e}");
    let e = one(&format!("{}\n1;2.000,5;0;0;0;0;0;1560;0\n", OURS.replace(',', ";"))).unwrap_err().to_string();
    assert!(e.contains("m.csv:2: column `q1_um`: expected a number, found `2.000,5`"), "{e}");
}

#[test]
fn a_quantity_without_a_unit_is_refused_at_its_header_column() {
    let e = one(&ours_text().replacen("t_s", "t", 1)).unwrap_err().to_string();
    assert!(e.contains("m.csv:1: header column 1: `t`: no unit in the name"), "{e}");
    let e = one(&ours_text().replacen("q3_um", "q3_inch", 1)).unwrap_err().to_string();
    assert!(e.contains("m.csv:1: header column 4: `q3_inch`: unknown unit `inch` for q3_um"), "{e}");
    let upper = OURS.to_uppercase();
    let e =
        one(&format!("{upper},time_ms\n{}\n", ROWS.iter().map(|r| format!("{r},1")).collect::<Vec<_>>().join("\n")))
            .unwrap_err()
            .to_string();
    assert!(e.contains("header column 10: `time_ms` gives t_s again (also column 1 `T_S`)"), "{e}");
    let e = one(&ours_text().replacen("irradiance", "power_mW", 1)).unwrap_err().to_string();
    assert!(e.contains("m.csv:1: no `irradiance` column") && e.contains("--mapping"), "{e}");
}

#[test]
fn labels_are_distinct_and_kinds_come_from_the_data() {
    let sweep = format!("{OURS}\n0.0,0,0,0,0,0,0,1555.0,0.1\n0.1,0,0,0,0,0,0,1556.0,0.2\n0.2,0,0,0,0,0,0,1557.0,0.3\n");
    let labelled = |label: &str, body: &str| format!("# label: {label}\n{body}").into_bytes();
    let (_dir, read) = folder(
        &[
            ("a.csv", labelled("scan", &sweep)),
            ("b.csv", labelled("scan", &ours_text())),
            ("c.csv", ours_text().into_bytes()),
            ("d.csv", labelled("X at 0", &ours_text())),
        ],
        Constants::default(),
    );
    let read = read.unwrap();
    let labels: Vec<&str> = read.traces.iter().map(|t| t.meta.label.as_str()).collect();
    assert_eq!(labels, ["scan (a.csv)", "scan (b.csv)", "c", "X at 0"]);
    assert_eq!(read.traces[0].meta.kind, TraceKind::WavelengthSweep);
    assert_eq!(read.traces[1].meta.kind, TraceKind::Motion);
    // Only a file read as it says keeps its bytes for the session.
    let native: Vec<bool> = read.files.iter().map(|f| f.native.is_some()).collect();
    assert_eq!(native, [false, false, false, true]);
}

#[test]
fn our_own_files_read_as_before() {
    let mut t = Trace::new(TraceMeta { label: "x".into(), ..TraceMeta::default() });
    for i in 0..4 {
        t.push_sample(i as f64 * 0.1, [i as f64, 0.0, 1.0, 0.0, 0.5, 0.0], 1560.0, 0.25 * i as f64);
    }
    let bytes = t.to_csv_bytes(Path::new("x.csv")).unwrap();
    let (_dir, read) = folder(&[("x.csv", bytes.clone())], Constants::default());
    let read = read.unwrap();
    assert_eq!(read.traces[0], t);
    assert_eq!(read.files[0].native, Some((crc32fast::hash(&bytes), bytes.len() as u64)));
}
