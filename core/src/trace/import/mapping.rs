//! Traces from other acquisition systems through a column mapping: a checked mapping (source column, unit,
//! scale, offset → our column) and the file read through it. Owns the mapping format.
//!
//! A mapping file (RON), every one of our nine columns given once:
//!
//! ```text
//! ColumnMapping(
//!     format_version: 1,
//!     columns: {
//!         "t_s":           (source: Column("time_ms"), unit: "ms"),
//!         "q1_um":         (source: Column("Z_nm"), unit: "nm"),
//!         "q2_um":         (source: Column("Y_nm"), unit: "nm"),
//!         "q3_um":         (source: Column("X_nm"), unit: "nm"),
//!         "q4_deg":        (source: Column("gonio_a_mrad"), unit: "mrad"),
//!         "q5_deg":        (source: Column("gonio_b_mrad"), unit: "mrad", offset: 0.0),
//!         "q6_deg":        (source: Constant(0.0), unit: "deg"),
//!         "wavelength_nm": (source: Column("lambda_pm"), unit: "pm"),
//!         "irradiance":    (source: Column("pd_V"), unit: "V", scale: 1.0),
//!     },
//! )
//! ```
//!
//! Our value = source value × unit factor × `scale` + `offset` (`offset` in our column's unit).
//! Units known per column: time `s ms us µs ns min`; joints 1-3 `m mm um µm nm pm`; joints 4-6
//! `deg ° rad mrad urad µrad arcsec`; wavelength `nm um µm pm m`; irradiance any unit (recorded
//! in the trace's `irradiance_unit`). Time must come from a column, with a positive factor.
//! Every source value must be finite, every row complete, time strictly increasing, at least one
//! row, and the scaled values finite: errors name the file, the line and the column.
//! Columns the mapping does not read are kept as extra columns.

use crate::files::{self, FieldError, FileError};
use crate::trace::table::{open_limited, read_table, ReadOptions, Table};
use crate::trace::{is_sweep, ExtraColumn, Trace, TraceError, TraceKind, REQUIRED_COLUMNS};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

/// The mapping format this program reads and writes.
pub const MAPPING_VERSION: u32 = 1;

/// Largest mapping file read (bytes); a mapping is a few hundred bytes.
pub const MAX_MAPPING_BYTES: u64 = 1 << 20;

const EXPECTED: &str = "a ColumnMapping(format_version: 1, columns: { \"t_s\": (source: Column(\"…\"), unit: \"s\"), … }) as documented in docs/session-format.md";

/// Where one of our columns comes from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Source {
    /// A column of the source file, by its header name.
    Column(String),
    /// A constant (a joint the other system does not record, a fixed laser), in `unit`.
    Constant(f64),
}

/// One of our columns: its source, the source's unit, a further factor and an offset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ColumnSource {
    /// The source column or a constant.
    pub source: Source,
    /// Unit of the source values (see the module documentation for the units known).
    pub unit: String,
    /// Further factor (a sensor gain, a sign), applied after the unit conversion. Default 1.
    #[serde(default = "unit_scale")]
    pub scale: f64,
    /// Added after scaling, in our column's unit (a stage's zero). Default 0.
    #[serde(default)]
    pub offset: f64,
}

/// A column is taken as it is unless the mapping gives a scale.
fn unit_scale() -> f64 {
    1.0
}

/// How the columns of a foreign CSV file become a trace.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ColumnMapping {
    /// Format version ([`MAPPING_VERSION`]).
    pub format_version: u32,
    /// Our column name → where it comes from; all nine required columns.
    pub columns: BTreeMap<String, ColumnSource>,
}

/// The factor from `unit` to our column's unit, if the unit is known for that column.
pub fn unit_factor(column: &str, unit: &str) -> Option<f64> {
    let u = unit.trim();
    let deg = 180.0 / std::f64::consts::PI;
    let table: &[(&[&str], f64)] = match column {
        "t_s" => &[(&["s"], 1.0), (&["ms"], 1e-3), (&["us", "µs", "μs"], 1e-6), (&["ns"], 1e-9), (&["min"], 60.0)],
        "q1_um" | "q2_um" | "q3_um" => {
            &[(&["m"], 1e6), (&["mm"], 1e3), (&["um", "µm", "μm"], 1.0), (&["nm"], 1e-3), (&["pm"], 1e-6)]
        }
        "q4_deg" | "q5_deg" | "q6_deg" => &[
            (&["deg", "°"], 1.0),
            (&["rad"], deg),
            (&["mrad"], deg * 1e-3),
            (&["urad", "µrad", "μrad"], deg * 1e-6),
            (&["arcsec"], 1.0 / 3600.0),
        ],
        "wavelength_nm" => &[(&["nm"], 1.0), (&["um", "µm", "μm"], 1e3), (&["pm"], 1e-3), (&["m"], 1e9)],
        "irradiance" => return (!u.is_empty()).then_some(1.0),
        _ => return None,
    };
    table.iter().find(|(names, _)| names.contains(&u)).map(|(_, f)| *f)
}

/// The units known for one of our columns, for messages.
pub(crate) fn known_units(column: &str) -> &'static str {
    match column {
        "t_s" => "s, ms, us (µs), ns, min",
        "q1_um" | "q2_um" | "q3_um" => "m, mm, um (µm), nm, pm",
        "q4_deg" | "q5_deg" | "q6_deg" => "deg (°), rad, mrad, urad (µrad), arcsec",
        "wavelength_nm" => "nm, um (µm), pm, m",
        _ => "any non-empty unit name",
    }
}

impl ColumnMapping {
    /// The identity mapping: our own column names and units.
    pub fn identity() -> Self {
        let columns = REQUIRED_COLUMNS
            .iter()
            .map(|&c| {
                let unit = match c {
                    "t_s" => "s",
                    "irradiance" => "normalised",
                    c if c.ends_with("_um") => "um",
                    c if c.ends_with("_deg") => "deg",
                    _ => "nm",
                };
                (
                    c.to_string(),
                    ColumnSource { source: Source::Column(c.into()), unit: unit.into(), scale: 1.0, offset: 0.0 },
                )
            })
            .collect();
        Self { format_version: MAPPING_VERSION, columns }
    }

    /// Load and check a mapping file (refused unread above [`MAX_MAPPING_BYTES`]).
    pub fn load(path: &Path) -> Result<Self, FileError> {
        let text = files::read_text_limited(
            path,
            MAX_MAPPING_BYTES,
            "a column mapping",
            "a mapping is a few hundred bytes: is this the right file?",
        )?;
        Self::from_ron_str(&text, path)
    }

    /// Parse and check mapping text; `origin` names it in errors.
    pub fn from_ron_str(text: &str, origin: &Path) -> Result<Self, FileError> {
        let mapping: Self = files::parse_ron(text, origin, EXPECTED)?;
        mapping.validate().map_err(|e| e.in_file(origin))?;
        Ok(mapping)
    }

    /// Save atomically as RON.
    pub fn save(&self, path: &Path) -> Result<(), FileError> {
        files::save_ron(path, self)
    }

    /// Checks: the version, every required column mapped once and nothing else, units known,
    /// factors finite and non-zero (positive for time), offsets and constants finite, time from
    /// a column, no source column read twice for different quantities.
    pub fn validate(&self) -> Result<(), FieldError> {
        if self.format_version != MAPPING_VERSION {
            return Err(FieldError::new(
                "format_version",
                format!(
                    "expected {MAPPING_VERSION} (this program reads mapping version {MAPPING_VERSION}), found {}",
                    self.format_version
                ),
            ));
        }
        for key in self.columns.keys() {
            if !REQUIRED_COLUMNS.contains(&key.as_str()) {
                return Err(FieldError::new(
                    format!("columns.\"{key}\""),
                    format!("not one of our columns (expected one of {})", REQUIRED_COLUMNS.join(", ")),
                ));
            }
        }
        for column in REQUIRED_COLUMNS {
            let field = |f: &str| format!("columns.\"{column}\"{f}");
            let Some(column_source) = self.columns.get(column) else {
                return Err(FieldError::new(
                    field(""),
                    "missing: every one of our nine columns needs a source column or a constant".to_string(),
                ));
            };
            let Some(factor) = unit_factor(column, &column_source.unit) else {
                return Err(FieldError::new(
                    field(".unit"),
                    format!(
                        "unknown unit `{}` for {column} (expected one of: {})",
                        column_source.unit,
                        known_units(column)
                    ),
                ));
            };
            if !(column_source.scale.is_finite() && column_source.scale != 0.0) {
                return Err(FieldError::new(
                    field(".scale"),
                    format!("expected a finite, non-zero factor, found {}", column_source.scale),
                ));
            }
            if !column_source.offset.is_finite() {
                return Err(FieldError::new(
                    field(".offset"),
                    format!("expected a finite number, found {}", column_source.offset),
                ));
            }
            match &column_source.source {
                Source::Constant(v) if column == "t_s" => {
                    return Err(FieldError::new(
                        field(".source"),
                        format!("expected Column(\"<time column>\"): time must be recorded, found Constant({v})"),
                    ))
                }
                Source::Constant(v) if !v.is_finite() => {
                    return Err(FieldError::new(field(".source"), format!("expected a finite constant, found {v}")))
                }
                Source::Column(name) if name.trim().is_empty() => {
                    return Err(FieldError::new(field(".source"), "expected a column name, found an empty one"))
                }
                _ => {}
            }
            if column == "t_s" && factor * column_source.scale <= 0.0 {
                return Err(FieldError::new(
                    field(".scale"),
                    format!("expected a positive factor for time (time must increase), found {}", column_source.scale),
                ));
            }
        }
        Ok(())
    }

    /// The source column name read for our column, if it is read from a column.
    fn source_column(&self, column: &str) -> Option<&str> {
        match self.columns.get(column).map(|c| &c.source) {
            Some(Source::Column(n)) => Some(n.trim()),
            _ => None,
        }
    }
}

/// Read a foreign CSV trace through a mapping (the mapping is checked first). The label comes
/// from a `# label:` line if the file has one, else from `label`; the kind from the data (a
/// file whose wavelength varies at fixed joints is a sweep).
pub fn import_reader<R: Read>(
    reader: R,
    origin: &Path,
    mapping: &ColumnMapping,
    label: &str,
    options: &ReadOptions,
) -> Result<Trace, TraceError> {
    mapping.validate().map_err(|e| TraceError::File(e.in_file(origin)))?;
    let table = read_table(reader, origin, options, |names, line| {
        for target in REQUIRED_COLUMNS {
            if let Some(source) = mapping.source_column(target) {
                if !names.iter().any(|n| n == source) {
                    return Err(TraceError::MappedColumnMissing {
                        file: origin.to_path_buf(),
                        line,
                        column: source.to_string(),
                        target: target.to_string(),
                        found: names.join(","),
                    });
                }
            }
        }
        let time_column = mapping.source_column("t_s").unwrap_or("t_s");
        Ok(names.iter().position(|n| n == time_column).unwrap_or(0))
    })?;
    let converted = convert_mapped_columns(&table, mapping, origin)?;
    let used: Vec<&str> = REQUIRED_COLUMNS.iter().filter_map(|t| mapping.source_column(t)).collect();
    let mut meta = table.meta;
    if meta.label.is_empty() {
        meta.label = label.to_string();
    }
    meta.irradiance_unit = mapping.columns["irradiance"].unit.trim().to_string();
    let extra = table
        .names
        .iter()
        .zip(table.columns)
        .filter(|(n, _)| !used.contains(&n.as_str()) && !REQUIRED_COLUMNS.contains(&n.as_str()))
        .map(|(n, values)| ExtraColumn { name: n.clone(), values })
        .collect();
    let mut trace = Trace::from_columns(meta, converted, extra);
    trace.meta.kind = if is_sweep(&trace) { TraceKind::WavelengthSweep } else { TraceKind::Motion };
    // Scaling keeps time increasing only up to rounding: say so rather than pass on a bad trace.
    trace.validate().map_err(|e| TraceError::Imported { file: origin.to_path_buf(), problem: e.to_string() })?;
    Ok(trace)
}

/// Our nine columns from a table read through `mapping`: each source column (or constant)
/// converted to our unit, scaled and offset; every converted value must be finite.
fn convert_mapped_columns(table: &Table, mapping: &ColumnMapping, origin: &Path) -> Result<Vec<Vec<f64>>, TraceError> {
    let rows = table.columns.first().map_or(0, Vec::len);
    let mut converted: Vec<Vec<f64>> = Vec::with_capacity(REQUIRED_COLUMNS.len());
    for target in REQUIRED_COLUMNS {
        let column_source = &mapping.columns[target];
        let factor = unit_factor(target, &column_source.unit).unwrap_or(1.0) * column_source.scale;
        let values: Vec<f64> = match &column_source.source {
            Source::Constant(v) => vec![v * factor + column_source.offset; rows],
            Source::Column(name) => {
                let source_index = table.names.iter().position(|n| n == name.trim()).unwrap_or(0);
                table.columns[source_index].iter().map(|v| v * factor + column_source.offset).collect()
            }
        };
        if let Some(row) = values.iter().position(|v| !v.is_finite()) {
            return Err(TraceError::ScaledNonFinite {
                file: origin.to_path_buf(),
                column: target.to_string(),
                row: row + 1,
                value: values[row],
            });
        }
        converted.push(values);
    }
    Ok(converted)
}

/// [`import_reader`] on a file, refused unread above [`ReadOptions::max_bytes`]; the label
/// defaults to the file's stem.
pub fn import_file(path: &Path, mapping: &ColumnMapping, options: &ReadOptions) -> Result<Trace, TraceError> {
    let file = open_limited(path, options)?;
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    import_reader(file, path, mapping, &stem, options)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn foreign_mapping() -> ColumnMapping {
        let text = r#"ColumnMapping(
            format_version: 1,
            columns: {
                "t_s": (source: Column("time_ms"), unit: "ms"),
                "q1_um": (source: Column("Z_nm"), unit: "nm"),
                "q2_um": (source: Constant(0.0), unit: "um"),
                "q3_um": (source: Column("X_nm"), unit: "nm"),
                "q4_deg": (source: Column("a_mrad"), unit: "mrad"),
                "q5_deg": (source: Constant(0.0), unit: "deg"),
                "q6_deg": (source: Constant(0.0), unit: "deg", offset: 1.5),
                "wavelength_nm": (source: Column("lambda_pm"), unit: "pm"),
                "irradiance": (source: Column("pd_V"), unit: "V", scale: 2.0),
            },
        )"#;
        ColumnMapping::from_ron_str(text, Path::new("m.ron")).unwrap()
    }

    #[test]
    fn mapped_columns_are_converted_with_units_scales_and_offsets() {
        let csv = "pd_V,time_ms,X_nm,Z_nm,a_mrad,lambda_pm,temperature_C\n\
                   0.5,0,1000,-2000,1000,1560000,21.5\n\
                   0.25,10,1500,-2000,0,1560500,21.6\n";
        let t =
            import_reader(csv.as_bytes(), Path::new("f.csv"), &foreign_mapping(), "from file", &ReadOptions::default())
                .unwrap();
        assert_eq!(t.t_s, [0.0, 0.01]);
        assert_eq!(t.q3_um, [1.0, 1.5]);
        assert_eq!(t.q1_um, [-2.0, -2.0]);
        assert_eq!(t.q2_um, [0.0, 0.0]);
        assert!((t.q4_deg[0] - 1f64.to_degrees()).abs() < 1e-12, "1000 mrad is 1 rad");
        assert_eq!(t.q6_deg, [1.5, 1.5]);
        assert_eq!(t.wavelength_nm, [1560.0, 1560.5]);
        assert_eq!(t.irradiance, [1.0, 0.5]);
        assert_eq!(t.meta.irradiance_unit, "V");
        assert_eq!(t.meta.label, "from file");
        assert_eq!(t.meta.kind, TraceKind::Motion);
        assert_eq!(t.extra.len(), 1);
        assert_eq!(t.extra[0].name, "temperature_C");
    }

    #[test]
    fn identity_mapping_reads_our_own_format_the_same() {
        let mut t = Trace::new(Default::default());
        t.meta.label = "x".into();
        t.meta.irradiance_unit = "normalised".into();
        for i in 0..5 {
            t.push_sample(i as f64 * 0.1, [i as f64, 0.0, 1.0, 0.0, 0.5, 0.0], 1560.0, 0.25 * i as f64);
        }
        let bytes = t.to_csv_bytes(Path::new("x.csv")).unwrap();
        let back =
            import_reader(&bytes[..], Path::new("x.csv"), &ColumnMapping::identity(), "y", &ReadOptions::default())
                .unwrap();
        assert_eq!(back, t);
    }

    fn mapping_text() -> String {
        files::to_ron_string(&foreign_mapping(), Path::new("m.ron")).unwrap()
    }

    /// Splice `token` into `text` at `at`, cut `cut` bytes there, or truncate: the fuzz mutations.
    fn mutate(text: &[u8], edits: &[(usize, usize, u8)]) -> Vec<u8> {
        let tokens: [&[u8]; 10] =
            [b",", b"\n", b"NaN", b"-inf", b"1e999", b"\"", b"(", b")", b"time_ms", b"# kind: x\n"];
        let mut b = text.to_vec();
        for &(at, cut, tok) in edits {
            let a = at % (b.len() + 1);
            match tok % 3 {
                0 => {
                    let e = (a + cut % 8).min(b.len());
                    b.drain(a..e);
                }
                1 => b.truncate(a),
                _ => {
                    b.splice(a..a, tokens[cut % tokens.len()].iter().copied());
                }
            }
        }
        b
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 1000, failure_persistence: None, ..ProptestConfig::default() })]

        #[test]
        fn mapping_parser_never_panics(edits in prop::collection::vec((any::<usize>(), any::<usize>(), any::<u8>()), 1..5)) {
            let text = mutate(mapping_text().as_bytes(), &edits);
            match ColumnMapping::from_ron_str(&String::from_utf8_lossy(&text), Path::new("fuzz.ron")) {
                Ok(m) => prop_assert!(m.validate().is_ok()),
                Err(e) => prop_assert!(e.to_string().starts_with("fuzz.ron"), "{}", e),
            }
        }

        #[test]
        fn import_never_panics(edits in prop::collection::vec((any::<usize>(), any::<usize>(), any::<u8>()), 1..5)) {
            let csv = b"pd_V,time_ms,X_nm,Z_nm,a_mrad,lambda_pm,temperature_C\n0.5,0,1000,-2000,1000,1560000,21.5\n0.25,10,1500,-2000,0,1560500,21.6\n";
            let bytes = mutate(csv, &edits);
            match import_reader(&bytes[..], Path::new("fuzz.csv"), &foreign_mapping(), "f", &ReadOptions::default()) {
                Ok(t) => {
                    prop_assert!(t.validate().is_ok());
                    prop_assert!(!t.is_empty());
                }
                Err(e) => prop_assert!(e.to_string().starts_with("fuzz.csv"), "{}", e),
            }
        }
    }
}
