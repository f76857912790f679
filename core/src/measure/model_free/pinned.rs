//! The envelope carried along a signal by a model of how it changes, pinned to the signal's own
//! fringe tops and bottoms. Owns the correction between extrema.

use super::count::ExtremumClass;
use super::envelope::{half_window, vertex, Envelope};

/// The envelope `carried` along a signal (from a model of how it changes), pinned to the signal's
/// own fringe tops and bottoms (`classes`, [`super::count_fringes`]): at each the top (bottom)
/// is the parabola vertex of the samples, the correction to the carried one (relative to its
/// amplitude) interpolated linearly between extrema of its kind and held beyond. Between them the
/// carried shape stays. An arccos read against it reaches 0 (1) at each fringe extremum, so an
/// envelope carried a few per cent off no longer costs a piece of a step at every extremum.
pub fn pinned_to_extrema<'a>(
    signal: &[f64],
    classes: &[(usize, ExtremumClass)],
    carried: &'a dyn Fn(usize) -> Envelope,
) -> impl Fn(usize) -> Envelope + 'a {
    let (mut tops, mut bottoms) = (Vec::new(), Vec::new());
    let fringe: Vec<(usize, ExtremumClass)> =
        classes.iter().copied().filter(|c| c.1 != ExtremumClass::Turning).collect();
    for (k, &(i, class)) in fringe.iter().enumerate() {
        let near = [k.checked_sub(1).map(|j| fringe[j].0), fringe.get(k + 1).map(|n| n.0)]
            .into_iter()
            .flatten()
            .map(|j| j.abs_diff(i))
            .min()
            .unwrap_or(signal.len());
        let Some((v, _)) = vertex(signal, i, half_window(2.0 * near as f64), 0.0) else { continue };
        let e = carried(i);
        match class {
            ExtremumClass::Top => tops.push((i as f64, (v - (e.offset + e.amplitude)) / e.amplitude)),
            _ => bottoms.push((i as f64, (v - (e.offset - e.amplitude)) / e.amplitude)),
        }
    }
    move |i: usize| {
        let e = carried(i);
        let top = e.offset + e.amplitude * (1.0 + piecewise_linear(&tops, i as f64));
        let bottom = e.offset - e.amplitude * (1.0 - piecewise_linear(&bottoms, i as f64));
        if top <= bottom {
            return e;
        }
        Envelope { offset: 0.5 * (top + bottom), amplitude: 0.5 * (top - bottom), ..e }
    }
}

/// Piecewise-linear interpolation in `(x, y)` points sorted by x, held beyond the ends; zero
/// without points.
pub fn piecewise_linear(points: &[(f64, f64)], x: f64) -> f64 {
    let k = points.partition_point(|p| p.0 < x);
    match (k.checked_sub(1).map(|j| points[j]), points.get(k)) {
        (None, None) => 0.0,
        (Some(a), None) => a.1,
        (None, Some(b)) => b.1,
        (Some(a), Some(b)) if b.0 > a.0 => a.1 + (b.1 - a.1) * (x - a.0) / (b.0 - a.0),
        (Some(a), Some(_)) => a.1,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fringe whose envelope grows along the signal, read against an envelope carried 5 % too
    /// deep: pinned to the extrema, the arccos reaches the top and the bottom at each of them,
    /// and between two it stays within the carried shape's error.
    #[test]
    fn an_envelope_pinned_to_the_extrema_meets_the_fringe_there() {
        let n = 20_000;
        let amp = |i: usize| 1.0 + 0.5 * i as f64 / n as f64;
        let phase = |i: usize| 5.0 * std::f64::consts::TAU * i as f64 / n as f64;
        let signal: Vec<f64> = (0..n).map(|i| 3.0 + amp(i) * phase(i).cos()).collect();
        let carried =
            |i: usize| Envelope { offset: 3.0, amplitude: 1.05 * amp(i), sigma_amplitude: 0.0, noise_sigma: 0.0 };
        let classes: Vec<(usize, ExtremumClass)> = (1..10)
            .map(|k| (k * n / 10, if k % 2 == 0 { ExtremumClass::Top } else { ExtremumClass::Bottom }))
            .chain(std::iter::once((n / 4 + 7, ExtremumClass::Turning)))
            .collect::<std::collections::BTreeMap<_, _>>()
            .into_iter()
            .collect();
        let pinned = pinned_to_extrema(&signal, &classes, &carried);
        for &(i, class) in classes.iter().filter(|c| c.1 != ExtremumClass::Turning) {
            let u = pinned(i).normalised(signal[i]);
            let want = if class == ExtremumClass::Top { 1.0 } else { -1.0 };
            assert!((u - want).abs() < 1e-3, "at {i}: {u} (carried {})", carried(i).normalised(signal[i]));
            assert!((carried(i).normalised(signal[i]) - want).abs() > 0.04, "the carried one misses it");
        }
        for i in (0..n).step_by(97) {
            let e = pinned(i);
            assert!((e.amplitude - amp(i)).abs() < 1e-3 * amp(i) && (e.offset - 3.0).abs() < 1e-3, "at {i}: {e:?}");
        }
    }
}
