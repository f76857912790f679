//! Streaming fringe counting for a live signal, and the turning points of a motion hint.
//! Owns the sample-by-sample counter a live view feeds batch after batch: unlike
//! [`crate::measure::extrema::count_extrema`], which sees a whole trace and adapts its hysteresis to the
//! recent swings, it confirms each extremum with the caller's fixed hysteresis and signs it with
//! the caller's direction for the batch.

/// Live fringe counting: each confirmed extremum of the irradiance is a λ/(4n) step of dL,
/// signed by the direction in which the model says the gap moves.
#[derive(Debug, Clone, Default)]
pub struct LiveCounter {
    looking_for_max: bool,
    extreme: f64,
    /// Signed number of λ/(4n) steps since the reset.
    pub steps: i64,
    /// Direction of the last counted step: +1 gap growing, −1 shrinking, 0 none yet.
    pub direction: i8,
    started: bool,
    first: Option<f64>,
}

impl LiveCounter {
    /// Feed samples; `hysteresis` is the drop from an extreme that confirms it, `sign` the
    /// direction of the gap change over these samples.
    pub fn feed(&mut self, samples: &[f64], hysteresis: f64, sign: f64) {
        for &v in samples {
            if !self.started {
                // The first sample is no extremum: wait until the signal has moved by the
                // hysteresis to know which extremum comes next.
                let first = *self.first.get_or_insert(v);
                if (v - first).abs() > hysteresis {
                    self.started = true;
                    self.looking_for_max = v > first;
                    self.extreme = v;
                }
                continue;
            }
            if self.looking_for_max {
                if v > self.extreme {
                    self.extreme = v;
                } else if v < self.extreme - hysteresis {
                    self.count(sign);
                    self.looking_for_max = false;
                    self.extreme = v;
                }
            } else if v < self.extreme {
                self.extreme = v;
            } else if v > self.extreme + hysteresis {
                self.count(sign);
                self.looking_for_max = true;
                self.extreme = v;
            }
        }
    }

    fn count(&mut self, sign: f64) {
        let s = if sign > 0.0 {
            1
        } else if sign < 0.0 {
            -1
        } else {
            0
        };
        self.steps += s as i64;
        if s != 0 {
            self.direction = s;
        }
    }
}

/// Indices where the motion hint turns back (its slope changes sign); steps below 1e-9 are
/// treated as standing still.
pub fn turning_points(hint: &[f64]) -> Vec<usize> {
    let mut out = vec![];
    let mut last_sign = 0.0;
    for i in 1..hint.len() {
        let d = hint[i] - hint[i - 1];
        if d.abs() < 1e-9 {
            continue;
        }
        let sign = d.signum();
        if last_sign != 0.0 && sign != last_sign {
            out.push(i - 1);
        }
        last_sign = sign;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_live_counter_counts_each_extremum_once_with_the_model_direction() {
        // 5 full fringes (10 extrema after the first) of a noisy cosine, gap growing.
        let signal: Vec<f64> = (0..5000)
            .map(|i| {
                let x = i as f64 / 1000.0 * std::f64::consts::TAU;
                1.0 + 0.4 * x.cos() + 0.01 * ((i * 7919 % 101) as f64 / 101.0 - 0.5)
            })
            .collect();
        let mut c = LiveCounter::default();
        c.feed(&signal, 0.1, 1.0);
        // The start is a maximum already passed: extrema at 0.5, 1, …, 4.5 fringes = 9.
        assert_eq!(c.steps, 9);
        assert_eq!(c.direction, 1);
        c.feed(&signal, 0.1, -1.0);
        assert_eq!(c.steps, 9 - 10, "back down: ten more extrema, counted negative");
        assert_eq!(c.direction, -1);
    }
}
