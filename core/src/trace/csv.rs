//! Our own trace format on disk: reading a file (the required columns first, the rest kept as
//! extra columns) and writing one atomically, bit-exact on reading back.

use super::plain::read_table_bytes;
use super::table::{open_limited, read_table_sized, Dialect, MetaLine, ReadOptions, Table};
use super::{escape_meta, ExtraColumn, Trace, TraceError, FORMAT_LINE, REQUIRED_COLUMNS};
use crate::files::{write_atomic, FileError};
use rayon::prelude::*;
use std::fmt::Write as _;
use std::io::{Read, Write};
use std::path::Path;

/// Rows formatted as one block of text, and blocks formatted at once (about 0.5 MB each).
const ROWS_PER_BLOCK: usize = 8192;
const BLOCKS_PER_BATCH: usize = 16;

/// The CSV text of `rows`: `ryu` writes the shortest text that parses back to the same bits (as
/// `{:?}` does) several times faster.
fn format_rows(columns: &[&[f64]], rows: std::ops::Range<usize>) -> Vec<u8> {
    let mut number = ryu::Buffer::new();
    let mut text = Vec::with_capacity(rows.len() * 16 * columns.len());
    for i in rows {
        for (c, col) in columns.iter().enumerate() {
            if c > 0 {
                text.push(b',');
            }
            text.extend_from_slice(number.format(col[i]).as_bytes());
        }
        text.push(b'\n');
    }
    text
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

impl Trace {
    /// Read and validate a trace file (at most [`DEFAULT_MAX_ROWS`](super::DEFAULT_MAX_ROWS) rows).
    pub fn read_csv(path: &Path) -> Result<Self, TraceError> {
        Self::read_csv_with(path, &ReadOptions::default())
    }

    /// Read and validate a trace file with options. A file larger than
    /// [`ReadOptions::max_bytes`] is refused from its size, before any of it is read.
    pub fn read_csv_with(path: &Path, options: &ReadOptions) -> Result<Self, TraceError> {
        let file = open_limited(path, options)?;
        let size = file.metadata().ok().map(|m| m.len());
        Self::from_csv_sized(file, path, options, size)
    }

    /// Read and validate a trace from any reader; `origin` names it in errors.
    pub fn from_csv_reader<R: Read>(reader: R, origin: &Path) -> Result<Self, TraceError> {
        Self::from_csv_reader_with(reader, origin, &ReadOptions::default())
    }

    /// Read and validate a trace from any reader, with options; `origin` names it in errors.
    /// Never panics, whatever the bytes.
    pub fn from_csv_reader_with<R: Read>(reader: R, origin: &Path, options: &ReadOptions) -> Result<Self, TraceError> {
        Self::from_csv_sized(reader, origin, options, None)
    }

    /// Read and validate a trace held in memory (a whole file's bytes), with options; `origin`
    /// names it in errors. The same trace as [`Trace::from_csv_reader_with`], read faster.
    pub fn from_csv_bytes(bytes: &[u8], origin: &Path, options: &ReadOptions) -> Result<Self, TraceError> {
        Ok(Self::from_csv_bytes_keyed(bytes, origin, options)?.0)
    }

    /// [`Trace::from_csv_bytes`] with every `# key: value` line of the file.
    pub(crate) fn from_csv_bytes_keyed(
        bytes: &[u8],
        origin: &Path,
        options: &ReadOptions,
    ) -> Result<(Self, Vec<MetaLine>), TraceError> {
        let mut table = read_table_bytes(bytes, origin, options, |names, line| {
            check_required(names, origin, line)?;
            Ok(0)
        })?;
        let keyed = std::mem::take(&mut table.meta_lines);
        Ok((Self::from_table(table), keyed))
    }

    /// [`Trace::from_csv_reader_with`] of an input of `size_bytes` when known (the columns are
    /// sized from it).
    pub(crate) fn from_csv_sized<R: Read>(
        reader: R,
        origin: &Path,
        options: &ReadOptions,
        size_bytes: Option<u64>,
    ) -> Result<Self, TraceError> {
        let table = read_table_sized(reader, origin, options, size_bytes, Dialect::OURS, |names, line| {
            check_required(names, origin, line)?;
            Ok(0)
        })?;
        Ok(Self::from_table(table))
    }

    /// The trace of a table whose required columns were checked: the rest are extra columns.
    fn from_table(table: Table) -> Self {
        let mut columns = table.columns;
        let extra_values = columns.split_off(REQUIRED_COLUMNS.len().min(columns.len()));
        let extra = table.names[REQUIRED_COLUMNS.len()..]
            .iter()
            .zip(extra_values)
            .map(|(name, values)| ExtraColumn { name: name.clone(), values })
            .collect();
        Trace::from_columns(table.meta, columns, extra)
    }

    /// The `#` metadata lines, each ending in `\n`.
    fn meta_lines(&self) -> String {
        let m = &self.meta;
        let mut lines = String::new();
        lines.push_str(FORMAT_LINE);
        lines.push('\n');
        for (key, value) in [
            ("label", m.label.as_str()),
            ("kind", m.kind.as_str()),
            ("bench", m.bench.as_str()),
            ("irradiance_unit", m.irradiance_unit.as_str()),
            ("notes", m.notes.as_str()),
        ] {
            let _ = writeln!(lines, "# {key}: {}", escape_meta(value));
        }
        if m.wavelength_scale_sigma_ppm > 0.0 {
            let _ = writeln!(lines, "# wavelength_scale_sigma_ppm: {}", m.wavelength_scale_sigma_ppm);
        }
        lines
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
        let mut csv_writer = csv::WriterBuilder::new().terminator(csv::Terminator::Any(b'\n')).from_writer(&mut writer);
        let columns: Vec<&[f64]> = self.columns().map(|(_, v)| v).collect();
        csv_writer.write_record(self.columns().map(|(name, _)| name)).map_err(csv_err)?;
        csv_writer.flush().map_err(io_err)?;
        drop(csv_writer);
        // The rows by hand: numbers need no quoting. Blocks of rows are formatted on every core,
        // a bounded number at a time, and written in order.
        let blocks: Vec<usize> = (0..self.len()).step_by(ROWS_PER_BLOCK).collect();
        for batch in blocks.chunks(BLOCKS_PER_BATCH) {
            let texts: Vec<Vec<u8>> = batch
                .par_iter()
                .map(|&start| format_rows(&columns, start..(start + ROWS_PER_BLOCK).min(self.len())))
                .collect();
            for text in texts {
                writer.write_all(&text).map_err(io_err)?;
            }
        }
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
