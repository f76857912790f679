//! The bench clock of a bench on controllers and of the emulators: real time since the start, times
//! a scale (1 for real hardware; emulators may run faster).

use std::sync::Arc;
use std::time::Instant;

/// The emulated time: real time since the start, times a scale (100 runs a 10-minute plan in 6 s).
#[derive(Debug)]
pub struct EmuClock {
    start: Instant,
    scale: f64,
}

impl EmuClock {
    /// A clock running `scale` times faster than real time (1 for real time).
    pub fn new(scale: f64) -> Arc<Self> {
        Arc::new(EmuClock { start: Instant::now(), scale: if scale.is_finite() && scale > 0.0 { scale } else { 1.0 } })
    }

    /// Emulated seconds since the start.
    pub fn now_s(&self) -> f64 {
        self.start.elapsed().as_secs_f64() * self.scale
    }

    /// The time scale.
    pub fn scale(&self) -> f64 {
        self.scale
    }
}
