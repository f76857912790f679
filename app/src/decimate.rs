//! Plot decimation: a long sampled signal reduced to its min and max per pixel column over the
//! visible range, so a plot of ten million samples costs what a plot of two thousand does.
//! Owns the append-only min/max pyramid and the per-column reduction; no egui in here.
//!
//! Each column's extremes are exact (not a subsample): the pyramid stores the min and max of
//! blocks of [`BLOCK`] and [`BLOCK`]² samples, and a column is covered by raw samples at its
//! edges and whole blocks inside.

/// Samples per block of the first pyramid level (the second level has `BLOCK²`).
pub const BLOCK: usize = 64;

/// A signal `y(t)` with `t` increasing, and its min/max pyramid, grown by appending.
#[derive(Debug, Clone, Default)]
pub struct Decimator {
    t: Vec<f64>,
    y: Vec<f64>,
    /// Min and max of each complete block of `BLOCK` samples.
    l1: Vec<(f64, f64)>,
    /// Min and max of each complete block of `BLOCK²` samples.
    l2: Vec<(f64, f64)>,
}

fn merge(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    (a.0.min(b.0), a.1.max(b.1))
}

const EMPTY: (f64, f64) = (f64::INFINITY, f64::NEG_INFINITY);

impl Decimator {
    /// An empty signal.
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Sample times.
    pub fn times(&self) -> &[f64] {
        &self.t
    }

    /// Sample values.
    pub fn values(&self) -> &[f64] {
        &self.y
    }

    /// Forget every sample.
    pub fn clear(&mut self) {
        *self = Self::default();
    }

    /// Append samples; a sample not later than the last one is dropped (times must increase).
    pub fn extend(&mut self, t: &[f64], y: &[f64]) {
        for (&ti, &yi) in t.iter().zip(y) {
            if self.t.last().is_some_and(|&last| ti <= last) || !ti.is_finite() {
                continue;
            }
            self.t.push(ti);
            self.y.push(yi);
            let n = self.y.len();
            if n % BLOCK == 0 {
                let block = self.y[n - BLOCK..].iter().fold(EMPTY, |a, &v| merge(a, (v, v)));
                self.l1.push(block);
                if self.l1.len() % BLOCK == 0 {
                    let m = self.l1.len();
                    self.l2.push(self.l1[m - BLOCK..].iter().fold(EMPTY, |a, &b| merge(a, b)));
                }
            }
        }
    }

    /// Keep only the last `keep` samples (a ring buffer that drops its oldest half at a time
    /// keeps appends cheap); the pyramid is rebuilt.
    pub fn keep_last(&mut self, keep: usize) {
        if self.t.len() <= keep {
            return;
        }
        let drop = self.t.len() - keep;
        let (t, y) = (self.t.split_off(drop), self.y.split_off(drop));
        self.clear();
        self.extend(&t, &y);
    }

    /// Min and max over samples `i0..i1` (exact).
    pub fn range_min_max(&self, i0: usize, i1: usize) -> (f64, f64) {
        let b2 = BLOCK * BLOCK;
        let mut acc = EMPTY;
        let mut i = i0;
        while i < i1 {
            if i % b2 == 0 && i + b2 <= i1 && i / b2 < self.l2.len() {
                acc = merge(acc, self.l2[i / b2]);
                i += b2;
            } else if i % BLOCK == 0 && i + BLOCK <= i1 && i / BLOCK < self.l1.len() {
                acc = merge(acc, self.l1[i / BLOCK]);
                i += BLOCK;
            } else {
                acc = merge(acc, (self.y[i], self.y[i]));
                i += 1;
            }
        }
        acc
    }

    /// The signal over `[t0, t1]` reduced for a plot `columns` pixels wide: every sample when
    /// there are fewer than two per column, otherwise the min and the max of each column (in
    /// time order within the column, so the line draws the column's full vertical extent).
    /// One sample on each side of the range is included so the line reaches the plot edges.
    pub fn decimate(&self, t0: f64, t1: f64, columns: usize) -> Vec<[f64; 2]> {
        if self.t.is_empty() || t1 <= t0 || columns == 0 {
            return vec![];
        }
        let lo = self.t.partition_point(|&t| t < t0).saturating_sub(1);
        let hi = (self.t.partition_point(|&t| t <= t1) + 1).min(self.t.len());
        if hi <= lo {
            return vec![];
        }
        if hi - lo <= 2 * columns {
            return (lo..hi).map(|i| [self.t[i], self.y[i]]).collect();
        }
        let mut out = Vec::with_capacity(2 * columns + 2);
        let width = (t1 - t0) / columns as f64;
        let mut i = lo;
        // The sample before the range, then one column after another.
        if self.t[i] < t0 {
            out.push([self.t[i], self.y[i]]);
            i += 1;
        }
        for c in 0..columns {
            let end_t = if c + 1 == columns { t1 } else { t0 + (c + 1) as f64 * width };
            let j = i + self.t[i..hi].partition_point(|&t| t <= end_t);
            if j > i {
                let (mn, mx) = self.range_min_max(i, j);
                let (t_left, t_right) = (self.t[i], self.t[j - 1]);
                if mn == mx {
                    out.push([t_left, mn]);
                } else {
                    // Min then max, each at a time inside the column; the first sample's value
                    // decides the order so a monotonic stretch is not drawn as a zigzag.
                    let rising = self.y[i] <= self.y[j - 1];
                    let (a, b) = if rising { (mn, mx) } else { (mx, mn) };
                    out.push([t_left, a]);
                    out.push([t_right, b]);
                }
            }
            i = j;
            if i >= hi {
                break;
            }
        }
        // The sample after the range.
        while i < hi {
            out.push([self.t[i], self.y[i]]);
            i += 1;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute(t: &[f64], y: &[f64], t0: f64, t1: f64, columns: usize) -> Vec<(f64, f64)> {
        let w = (t1 - t0) / columns as f64;
        (0..columns)
            .map(|c| {
                let (a, b) = (t0 + c as f64 * w, if c + 1 == columns { t1 } else { t0 + (c + 1) as f64 * w });
                t.iter()
                    .zip(y)
                    .filter(|(&ti, _)| ti > a && ti <= b || (c == 0 && ti == a))
                    .fold(EMPTY, |acc, (_, &v)| merge(acc, (v, v)))
            })
            .collect()
    }

    #[test]
    fn block_min_max_match_a_brute_force_scan() {
        let n = 3 * BLOCK * BLOCK + 17;
        let y: Vec<f64> = (0..n).map(|i| ((i as f64) * 0.37).sin() * (1.0 + (i % 97) as f64)).collect();
        let t: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let mut d = Decimator::new();
        d.extend(&t, &y);
        for (i0, i1) in [(0, n), (5, 4100), (4096, 8192), (63, 65), (100, 100 + 2 * BLOCK * BLOCK + 3)] {
            let want = y[i0..i1].iter().fold(EMPTY, |a, &v| merge(a, (v, v)));
            assert_eq!(d.range_min_max(i0, i1), want, "{i0}..{i1}");
        }
    }

    #[test]
    fn a_million_samples_reduce_to_two_points_per_column_with_exact_extremes() {
        let n = 1_000_000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 1e-3).collect();
        let y: Vec<f64> = t.iter().map(|&x| (x * 7.0).sin() + 0.01 * (x * 1000.0).cos()).collect();
        let mut d = Decimator::new();
        d.extend(&t, &y);
        let (t0, t1, cols) = (100.0, 900.0, 800);
        let pts = d.decimate(t0, t1, cols);
        assert!(pts.len() <= 2 * cols + 2, "{} points", pts.len());
        let expected = brute(&t, &y, t0, t1, cols);
        // Every column's extremes appear among the points that fall in the column.
        let w = (t1 - t0) / cols as f64;
        for (c, &(mn, mx)) in expected.iter().enumerate() {
            let (a, b) = (t0 + c as f64 * w, t0 + (c + 1) as f64 * w);
            let inside: Vec<f64> =
                pts.iter().filter(|p| (p[0] > a || (c == 0 && p[0] >= a)) && p[0] <= b + 1e-12).map(|p| p[1]).collect();
            assert!(inside.contains(&mn) && inside.contains(&mx), "column {c}");
        }
        // Few samples: all of them, unreduced.
        let few = d.decimate(10.0, 10.5, 800);
        assert_eq!(few.len(), 501 + 2);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        #[test]
        fn decimation_never_loses_an_extreme(
            ys in prop::collection::vec(-1e3f64..1e3, 1..6000),
            cols in 1usize..300,
            a in 0.0f64..1.0, span in 0.01f64..1.0,
        ) {
            let n = ys.len();
            let t: Vec<f64> = (0..n).map(|i| i as f64).collect();
            let mut d = Decimator::new();
            d.extend(&t, &ys);
            let t0 = a * n as f64;
            let t1 = t0 + span * n as f64;
            let pts = d.decimate(t0, t1, cols);
            let inside: Vec<f64> = t.iter().zip(&ys).filter(|(&ti, _)| ti >= t0 && ti <= t1).map(|(_, &v)| v).collect();
            if let (Some(mn), Some(mx)) = (inside.iter().cloned().reduce(f64::min), inside.iter().cloned().reduce(f64::max)) {
                let got: Vec<f64> = pts.iter().filter(|p| p[0] >= t0 && p[0] <= t1).map(|p| p[1]).collect();
                prop_assert!(got.contains(&mn) && got.contains(&mx));
            }
            prop_assert!(pts.len() <= (2 * cols + 2).max(inside.len() + 2));
        }
    }
}
