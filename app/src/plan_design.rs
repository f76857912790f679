//! The wizard's "design a plan for this bench": the core's experiment design
//! (`photorobot_core::identify::design::design`, what `photorobot design` runs) for the bench
//! preset at hand, on a background thread, with the command line's defaults (margin 0.6, pilot
//! seed 1, the nominal design as prior).

use photorobot_core::bench::BenchPreset;
use photorobot_core::identify::design::{design, Design, DesignOptions};
use std::sync::mpsc::{channel, Receiver};

/// The design margin the wizard uses, as `photorobot design` by default.
pub const MARGIN: f64 = 0.6;

/// A design for a preset: computing, or done (or failed).
#[derive(Default)]
pub struct PlanDesign {
    /// The preset being designed for, and where its result comes.
    pending: Option<(String, Receiver<Result<Design, String>>)>,
    /// The preset designed for, and the design or why it failed.
    pub result: Option<(String, Result<Design, String>)>,
}

impl PlanDesign {
    /// Start designing for `preset` (an embedded name or a preset file); a design running goes on.
    pub fn start(&mut self, preset: &str) {
        if self.pending.is_some() {
            return;
        }
        let (tx, rx) = channel();
        let name = preset.to_string();
        std::thread::Builder::new()
            .name("plan design".into())
            .spawn(move || {
                let options = DesignOptions { margin: MARGIN, ..Default::default() };
                let d = BenchPreset::resolve(&name)
                    .map_err(|e| e.to_string())
                    .and_then(|p| design(&p, &options, &[]).map_err(|e| e.to_string()));
                let _ = tx.send(d);
            })
            .expect("the OS starts a thread");
        self.pending = Some((preset.to_string(), rx));
    }

    /// Whether a design is computing.
    pub fn running(&self) -> bool {
        self.pending.is_some()
    }

    /// Take a finished design into [`PlanDesign::result`]; true when one just arrived.
    pub fn poll(&mut self) -> bool {
        let Some((preset, rx)) = &self.pending else { return false };
        match rx.try_recv() {
            Ok(d) => {
                self.result = Some((preset.clone(), d));
                self.pending = None;
                true
            }
            Err(std::sync::mpsc::TryRecvError::Empty) => false,
            Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                self.result = Some((preset.clone(), Err("the design stopped without a result".into())));
                self.pending = None;
                true
            }
        }
    }
}
