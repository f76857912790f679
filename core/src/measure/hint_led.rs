//! Whether a tracked motion followed its motion hint rather than its fringes: the tracked gap's
//! travel, in steps of λ/(4n), against the fringe extrema the signal shows (the paper's count,
//! which reads the irradiance alone). A tracking that reads the fringes travels within about a
//! step of the count; one that its hint led travels as far as the hint, whatever the fringes say.

use super::MotionMeasurement;

/// The departure allowed between the tracked travel and the extrema counted (steps of λ/(4n)),
/// or [`HINT_LED_SHARE`] of the count when that is more. On the independent simulator's
/// two-beam recordings every motion tracked from the true extrinsics' hint is within 1.1 steps
/// of its count; tracked from extrinsics 3° off, its translations and turns departed by 5-39.
pub const HINT_LED_STEPS: f64 = 3.0;
/// The departure allowed as a share of the count: extrema missed where the contrast is low, or
/// counted twice in noise, on long motions.
pub const HINT_LED_SHARE: f64 = 0.25;

/// The travel of the tracked gap `dl_nm` in steps of `step_nm`, blind to wiggles under half a
/// step (noise): the anchor moves once the gap has left it by half a step.
pub fn tracked_travel_steps(dl_nm: &[f64], step_nm: f64) -> f64 {
    let Some(&first) = dl_nm.first() else { return 0.0 };
    let (mut anchor, mut travel) = (first, 0.0);
    for &x in dl_nm {
        if (x - anchor).abs() >= 0.5 * step_nm {
            travel += (x - anchor).abs();
            anchor = x;
        }
    }
    travel / step_nm
}

/// A motion whose tracking departs from its fringe count.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HintLed {
    /// The tracked travel (steps of λ/(4n)).
    pub travel_steps: f64,
    /// The extrema the signal shows.
    pub counted: usize,
}

impl HintLed {
    /// What a report says of it.
    pub fn describe(&self) -> String {
        format!(
            "its tracked gap travels {:.1} steps of λ/4 where its signal shows {} fringe extrema: the tracking \
             followed the motion hint, not the fringes (the extrinsics it was analysed with are far from the bench's)",
            self.travel_steps, self.counted
        )
    }
}

/// [`HintLed`] when the tracked travel of `m` departs from its extrema count by more than
/// [`HINT_LED_STEPS`] and [`HINT_LED_SHARE`] of the count.
pub fn hint_led(m: &MotionMeasurement) -> Option<HintLed> {
    let travel_steps = tracked_travel_steps(&m.track.dl_nm, m.count.resolution_nm);
    let counted = m.count.counted;
    let allowed = HINT_LED_STEPS.max(HINT_LED_SHARE * counted as f64);
    ((travel_steps - counted as f64).abs() > allowed).then_some(HintLed { travel_steps, counted })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A monotonic ramp travels its length; noise under half a step adds nothing; a
    /// back-and-forth travels both ways.
    #[test]
    fn the_travel_counts_steps_not_noise() {
        let step = 390.0;
        let ramp: Vec<f64> = (0..=1000).map(|i| i as f64 * 3.9).collect(); // 3900 nm: 10 steps
        assert!((tracked_travel_steps(&ramp, step) - 10.0).abs() < 0.01);
        let noisy: Vec<f64> = (0..5000).map(|i| if i % 2 == 0 { 80.0 } else { -80.0 }).collect();
        assert_eq!(tracked_travel_steps(&noisy, step), 0.0);
        let there_and_back: Vec<f64> = ramp.iter().chain(ramp.iter().rev()).copied().collect();
        assert!((tracked_travel_steps(&there_and_back, step) - 20.0).abs() < 0.01);
        assert_eq!(tracked_travel_steps(&[], step), 0.0);
    }
}
