//! Traces recorded elsewhere, a folder at a time: files in our format, files as other labs' recorders write them,
//! or any file through a column mapping. Owns which format a file is in and how a folder's traces are named.
//!
//! Without a mapping each file is read in our format when its header starts with our nine columns
//! in order (the bytes are then kept as they are), else as another lab's export
//! ([`lab`](self::lab): `;` or tab separators with a decimal comma, our columns in any order and
//! case with units in their names, a constant given once instead of a column). With a mapping
//! ([`ColumnMapping`]) every file reads through it.
//!
//! Every trace of a folder is one trace of the identification, told apart by its label: the
//! `# label:` line when the file has one, else the file's name without `.csv`; a label that several
//! files share gets each file's name after it, `label (name)`. A file without a `# kind:` line is a
//! sweep when its wavelength varies at fixed joints, else a motion.

mod lab;
mod mapping;

pub use lab::Constants;
pub use mapping::{
    import_file, import_reader, unit_factor, ColumnMapping, ColumnSource, Source, MAPPING_VERSION, MAX_MAPPING_BYTES,
};

use super::table::{open_limited, ReadOptions};
use super::{is_sweep, Trace, TraceError, TraceKind, REQUIRED_COLUMNS};
use crate::files::FileError;
use std::io::Read;
use std::path::{Path, PathBuf};

/// How a folder's files are read.
#[derive(Debug, Clone, Default)]
pub struct FolderOptions<'a> {
    /// Read every file through this column mapping; `None`: our format or a lab's export.
    pub mapping: Option<&'a ColumnMapping>,
    /// Values for files that have neither a column nor a comment line for them.
    pub constants: Constants,
}

/// The `.csv` files of a folder, sorted by name (one motion or sweep per file).
pub fn csv_files(dir: &Path) -> Result<Vec<PathBuf>, FileError> {
    let entries = std::fs::read_dir(dir).map_err(|source| FileError::Io {
        file: dir.to_path_buf(),
        action: "cannot list the folder",
        source,
    })?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && p.extension().is_some_and(|e| e.eq_ignore_ascii_case("csv")))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(FileError::Invalid {
            file: dir.to_path_buf(),
            field: "(folder)".into(),
            problem: "no .csv files (expected one trace per file, *.csv)".into(),
        });
    }
    Ok(files)
}

/// Read every trace of a folder: in our format or a lab's export without a mapping, through the
/// mapping otherwise.
pub fn read_folder(dir: &Path, mapping: Option<&ColumnMapping>) -> Result<Vec<Trace>, TraceError> {
    Ok(read_folder_sourced(dir, mapping)?.traces)
}

/// Where a trace read from a file came from.
#[derive(Debug, Clone)]
pub struct TraceFile {
    /// The file.
    pub path: PathBuf,
    /// In our format, its label and kind as the file says: the CRC-32 and size of the bytes the
    /// trace was read from, so that a copy of the file can be checked to hold exactly that trace.
    /// `None` for a trace read any other way, or named otherwise than the file says.
    pub native: Option<(u32, u64)>,
}

/// Traces read from files, each with where it came from (`files[i]` is `traces[i]`'s).
#[derive(Debug, Clone, Default)]
pub struct Sourced {
    /// The traces, in file-name order.
    pub traces: Vec<Trace>,
    /// Their files.
    pub files: Vec<TraceFile>,
}

/// [`read_folder`], each trace with its file ([`Sourced`]).
pub fn read_folder_sourced(dir: &Path, mapping: Option<&ColumnMapping>) -> Result<Sourced, TraceError> {
    read_folder_with(dir, &FolderOptions { mapping, ..FolderOptions::default() })
}

/// Read every trace of a folder with `options`, each with its file, labels made distinct.
pub fn read_folder_with(dir: &Path, options: &FolderOptions) -> Result<Sourced, TraceError> {
    use rayon::prelude::*;
    let read_options = ReadOptions::default();
    // Read in parallel; the first failing file (in name order) is the one reported.
    let read: Vec<Result<(Trace, TraceFile), TraceError>> = csv_files(dir)?
        .par_iter()
        .map(|p| match options.mapping {
            Some(m) => Ok((import_file(p, m, &read_options)?, TraceFile { path: p.clone(), native: None })),
            None => read_file(p, &read_options, &options.constants),
        })
        .collect();
    let (mut traces, mut files): (Vec<Trace>, Vec<TraceFile>) =
        read.into_iter().collect::<Result<Vec<_>, _>>()?.into_iter().unzip();
    distinct_labels(&mut traces, &mut files);
    Ok(Sourced { traces, files })
}

/// A label that several traces share gets each one's file name after it.
fn distinct_labels(traces: &mut [Trace], files: &mut [TraceFile]) {
    let labels: Vec<String> = traces.iter().map(|t| t.meta.label.clone()).collect();
    for (k, (trace, file)) in traces.iter_mut().zip(files.iter_mut()).enumerate() {
        if labels.iter().enumerate().any(|(j, l)| j != k && *l == labels[k]) {
            let name = file.path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            trace.meta.label = format!("{} ({name})", labels[k]);
            file.native = None;
        }
    }
}

/// Whether a header line starts with our nine columns, in order.
fn is_ours(header: &[u8]) -> bool {
    let names: Vec<&[u8]> = header.split(|&b| b == b',').map(|n| n.trim_ascii()).collect();
    names.len() >= REQUIRED_COLUMNS.len() && REQUIRED_COLUMNS.iter().zip(&names).all(|(r, n)| r.as_bytes() == *n)
}

/// One file without a mapping: in our format when its header is ours, else as a lab's export;
/// labelled by its name when it has no label, its kind from its data when it does not say.
pub fn read_file(path: &Path, options: &ReadOptions, constants: &Constants) -> Result<(Trace, TraceFile), TraceError> {
    let mut bytes = Vec::new();
    open_limited(path, options)?.read_to_end(&mut bytes).map_err(|source| FileError::Io {
        file: path.to_path_buf(),
        action: "cannot read",
        source,
    })?;
    let ours = is_ours(lab::header_line(&bytes));
    let (mut trace, keyed) = match ours {
        true => Trace::from_csv_bytes_keyed(&bytes, path, options)?,
        false => lab::read_lab(&bytes, path, options, constants)?,
    };
    let mut as_written = ours;
    if trace.meta.label.trim().is_empty() {
        trace.meta.label = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        as_written = false;
    }
    if !keyed.iter().any(|m| m.key == "kind") {
        let kind = if is_sweep(&trace) { TraceKind::WavelengthSweep } else { TraceKind::Motion };
        as_written &= kind == trace.meta.kind;
        trace.meta.kind = kind;
    }
    let native = as_written.then(|| (crc32fast::hash(&bytes), bytes.len() as u64));
    Ok((trace, TraceFile { path: path.to_path_buf(), native }))
}

#[cfg(test)]
mod tests;
