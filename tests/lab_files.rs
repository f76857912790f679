//! How a lab's recorder writes its trace files: our documented format with its label line, or the
//! variants other labs' exports take (no comment lines, CRLF, `;` with a decimal comma, columns in
//! another order with extra ones, time in ms, a constant wavelength given once, upper-case names
//! after a byte-order mark). The same samples in every style, so that each must read the same.

use std::fmt::Write as _;

/// One sample as the recorder took it: time (s), joints (µm, °), wavelength (nm), photodiode (V).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    pub t_s: f64,
    pub q: [f64; 6],
    pub wavelength_nm: f64,
    pub irradiance: f64,
}

/// A style of trace file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileStyle {
    /// Our format: a comment, the `# label:` line, our header, commas.
    Ours,
    /// Our header and rows, no comment lines at all (no label: the file name is the label).
    Plain,
    /// [`FileStyle::Plain`] with CRLF line ends.
    Crlf,
    /// `;` as the separator and a decimal comma, as a spreadsheet in a French or German locale
    /// exports.
    SemicolonDecimalComma,
    /// The columns in another order, with extra columns (a temperature, a sample counter).
    Reordered,
    /// Time in milliseconds, in a `t_ms` column.
    Milliseconds,
    /// No wavelength column in a motion's file: the fixed laser wavelength given once, in a
    /// `# wavelength_nm:` line (a sweep's file keeps its column).
    WavelengthOnce,
    /// A UTF-8 byte-order mark, then the header's names in upper case.
    UpperCaseBom,
}

impl FileStyle {
    /// Every style, ours first.
    pub const ALL: [FileStyle; 8] = [
        FileStyle::Ours,
        FileStyle::Plain,
        FileStyle::Crlf,
        FileStyle::SemicolonDecimalComma,
        FileStyle::Reordered,
        FileStyle::Milliseconds,
        FileStyle::WavelengthOnce,
        FileStyle::UpperCaseBom,
    ];

    /// A short name for messages.
    pub fn name(self) -> &'static str {
        match self {
            FileStyle::Ours => "ours",
            FileStyle::Plain => "plain",
            FileStyle::Crlf => "crlf",
            FileStyle::SemicolonDecimalComma => "semicolon-decimal-comma",
            FileStyle::Reordered => "reordered",
            FileStyle::Milliseconds => "milliseconds",
            FileStyle::WavelengthOnce => "wavelength-once",
            FileStyle::UpperCaseBom => "upper-case-bom",
        }
    }

    /// The whole file of one record labelled `label`.
    pub fn file(self, label: &str, rows: &[Row]) -> Vec<u8> {
        let sweep = rows.first().zip(rows.last()).is_some_and(|(a, b)| a.wavelength_nm != b.wavelength_nm);
        let mut text = String::new();
        match self {
            FileStyle::Ours => {
                let _ = write!(text, "# recorded by an independent simulator\n# label: {label}\n");
            }
            FileStyle::WavelengthOnce if !sweep => {
                let nm = rows.first().map_or(0.0, |r| r.wavelength_nm);
                let _ = writeln!(text, "# wavelength_nm: {nm:.6}");
            }
            FileStyle::UpperCaseBom => text.push('\u{feff}'),
            _ => {}
        }
        let columns = self.columns(sweep);
        let separator = if self == FileStyle::SemicolonDecimalComma { ";" } else { "," };
        let names: Vec<String> = columns
            .iter()
            .map(|c| if self == FileStyle::UpperCaseBom { c.name().to_uppercase() } else { c.name().to_string() })
            .collect();
        text += &names.join(separator);
        text.push('\n');
        for (k, r) in rows.iter().enumerate() {
            let fields: Vec<String> = columns.iter().map(|c| c.field(r, k)).collect();
            let mut line = fields.join(separator);
            if self == FileStyle::SemicolonDecimalComma {
                line = line.replace('.', ",");
            }
            text += &line;
            text.push('\n');
        }
        if self == FileStyle::Crlf {
            text = text.replace('\n', "\r\n");
        }
        text.into_bytes()
    }

    /// The columns written, in order.
    fn columns(self, sweep: bool) -> Vec<Column> {
        use Column::*;
        let ours = vec![Time, Joint(0), Joint(1), Joint(2), Joint(3), Joint(4), Joint(5), Wavelength, Irradiance];
        match self {
            FileStyle::Reordered => vec![
                Irradiance,
                Counter,
                Joint(5),
                Time,
                Joint(2),
                Joint(0),
                Wavelength,
                Temperature,
                Joint(1),
                Joint(4),
                Joint(3),
            ],
            FileStyle::Milliseconds => std::iter::once(TimeMs).chain(ours.into_iter().skip(1)).collect(),
            FileStyle::WavelengthOnce if !sweep => ours.into_iter().filter(|c| *c != Wavelength).collect(),
            _ => ours,
        }
    }
}

/// A column of a file.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Column {
    Time,
    TimeMs,
    Joint(usize),
    Wavelength,
    Irradiance,
    Temperature,
    Counter,
}

impl Column {
    fn name(self) -> &'static str {
        match self {
            Column::Time => "t_s",
            Column::TimeMs => "t_ms",
            Column::Joint(j) => ["q1_um", "q2_um", "q3_um", "q4_deg", "q5_deg", "q6_deg"][j],
            Column::Wavelength => "wavelength_nm",
            Column::Irradiance => "irradiance",
            Column::Temperature => "temperature_C",
            Column::Counter => "sample",
        }
    }

    /// The field of row `r`, the `k`-th of its file.
    fn field(self, r: &Row, k: usize) -> String {
        match self {
            Column::Time => format!("{:.6}", r.t_s),
            Column::TimeMs => format!("{:.3}", r.t_s * 1e3),
            Column::Joint(j) => format!("{}", r.q[j]),
            Column::Wavelength => format!("{:.6}", r.wavelength_nm),
            Column::Irradiance => format!("{:.7}", r.irradiance),
            Column::Temperature => format!("{:.3}", 21.0 + 1e-3 * (k % 7) as f64),
            Column::Counter => k.to_string(),
        }
    }
}
