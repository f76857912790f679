//! Recorded traces (time, joints, laser wavelength, irradiance, extra channels) and their CSV interchange format.
//! Owns the column layout, the `# key: value` metadata header, validated reading (also the import path for data
//! from other acquisition systems) and atomic writing.
//!
//! # File format (`# photorobot trace v1`)
//!
//! ```text
//! # photorobot trace v1
//! # label: X_w at q1 = -150 µm
//! # kind: Motion
//! # bench: table2-ideal
//! # irradiance_unit: normalised
//! # notes: free text; newlines are written as \n, backslashes as \\
//! t_s,q1_um,q2_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,irradiance,temperature_C
//! 0.0,-150.0,0.0,-150.0,0.0,0.0,0.0,1560.0,0.4132,21.5
//! ```
//!
//! - Comment lines (`#`) before the header carry the metadata; unknown keys and lines that are
//!   not `key: value` are ignored, missing keys get [`TraceMeta::default`] (data imported from
//!   elsewhere has none). Comment lines and blank lines are also allowed between data rows.
//! - The header starts with the nine [`REQUIRED_COLUMNS`] in that order; any further columns are
//!   kept as [`ExtraColumn`]s. Names are trimmed, so `t_s, q1_um, …` is accepted.
//! - Every field is a finite decimal number (surrounding spaces allowed); time strictly increases.
//! - Line endings may be `\n` or `\r\n`. Line numbers in errors are 1-based and count every line
//!   of the file (a quoted field spanning lines is reported at its last line).
//! - Numbers are written in Rust's shortest round-trip form, so write-then-read is bit-exact.
//! - A file above [`ReadOptions::max_bytes`] (default [`DEFAULT_MAX_BYTES`], 2 GiB) is refused
//!   from its size without being read; more than [`ReadOptions::max_rows`] rows are refused too.
//! - [`read_table`] reads any numeric CSV with these rules; `crate::import` uses it for files from
//!   other acquisition systems.

use crate::files::{write_atomic, FileError};
use serde::{Deserialize, Serialize};
use std::fmt::{self, Write as _};
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// First line of a trace written by this program.
pub const FORMAT_LINE: &str = "# photorobot trace v1";

/// The required columns, in order, at the start of the header row.
pub const REQUIRED_COLUMNS: [&str; 9] =
    ["t_s", "q1_um", "q2_um", "q3_um", "q4_deg", "q5_deg", "q6_deg", "wavelength_nm", "irradiance"];

/// Default largest number of data rows [`Trace::read_csv`] accepts (50 million, about 4 GB
/// of columns in memory); larger files are refused with a message instead of exhausting memory.
pub const DEFAULT_MAX_ROWS: usize = 50_000_000;

/// Default largest trace file [`Trace::read_csv`] opens: 2 GiB (about 25 million rows of the
/// nine required columns). A larger file is refused from its size, without reading it.
pub const DEFAULT_MAX_BYTES: u64 = 2 << 30;

/// Longest metadata line accepted (bytes); longer ones are refused rather than read whole.
const MAX_META_LINE_BYTES: u64 = 64 * 1024;

/// What a trace records.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum TraceKind {
    /// The robot moves; the laser wavelength is fixed.
    #[default]
    Motion,
    /// The joints are fixed; the laser wavelength is swept.
    WavelengthSweep,
    /// Nothing moves (noise or drift record).
    Static,
}

impl TraceKind {
    /// All kinds, in the order they are documented.
    pub const ALL: [TraceKind; 3] = [TraceKind::Motion, TraceKind::WavelengthSweep, TraceKind::Static];

    /// The name written in the `# kind:` line.
    pub fn as_str(self) -> &'static str {
        match self {
            TraceKind::Motion => "Motion",
            TraceKind::WavelengthSweep => "WavelengthSweep",
            TraceKind::Static => "Static",
        }
    }

    /// Parse a `# kind:` value (case-insensitive, surrounding spaces ignored).
    pub fn parse(text: &str) -> Option<Self> {
        let t = text.trim();
        Self::ALL.into_iter().find(|k| k.as_str().eq_ignore_ascii_case(t))
    }
}

impl fmt::Display for TraceKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Metadata of a trace, written as `# key: value` lines before the header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TraceMeta {
    /// Label of the motion (usually the plan segment's label). Default "".
    pub label: String,
    /// What the trace records. Default [`TraceKind::Motion`].
    pub kind: TraceKind,
    /// Which bench recorded it (virtual preset name or hardware description). Default "".
    pub bench: String,
    /// Unit of the irradiance column, e.g. "normalised" or "V". Default "normalised".
    pub irradiance_unit: String,
    /// Free text. Default "".
    pub notes: String,
}

impl Default for TraceMeta {
    fn default() -> Self {
        Self {
            label: String::new(),
            kind: TraceKind::Motion,
            bench: String::new(),
            irradiance_unit: "normalised".into(),
            notes: String::new(),
        }
    }
}

/// A further recorded channel beyond the required columns (temperature, a second photodiode…).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExtraColumn {
    /// Column name as in the header (non-empty, no surrounding spaces, unique).
    pub name: String,
    /// One value per sample.
    pub values: Vec<f64>,
}

/// A recorded trace, column by column. Joints are in display units (µm for q1..q3, degrees for
/// q4..q6), as in the CSV header; every column has one value per sample.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Trace {
    /// Metadata.
    pub meta: TraceMeta,
    /// Time since the start of the recording (s), strictly increasing.
    pub t_s: Vec<f64>,
    /// Joint q1 (µm).
    pub q1_um: Vec<f64>,
    /// Joint q2 (µm).
    pub q2_um: Vec<f64>,
    /// Joint q3 (µm).
    pub q3_um: Vec<f64>,
    /// Joint q4 (°).
    pub q4_deg: Vec<f64>,
    /// Joint q5 (°).
    pub q5_deg: Vec<f64>,
    /// Joint q6 (°).
    pub q6_deg: Vec<f64>,
    /// Laser vacuum wavelength (nm).
    pub wavelength_nm: Vec<f64>,
    /// Reflected irradiance, in `meta.irradiance_unit`.
    pub irradiance: Vec<f64>,
    /// Further channels, in header order.
    pub extra: Vec<ExtraColumn>,
}

/// Options for reading a trace.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadOptions {
    /// Largest number of data rows accepted; a file with more is refused. Default [`DEFAULT_MAX_ROWS`].
    pub max_rows: usize,
    /// Largest file accepted (bytes), checked from the file's size before reading. Default
    /// [`DEFAULT_MAX_BYTES`].
    pub max_bytes: u64,
}

impl Default for ReadOptions {
    fn default() -> Self {
        Self { max_rows: DEFAULT_MAX_ROWS, max_bytes: DEFAULT_MAX_BYTES }
    }
}

/// Why a trace could not be read, written or accepted. Errors about a file name the file and,
/// where it applies, the 1-based line and the column, and say what was expected.
#[derive(Debug, Error)]
pub enum TraceError {
    /// The file could not be read or written.
    #[error(transparent)]
    File(#[from] FileError),
    /// The file ends before a header row: empty, or metadata lines only.
    #[error("{file}: truncated file: no header row (expected a header line `{expected}`)", file = .file.display(), expected = REQUIRED_COLUMNS.join(","))]
    NoHeader {
        /// The file.
        file: PathBuf,
    },
    /// The `# photorobot trace vN` line names a version this program does not read.
    #[error("{file}:{line}: unsupported format `{found}` (expected `{expected}`)", file = .file.display(), expected = FORMAT_LINE)]
    UnsupportedFormat {
        /// The file.
        file: PathBuf,
        /// Line of the format line.
        line: usize,
        /// The line as found.
        found: String,
    },
    /// A metadata line has a value that is not allowed.
    #[error("{file}:{line}: metadata `{key}`: expected {expected}, found `{found}`", file = .file.display())]
    BadMeta {
        /// The file.
        file: PathBuf,
        /// Line of the metadata.
        line: usize,
        /// The key.
        key: String,
        /// What was expected.
        expected: String,
        /// The value as found.
        found: String,
    },
    /// Required columns are absent from the header.
    #[error("{file}:{line}: missing required column(s) {missing}{unknown} (expected the header to start with `{expected}`; found `{found}`)",
        file = .file.display(),
        missing = quoted_list(.missing),
        unknown = if .unknown.is_empty() { String::new() } else { format!("; unknown column(s) in their place: {}", quoted_list(.unknown)) },
        expected = REQUIRED_COLUMNS.join(","))]
    MissingColumns {
        /// The file.
        file: PathBuf,
        /// Line of the header.
        line: usize,
        /// Required columns not found.
        missing: Vec<String>,
        /// Names found among the first nine columns that are not required columns.
        unknown: Vec<String>,
        /// The header as found (joined with commas).
        found: String,
    },
    /// All required columns are present but not in the required order at the start.
    #[error("{file}:{line}: column `{column}` is column {found_position}, expected column {expected_position} (expected the header to start with `{expected}`)",
        file = .file.display(), expected = REQUIRED_COLUMNS.join(","))]
    MisorderedColumns {
        /// The file.
        file: PathBuf,
        /// Line of the header.
        line: usize,
        /// The first required column out of place.
        column: String,
        /// Its 1-based position in the header.
        found_position: usize,
        /// Its required 1-based position.
        expected_position: usize,
    },
    /// Another problem with the header: an empty or duplicated name, or a name that is not text.
    #[error("{file}:{line}: header column {position}: {problem}", file = .file.display())]
    BadHeader {
        /// The file.
        file: PathBuf,
        /// Line of the header.
        line: usize,
        /// 1-based column position.
        position: usize,
        /// What is wrong and what was expected.
        problem: String,
    },
    /// A data row has a different number of fields from the header.
    #[error("{file}:{line}: expected {expected} fields (one per header column), found {found}{hint}",
        file = .file.display(),
        hint = if .found < .expected { " (truncated row?)" } else { "" })]
    FieldCount {
        /// The file.
        file: PathBuf,
        /// Line of the row.
        line: usize,
        /// Number of header columns.
        expected: usize,
        /// Number of fields in the row.
        found: usize,
    },
    /// A field is not a decimal number.
    #[error("{file}:{line}: column `{column}`: expected a number, found {}", show_field(.text), file = .file.display())]
    NotANumber {
        /// The file.
        file: PathBuf,
        /// Line of the row.
        line: usize,
        /// Column name.
        column: String,
        /// The field as found (lossy, shortened).
        text: String,
    },
    /// A field is NaN or infinite.
    #[error("{file}:{line}: column `{column}`: expected a finite number, found {value}", file = .file.display())]
    NonFinite {
        /// The file.
        file: PathBuf,
        /// Line of the row.
        line: usize,
        /// Column name.
        column: String,
        /// The value.
        value: f64,
    },
    /// Time does not strictly increase.
    #[error("{file}:{line}: column `{column}`: time {t}{unit} is not after {previous_t}{unit} on line {previous_line} (expected strictly increasing time)",
        file = .file.display(), unit = if .column == "t_s" { " s" } else { "" })]
    NonMonotonicTime {
        /// The file.
        file: PathBuf,
        /// Line of the offending row.
        line: usize,
        /// The time column (`t_s` in our format; the source column of an import).
        column: String,
        /// Its time (in the column's unit).
        t: f64,
        /// Line of the previous row.
        previous_line: usize,
        /// The previous time (in the column's unit).
        previous_t: f64,
    },
    /// A header but no data rows.
    #[error("{file}: empty trace: the header is followed by no data rows (expected at least one row)", file = .file.display())]
    EmptyTrace {
        /// The file.
        file: PathBuf,
    },
    /// More data rows than [`ReadOptions::max_rows`].
    #[error("{file}:{line}: more than {max_rows} data rows; refusing to read further (expected at most {max_rows} rows, see ReadOptions::max_rows)", file = .file.display())]
    TooLarge {
        /// The file.
        file: PathBuf,
        /// Line of the first row beyond the limit.
        line: usize,
        /// The limit.
        max_rows: usize,
    },
    /// The CSV reader failed on the text itself.
    #[error("{file}:{line}: malformed CSV: {message}", file = .file.display())]
    Csv {
        /// The file.
        file: PathBuf,
        /// Line where the reader stopped.
        line: usize,
        /// The reader's message.
        message: String,
    },
    /// Import: a column the mapping reads is not in the file's header.
    #[error("{file}:{line}: no column `{column}` in the header (the column mapping reads it for `{target}`); found `{found}`", file = .file.display())]
    MappedColumnMissing {
        /// The file.
        file: PathBuf,
        /// Line of the header.
        line: usize,
        /// The source column the mapping names.
        column: String,
        /// Our column it feeds.
        target: String,
        /// The header as found (joined with commas).
        found: String,
    },
    /// Import: a value is no longer finite after the mapping's unit conversion and scale.
    #[error("{file}: column `{column}`, data row {row}: {value} after the mapping's unit conversion and scale (expected a finite number: check the mapping's unit and scale)", file = .file.display())]
    ScaledNonFinite {
        /// The file.
        file: PathBuf,
        /// Our column.
        column: String,
        /// 1-based data row.
        row: usize,
        /// The value after scaling.
        value: f64,
    },
    /// Import: the converted trace is not valid (e.g. time no longer increases after rounding).
    #[error("{file}: after the column mapping: {problem}", file = .file.display())]
    Imported {
        /// The file.
        file: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// In memory: a column's length differs from the number of samples.
    #[error("trace column `{column}` has {found} values, expected {expected} (one per t_s sample)")]
    LengthMismatch {
        /// Column name.
        column: String,
        /// Number of samples (length of `t_s`).
        expected: usize,
        /// Length of the column.
        found: usize,
    },
    /// In memory: a sample is NaN or infinite.
    #[error("trace row {row}, column `{column}`: expected a finite number, found {value}")]
    NonFiniteSample {
        /// 0-based sample index.
        row: usize,
        /// Column name.
        column: String,
        /// The value.
        value: f64,
    },
    /// In memory: time does not strictly increase.
    #[error("trace row {row}: time {t_s} s is not after {previous_t_s} s at row {} (expected strictly increasing time)", .row - 1)]
    NonMonotonicSample {
        /// 0-based sample index.
        row: usize,
        /// Its time (s).
        t_s: f64,
        /// The previous sample's time (s).
        previous_t_s: f64,
    },
    /// In memory: an extra column's name cannot be written.
    #[error("trace extra column {index} (`{name}`): {problem}")]
    BadColumnName {
        /// 0-based index in [`Trace::extra`].
        index: usize,
        /// The name.
        name: String,
        /// What is wrong and what was expected.
        problem: String,
    },
    /// In memory: an empty trace cannot be written (it could not be read back).
    #[error("{file}: refusing to write an empty trace (expected at least one sample)", file = .file.display())]
    WriteEmpty {
        /// The file.
        file: PathBuf,
    },
}

fn quoted_list(names: &[String]) -> String {
    names.iter().map(|n| format!("`{n}`")).collect::<Vec<_>>().join(", ")
}

fn show_field(text: &str) -> String {
    if text.is_empty() {
        "an empty field".into()
    } else {
        format!("`{text}`")
    }
}

/// Shorten a field for an error message (at most 40 characters).
fn field_text(bytes: &[u8]) -> String {
    let s = String::from_utf8_lossy(bytes);
    let s = s.trim();
    if s.chars().count() > 40 {
        format!("{}…", s.chars().take(40).collect::<String>())
    } else {
        s.to_string()
    }
}

/// Parse a numeric field: UTF-8, surrounding whitespace (including a `\r`) ignored.
#[inline]
fn parse_field(bytes: &[u8]) -> Option<f64> {
    std::str::from_utf8(bytes.trim_ascii()).ok()?.parse::<f64>().ok()
}

/// Escape a metadata value so that it fits on one line.
fn escape_meta(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            c => out.push(c),
        }
    }
    out
}

/// Undo [`escape_meta`]; an unknown escape is kept as written (e.g. a Windows path).
fn unescape_meta(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut chars = s.chars().peekable();
    while let Some(c) = chars.next() {
        if c != '\\' {
            out.push(c);
            continue;
        }
        match chars.peek() {
            Some('\\') => out.push('\\'),
            Some('n') => out.push('\n'),
            Some('r') => out.push('\r'),
            _ => {
                out.push('\\');
                continue;
            }
        }
        chars.next();
    }
    out
}

/// Read the metadata lines (and blank lines) before the header. Returns the metadata and the
/// number of lines consumed.
fn read_meta<R: BufRead>(reader: &mut R, file: &Path) -> Result<(TraceMeta, usize), TraceError> {
    let io_err = |source| TraceError::File(FileError::Io { file: file.to_path_buf(), action: "cannot read", source });
    let mut meta = TraceMeta::default();
    let mut lines = 0usize;
    let mut line = Vec::new();
    // A UTF-8 byte-order mark (spreadsheet exports) is skipped.
    if reader.fill_buf().map_err(io_err)?.starts_with(b"\xEF\xBB\xBF") {
        reader.consume(3);
    }
    loop {
        let buf = reader.fill_buf().map_err(io_err)?;
        match buf.first() {
            Some(b'#') | Some(b'\n') | Some(b'\r') => {}
            _ => break,
        }
        line.clear();
        reader.by_ref().take(MAX_META_LINE_BYTES).read_until(b'\n', &mut line).map_err(io_err)?;
        lines += 1;
        if line.len() as u64 >= MAX_META_LINE_BYTES && line.last() != Some(&b'\n') {
            return Err(TraceError::BadMeta {
                file: file.to_path_buf(),
                line: lines,
                key: "(comment line)".into(),
                expected: format!("a line shorter than {MAX_META_LINE_BYTES} bytes"),
                found: field_text(&line),
            });
        }
        let text = String::from_utf8_lossy(&line);
        let text = text.trim_end_matches(['\n', '\r']);
        let Some(body) = text.strip_prefix('#') else {
            continue; // a blank line
        };
        let trimmed = body.trim();
        if let Some(version) = trimmed.strip_prefix("photorobot trace v") {
            if version.trim() != "1" {
                return Err(TraceError::UnsupportedFormat {
                    file: file.to_path_buf(),
                    line: lines,
                    found: text.to_string(),
                });
            }
            continue;
        }
        let Some((key, value)) = body.split_once(':') else {
            continue; // a free comment
        };
        let value = unescape_meta(value.strip_prefix(' ').unwrap_or(value));
        match key.trim().to_ascii_lowercase().as_str() {
            "label" => meta.label = value,
            "bench" => meta.bench = value,
            "irradiance_unit" => meta.irradiance_unit = value,
            "notes" => meta.notes = value,
            "kind" => {
                meta.kind = TraceKind::parse(&value).ok_or_else(|| TraceError::BadMeta {
                    file: file.to_path_buf(),
                    line: lines,
                    key: "kind".into(),
                    expected: "Motion, WavelengthSweep or Static".into(),
                    found: value.clone(),
                })?
            }
            _ => {} // unknown keys are ignored (forward compatibility, other systems)
        }
    }
    Ok((meta, lines))
}

/// Check the header row's names: UTF-8, non-empty, on one line, unique. Returns them trimmed.
fn check_names(rec: &csv::ByteRecord, file: &Path, line: usize) -> Result<Vec<String>, TraceError> {
    let mut names = Vec::with_capacity(rec.len());
    for (i, field) in rec.iter().enumerate() {
        let name = std::str::from_utf8(field).map_err(|_| TraceError::BadHeader {
            file: file.to_path_buf(),
            line,
            position: i + 1,
            problem: format!("expected a column name in UTF-8 text, found bytes `{}`", field_text(field)),
        })?;
        let name = name.trim();
        if name.is_empty() {
            return Err(TraceError::BadHeader {
                file: file.to_path_buf(),
                line,
                position: i + 1,
                problem: "expected a column name, found an empty one".into(),
            });
        }
        if name.contains(['\n', '\r']) {
            return Err(TraceError::BadHeader {
                file: file.to_path_buf(),
                line,
                position: i + 1,
                problem: "expected a column name on one line, found a line break in it".into(),
            });
        }
        if let Some(first) = names.iter().position(|n: &&str| *n == name) {
            return Err(TraceError::BadHeader {
                file: file.to_path_buf(),
                line,
                position: i + 1,
                problem: format!("column `{name}` appears twice (also column {}); expected unique names", first + 1),
            });
        }
        names.push(name);
    }
    Ok(names.into_iter().map(str::to_string).collect())
}

/// Check that a header starts with the [`REQUIRED_COLUMNS`] in order.
fn check_required(names: &[String], file: &Path, line: usize) -> Result<(), TraceError> {
    let missing: Vec<String> =
        REQUIRED_COLUMNS.iter().filter(|r| !names.iter().any(|n| n == *r)).map(|r| r.to_string()).collect();
    if !missing.is_empty() {
        let unknown = names
            .iter()
            .take(REQUIRED_COLUMNS.len())
            .filter(|n| !REQUIRED_COLUMNS.contains(&n.as_str()))
            .map(|n| n.to_string())
            .collect();
        let mut found = names.join(",");
        if found.chars().count() > 200 {
            found = format!("{}…", found.chars().take(200).collect::<String>());
        }
        return Err(TraceError::MissingColumns { file: file.to_path_buf(), line, missing, unknown, found });
    }
    for (k, required) in REQUIRED_COLUMNS.iter().enumerate() {
        if names[k] != *required {
            let found_position = names.iter().position(|n| n == required).unwrap_or(0) + 1;
            return Err(TraceError::MisorderedColumns {
                file: file.to_path_buf(),
                line,
                column: required.to_string(),
                found_position,
                expected_position: k + 1,
            });
        }
    }
    Ok(())
}

/// A numeric CSV table as read from a file: the `#` metadata lines, the column names and one
/// vector per column. Every value is finite, every row has one field per column, the time
/// column strictly increases and there is at least one row.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// Metadata from the `# key: value` lines (defaults where absent).
    pub meta: TraceMeta,
    /// 1-based line of the header row.
    pub header_line: usize,
    /// Column names, trimmed, unique, in file order.
    pub names: Vec<String>,
    /// One vector per column, in file order.
    pub columns: Vec<Vec<f64>>,
}

/// Open a file for [`read_table`], refusing it from its size when above [`ReadOptions::max_bytes`].
pub fn open_limited(path: &Path, options: &ReadOptions) -> Result<std::fs::File, TraceError> {
    crate::files::check_size(
        path,
        options.max_bytes,
        "a trace file",
        "split the recording into one file per motion, or raise ReadOptions::max_bytes",
    )?;
    Ok(std::fs::File::open(path).map_err(|source| FileError::Io {
        file: path.to_path_buf(),
        action: "cannot open",
        source,
    })?)
}

/// Read a numeric CSV table with the trace format's rules (metadata lines, comments, blank
/// lines, `\r\n`, a byte-order mark, line numbers in errors). `header` checks the column
/// names (given with the header's line) and returns the index of the time column, which must
/// strictly increase. Never panics, whatever the bytes.
pub fn read_table<R: Read>(
    reader: R,
    origin: &Path,
    options: &ReadOptions,
    header: impl FnOnce(&[String], usize) -> Result<usize, TraceError>,
) -> Result<Table, TraceError> {
    let file = || origin.to_path_buf();
    let mut input = BufReader::with_capacity(64 * 1024, reader);
    let (meta, meta_lines) = read_meta(&mut input, origin)?;
    // A final '\n' makes every record end with one, so the reader's line count after a
    // record is always one past the record's (last) line. `\r` before it is trimmed as space.
    let mut csv_reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .terminator(csv::Terminator::Any(b'\n'))
        .comment(Some(b'#'))
        .buffer_capacity(64 * 1024)
        .from_reader(input.chain(&b"\n"[..]));
    let mut rec = csv::ByteRecord::new();
    let mut next = |rec: &mut csv::ByteRecord| -> Result<Option<usize>, TraceError> {
        loop {
            let more = csv_reader.read_byte_record(rec).map_err(|e| {
                let line = meta_lines + csv_reader.position().line() as usize;
                match e.into_kind() {
                    csv::ErrorKind::Io(source) => {
                        TraceError::File(FileError::Io { file: file(), action: "cannot read", source })
                    }
                    other => TraceError::Csv { file: file(), line, message: format!("{other:?}") },
                }
            })?;
            if !more {
                return Ok(None);
            }
            // A blank line ending in "\r\n" arrives as one field holding "\r": skip it.
            if rec.len() == 1 && rec[0].iter().all(|b| b.is_ascii_whitespace()) {
                continue;
            }
            let line = meta_lines + (csv_reader.position().line() as usize).saturating_sub(1);
            return Ok(Some(line));
        }
    };

    let Some(header_line) = next(&mut rec)? else {
        return Err(TraceError::NoHeader { file: file() });
    };
    let names = check_names(&rec, origin, header_line)?;
    let time = header(&names, header_line)?;
    let n_cols = names.len();
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); n_cols];
    let mut rows = 0usize;
    let mut previous: Option<(usize, f64)> = None;
    while let Some(line) = next(&mut rec)? {
        if rows >= options.max_rows {
            return Err(TraceError::TooLarge { file: file(), line, max_rows: options.max_rows });
        }
        if rec.len() != n_cols {
            return Err(TraceError::FieldCount { file: file(), line, expected: n_cols, found: rec.len() });
        }
        for (c, field) in rec.iter().enumerate() {
            let v = parse_field(field).ok_or_else(|| TraceError::NotANumber {
                file: file(),
                line,
                column: names[c].clone(),
                text: field_text(field),
            })?;
            if !v.is_finite() {
                return Err(TraceError::NonFinite { file: file(), line, column: names[c].clone(), value: v });
            }
            columns[c].push(v);
        }
        let t = columns[time][rows];
        if let Some((previous_line, previous_t)) = previous {
            if t <= previous_t {
                return Err(TraceError::NonMonotonicTime {
                    file: file(),
                    line,
                    column: names[time].clone(),
                    t,
                    previous_line,
                    previous_t,
                });
            }
        }
        previous = Some((line, t));
        rows += 1;
    }
    if rows == 0 {
        return Err(TraceError::EmptyTrace { file: file() });
    }
    Ok(Table { meta, header_line, names, columns })
}

impl Trace {
    /// An empty trace with the given metadata.
    pub fn new(meta: TraceMeta) -> Self {
        Self::with_capacity(meta, 0)
    }

    /// An empty trace with room for `rows` samples in each required column.
    pub fn with_capacity(meta: TraceMeta, rows: usize) -> Self {
        let v = || Vec::with_capacity(rows);
        Self {
            meta,
            t_s: v(),
            q1_um: v(),
            q2_um: v(),
            q3_um: v(),
            q4_deg: v(),
            q5_deg: v(),
            q6_deg: v(),
            wavelength_nm: v(),
            irradiance: v(),
            extra: Vec::new(),
        }
    }

    /// Number of samples (length of `t_s`).
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    /// True if there are no samples.
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// The joint vector of sample `i` in display units (µm, µm, µm, °, °, °).
    ///
    /// # Panics
    /// If `i >= self.len()` or a joint column is shorter than `t_s` (see [`Trace::validate`]).
    pub fn joints_display(&self, i: usize) -> [f64; 6] {
        [self.q1_um[i], self.q2_um[i], self.q3_um[i], self.q4_deg[i], self.q5_deg[i], self.q6_deg[i]]
    }

    /// Joint column `j` (0-based: 0 is q1 … 5 is q6), in display units.
    ///
    /// # Panics
    /// If `j >= 6`.
    pub fn joint_column(&self, j: usize) -> &[f64] {
        match j {
            0 => &self.q1_um,
            1 => &self.q2_um,
            2 => &self.q3_um,
            3 => &self.q4_deg,
            4 => &self.q5_deg,
            5 => &self.q6_deg,
            _ => panic!("joint index {j} out of range: a trace has joints 0..6 (q1..q6)"),
        }
    }

    /// The required columns in header order (name, values).
    pub fn required_columns(&self) -> [(&'static str, &[f64]); 9] {
        [
            (REQUIRED_COLUMNS[0], &self.t_s),
            (REQUIRED_COLUMNS[1], &self.q1_um),
            (REQUIRED_COLUMNS[2], &self.q2_um),
            (REQUIRED_COLUMNS[3], &self.q3_um),
            (REQUIRED_COLUMNS[4], &self.q4_deg),
            (REQUIRED_COLUMNS[5], &self.q5_deg),
            (REQUIRED_COLUMNS[6], &self.q6_deg),
            (REQUIRED_COLUMNS[7], &self.wavelength_nm),
            (REQUIRED_COLUMNS[8], &self.irradiance),
        ]
    }

    /// Every column in file order (required, then extra): name and values.
    pub fn columns(&self) -> impl Iterator<Item = (&str, &[f64])> {
        self.required_columns().into_iter().chain(self.extra.iter().map(|c| (c.name.as_str(), c.values.as_slice())))
    }

    /// The extra column called `name`, if any.
    pub fn extra_column(&self, name: &str) -> Option<&[f64]> {
        self.extra.iter().find(|c| c.name == name).map(|c| c.values.as_slice())
    }

    /// Append one sample to the required columns (joints in display units). Extra columns, if
    /// any, must be filled by the caller (see [`Trace::push_sample_with_extras`]);
    /// [`Trace::validate`] reports a column left short.
    pub fn push_sample(&mut self, t_s: f64, q_display: [f64; 6], wavelength_nm: f64, irradiance: f64) {
        self.t_s.push(t_s);
        self.q1_um.push(q_display[0]);
        self.q2_um.push(q_display[1]);
        self.q3_um.push(q_display[2]);
        self.q4_deg.push(q_display[3]);
        self.q5_deg.push(q_display[4]);
        self.q6_deg.push(q_display[5]);
        self.wavelength_nm.push(wavelength_nm);
        self.irradiance.push(irradiance);
    }

    /// Append one sample including one value per extra column (in [`Trace::extra`] order).
    /// Nothing is appended if `extras` has the wrong length.
    pub fn push_sample_with_extras(
        &mut self,
        t_s: f64,
        q_display: [f64; 6],
        wavelength_nm: f64,
        irradiance: f64,
        extras: &[f64],
    ) -> Result<(), TraceError> {
        if extras.len() != self.extra.len() {
            return Err(TraceError::LengthMismatch {
                column: "extras".into(),
                expected: self.extra.len(),
                found: extras.len(),
            });
        }
        self.push_sample(t_s, q_display, wavelength_nm, irradiance);
        for (c, &v) in self.extra.iter_mut().zip(extras) {
            c.values.push(v);
        }
        Ok(())
    }

    /// Check a trace built in memory: every column as long as `t_s`, extra column names
    /// writable (non-empty, no surrounding spaces or line breaks, unique, not a required
    /// name), every value finite, time strictly increasing. An empty trace is valid.
    pub fn validate(&self) -> Result<(), TraceError> {
        let n = self.len();
        for (i, c) in self.extra.iter().enumerate() {
            let bad = |problem: &str| TraceError::BadColumnName {
                index: i,
                name: c.name.clone(),
                problem: problem.to_string(),
            };
            if c.name.is_empty() {
                return Err(bad("expected a non-empty name"));
            }
            if c.name.trim() != c.name || c.name.contains(['\n', '\r']) {
                return Err(bad("expected a name without surrounding spaces or line breaks"));
            }
            if REQUIRED_COLUMNS.contains(&c.name.as_str()) {
                return Err(bad("expected a name other than the required columns"));
            }
            if self.extra[..i].iter().any(|o| o.name == c.name) {
                return Err(bad("expected a unique name, found it twice"));
            }
        }
        for (name, values) in self.columns() {
            if values.len() != n {
                return Err(TraceError::LengthMismatch { column: name.to_string(), expected: n, found: values.len() });
            }
            if let Some(row) = values.iter().position(|v| !v.is_finite()) {
                return Err(TraceError::NonFiniteSample { row, column: name.to_string(), value: values[row] });
            }
        }
        if let Some(k) = self.t_s.windows(2).position(|w| w[1] <= w[0]) {
            return Err(TraceError::NonMonotonicSample { row: k + 1, t_s: self.t_s[k + 1], previous_t_s: self.t_s[k] });
        }
        Ok(())
    }

    /// Read and validate a trace file (at most [`DEFAULT_MAX_ROWS`] rows).
    pub fn read_csv(path: &Path) -> Result<Self, TraceError> {
        Self::read_csv_with(path, &ReadOptions::default())
    }

    /// Read and validate a trace file with options. A file larger than
    /// [`ReadOptions::max_bytes`] is refused from its size, before any of it is read.
    pub fn read_csv_with(path: &Path, options: &ReadOptions) -> Result<Self, TraceError> {
        let f = open_limited(path, options)?;
        Self::from_csv_reader_with(f, path, options)
    }

    /// Read and validate a trace from any reader; `origin` names it in errors.
    pub fn from_csv_reader<R: Read>(reader: R, origin: &Path) -> Result<Self, TraceError> {
        Self::from_csv_reader_with(reader, origin, &ReadOptions::default())
    }

    /// Read and validate a trace from any reader, with options; `origin` names it in errors.
    /// Never panics, whatever the bytes.
    pub fn from_csv_reader_with<R: Read>(reader: R, origin: &Path, options: &ReadOptions) -> Result<Self, TraceError> {
        let table = read_table(reader, origin, options, |names, line| {
            check_required(names, origin, line)?;
            Ok(0)
        })?;
        let mut columns = table.columns;
        let extra_values = columns.split_off(REQUIRED_COLUMNS.len().min(columns.len()));
        let extra = table.names[REQUIRED_COLUMNS.len()..]
            .iter()
            .zip(extra_values)
            .map(|(name, values)| ExtraColumn { name: name.clone(), values })
            .collect();
        Ok(Trace::from_columns(table.meta, columns, extra))
    }

    /// A trace from its required columns in [`REQUIRED_COLUMNS`] order (missing ones empty)
    /// and its extra columns; see [`Trace::validate`].
    pub fn from_columns(meta: TraceMeta, required: Vec<Vec<f64>>, extra: Vec<ExtraColumn>) -> Self {
        let mut columns = required.into_iter();
        let mut next = || columns.next().unwrap_or_default();
        Self {
            meta,
            t_s: next(),
            q1_um: next(),
            q2_um: next(),
            q3_um: next(),
            q4_deg: next(),
            q5_deg: next(),
            q6_deg: next(),
            wavelength_nm: next(),
            irradiance: next(),
            extra,
        }
    }

    /// The `#` metadata lines, each ending in `\n`.
    fn meta_lines(&self) -> String {
        let m = &self.meta;
        let mut s = String::new();
        s.push_str(FORMAT_LINE);
        s.push('\n');
        for (key, value) in [
            ("label", m.label.as_str()),
            ("kind", m.kind.as_str()),
            ("bench", m.bench.as_str()),
            ("irradiance_unit", m.irradiance_unit.as_str()),
            ("notes", m.notes.as_str()),
        ] {
            let _ = writeln!(s, "# {key}: {}", escape_meta(value));
        }
        s
    }

    /// Write the trace as CSV to any writer (after [`Trace::validate`]); `origin` names the
    /// destination in errors. Numbers are written in shortest round-trip form.
    pub fn write_csv_to<W: Write>(&self, writer: W, origin: &Path) -> Result<(), TraceError> {
        self.validate()?;
        if self.is_empty() {
            return Err(TraceError::WriteEmpty { file: origin.to_path_buf() });
        }
        let io_err = |e: std::io::Error| {
            TraceError::File(FileError::Io { file: origin.to_path_buf(), action: "cannot write", source: e })
        };
        let csv_err = |e: csv::Error| match e.into_kind() {
            csv::ErrorKind::Io(source) => io_err(source),
            other => {
                TraceError::File(FileError::Serialise { file: origin.to_path_buf(), message: format!("{other:?}") })
            }
        };
        let mut writer = std::io::BufWriter::with_capacity(64 * 1024, writer);
        writer.write_all(self.meta_lines().as_bytes()).map_err(io_err)?;
        let mut w = csv::WriterBuilder::new().terminator(csv::Terminator::Any(b'\n')).from_writer(&mut writer);
        let columns: Vec<&[f64]> = self.columns().map(|(_, v)| v).collect();
        w.write_record(self.columns().map(|(name, _)| name)).map_err(csv_err)?;
        let mut text = String::with_capacity(32 * columns.len());
        let mut ends = Vec::with_capacity(columns.len());
        for i in 0..self.len() {
            text.clear();
            ends.clear();
            for col in &columns {
                // `{:?}` is the shortest representation that parses back to the same bits.
                let _ = write!(text, "{:?}", col[i]);
                ends.push(text.len());
            }
            let fields = ends.iter().scan(0, |start, &end| {
                let f = &text[*start..end];
                *start = end;
                Some(f)
            });
            w.write_record(fields).map_err(csv_err)?;
        }
        w.flush().map_err(io_err)?;
        drop(w);
        writer.flush().map_err(io_err)
    }

    /// The trace as CSV bytes (see [`Trace::write_csv_to`]).
    pub fn to_csv_bytes(&self, origin: &Path) -> Result<Vec<u8>, TraceError> {
        let mut out = Vec::with_capacity(self.len() * (10 + 12 * self.columns().count()));
        self.write_csv_to(&mut out, origin)?;
        Ok(out)
    }

    /// Validate and save atomically (a crash leaves the old file or the new one, never half).
    pub fn write_csv(&self, path: &Path) -> Result<(), TraceError> {
        let bytes = self.to_csv_bytes(path)?;
        write_atomic(path, &bytes)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

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

    #[test]
    fn every_bad_input_class_names_file_line_and_expectation() {
        let row = |t: &str| format!("{t},0,0,0,0,0,0,1560,0.5");
        let ok2 = format!("{HEADER}\n{}\n{}\n", row("0"), row("0.1"));
        let cases: Vec<(&str, String, Vec<&str>)> = vec![
            ("empty file", String::new(), vec!["bad.csv: truncated file: no header row", "expected a header line `t_s,q1_um"]),
            ("meta only", "# photorobot trace v1\n# label: x\n".into(), vec!["bad.csv: truncated file: no header row"]),
            (
                "missing columns",
                "t_s,q1_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,irradiance\n0,0,0,0,0,0,1560,1\n".into(),
                vec!["bad.csv:1: missing required column(s) `q2_um`", "expected the header to start with `t_s,q1_um,q2_um"],
            ),
            (
                "unknown column in place of a required one",
                format!("# c\n{}\n{}\n", HEADER.replace("t_s", "time"), row("0")),
                vec!["bad.csv:2: missing required column(s) `t_s`; unknown column(s) in their place: `time`", "found `time,q1_um"],
            ),
            (
                "misordered columns",
                format!("{}\n{}\n", HEADER.replace("q1_um,q2_um", "q2_um,q1_um"), row("0")),
                vec!["bad.csv:1: column `q1_um` is column 3, expected column 2", "expected the header to start with"],
            ),
            (
                "required column after an extra",
                "t_s,q1_um,q2_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,extra,irradiance\n".into(),
                vec!["bad.csv:1: column `irradiance` is column 10, expected column 9"],
            ),
            ("duplicate column", format!("{HEADER},a,a\n"), vec!["bad.csv:1: header column 11: column `a` appears twice (also column 10)"]),
            ("empty column name", format!("{HEADER},,b\n"), vec!["bad.csv:1: header column 10: expected a column name, found an empty one"]),
            (
                "too few fields",
                format!("{ok2}0.2,0,0,0,0,0,0,1560\n"),
                vec!["bad.csv:4: expected 9 fields (one per header column), found 8 (truncated row?)"],
            ),
            ("too many fields", format!("{ok2}{},7\n", row("0.2")), vec!["bad.csv:4: expected 9 fields (one per header column), found 10"]),
            ("non-numeric", format!("{ok2}0.2,0,0,abc,0,0,0,1560,0.5\n"), vec!["bad.csv:4: column `q3_um`: expected a number, found `abc`"]),
            ("empty field", format!("{ok2}0.2,0,0,0,,0,0,1560,0.5\n"), vec!["bad.csv:4: column `q4_deg`: expected a number, found an empty field"]),
            ("NaN", format!("{ok2}0.2,0,0,0,0,NaN,0,1560,0.5\n"), vec!["bad.csv:4: column `q5_deg`: expected a finite number, found NaN"]),
            ("infinite", format!("{ok2}0.2,0,0,0,0,0,0,1560,-inf\n"), vec!["bad.csv:4: column `irradiance`: expected a finite number, found -inf"]),
            ("overflow", format!("{ok2}0.2,0,0,0,0,0,0,1e999,0.5\n"), vec!["bad.csv:4: column `wavelength_nm`: expected a finite number, found inf"]),
            (
                "time goes back",
                format!("{ok2}{}\n", row("0.05")),
                vec!["bad.csv:4: column `t_s`: time 0.05 s is not after 0.1 s on line 3 (expected strictly increasing time)"],
            ),
            (
                "time repeats",
                format!("{HEADER}\n{}\n\n{}\n", row("2"), row("2")),
                vec!["bad.csv:4: column `t_s`: time 2 s is not after 2 s on line 2"],
            ),
            ("header only", format!("# photorobot trace v1\n{HEADER}\n"), vec!["bad.csv: empty trace: the header is followed by no data rows (expected at least one row)"]),
            ("bad kind", format!("# kind: Wobble\n{ok2}"), vec!["bad.csv:1: metadata `kind`: expected Motion, WavelengthSweep or Static, found `Wobble`"]),
            ("future version", format!("# photorobot trace v2\n{ok2}"), vec!["bad.csv:1: unsupported format `# photorobot trace v2` (expected `# photorobot trace v1`)"]),
            ("not UTF-8 field", format!("{ok2}0.2,0,0,0,0,0,0,1560,\u{FFFD}\n"), vec!["bad.csv:4: column `irradiance`: expected a number"]),
        ];
        for (name, text, wants) in &cases {
            let err = read_str(text).expect_err(name).to_string();
            for want in wants {
                assert!(err.contains(want), "{name}: got `{err}`, want `{want}`");
            }
        }
        // Raw invalid UTF-8 in a header name.
        let mut bytes = format!("{HEADER},").into_bytes();
        bytes.extend_from_slice(b"\xff\xfe\n");
        let err = Trace::from_csv_reader(&bytes[..], Path::new("bad.csv")).unwrap_err().to_string();
        assert!(err.starts_with("bad.csv:1: header column 10: expected a column name in UTF-8 text"), "{err}");
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
        let text =
            "t_s, q1_um, q2_um, q3_um, q4_deg, q5_deg, q6_deg, wavelength_nm, irradiance, temperature_C, pd2_V\r\n\
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
        match Trace::from_csv_reader(bytes, Path::new("fuzz.csv")) {
            Ok(t) => {
                t.validate().unwrap();
                assert!(!t.is_empty());
            }
            Err(e) => assert!(e.to_string().starts_with("fuzz.csv"), "{e}"),
        }
    }

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
}
