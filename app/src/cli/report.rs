//! `photorobot report <session> --out FILE`: the session's calibration report as one HTML file.
//! Owns only argument parsing; the work is `photorobot_core::report`.

use super::common::CliError;
use std::io::Write;
use std::path::PathBuf;

/// Arguments of `photorobot report`.
#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    /// The session: its folder or its session.ron.
    pub session: PathBuf,
    /// The HTML file to write.
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
}

/// `photorobot report`: the session's HTML report, written atomically.
pub fn report(a: &ReportArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let session = photorobot_core::session::Session::load(&a.session)?;
    let html = photorobot_core::report::render_html(&session);
    photorobot_core::files::write_atomic(&a.out, html.as_bytes())?;
    writeln!(out, "report written to {}", a.out.display())?;
    Ok(())
}
