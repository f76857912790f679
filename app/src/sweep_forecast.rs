//! What the wizard's steps lose on a bench without a tunable laser, forecast before step 1: the
//! plans the chosen identifier uses, run once on a pilot virtual bench of the preset
//! (`photorobot_core::identify::sweep_cost::predict`) on a background thread, and kept for the
//! bench, preset and identifier it was computed for.

use photorobot_core::bench::BenchPreset;
use photorobot_core::identify::sweep_cost::{predict, SweepCost};
use photorobot_core::plan::Plan;
use std::sync::mpsc::{channel, Receiver};

/// For which bench, preset and identifier a forecast holds.
type Key = (String, String, bool);

/// The forecast, computing or computed.
#[derive(Default)]
pub struct SweepForecast {
    key: Option<Key>,
    pending: Option<Receiver<Result<SweepCost, String>>>,
    result: Option<Result<SweepCost, String>>,
}

impl SweepForecast {
    /// A forecast is computed (or failed), whatever it was asked for.
    pub fn ready(&self) -> bool {
        self.result.is_some()
    }

    /// The forecast for `bench` modelled by `preset` with the plans of the identifier
    /// (`joint_mode`): started on a background thread the first time it is asked for, `None`
    /// while it computes.
    pub fn get(
        &mut self,
        bench: &str,
        preset: &str,
        joint_mode: bool,
        plans: impl FnOnce() -> Vec<Plan>,
    ) -> Option<&Result<SweepCost, String>> {
        let key = (bench.to_string(), preset.to_string(), joint_mode);
        if self.key.as_ref() != Some(&key) {
            let (tx, rx) = channel();
            let (preset, plans) = (preset.to_string(), plans());
            std::thread::Builder::new()
                .name("sweep cost forecast".into())
                .spawn(move || {
                    let cost =
                        BenchPreset::resolve(&preset).map_err(|e| e.to_string()).and_then(|p| predict(&p, &plans));
                    let _ = tx.send(cost);
                })
                .expect("the OS starts a thread");
            *self = SweepForecast { key: Some(key), pending: Some(rx), result: None };
        }
        if let Some(rx) = &self.pending {
            if let Ok(r) = rx.try_recv() {
                self.result = Some(r);
                self.pending = None;
            }
        }
        self.result.as_ref()
    }
}
