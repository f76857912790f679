//! Why a trace could not be read, written, imported or accepted.

use super::{FORMAT_LINE, REQUIRED_COLUMNS};
use crate::files::FileError;
use std::path::PathBuf;
use thiserror::Error;

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
        file = .file.display())]
    FieldCount {
        /// The file.
        file: PathBuf,
        /// Line of the row.
        line: usize,
        /// Number of header columns.
        expected: usize,
        /// Number of fields in the row.
        found: usize,
        /// What may have caused it, in parentheses after a space, or empty.
        hint: String,
    },
    /// A number with the other decimal mark than the file's earlier numbers: a file holds to one.
    #[error("{file}:{line}: column `{column}`: `{text}` does not use {earlier}, as the earlier numbers of this file do \
             (expected one decimal mark throughout a file)", file = .file.display())]
    MixedDecimalMarks {
        /// The file.
        file: PathBuf,
        /// Line of the row.
        line: usize,
        /// Column name.
        column: String,
        /// The field as found.
        text: String,
        /// The mark of the earlier numbers, in words.
        earlier: &'static str,
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
    /// More data rows than [`ReadOptions::max_rows`](super::ReadOptions::max_rows).
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
    /// A lab's file: one of our columns is neither in the header nor given otherwise.
    #[error("{file}:{line}: no `{column}` column: {how}; found `{found}` (a file whose names are not ours reads through a column mapping, --mapping)", file = .file.display())]
    LabColumnMissing {
        /// The file.
        file: PathBuf,
        /// Line of the header.
        line: usize,
        /// Our column(s) missing.
        column: String,
        /// The header as found (joined with commas).
        found: String,
        /// What would give it.
        how: String,
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
        /// 0-based index in [`Trace::extra`](super::Trace::extra).
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
