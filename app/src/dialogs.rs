//! File dialogs behind a small trait: the app opens real ones (rfd, through the desktop portal),
//! tests and headless runs script the answers and never open one.

use std::path::PathBuf;

/// The file dialogs the workbench uses.
pub trait Dialogs {
    /// Pick CSV trace files to import (empty when cancelled).
    fn open_traces(&mut self) -> Vec<PathBuf>;
    /// Pick where to save a CSV trace (`None` when cancelled).
    fn save_trace(&mut self, suggested_name: &str) -> Option<PathBuf>;
}

/// Native dialogs (rfd).
#[derive(Debug, Default)]
pub struct NativeDialogs;

impl Dialogs for NativeDialogs {
    fn open_traces(&mut self) -> Vec<PathBuf> {
        rfd::FileDialog::new().add_filter("CSV trace", &["csv"]).pick_files().unwrap_or_default()
    }

    fn save_trace(&mut self, suggested_name: &str) -> Option<PathBuf> {
        rfd::FileDialog::new().add_filter("CSV trace", &["csv"]).set_file_name(suggested_name).save_file()
    }
}

/// Answers given in advance (tests, headless runs): each call takes the next one.
#[derive(Debug, Default)]
pub struct ScriptedDialogs {
    /// Answers to [`Dialogs::open_traces`], first first.
    pub opens: Vec<Vec<PathBuf>>,
    /// Answers to [`Dialogs::save_trace`], first first.
    pub saves: Vec<Option<PathBuf>>,
}

impl Dialogs for ScriptedDialogs {
    fn open_traces(&mut self) -> Vec<PathBuf> {
        if self.opens.is_empty() {
            vec![]
        } else {
            self.opens.remove(0)
        }
    }

    fn save_trace(&mut self, _suggested_name: &str) -> Option<PathBuf> {
        if self.saves.is_empty() {
            None
        } else {
            self.saves.remove(0)
        }
    }
}
