//! Tests of the trace format: round trips, every bad input class, limits and fuzzing.

use super::*;
use proptest::prelude::*;
use std::path::Path;

const HEADER: &str = "t_s,q1_um,q2_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,irradiance";

fn read_str(text: &str) -> Result<Trace, TraceError> {
    Trace::from_csv_reader(text.as_bytes(), Path::new("bad.csv"))
}

/// A trace with awkward values: subnormals, signed zero, huge and tiny magnitudes.
fn awkward_trace() -> Trace {
    let meta = TraceMeta {
        label: "X_w at q1 = -150 µm: move 3".into(),
        kind: TraceKind::WavelengthSweep,
        bench: "femto-lab (virtual)".into(),
        irradiance_unit: "V".into(),
        notes: "line one\nline two with C:\\path\\n and a trailing space ".into(),
        wavelength_scale_sigma_ppm: 31.25,
    };
    let mut t = Trace::with_capacity(meta, 8);
    t.extra = vec![
        ExtraColumn { name: "temperature_C".into(), values: vec![] },
        ExtraColumn { name: "odd, \"quoted\" name".into(), values: vec![] },
    ];
    let values = [0.1 + 0.2, -0.0, 5e-324, 1e300, -1.7976931348623157e308, std::f64::consts::PI, 1e8 / 7.0, 2.5e-7];
    for (i, &v) in values.iter().enumerate() {
        let t_s = i as f64 * 0.001 + 1e-9;
        let q = [v, -v, v * 0.5, v / 3.0, 1.0 / 3.0, -(i as f64)];
        t.push_sample_with_extras(t_s, q, 1560.0 + v.abs().min(1.0), v, &[21.5 + t_s, v]).unwrap();
    }
    t
}

fn assert_bit_identical(a: &Trace, b: &Trace) {
    assert_eq!(a.meta, b.meta);
    let ca: Vec<_> = a.columns().collect();
    let cb: Vec<_> = b.columns().collect();
    assert_eq!(ca.len(), cb.len());
    for ((na, va), (nb, vb)) in ca.iter().zip(&cb) {
        assert_eq!(na, nb);
        let ba: Vec<u64> = va.iter().map(|v| v.to_bits()).collect();
        let bb: Vec<u64> = vb.iter().map(|v| v.to_bits()).collect();
        assert_eq!(ba, bb, "column {na}");
    }
}

#[test]
fn write_then_read_is_bit_identical_with_meta() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("trace.csv");
    let t = awkward_trace();
    t.write_csv(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.starts_with("# photorobot trace v1\n# label: X_w at q1 = -150 µm: move 3\n"), "{text}");
    assert!(text.contains(&format!("\n{HEADER},temperature_C,\"odd, \"\"quoted\"\" name\"\n")), "{text}");
    let back = Trace::read_csv(&path).unwrap();
    assert_bit_identical(&t, &back);
    // Saving again over the file leaves only the file.
    back.write_csv(&path).unwrap();
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

/// The files we write, and plain rows with `\r\n`, blank lines and comments, take the fast
/// path of reading from memory; a quote anywhere leaves the file to the `csv` crate's reader.
#[test]
fn plain_files_take_the_fast_path() {
    let fast = |bytes: &[u8]| plain::plain_table(bytes, Path::new("f.csv"), &ReadOptions::default(), &|_, _| Ok(0));
    let mut t = awkward_trace();
    t.extra.clear();
    let written = t.to_csv_bytes(Path::new("f.csv")).unwrap();
    let table = fast(&written).expect("our files are plain");
    assert_eq!(
        table.columns[8].iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        t.irradiance.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    let crlf = format!(
        "# label: crlf\r\n\r\n{HEADER}\r\n0,1,2,3,4,5,6,1560,0.5\r\n\r\n# a comment\r\n1,1,2,3,4,5,6,1560,0.25\r\n"
    );
    assert_eq!(fast(crlf.as_bytes()).expect("plain rows").columns[0], [0.0, 1.0]);
    assert!(
        fast(awkward_trace().to_csv_bytes(Path::new("f.csv")).unwrap().as_slice()).is_none(),
        "a quoted column name"
    );
    assert!(fast(crlf.replace(",0.25", ",x").as_bytes()).is_none(), "a bad row is left to the full reader");
}

#[test]
fn crlf_blank_lines_and_comments_are_accepted_and_counted() {
    let text = format!(
        "# label: crlf\r\n\r\n{HEADER}\r\n0,1,2,3,4,5,6,1560,0.5\r\n\r\n# a comment\r\n1,1,2,3,4,5,6,1560,x\r\n"
    );
    let err = read_str(&text).unwrap_err().to_string();
    assert!(err.starts_with("bad.csv:7: column `irradiance`: expected a number, found `x`"), "{err}");
    let ok = read_str(&text.replace(",x", ",0.25")).unwrap();
    assert_eq!(ok.meta.label, "crlf");
    assert_eq!(ok.irradiance, [0.5, 0.25]);
    assert_eq!(ok.t_s, [0.0, 1.0]);
}

/// A data row at time `t_s` (joints 0, 1560 nm, irradiance 0.5).
fn data_row(t_s: &str) -> String {
    format!("{t_s},0,0,0,0,0,0,1560,0.5")
}

/// A valid trace of two rows (times 0 and 0.1), without metadata.
fn two_rows() -> String {
    format!("{HEADER}\n{}\n{}\n", data_row("0"), data_row("0.1"))
}

/// Each named text must be refused with a message containing every wanted piece.
fn assert_each_text_fails_naming_file_line_and_expectation(cases: &[(&str, String, Vec<&str>)]) {
    for (name, text, wants) in cases {
        let err = read_str(text).expect_err(name).to_string();
        for want in wants {
            assert!(err.contains(want), "{name}: got `{err}`, want `{want}`");
        }
    }
}

/// Truncated files and headers with missing, misplaced, duplicated, empty or non-text names.
#[test]
fn bad_headers_name_file_line_and_expectation() {
    let cases: Vec<(&str, String, Vec<&str>)> = vec![
        (
            "empty file",
            String::new(),
            vec!["bad.csv: truncated file: no header row", "expected a header line `t_s,q1_um"],
        ),
        ("meta only", "# photorobot trace v1\n# label: x\n".into(), vec!["bad.csv: truncated file: no header row"]),
        (
            "missing columns",
            "t_s,q1_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,irradiance\n0,0,0,0,0,0,1560,1\n".into(),
            vec!["bad.csv:1: missing required column(s) `q2_um`", "expected the header to start with `t_s,q1_um,q2_um"],
        ),
        (
            "unknown column in place of a required one",
            format!("# c\n{}\n{}\n", HEADER.replace("t_s", "time"), data_row("0")),
            vec![
                "bad.csv:2: missing required column(s) `t_s`; unknown column(s) in their place: `time`",
                "found `time,q1_um",
            ],
        ),
        (
            "misordered columns",
            format!("{}\n{}\n", HEADER.replace("q1_um,q2_um", "q2_um,q1_um"), data_row("0")),
            vec!["bad.csv:1: column `q1_um` is column 3, expected column 2", "expected the header to start with"],
        ),
        (
            "required column after an extra",
            "t_s,q1_um,q2_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,extra,irradiance\n".into(),
            vec!["bad.csv:1: column `irradiance` is column 10, expected column 9"],
        ),
        (
            "duplicate column",
            format!("{HEADER},a,a\n"),
            vec!["bad.csv:1: header column 11: column `a` appears twice (also column 10)"],
        ),
        (
            "empty column name",
            format!("{HEADER},,b\n"),
            vec!["bad.csv:1: header column 10: expected a column name, found an empty one"],
        ),
    ];
    assert_each_text_fails_naming_file_line_and_expectation(&cases);
    // Raw invalid UTF-8 in a header name.
    let mut bytes = format!("{HEADER},").into_bytes();
    bytes.extend_from_slice(b"\xff\xfe\n");
    let err = Trace::from_csv_reader(&bytes[..], Path::new("bad.csv")).unwrap_err().to_string();
    assert!(err.starts_with("bad.csv:1: header column 10: expected a column name in UTF-8 text"), "{err}");
}

/// Rows with the wrong field count, fields that are not finite numbers, and time that does not increase.
#[test]
fn bad_rows_name_file_line_and_expectation() {
    let valid = two_rows();
    let cases: Vec<(&str, String, Vec<&str>)> = vec![
        (
            "too few fields",
            format!("{valid}0.2,0,0,0,0,0,0,1560\n"),
            vec!["bad.csv:4: expected 9 fields (one per header column), found 8 (truncated row?)"],
        ),
        (
            "too many fields",
            format!("{valid}{},7\n", data_row("0.2")),
            vec!["bad.csv:4: expected 9 fields (one per header column), found 10"],
        ),
        (
            "non-numeric",
            format!("{valid}0.2,0,0,abc,0,0,0,1560,0.5\n"),
            vec!["bad.csv:4: column `q3_um`: expected a number, found `abc`"],
        ),
        (
            "empty field",
            format!("{valid}0.2,0,0,0,,0,0,1560,0.5\n"),
            vec!["bad.csv:4: column `q4_deg`: expected a number, found an empty field"],
        ),
        (
            "NaN",
            format!("{valid}0.2,0,0,0,0,NaN,0,1560,0.5\n"),
            vec!["bad.csv:4: column `q5_deg`: expected a finite number, found NaN"],
        ),
        (
            "infinite",
            format!("{valid}0.2,0,0,0,0,0,0,1560,-inf\n"),
            vec!["bad.csv:4: column `irradiance`: expected a finite number, found -inf"],
        ),
        (
            "overflow",
            format!("{valid}0.2,0,0,0,0,0,0,1e999,0.5\n"),
            vec!["bad.csv:4: column `wavelength_nm`: expected a finite number, found inf"],
        ),
        (
            "time goes back",
            format!("{valid}{}\n", data_row("0.05")),
            vec![
                "bad.csv:4: column `t_s`: time 0.05 s is not after 0.1 s on line 3 (expected strictly increasing time)",
            ],
        ),
        (
            "time repeats",
            format!("{HEADER}\n{}\n\n{}\n", data_row("2"), data_row("2")),
            vec!["bad.csv:4: column `t_s`: time 2 s is not after 2 s on line 2"],
        ),
        (
            "not UTF-8 field",
            format!("{valid}0.2,0,0,0,0,0,0,1560,\u{FFFD}\n"),
            vec!["bad.csv:4: column `irradiance`: expected a number"],
        ),
    ];
    assert_each_text_fails_naming_file_line_and_expectation(&cases);
}

/// A header without rows, a bad metadata value and a future format version.
#[test]
fn bad_metadata_and_empty_traces_name_file_line_and_expectation() {
    let valid = two_rows();
    let cases: Vec<(&str, String, Vec<&str>)> = vec![
        (
            "header only",
            format!("# photorobot trace v1\n{HEADER}\n"),
            vec!["bad.csv: empty trace: the header is followed by no data rows (expected at least one row)"],
        ),
        (
            "bad kind",
            format!("# kind: Wobble\n{valid}"),
            vec!["bad.csv:1: metadata `kind`: expected Motion, WavelengthSweep or Static, found `Wobble`"],
        ),
        (
            "negative wavelength scale σ",
            format!("# wavelength_scale_sigma_ppm: -3\n{valid}"),
            vec!["bad.csv:1: metadata `wavelength_scale_sigma_ppm`: expected a finite non-negative number (ppm), found `-3`"],
        ),
        (
            "future version",
            format!("# photorobot trace v2\n{valid}"),
            vec!["bad.csv:1: unsupported format `# photorobot trace v2` (expected `# photorobot trace v1`)"],
        ),
    ];
    assert_each_text_fails_naming_file_line_and_expectation(&cases);
}

#[test]
fn too_many_rows_are_refused_with_the_limit() {
    let mut text = format!("{HEADER}\n");
    for i in 0..5 {
        text.push_str(&format!("{i},0,0,0,0,0,0,1560,0.5\n"));
    }
    let opts = ReadOptions { max_rows: 4, ..ReadOptions::default() };
    let err = Trace::from_csv_reader_with(text.as_bytes(), Path::new("big.csv"), &opts).unwrap_err().to_string();
    assert!(err.starts_with("big.csv:6: more than 4 data rows; refusing to read further"), "{err}");
    let opts = ReadOptions { max_rows: 5, ..ReadOptions::default() };
    assert_eq!(Trace::from_csv_reader_with(text.as_bytes(), Path::new("big.csv"), &opts).unwrap().len(), 5);
    assert_eq!(ReadOptions::default().max_rows, 50_000_000);
}

#[test]
fn missing_file_is_named() {
    let err = Trace::read_csv(Path::new("/no/such/trace.csv")).unwrap_err().to_string();
    assert!(err.contains("/no/such/trace.csv") && err.contains("cannot open"), "{err}");
}

#[test]
fn imports_foreign_csv_without_meta_with_two_extra_columns() {
    // As exported by another acquisition system: no comments, spaces after commas,
    // exponent notation, Windows line endings, no final line break.
    let text = "t_s, q1_um, q2_um, q3_um, q4_deg, q5_deg, q6_deg, wavelength_nm, irradiance, temperature_C, pd2_V\r\n\
                    0.000, -150, 0, 0, 0, 0, 0, 1560.0, 0.412, 21.50, 1.0e-3\r\n\
                    0.010, -149.5, 0, 0, 0, 0, 0, 1560.0, 0.398, 21.51, 1.1e-3\r\n\
                    0.020, -149.0, 0, 0, 0.5, -0.25, 0, 1560.0, 0.377, 21.52, 1.2E-3";
    let t = Trace::from_csv_reader(text.as_bytes(), Path::new("import.csv")).unwrap();
    assert_eq!(t.meta, TraceMeta::default());
    assert_eq!(t.len(), 3);
    assert_eq!(t.t_s, [0.0, 0.01, 0.02]);
    assert_eq!(t.joint_column(0), [-150.0, -149.5, -149.0]);
    assert_eq!(t.joints_display(2), [-149.0, 0.0, 0.0, 0.5, -0.25, 0.0]);
    assert_eq!(t.irradiance, [0.412, 0.398, 0.377]);
    let names: Vec<&str> = t.extra.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["temperature_C", "pd2_V"]);
    assert_eq!(t.extra_column("temperature_C").unwrap(), [21.5, 21.51, 21.52]);
    assert_eq!(t.extra_column("pd2_V").unwrap(), [1.0e-3, 1.1e-3, 1.2e-3]);
    t.validate().unwrap();
}

#[test]
fn validate_catches_in_memory_mistakes() {
    let mut t = Trace::new(TraceMeta::default());
    t.validate().unwrap();
    t.push_sample(0.0, [0.0; 6], 1560.0, 0.5);
    t.push_sample(0.1, [1.0; 6], 1560.0, 0.5);
    t.validate().unwrap();
    let mut short = t.clone();
    short.q5_deg.pop();
    assert_eq!(
        short.validate().unwrap_err().to_string(),
        "trace column `q5_deg` has 1 values, expected 2 (one per t_s sample)"
    );
    let mut nan = t.clone();
    nan.irradiance[1] = f64::NAN;
    assert_eq!(
        nan.validate().unwrap_err().to_string(),
        "trace row 1, column `irradiance`: expected a finite number, found NaN"
    );
    let mut back = t.clone();
    back.t_s[1] = 0.0;
    assert_eq!(
        back.validate().unwrap_err().to_string(),
        "trace row 1: time 0 s is not after 0 s at row 0 (expected strictly increasing time)"
    );
    let mut extra = t.clone();
    extra.extra.push(ExtraColumn { name: "T".into(), values: vec![1.0] });
    assert!(extra.validate().unwrap_err().to_string().contains("column `T` has 1 values, expected 2"));
    extra.extra[0].values.push(2.0);
    extra.validate().unwrap();
    assert!(extra.push_sample_with_extras(0.2, [0.0; 6], 1560.0, 0.5, &[]).is_err());
    assert_eq!(extra.len(), 2, "nothing appended on error");
    extra.extra[0].name = "irradiance".into();
    assert!(extra.validate().unwrap_err().to_string().contains("expected a name other than the required columns"));
    // Writing refuses invalid and empty traces, and names the destination.
    let dir = tempfile::tempdir().unwrap();
    assert!(nan.write_csv(&dir.path().join("x.csv")).is_err());
    let err = Trace::default().write_csv(&dir.path().join("e.csv")).unwrap_err().to_string();
    assert!(err.contains("e.csv: refusing to write an empty trace"), "{err}");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn meta_escaping_round_trips() {
    for s in ["", "a\\b", "\\n literal", "x\ny\r\nz", "trailing\\", " lead", "ü:µ:°"] {
        assert_eq!(unescape_meta(&escape_meta(s)), s);
        assert!(!escape_meta(s).contains('\n'));
    }
}

/// Mutations applied to a valid file in the fuzz test.
#[derive(Debug, Clone)]
enum Mutation {
    Delete(usize, usize),
    Insert(usize, &'static str),
    SetByte(usize, u8),
    Truncate(usize),
    DuplicateLine(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let tokens = prop::sample::select(vec![
        ",",
        "\n",
        "\r\n",
        "\"",
        "#",
        "# kind: x\n",
        "NaN",
        "inf",
        "-",
        "1e999",
        "0",
        "9.5",
        "t_s",
        "q1_um,",
        " ",
        "\u{FEFF}",
        "\u{b5}",
        "\0",
    ]);
    prop_oneof![
        (any::<usize>(), 0usize..20).prop_map(|(a, n)| Mutation::Delete(a, n)),
        (any::<usize>(), tokens).prop_map(|(a, s)| Mutation::Insert(a, s)),
        (any::<usize>(), any::<u8>()).prop_map(|(a, b)| Mutation::SetByte(a, b)),
        any::<usize>().prop_map(Mutation::Truncate),
        any::<usize>().prop_map(Mutation::DuplicateLine),
    ]
}

fn apply(bytes: &mut Vec<u8>, m: &Mutation) {
    let len = bytes.len().max(1);
    match *m {
        Mutation::Delete(a, n) => {
            let a = a % len;
            let b = (a + n).min(bytes.len());
            if a < b {
                bytes.drain(a..b);
            }
        }
        Mutation::Insert(a, s) => {
            let a = a % (bytes.len() + 1);
            bytes.splice(a..a, s.bytes());
        }
        Mutation::SetByte(a, b) => {
            if !bytes.is_empty() {
                let a = a % bytes.len();
                bytes[a] = b;
            }
        }
        Mutation::Truncate(a) => bytes.truncate(a % len),
        Mutation::DuplicateLine(a) => {
            let lines: Vec<&[u8]> = bytes.split(|&b| b == b'\n').collect();
            let k = a % lines.len();
            let mut out = Vec::with_capacity(bytes.len() * 2);
            for (i, l) in lines.iter().enumerate() {
                out.extend_from_slice(l);
                if i == k {
                    out.push(b'\n');
                    out.extend_from_slice(l);
                }
                if i + 1 < lines.len() {
                    out.push(b'\n');
                }
            }
            *bytes = out;
        }
    }
}

/// Reading must never panic; whatever it accepts is a valid, non-empty trace, and whatever it
/// refuses is explained with the file's name.
fn check_any_input(bytes: &[u8]) {
    let read = Trace::from_csv_reader(bytes, Path::new("fuzz.csv"));
    match &read {
        Ok(t) => {
            t.validate().unwrap();
            assert!(!t.is_empty());
        }
        Err(e) => assert!(e.to_string().starts_with("fuzz.csv"), "{e}"),
    }
    assert_same_reading(&read, &Trace::from_csv_bytes(bytes, Path::new("fuzz.csv"), &ReadOptions::default()));
}

/// Two readings of one input agree: the same trace to the bit, or the same error.
fn assert_same_reading(a: &Result<Trace, TraceError>, b: &Result<Trace, TraceError>) {
    match (a, b) {
        (Ok(a), Ok(b)) => assert_bit_identical(a, b),
        (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string()),
        _ => panic!("one reading failed, the other did not: {a:?} vs {b:?}"),
    }
}

/// Lines of a trace file, plain and awkward, for the in-memory reader's fast path.
const LINES: [&str; 14] = [
    "0,1,2,3,4,5,6,1560,0.5",
    "0,1,2,3,4,5,6,1560,0.5\r",
    " 0 , 1,2,3 ,4,5,6,1560 ,0.25 ",
    "",
    "\r",
    "   ",
    "# a comment, with a comma",
    "\"0\",1,2,3,4,5,6,1560,0.5",
    "0,1,2,3,4,5,6,1560",
    "0,1,2,3,4,5,6,1560,nan",
    "0,1,2,3,4,5,6,1560,x",
    "0,1,2,3,4,5,6,1560,0.5,7",
    " #0,1,2,3,4,5,6,1560,0.5",
    "0,1,2,3,4,5,6,,0.5",
];

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn any_finite_values_round_trip_bit_exactly(
        values in prop::collection::vec(any::<f64>().prop_filter("finite", |v| v.is_finite()), 1..40),
        label in "\\PC{0,30}",
    ) {
        let mut t = Trace::new(TraceMeta { label, ..TraceMeta::default() });
        for (i, &v) in values.iter().enumerate() {
            t.push_sample(i as f64 + v.fract().abs() * 0.5, [v, -v, v, v, v, v], v, v);
        }
        let bytes = t.to_csv_bytes(Path::new("rt.csv")).unwrap();
        let back = Trace::from_csv_reader(&bytes[..], Path::new("rt.csv")).unwrap();
        assert_bit_identical(&t, &back);
    }

    /// A field equal to the column's last one is not parsed again: the values read are those of
    /// parsing every field, whatever the repeats, the spacing and the lengths (fields longer than
    /// the bytes kept, fields that differ only past them), and the same when the columns are
    /// sized from the input's length.
    #[test]
    fn repeated_fields_read_as_each_field_parses(
        rows in prop::collection::vec(prop::collection::vec(0usize..8, 8), 1..30),
    ) {
        const POOL: [&str; 8] = [
            "0.0",
            "-0.0",
            " 1.5",
            "1.5 ",
            "150.000000000000000000000000000000001",
            "150.000000000000000000000000000000002",
            "1e-310",
            "-2.5e+3",
        ];
        let mut text = format!("{HEADER}\n");
        for (i, row) in rows.iter().enumerate() {
            text += &i.to_string();
            for &k in row {
                text += ",";
                text += POOL[k];
            }
            text += "\n";
        }
        let t = read_str(&text).unwrap();
        // Sized from the input's length and the first row's (rows here differ up to fivefold).
        let sized = Trace::from_csv_sized(text.as_bytes(), Path::new("bad.csv"), &ReadOptions::default(), Some(text.len() as u64));
        assert_bit_identical(&t, &sized.unwrap());
        let columns: Vec<&[f64]> = t.columns().skip(1).map(|(_, v)| v).collect();
        for (i, row) in rows.iter().enumerate() {
            for (c, &k) in row.iter().enumerate() {
                let want: f64 = POOL[k].trim().parse().unwrap();
                prop_assert_eq!(columns[c][i].to_bits(), want.to_bits(), "row {} column {}", i, c);
            }
        }
    }

    /// Read from memory (the fast path over plain rows) or through the `csv` crate's reader,
    /// a file gives the same trace or the same error, whatever its lines.
    #[test]
    fn reading_from_memory_reads_as_the_csv_reader_does(
        lines in prop::collection::vec((0usize..LINES.len(), 0u32..3), 0..12),
        which_header in 0usize..4,
        end in prop::bool::ANY,
    ) {
        let header = [HEADER.to_string(), format!("{HEADER},temperature_C"), format!("{HEADER}\r"), format!(" {HEADER}")];
        let mut text = format!("# label: l\n\n{}\n", header[which_header]);
        for (i, (k, step)) in lines.iter().enumerate() {
            // Times increase by 0, 1 or 2 per line (0: a repeated time).
            let t = lines[..i].iter().map(|l| l.1).sum::<u32>() + step;
            text += &LINES[*k].replacen('0', &t.to_string(), 1);
            text += "\n";
        }
        if !end {
            text.pop();
        }
        let bytes = text.as_bytes();
        let origin = Path::new("m.csv");
        assert_same_reading(
            &Trace::from_csv_reader(bytes, origin),
            &Trace::from_csv_bytes(bytes, origin, &ReadOptions::default()),
        );
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..600)) {
        check_any_input(&bytes);
    }

    #[test]
    fn mutated_valid_files_never_panic(mutations in prop::collection::vec(mutation(), 1..6)) {
        let mut bytes = awkward_trace().to_csv_bytes(Path::new("fuzz.csv")).unwrap();
        for m in &mutations {
            apply(&mut bytes, m);
        }
        check_any_input(&bytes);
    }
}

/// A trace of samples at the given times, every column a function of the time; with a
/// `temperature_C` extra column when `extra`.
fn timed_trace(times: &[f64], extra: bool) -> Trace {
    let mut t = Trace::new(TraceMeta::default());
    if extra {
        t.extra.push(ExtraColumn { name: "temperature_C".into(), values: Vec::new() });
    }
    for &s in times {
        let q = [s, 2.0 * s, 3.0 * s, -s, 0.5 * s, s * s];
        t.push_sample_with_extras(s, q, 1550.0 + s, (3.0 * s).sin(), &vec![20.0 + s; t.extra.len()]).unwrap();
    }
    t
}

proptest! {
    /// Appending keeps exactly the later samples, as pushing them one by one does, and every
    /// column as long as the time column: with and without matching extra columns, from an
    /// empty trace.
    #[test]
    fn appending_keeps_the_later_samples_as_pushing_them_does(
        a in proptest::collection::vec(0u32..50, 0..20),
        b in proptest::collection::vec(0u32..50, 0..20),
        extra_a in any::<bool>(),
        extra_b in any::<bool>(),
    ) {
        let times = |v: &Vec<u32>| { let mut v: Vec<f64> = v.iter().map(|&k| f64::from(k) * 0.1).collect(); v.sort_by(f64::total_cmp); v.dedup(); v };
        let (first, second) = (timed_trace(&times(&a), extra_a), timed_trace(&times(&b), extra_b));
        let mut appended = first.clone();
        appended.append_later(&second);
        let mut pushed = first.clone();
        if extra_a != extra_b {
            pushed.extra.clear();
        }
        for i in 0..second.len() {
            if pushed.t_s.last().is_none_or(|&last| second.t_s[i] > last) {
                let extras: Vec<f64> = second.extra.iter().take(pushed.extra.len()).map(|c| c.values[i]).collect();
                pushed.push_sample_with_extras(second.t_s[i], second.joints_display(i), second.wavelength_nm[i], second.irradiance[i], &extras).unwrap();
            }
        }
        prop_assert_eq!(&appended, &pushed);
        prop_assert!(appended.validate().is_ok());
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 500, failure_persistence: None, ..ProptestConfig::default() })]

    /// A sweep is told from the columns' whole spans: the wavelength's over 0.1 nm, every
    /// joint's under 0.05, whatever the order and number of the values and however close to
    /// the limits.
    #[test]
    fn sweeps_are_told_by_their_columns_whole_spans(
        wl in prop::collection::vec(prop::sample::select(vec![1560.0, 1560.05, 1560.1, 1560.1000001, 1560.2, f64::NAN]), 1..12),
        joint in prop::collection::vec(prop::sample::select(vec![0.0, 0.01, 0.05, 0.0499999, -0.03, f64::NAN]), 1..12),
        which in 0usize..6,
        repeat in 1usize..3000,
    ) {
        // Each value repeated, so that the spans build up across the blocks they are read in.
        let n = wl.len().min(joint.len());
        let mut t = Trace::new(TraceMeta::default());
        for i in 0..n * repeat {
            let mut q = [0.0; 6];
            q[which] = joint[i / repeat];
            t.push_sample(i as f64, q, wl[i / repeat], 0.5);
        }
        let span = |c: &[f64]| {
            let (lo, hi) = c.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
            hi - lo
        };
        let whole = span(&t.wavelength_nm) > 0.1 && (0..6).all(|j| span(t.joint_column(j)) < 0.05);
        prop_assert_eq!(is_sweep(&t), whole);
    }
}
