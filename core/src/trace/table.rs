//! Reading a numeric CSV table under the trace format's rules: the `# key: value` metadata
//! lines, the header, finite numbers, strictly increasing time and size limits. Both our own
//! format and foreign imports read through [`read_table`].

use super::{unescape_meta, TraceError, TraceKind, TraceMeta, DEFAULT_MAX_BYTES, DEFAULT_MAX_ROWS};
use crate::files::FileError;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// Longest metadata line accepted (bytes); longer ones are refused rather than read whole.
const MAX_META_LINE_BYTES: u64 = 64 * 1024;

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

/// How a file separates its fields and writes its decimals.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dialect {
    /// The field separator: `,`, `;` or a tab.
    pub separator: u8,
    /// A decimal comma is read as well as a decimal point (never with `,` as the separator): a
    /// file uses one mark throughout, the first one a number of it shows.
    pub decimal_comma: bool,
}

impl Dialect {
    /// Our format: commas between fields, a decimal point.
    pub const OURS: Dialect = Dialect { separator: b',', decimal_comma: false };
}

/// The decimal mark of a file, as its numbers show it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mark {
    /// No number with a fraction yet.
    Unknown,
    Point,
    Comma,
}

impl Mark {
    fn words(self) -> &'static str {
        match self {
            Mark::Comma => "a decimal comma",
            _ => "a decimal point",
        }
    }
}

/// Parse a field that may use a decimal comma, holding the file to the first mark it used.
fn parse_with_mark(field: &[u8], mark: &mut Mark) -> Result<f64, Option<Mark>> {
    let bytes = field.trim_ascii();
    let (point, comma) = (bytes.contains(&b'.'), bytes.contains(&b','));
    let this = match (point, comma) {
        (true, true) => return Err(None),
        (true, false) => Mark::Point,
        (false, true) => Mark::Comma,
        (false, false) => Mark::Unknown,
    };
    if this != Mark::Unknown {
        if *mark != Mark::Unknown && *mark != this {
            return Err(Some(*mark));
        }
        *mark = this;
    }
    if this != Mark::Comma {
        return parse_field(bytes).ok_or(None);
    }
    let mut buffer = [0u8; 64];
    let text = buffer.get_mut(..bytes.len()).ok_or(None)?;
    for (to, &from) in text.iter_mut().zip(bytes) {
        *to = if from == b',' { b'.' } else { from };
    }
    parse_field(text).ok_or(None)
}

/// The last field read in a column and its value: most columns of a recording repeat their
/// field row after row (the stages that do not move, a fixed wavelength), and comparing a few
/// bytes costs a fraction of parsing them.
#[derive(Clone, Default)]
struct LastField {
    bytes: [u8; 32],
    /// Length of the field in `bytes`; 0 before the first (an empty field is never a number).
    len: usize,
    value: f64,
}

impl LastField {
    /// The value of `field` when it is the last field kept, byte for byte.
    fn value_of(&self, field: &[u8]) -> Option<f64> {
        (self.len > 0 && field == &self.bytes[..self.len]).then_some(self.value)
    }

    /// Keep `field` (parsed to the finite `value`) when it fits.
    fn keep(&mut self, field: &[u8], value: f64) {
        if let Some(bytes) = self.bytes.get_mut(..field.len()) {
            bytes.copy_from_slice(field);
            self.len = field.len();
            self.value = value;
        }
    }
}

/// A `# key: value` line before the header: its 1-based line, its key (trimmed, lower case) and
/// its value (unescaped).
#[derive(Debug, Clone, PartialEq)]
pub struct MetaLine {
    /// 1-based line of the file.
    pub line: usize,
    /// The key, trimmed and in lower case.
    pub key: String,
    /// The value, unescaped.
    pub value: String,
}

/// Read the metadata lines (and blank lines) before the header. Returns the metadata, the
/// number of lines consumed and every `key: value` line (known keys and others).
pub(super) fn read_meta<R: BufRead>(
    reader: &mut R,
    file: &Path,
) -> Result<(TraceMeta, usize, Vec<MetaLine>), TraceError> {
    let io_err = |source| TraceError::File(FileError::Io { file: file.to_path_buf(), action: "cannot read", source });
    let mut meta = TraceMeta::default();
    let mut lines = 0usize;
    let mut line = Vec::new();
    let mut keyed = Vec::new();
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
        let key = key.trim().to_ascii_lowercase();
        keyed.push(MetaLine { line: lines, key: key.clone(), value: value.clone() });
        match key.as_str() {
            "label" => meta.label = value,
            "bench" => meta.bench = value,
            "irradiance_unit" => meta.irradiance_unit = value,
            "notes" => meta.notes = value,
            "wavelength_scale_sigma_ppm" => {
                meta.wavelength_scale_sigma_ppm =
                    value.trim().parse::<f64>().ok().filter(|v| v.is_finite() && *v >= 0.0).ok_or_else(|| {
                        TraceError::BadMeta {
                            file: file.to_path_buf(),
                            line: lines,
                            key: "wavelength_scale_sigma_ppm".into(),
                            expected: "a finite non-negative number (ppm)".into(),
                            found: value.clone(),
                        }
                    })?
            }
            "kind" => {
                meta.kind = TraceKind::parse(&value).ok_or_else(|| TraceError::BadMeta {
                    file: file.to_path_buf(),
                    line: lines,
                    key: "kind".into(),
                    expected: "Motion, WavelengthSweep or Static".into(),
                    found: value.clone(),
                })?
            }
            _ => {} // unknown keys are ignored here (forward compatibility, other systems)
        }
    }
    Ok((meta, lines, keyed))
}

/// Check the header row's names: UTF-8, non-empty, on one line, unique. Returns them trimmed.
pub(super) fn check_names(header: &csv::ByteRecord, file: &Path, line: usize) -> Result<Vec<String>, TraceError> {
    let mut names = Vec::with_capacity(header.len());
    for (i, field) in header.iter().enumerate() {
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

/// A numeric CSV table as read from a file: the `#` metadata lines, the column names and one
/// vector per column. Every value is finite, every row has one field per column, the time
/// column strictly increases and there is at least one row.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// Metadata from the `# key: value` lines (defaults where absent).
    pub meta: TraceMeta,
    /// Every `# key: value` line before the header, known keys and others.
    pub meta_lines: Vec<MetaLine>,
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
    read_table_sized(reader, origin, options, None, Dialect::OURS, header)
}

/// [`read_table`] of an input of `size_bytes` when known: the columns are sized from it and the
/// first row's length instead of growing row by row.
pub(crate) fn read_table_sized<R: Read>(
    reader: R,
    origin: &Path,
    options: &ReadOptions,
    size_bytes: Option<u64>,
    dialect: Dialect,
    header: impl FnOnce(&[String], usize) -> Result<usize, TraceError>,
) -> Result<Table, TraceError> {
    let file = || origin.to_path_buf();
    let mut input = BufReader::with_capacity(64 * 1024, reader);
    let (meta, meta_lines, keyed) = read_meta(&mut input, origin)?;
    // A final '\n' makes every record end with one, so the reader's line count after a
    // record is always one past the record's (last) line. `\r` before it is trimmed as space.
    let mut csv_reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .delimiter(dialect.separator)
        .terminator(csv::Terminator::Any(b'\n'))
        .comment(Some(b'#'))
        .buffer_capacity(64 * 1024)
        .from_reader(input.chain(&b"\n"[..]));
    let mut record = csv::ByteRecord::new();
    let mut next_record = |record: &mut csv::ByteRecord| -> Result<Option<usize>, TraceError> {
        loop {
            let more = csv_reader.read_byte_record(record).map_err(|e| {
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
            if record.len() == 1 && record[0].iter().all(|b| b.is_ascii_whitespace()) {
                continue;
            }
            let line = meta_lines + (csv_reader.position().line() as usize).saturating_sub(1);
            return Ok(Some(line));
        }
    };

    let Some(header_line) = next_record(&mut record)? else {
        return Err(TraceError::NoHeader { file: file() });
    };
    let names = check_names(&record, origin, header_line)?;
    let time_column = header(&names, header_line)?;
    let mut rows = Rows::new(names.len(), time_column, size_bytes);
    rows.decimal_comma = dialect.decimal_comma;
    let mut previous_line = header_line;
    while let Some(line) = next_record(&mut record)? {
        if rows.len() >= options.max_rows {
            return Err(TraceError::TooLarge { file: file(), line, max_rows: options.max_rows });
        }
        let bad = |bad: BadRow| bad.at(origin, (line, previous_line), &names, dialect);
        if record.len() != names.len() {
            return Err(bad(BadRow::FieldCount { expected: names.len(), found: record.len() }));
        }
        let row_bytes = record.as_slice().len() + record.len();
        rows.push(record.iter(), row_bytes, options.max_rows).map_err(bad)?;
        previous_line = line;
    }
    if rows.len() == 0 {
        return Err(TraceError::EmptyTrace { file: file() });
    }
    Ok(Table { meta, meta_lines: keyed, header_line, names, columns: rows.into_columns() })
}

/// What is wrong with a data row, before the file and line are known.
#[derive(Debug)]
pub(super) enum BadRow {
    FieldCount {
        expected: usize,
        found: usize,
    },
    NotANumber {
        column: usize,
        text: String,
    },
    /// A number with the other decimal mark than the file's earlier numbers.
    MixedDecimalMarks {
        column: usize,
        text: String,
        earlier: &'static str,
    },
    NonFinite {
        column: usize,
        value: f64,
    },
    NonMonotonicTime {
        column: usize,
        t: f64,
        previous_t: f64,
    },
}

impl BadRow {
    /// The error of this row at `lines.0` of `file` (`lines.1`: the row before it).
    fn at(self, file: &Path, (line, previous_line): (usize, usize), names: &[String], dialect: Dialect) -> TraceError {
        let file = file.to_path_buf();
        match self {
            BadRow::FieldCount { expected, found } => {
                let hint = match (found < expected, dialect.separator) {
                    (true, _) => " (truncated row?)".to_string(),
                    (false, b',') => " (a decimal comma with `,` as the separator cannot be read: export with `;` \
                                      as the separator, or with a decimal point)"
                        .to_string(),
                    _ => String::new(),
                };
                TraceError::FieldCount { file, line, expected, found, hint }
            }
            BadRow::NotANumber { column, text } => {
                TraceError::NotANumber { file, line, column: names[column].clone(), text }
            }
            BadRow::MixedDecimalMarks { column, text, earlier } => {
                TraceError::MixedDecimalMarks { file, line, column: names[column].clone(), text, earlier }
            }
            BadRow::NonFinite { column, value } => {
                TraceError::NonFinite { file, line, column: names[column].clone(), value }
            }
            BadRow::NonMonotonicTime { column, t, previous_t } => {
                TraceError::NonMonotonicTime { file, line, column: names[column].clone(), t, previous_line, previous_t }
            }
        }
    }
}

/// The columns of a table as its rows arrive: every field parsed, every value finite, the time
/// column strictly increasing.
pub(super) struct Rows {
    columns: Vec<Vec<f64>>,
    last: Vec<LastField>,
    time_column: usize,
    /// Size of the input when known, to reserve the columns from the first row's length.
    size_bytes: Option<u64>,
    rows: usize,
    /// A decimal comma is read as well as a point ([`Dialect::decimal_comma`]).
    pub(super) decimal_comma: bool,
    mark: Mark,
}

impl Rows {
    pub(super) fn new(n_cols: usize, time_column: usize, size_bytes: Option<u64>) -> Self {
        Self {
            columns: vec![Vec::new(); n_cols],
            last: vec![LastField::default(); n_cols],
            time_column,
            size_bytes,
            rows: 0,
            decimal_comma: false,
            mark: Mark::Unknown,
        }
    }

    pub(super) fn len(&self) -> usize {
        self.rows
    }

    /// Add a row of `fields` (`row_bytes` long in the input, with its delimiters). A wrong
    /// number of fields is found after the fields before it are parsed: a caller that must
    /// report it first checks it first.
    pub(super) fn push<'a>(
        &mut self,
        mut fields: impl Iterator<Item = &'a [u8]>,
        row_bytes: usize,
        max_rows: usize,
    ) -> Result<(), BadRow> {
        let n_cols = self.columns.len();
        if let Some(size) = self.size_bytes.take() {
            // The rows of a recording are about as long as its first.
            let rows_est = size / row_bytes.max(1) as u64 + 1;
            self.columns.iter_mut().for_each(|c| c.reserve(rows_est.min(max_rows as u64) as usize));
        }
        for column in 0..n_cols {
            let field = fields.next().ok_or(BadRow::FieldCount { expected: n_cols, found: column })?;
            let value = match self.last[column].value_of(field) {
                Some(value) => value,
                None => {
                    let value = if self.decimal_comma {
                        parse_with_mark(field, &mut self.mark).map_err(|earlier| match earlier {
                            Some(m) => {
                                BadRow::MixedDecimalMarks { column, text: field_text(field), earlier: m.words() }
                            }
                            None => BadRow::NotANumber { column, text: field_text(field) },
                        })?
                    } else {
                        parse_field(field).ok_or_else(|| BadRow::NotANumber { column, text: field_text(field) })?
                    };
                    if !value.is_finite() {
                        return Err(BadRow::NonFinite { column, value });
                    }
                    self.last[column].keep(field, value);
                    value
                }
            };
            self.columns[column].push(value);
        }
        let more = fields.count();
        if more > 0 {
            return Err(BadRow::FieldCount { expected: n_cols, found: n_cols + more });
        }
        let time = &self.columns[self.time_column];
        if let [.., previous_t, t] = time[..] {
            if t <= previous_t {
                return Err(BadRow::NonMonotonicTime { column: self.time_column, t, previous_t });
            }
        }
        self.rows += 1;
        Ok(())
    }

    /// The columns, each as long as the rows read.
    pub(super) fn into_columns(self) -> Vec<Vec<f64>> {
        let mut columns = self.columns;
        // A first row much shorter than the others sized the columns too large.
        for c in columns.iter_mut().filter(|c| c.capacity() > c.len() + c.len() / 2) {
            c.shrink_to_fit();
        }
        columns
    }
}
