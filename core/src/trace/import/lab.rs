//! Trace files as other labs' recorders write them, read without a mapping: the separator and the decimal mark
//! found from the file, our columns found by name in any order and case with their unit in the name, constants given once.
//!
//! - **Separator**: `,`, `;` or a tab, whichever splits the header into the most fields. With `;` or a
//!   tab, numbers may use a decimal comma; a file holds to the first mark its numbers show, and a
//!   number with the other mark is refused with its line and column. A decimal comma with `,` as the
//!   separator cannot be told from a separator: such a row has more fields than the header, and is
//!   refused so.
//! - **Names**: a column is ours when its name, trimmed and in any case, is a quantity and a unit:
//!   `t` or `time`, `q1`…`q6`, `wavelength` or `lambda`, `irradiance`; the unit after an underscore
//!   (`t_ms`), in brackets (`t [ms]`) or parentheses (`t (ms)`), among the units of the column mapping
//!   ([`super::mapping::unit_factor`]). The irradiance may have any unit or none. A quantity without a
//!   unit (`t`, `q1`) is refused: seconds or milliseconds is not a guess to make. Other columns are kept
//!   as extra columns.
//! - **Constants**: a quantity the file has no column for may be given once in a comment line before
//!   the header, `# wavelength_nm: 1560` or `# wavelength: 1560 nm` (also a joint the recorder does not
//!   log, `# q6_deg: 0`), or for a whole folder by the caller ([`Constants`]). A line and a column for
//!   the same quantity are refused. The time and the irradiance must be columns.

use super::mapping::{known_units, unit_factor};
use crate::trace::table::{read_table_sized, Dialect, MetaLine, ReadOptions, Table};
use crate::trace::{ExtraColumn, Trace, TraceError, REQUIRED_COLUMNS};
use std::path::Path;

/// Values given for a whole folder, for files that have neither a column nor a comment line for
/// them (our column name → value in our unit).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Constants {
    /// The laser's fixed wavelength (nm).
    pub wavelength_nm: Option<f64>,
}

/// The quantity names each of our columns answers to (lower case).
const STEMS: [&[&str]; 9] =
    [&["t", "time"], &["q1"], &["q2"], &["q3"], &["q4"], &["q5"], &["q6"], &["wavelength", "lambda"], &["irradiance"]];

/// A name split into a quantity of ours (index into [`REQUIRED_COLUMNS`]) and its unit as written.
fn recognise(name: &str) -> Option<(usize, Option<String>)> {
    let name = name.trim();
    let (stem, unit) = split_unit(name);
    let stem = stem.to_lowercase();
    let column = STEMS.iter().position(|s| s.contains(&stem.as_str()))?;
    Some((column, unit.map(str::to_string)))
}

/// `t [ms]`, `t (ms)` and `t_ms` → (`t`, `ms`); a name without a unit → (name, None).
fn split_unit(name: &str) -> (&str, Option<&str>) {
    for (open, close) in [('[', ']'), ('(', ')')] {
        if let Some(inner) = name.strip_suffix(close).and_then(|n| n.rsplit_once(open)) {
            return (inner.0.trim(), Some(inner.1.trim()));
        }
    }
    match name.rsplit_once('_') {
        Some((stem, unit)) if STEMS.iter().any(|s| s.contains(&stem.to_lowercase().as_str())) => (stem, Some(unit)),
        _ => (name, None),
    }
}

/// The factor from `unit` (any case) to our column's unit, or why not.
fn factor(column: usize, unit: Option<&str>) -> Result<f64, String> {
    let ours = REQUIRED_COLUMNS[column];
    match unit {
        None if column == 8 => Ok(1.0),
        None => Err(format!(
            "no unit in the name (expected a unit after an underscore or in brackets, e.g. `{ours}`; units known: {})",
            known_units(ours)
        )),
        Some(u) => {
            let lower = u.to_lowercase();
            unit_factor(ours, &lower)
                .or_else(|| unit_factor(ours, u))
                .ok_or_else(|| format!("unknown unit `{u}` for {ours} (expected one of: {})", known_units(ours)))
        }
    }
}

/// Where each of our columns comes from in one file.
#[derive(Debug, Clone, Copy, PartialEq)]
enum From {
    /// A column of the file (index) and the factor to our unit.
    Column(usize, f64),
    /// A constant, in our unit.
    Constant(f64),
}

/// The separator of a header line: `,`, `;` or a tab, whichever gives the most fields.
fn separator_of(header: &[u8]) -> u8 {
    [b',', b';', b'\t']
        .into_iter()
        .max_by_key(|&s| (header.iter().filter(|&&b| b == s).count(), s == b','))
        .unwrap_or(b',')
}

/// The first line that is neither a comment nor blank (after a byte-order mark).
pub(super) fn header_line(bytes: &[u8]) -> &[u8] {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    bytes
        .split(|&b| b == b'\n')
        .find(|l| l.first() != Some(&b'#') && !l.iter().all(u8::is_ascii_whitespace))
        .unwrap_or(&[])
}

/// Read one file of another lab's export (the module documentation says what is accepted).
pub(super) fn read_lab(
    bytes: &[u8],
    path: &Path,
    options: &ReadOptions,
    folder: &Constants,
) -> Result<(Trace, Vec<MetaLine>), TraceError> {
    let separator = separator_of(header_line(bytes));
    let dialect = Dialect { separator, decimal_comma: separator != b',' };
    let mut columns: Option<Vec<Option<(usize, f64)>>> = None;
    let table = read_table_sized(bytes, path, options, Some(bytes.len() as u64), dialect, |names, line| {
        let found = header_columns(names, path, line)?;
        let time = found[0].map_or(0, |c| c.0);
        columns = Some(found);
        Ok(time)
    })?;
    let found = columns.unwrap_or_default();
    let sources = sources(&found, &table, path, folder, dialect)?;
    let rows = table.columns.first().map_or(0, Vec::len);
    let ours: Vec<Vec<f64>> = sources
        .iter()
        .map(|s| match *s {
            From::Column(c, f) => table.columns[c].iter().map(|v| v * f).collect(),
            From::Constant(v) => vec![v; rows],
        })
        .collect();
    let used: Vec<usize> = found.iter().flatten().map(|c| c.0).collect();
    let extra = table
        .names
        .iter()
        .zip(&table.columns)
        .enumerate()
        .filter(|(i, _)| !used.contains(i))
        .map(|(_, (name, values))| ExtraColumn { name: name.clone(), values: values.clone() })
        .collect();
    let mut meta = table.meta.clone();
    if let Some(i) = found[8].map(|c| c.0) {
        if let Some((_, Some(unit))) = recognise(&table.names[i]) {
            meta.irradiance_unit = unit;
        }
    }
    let trace = Trace::from_columns(meta, ours, extra);
    trace.validate().map_err(|e| TraceError::Imported { file: path.to_path_buf(), problem: e.to_string() })?;
    Ok((trace, table.meta_lines))
}

/// Our columns found in a header: (index in the file, factor to our unit) per column of ours.
fn header_columns(names: &[String], path: &Path, line: usize) -> Result<Vec<Option<(usize, f64)>>, TraceError> {
    let mut found: Vec<Option<(usize, f64)>> = vec![None; REQUIRED_COLUMNS.len()];
    for (i, name) in names.iter().enumerate() {
        let Some((column, unit)) = recognise(name) else { continue };
        let bad = |problem: String| TraceError::BadHeader { file: path.to_path_buf(), line, position: i + 1, problem };
        let f = factor(column, unit.as_deref()).map_err(|p| bad(format!("`{name}`: {p}")))?;
        if let Some((first, _)) = found[column] {
            return Err(bad(format!(
                "`{name}` gives {} again (also column {} `{}`); expected one column per quantity",
                REQUIRED_COLUMNS[column],
                first + 1,
                names[first]
            )));
        }
        found[column] = Some((i, f));
    }
    if found[0].is_none() || found[8].is_none() {
        let missing: Vec<&str> =
            [0, 8].into_iter().filter(|&c| found[c].is_none()).map(|c| REQUIRED_COLUMNS[c]).collect();
        return Err(TraceError::LabColumnMissing {
            file: path.to_path_buf(),
            line,
            column: missing.join(" and "),
            found: names.join(","),
            how: "they must be columns".into(),
        });
    }
    Ok(found)
}

/// Where each of our columns comes from: the file's column, its comment line, or the folder's
/// constant, in that order; a column and a comment line for one quantity are refused.
fn sources(
    found: &[Option<(usize, f64)>],
    table: &Table,
    path: &Path,
    folder: &Constants,
    dialect: Dialect,
) -> Result<Vec<From>, TraceError> {
    let mut out = Vec::with_capacity(REQUIRED_COLUMNS.len());
    for (column, f) in found.iter().enumerate() {
        let line = table.meta_lines.iter().find(|m| recognise(&m.key).is_some_and(|r| r.0 == column));
        let given = line.map(|m| constant(m, column, path, dialect)).transpose()?;
        out.push(match (f, given) {
            (Some(_), Some(_)) => {
                let m = line.expect("given from a line");
                return Err(TraceError::BadMeta {
                    file: path.to_path_buf(),
                    line: m.line,
                    key: m.key.clone(),
                    expected: format!("either a {} column or this line, not both", REQUIRED_COLUMNS[column]),
                    found: m.value.clone(),
                });
            }
            (Some((c, f)), None) => From::Column(*c, *f),
            (None, Some(v)) => From::Constant(v),
            (None, None) => match (column, folder.wavelength_nm) {
                (7, Some(nm)) => From::Constant(nm),
                _ => {
                    return Err(TraceError::LabColumnMissing {
                        file: path.to_path_buf(),
                        line: table.header_line,
                        column: REQUIRED_COLUMNS[column].to_string(),
                        found: table.names.join(","),
                        how: format!(
                            "expected a column, or its value given once before the header (`# {}: …`){}",
                            REQUIRED_COLUMNS[column],
                            if column == 7 { ", or for the whole folder (--wavelength-nm)" } else { "" }
                        ),
                    })
                }
            },
        });
    }
    Ok(out)
}

/// The value of a `# quantity_unit: value` or `# quantity: value unit` line, in our unit.
fn constant(m: &MetaLine, column: usize, path: &Path, dialect: Dialect) -> Result<f64, TraceError> {
    let ours = REQUIRED_COLUMNS[column];
    let bad = |expected: String| TraceError::BadMeta {
        file: path.to_path_buf(),
        line: m.line,
        key: m.key.clone(),
        expected,
        found: m.value.clone(),
    };
    let (_, key_unit) = recognise(&m.key).unwrap_or((column, None));
    let text = m.value.trim();
    let (number, value_unit) = match text.split_once(char::is_whitespace) {
        Some((n, u)) => (n, Some(u.trim())),
        None => (text, None),
    };
    let unit = match (key_unit.as_deref(), value_unit) {
        (Some(_), Some(_)) => return Err(bad(format!("a number in {ours}'s unit, the unit given once"))),
        (k, v) => k.or(v),
    };
    let f = factor(column, unit).map_err(bad)?;
    let number = if dialect.decimal_comma { number.replace(',', ".") } else { number.to_string() };
    match number.parse::<f64>() {
        Ok(v) if (v * f).is_finite() => Ok(v * f),
        _ => Err(bad(format!("a finite number for {ours}"))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_quantities_with_units_in_any_case_and_spelling() {
        assert_eq!(recognise("t_s"), Some((0, Some("s".into()))));
        assert_eq!(recognise("T_MS"), Some((0, Some("MS".into()))));
        assert_eq!(recognise(" time [ms] "), Some((0, Some("ms".into()))));
        assert_eq!(recognise("Wavelength (nm)"), Some((7, Some("nm".into()))));
        assert_eq!(recognise("lambda_pm"), Some((7, Some("pm".into()))));
        assert_eq!(recognise("irradiance"), Some((8, None)));
        assert_eq!(recognise("IRRADIANCE_V"), Some((8, Some("V".into()))));
        assert_eq!(recognise("q4_mrad"), Some((4, Some("mrad".into()))));
        assert_eq!(recognise("temperature_C"), None);
        assert_eq!(recognise("sample"), None);
    }

    #[test]
    fn units_convert_and_a_missing_unit_is_refused() {
        assert_eq!(factor(0, Some("MS")), Ok(1e-3));
        assert_eq!(factor(1, Some("nm")), Ok(1e-3));
        assert!(factor(4, Some("mrad")).is_ok_and(|f| (f - 0.001f64.to_degrees()).abs() < 1e-15));
        assert_eq!(factor(8, None), Ok(1.0));
        assert!(factor(0, None).unwrap_err().contains("no unit"));
        assert!(factor(2, Some("inch")).unwrap_err().contains("unknown unit `inch`"));
    }

    #[test]
    fn the_separator_is_the_one_that_splits_the_header_most() {
        assert_eq!(separator_of(b"t_s,q1_um,q2_um"), b',');
        assert_eq!(separator_of(b"t_s;q1_um;q2_um"), b';');
        assert_eq!(separator_of(b"t_s\tq1_um\tq2_um"), b'\t');
        assert_eq!(separator_of(b"t_s"), b',');
        assert_eq!(header_line(b"\xEF\xBB\xBF# a\n\n t_s;x\r\n1;2\n"), b" t_s;x\r");
    }
}
