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
//! # wavelength_scale_sigma_ppm: 31.5   (sweeps timed by a wavelength monitor; absent when 0)
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
//! - [`read_table`] reads any numeric CSV with these rules; [`import`] uses it for files from
//!   other acquisition systems.
//!
//! Files: `table` reads a numeric CSV table under these rules, `csv` reads and writes our own
//! format, `import` reads foreign formats through a column mapping, `error` says what went wrong.

mod csv;
mod error;
pub mod import;
mod plain;
mod table;

pub use error::TraceError;
pub use table::{open_limited, read_table, MetaLine, ReadOptions, Table};

use serde::{Deserialize, Serialize};
use std::fmt;

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
    /// A sweep's wavelength scale uncertainty (ppm, 1σ): how well its time base (a wavelength
    /// monitor fitted with a line) knows the sweep's speed. Every gap the sweep gives carries this
    /// fraction of itself on top of its fit's σ. 0 (the default, not written) when the
    /// wavelengths are exact or the source does not say.
    pub wavelength_scale_sigma_ppm: f64,
}

impl Default for TraceMeta {
    fn default() -> Self {
        Self {
            label: String::new(),
            kind: TraceKind::Motion,
            bench: String::new(),
            irradiance_unit: "normalised".into(),
            notes: String::new(),
            wavelength_scale_sigma_ppm: 0.0,
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

impl Trace {
    /// An empty trace with the given metadata.
    pub fn new(meta: TraceMeta) -> Self {
        Self::with_capacity(meta, 0)
    }

    /// An empty trace with room for `rows` samples in each required column.
    pub fn with_capacity(meta: TraceMeta, rows: usize) -> Self {
        let empty_column = || Vec::with_capacity(rows);
        Self {
            meta,
            t_s: empty_column(),
            q1_um: empty_column(),
            q2_um: empty_column(),
            q3_um: empty_column(),
            q4_deg: empty_column(),
            q5_deg: empty_column(),
            q6_deg: empty_column(),
            wavelength_nm: empty_column(),
            irradiance: empty_column(),
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

    /// Joint `j`'s column (0..6: q1..q6, display units), to write.
    ///
    /// # Panics
    /// If `j >= 6`.
    pub fn joint_column_mut(&mut self, j: usize) -> &mut Vec<f64> {
        match j {
            0 => &mut self.q1_um,
            1 => &mut self.q2_um,
            2 => &mut self.q3_um,
            3 => &mut self.q4_deg,
            4 => &mut self.q5_deg,
            5 => &mut self.q6_deg,
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

    /// Append the samples of `other` later than this trace's last (all of them when this one is
    /// empty), column by column. Extra columns continue where both traces have the same ones,
    /// in the same order; otherwise this trace's are dropped, so that every column stays as
    /// long as `t_s`.
    pub fn append_later(&mut self, other: &Trace) {
        let from = self.t_s.last().map_or(0, |&last| other.t_s.partition_point(|&t| t <= last));
        let same_extras =
            self.extra.len() == other.extra.len() && self.extra.iter().zip(&other.extra).all(|(a, b)| a.name == b.name);
        if !same_extras {
            self.extra.clear();
        }
        let columns = [
            (&mut self.t_s, &other.t_s),
            (&mut self.q1_um, &other.q1_um),
            (&mut self.q2_um, &other.q2_um),
            (&mut self.q3_um, &other.q3_um),
            (&mut self.q4_deg, &other.q4_deg),
            (&mut self.q5_deg, &other.q5_deg),
            (&mut self.q6_deg, &other.q6_deg),
            (&mut self.wavelength_nm, &other.wavelength_nm),
            (&mut self.irradiance, &other.irradiance),
        ];
        let extras = self.extra.iter_mut().zip(&other.extra).map(|(a, b)| (&mut a.values, &b.values));
        for (to, from_column) in columns.into_iter().chain(extras) {
            to.extend_from_slice(from_column.get(from..).unwrap_or(&[]));
        }
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
        let samples = self.len();
        for (i, column) in self.extra.iter().enumerate() {
            let bad = |problem: &str| TraceError::BadColumnName {
                index: i,
                name: column.name.clone(),
                problem: problem.to_string(),
            };
            if column.name.is_empty() {
                return Err(bad("expected a non-empty name"));
            }
            if column.name.trim() != column.name || column.name.contains(['\n', '\r']) {
                return Err(bad("expected a name without surrounding spaces or line breaks"));
            }
            if REQUIRED_COLUMNS.contains(&column.name.as_str()) {
                return Err(bad("expected a name other than the required columns"));
            }
            if self.extra[..i].iter().any(|other| other.name == column.name) {
                return Err(bad("expected a unique name, found it twice"));
            }
        }
        for (name, values) in self.columns() {
            if values.len() != samples {
                return Err(TraceError::LengthMismatch {
                    column: name.to_string(),
                    expected: samples,
                    found: values.len(),
                });
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
}

/// True when the trace is a wavelength sweep: the wavelength varies while the joints stay.
pub fn is_sweep(trace: &Trace) -> bool {
    spans(&trace.wavelength_nm, |s| s > 0.1) && (0..6).all(|j| !spans(trace.joint_column(j), |s| s >= 0.05))
}

/// Whether a column's span (largest minus smallest value, NaN ignored) is `enough`, read block
/// by block only as far as it takes to tell (a motion's fixed wavelength whole).
fn spans(column: &[f64], enough: impl Fn(f64) -> bool) -> bool {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    column.chunks(4096).any(|block| {
        (lo, hi) = block.iter().fold((lo, hi), |(a, b), &v| (a.min(v), b.max(v)));
        enough(hi - lo)
    })
}

#[cfg(test)]
mod tests;
