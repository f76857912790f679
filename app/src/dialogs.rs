//! File dialogs behind a small trait: the app opens real ones (rfd, through the desktop portal),
//! tests and headless runs script the answers and never open one.

use std::path::PathBuf;

/// The file dialogs the workbench uses.
pub trait Dialogs {
    /// Pick CSV trace files to import (empty when cancelled).
    fn open_traces(&mut self) -> Vec<PathBuf>;
    /// Pick where to save a CSV trace (`None` when cancelled).
    fn save_trace(&mut self, suggested_name: &str) -> Option<PathBuf>;
    /// Pick a session folder to open (`None` when cancelled).
    fn open_session(&mut self) -> Option<PathBuf>;
    /// Pick (or create) the folder to save a session in (`None` when cancelled).
    fn save_session(&mut self) -> Option<PathBuf>;
    /// Pick where to write the HTML report (`None` when cancelled).
    fn save_report(&mut self) -> Option<PathBuf>;
    /// Pick where to write a motion plan (RON) (`None` when cancelled).
    fn save_plan(&mut self, suggested_name: &str) -> Option<PathBuf>;
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

    fn open_session(&mut self) -> Option<PathBuf> {
        rfd::FileDialog::new().set_title("Open a session folder").pick_folder()
    }

    fn save_session(&mut self) -> Option<PathBuf> {
        rfd::FileDialog::new().set_title("Save the session in a folder").pick_folder()
    }

    fn save_report(&mut self) -> Option<PathBuf> {
        rfd::FileDialog::new().add_filter("HTML report", &["html"]).set_file_name("report.html").save_file()
    }

    fn save_plan(&mut self, suggested_name: &str) -> Option<PathBuf> {
        rfd::FileDialog::new().add_filter("motion plan (RON)", &["ron"]).set_file_name(suggested_name).save_file()
    }
}

/// Answers given in advance (tests, headless runs): each call takes the next one.
#[derive(Debug, Default)]
pub struct ScriptedDialogs {
    /// Answers to [`Dialogs::open_traces`], first first.
    pub opens: Vec<Vec<PathBuf>>,
    /// Answers to [`Dialogs::save_trace`], [`Dialogs::save_report`] and [`Dialogs::save_plan`],
    /// first first.
    pub saves: Vec<Option<PathBuf>>,
    /// Answers to [`Dialogs::open_session`] and [`Dialogs::save_session`], first first.
    pub folders: Vec<Option<PathBuf>>,
}

fn next<T>(answers: &mut Vec<Option<T>>) -> Option<T> {
    if answers.is_empty() {
        None
    } else {
        answers.remove(0)
    }
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
        next(&mut self.saves)
    }

    fn open_session(&mut self) -> Option<PathBuf> {
        next(&mut self.folders)
    }

    fn save_session(&mut self) -> Option<PathBuf> {
        next(&mut self.folders)
    }

    fn save_report(&mut self) -> Option<PathBuf> {
        next(&mut self.saves)
    }

    fn save_plan(&mut self, _suggested_name: &str) -> Option<PathBuf> {
        next(&mut self.saves)
    }
}
