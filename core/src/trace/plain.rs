//! Reading a table held in memory, fast: the rows of the files we write (numbers between
//! commas, one row per line, no quotes) split at their commas and line ends directly, without
//! the `csv` crate's general tokenizer. A table with anything else in it (a quote, a header the
//! full reader would skip, a bad row) is read again by [`read_table_sized`], which then reads it
//! or names its problem: this path only ever returns the table that one would.

use super::table::{check_names, read_meta, read_table_sized, Dialect, ReadOptions, Rows, Table};
use super::TraceError;
use std::path::Path;

/// [`read_table`](super::read_table) of a whole input held in memory.
pub(crate) fn read_table_bytes(
    bytes: &[u8],
    origin: &Path,
    options: &ReadOptions,
    header: impl Fn(&[String], usize) -> Result<usize, TraceError>,
) -> Result<Table, TraceError> {
    match plain_table(bytes, origin, options, &header) {
        Some(table) => Ok(table),
        None => read_table_sized(bytes, origin, options, Some(bytes.len() as u64), Dialect::OURS, header),
    }
}

/// The table of `bytes` when every line after the metadata is a plain row, a comment or
/// blank, and every row is good; `None` otherwise.
pub(super) fn plain_table(
    bytes: &[u8],
    origin: &Path,
    options: &ReadOptions,
    header: &impl Fn(&[String], usize) -> Result<usize, TraceError>,
) -> Option<Table> {
    if memchr::memchr(b'"', bytes).is_some() {
        return None;
    }
    let mut rest = bytes;
    let (meta, meta_lines, keyed) = read_meta(&mut rest, origin).ok()?;
    let mut lines = Lines(rest);
    let header_text = lines.next()?;
    if header_text.first() == Some(&b'#') || header_text.trim_ascii().is_empty() {
        return None;
    }
    let header_line = meta_lines + 1;
    let record = csv::ByteRecord::from(header_text.split(|&b| b == b',').collect::<Vec<_>>());
    let names = check_names(&record, origin, header_line).ok()?;
    let time_column = header(&names, header_line).ok()?;
    let mut rows = Rows::new(names.len(), time_column, Some(bytes.len() as u64));
    for line in lines {
        // The lines the full reader skips: empty, a comment, or blank (one field, a `\r`).
        if line.first() == Some(&b'#') || line.iter().all(u8::is_ascii_whitespace) {
            continue;
        }
        if rows.len() >= options.max_rows {
            return None;
        }
        rows.push(line.split(|&b| b == b','), line.len() + 1, options.max_rows).ok()?;
    }
    (rows.len() > 0).then(|| Table { meta, meta_lines: keyed, header_line, names, columns: rows.into_columns() })
}

/// The lines of a text, each without its `\n`.
struct Lines<'a>(&'a [u8]);

impl<'a> Iterator for Lines<'a> {
    type Item = &'a [u8];

    fn next(&mut self) -> Option<&'a [u8]> {
        if self.0.is_empty() {
            return None;
        }
        let end = memchr::memchr(b'\n', self.0).unwrap_or(self.0.len());
        let line = &self.0[..end];
        self.0 = &self.0[(end + 1).min(self.0.len())..];
        Some(line)
    }
}
