//! The phase-equivalent gap from the samples alone: arccos of the envelope-normalised signal,
//! unwrapped through fringe extrema and reversed at the signal's own turning points.

use super::count::{ExtremumClass, FringeCount};
use super::envelope::Envelope;
use nalgebra::{DMatrix, DVector};

/// What the motion's geometry says of the gap's form: `gap = Σ c_k·basis_k(sample)` with free
/// coefficients (a rigid rotation: 1, cos φ, sin φ; a circle of pure translation: 1 and the
/// translation), and how many times at most it turns back.
pub struct PathForm<'a> {
    /// The basis functions at a sample (index into the signal).
    pub basis: &'a dyn Fn(usize) -> Vec<f64>,
    /// The most turning points the gap has along the motion.
    pub max_reversals: usize,
}

/// The model-free gap along a signal.
#[derive(Debug, Clone, PartialEq)]
pub struct Unwrapped {
    /// The gap change from the first sample (nm), up to one global sign.
    pub gap_nm: Vec<f64>,
    /// The fringe extrema taken as turning points of the gap (sample indices) besides the
    /// signal's own turning points.
    pub reversals_at_fringe_extrema: Vec<usize>,
    /// The peak to peak (nm) of the next best placement of those reversals when it fits the
    /// path's form nearly as well: the samples cannot tell the two apart.
    pub runner_up_peak_to_peak_nm: Option<f64>,
    /// How far (nm) the gap may have gone past a fringe extremum where it turned back unseen: the
    /// excursion whose intensity change stays within the hysteresis. Zero when no reversal sits
    /// at a fringe extremum.
    pub hidden_excursion_nm: f64,
}

/// How much worse (rms, in steps) than the best a placement of the reversals may fit the path's
/// form and still be a contender: the arccos error at a fringe extremum, a few hundredths of a
/// step, and the fringe's distortion.
const CONTENDER_STEPS: f64 = 0.08;
/// Most fringe extrema over which reversals are placed by trial (beyond, none are added).
const MAX_TRIAL_EXTREMA: usize = 120;

/// The gap change along `signal` from its first sample (nm, in steps `step_nm` = λ/(4n)), up to
/// one global sign: between consecutive extrema the intensity is monotonic and the gap moves one
/// way, `arccos((I − A)/B)/π` steps from where the stretch began; through a fringe top or bottom
/// it keeps its direction, at a turning point ([`ExtremumClass::Turning`]) it reverses.
///
/// A reversal exactly at a fringe extremum looks like a crossing. With the path's `form`, the
/// signal's own turning points are completed up to `form.max_reversals` by reversals placed at
/// fringe extrema, the placement whose gap the form fits best (least squares at the extrema);
/// without it, every fringe extremum is a crossing and the gap can read larger than it is.
pub fn unwrap_gap_nm(
    signal: &[f64],
    envelope_at: &dyn Fn(usize) -> Envelope,
    count: &FringeCount,
    step_nm: f64,
    form: Option<&PathForm<'_>>,
) -> Unwrapped {
    let n = signal.len();
    if n == 0 {
        return Unwrapped {
            gap_nm: vec![],
            reversals_at_fringe_extrema: vec![],
            runner_up_peak_to_peak_nm: None,
            hidden_excursion_nm: 0.0,
        };
    }
    let theta: Vec<f64> =
        (0..n).map(|i| envelope_at(i).normalised(signal[i]).clamp(-1.0, 1.0).acos() / std::f64::consts::PI).collect();
    let mut bounds: Vec<(usize, Option<ExtremumClass>)> = vec![(0, None)];
    bounds.extend(count.classes.iter().filter(|c| c.0 > 0 && c.0 < n - 1).map(|&(i, c)| (i, Some(c))));
    bounds.push((n - 1, None));
    hidden_end_extrema(&mut bounds, &theta, count);
    // The move of each stretch between consecutive bounds, in steps (≥ 0).
    let moves: Vec<f64> = bounds.windows(2).map(|w| (theta[w[1].0] - theta[w[0].0]).abs()).collect();
    let definite: Vec<bool> = bounds.iter().map(|b| b.1 == Some(ExtremumClass::Turning)).collect();
    let candidates: Vec<usize> = (1..bounds.len() - 1).filter(|&j| !definite[j]).collect();
    let mut reversed = definite.clone();
    let mut runner_up = None;
    if let Some(form) = form {
        let spare = form.max_reversals.saturating_sub(definite.iter().filter(|d| **d).count());
        if spare > 0 && candidates.len() <= MAX_TRIAL_EXTREMA && bounds.len() > form_dims(form, bounds[0].0) + 1 {
            let (best, second) = best_placement(&bounds, &moves, &definite, &candidates, spare, form);
            for &j in &best.1 {
                reversed[j] = true;
            }
            if let Some((rms, at, ptp)) = second {
                if rms <= best.0 + CONTENDER_STEPS {
                    let _ = at;
                    runner_up = Some(ptp * step_nm);
                }
            }
        }
    }
    let mut gap_nm = vec![0.0; n];
    let mut dir = 1.0;
    for (j, w) in bounds.windows(2).enumerate() {
        let ((a, _), (b, _)) = (w[0], w[1]);
        let way = if theta[b] >= theta[a] { 1.0 } else { -1.0 };
        let base = gap_nm[a];
        for t in a..=b {
            gap_nm[t] = base + dir * way * (theta[t] - theta[a]) * step_nm;
        }
        if reversed[j + 1] {
            dir = -dir;
        }
    }
    let reversals_at_fringe_extrema: Vec<usize> =
        candidates.iter().filter(|&&j| reversed[j]).map(|&j| bounds[j].0).collect();
    let b = count.smallest_amplitude;
    let hidden = if reversals_at_fringe_extrema.is_empty() || b.is_nan() || b <= 0.0 {
        0.0
    } else {
        (1.0 - (count.hysteresis / b).min(2.0)).acos() / std::f64::consts::PI * step_nm
    };
    Unwrapped { gap_nm, reversals_at_fringe_extrema, runner_up_peak_to_peak_nm: runner_up, hidden_excursion_nm: hidden }
}

/// A fringe extremum within the hysteresis of either end of the signal: the detector confirms
/// an extremum only after a swing of the hysteresis on both sides, so the gap can cross a fringe
/// top or bottom just after the first sample (or before the last) unseen, and the first stretch
/// would read a move of `1 − θ` as `θ`. Where the first (last) stretch's θ comes closer to 0 or
/// 1 inside it than at both its ends, by more than the noise, a fringe extremum is added there.
fn hidden_end_extrema(bounds: &mut Vec<(usize, Option<ExtremumClass>)>, theta: &[f64], count: &FringeCount) {
    let near = count.step_tolerance.max(0.02);
    let sigma = count.hysteresis / super::NOISE_HYSTERESIS_SIGMA / count.smallest_amplitude;
    let margin = if sigma.is_finite() { 2.0 * (2.0 * sigma).sqrt() / std::f64::consts::PI } else { near };
    let detour = |a: usize, b: usize| -> Option<(usize, ExtremumClass)> {
        if b <= a + 2 {
            return None;
        }
        let (lo, hi) = (theta[a].min(theta[b]), theta[a].max(theta[b]));
        let (i_min, t_min) = (a..=b).map(|i| (i, theta[i])).min_by(|x, y| x.1.total_cmp(&y.1))?;
        let (i_max, t_max) = (a..=b).map(|i| (i, theta[i])).max_by(|x, y| x.1.total_cmp(&y.1))?;
        if t_min < near && lo - t_min > margin && i_min > a && i_min < b {
            return Some((i_min, ExtremumClass::Top));
        }
        if t_max > 1.0 - near && t_max - hi > margin && i_max > a && i_max < b {
            return Some((i_max, ExtremumClass::Bottom));
        }
        None
    };
    let last = bounds.len() - 1;
    if let Some((i, c)) = detour(bounds[last - 1].0, bounds[last].0) {
        bounds.insert(last, (i, Some(c)));
    }
    if let Some((i, c)) = detour(bounds[0].0, bounds[1].0) {
        bounds.insert(1, (i, Some(c)));
    }
}

fn form_dims(form: &PathForm<'_>, at: usize) -> usize {
    (form.basis)(at).len()
}

/// The gap (steps) at each bound with reversals at the bounds flagged in `reversed`.
fn gap_at_bounds(moves: &[f64], reversed: &[bool]) -> Vec<f64> {
    let mut out = Vec::with_capacity(moves.len() + 1);
    let (mut g, mut dir) = (0.0, 1.0);
    out.push(g);
    for (j, m) in moves.iter().enumerate() {
        g += dir * m;
        out.push(g);
        if reversed[j + 1] {
            dir = -dir;
        }
    }
    out
}

fn peak_to_peak(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::NEG_INFINITY, f64::max) - v.iter().copied().fold(f64::INFINITY, f64::min)
}

/// The rms residual (steps) of the form's least-squares fit to the gap at the bounds.
fn form_residual(bounds: &[(usize, Option<ExtremumClass>)], gap: &[f64], form: &PathForm<'_>) -> f64 {
    let rows: Vec<Vec<f64>> = bounds.iter().map(|b| (form.basis)(b.0)).collect();
    let cols = rows[0].len();
    let a = DMatrix::from_fn(rows.len(), cols, |r, c| rows[r][c]);
    let y = DVector::from_column_slice(gap);
    let Ok(x) = a.clone().svd(true, true).solve(&y, 1e-12) else { return f64::INFINITY };
    ((&a * x - y).norm_squared() / rows.len() as f64).sqrt()
}

/// Each placement of up to `spare` reversals among the `candidates` bounds: the best (rms and its
/// bounds) and the runner-up with a different peak to peak (rms, bounds, peak to peak in steps).
#[allow(clippy::type_complexity)]
fn best_placement(
    bounds: &[(usize, Option<ExtremumClass>)],
    moves: &[f64],
    definite: &[bool],
    candidates: &[usize],
    spare: usize,
    form: &PathForm<'_>,
) -> ((f64, Vec<usize>, f64), Option<(f64, Vec<usize>, f64)>) {
    let mut trials: Vec<Vec<usize>> = vec![vec![]];
    for &a in candidates {
        trials.push(vec![a]);
        if spare >= 2 {
            trials.extend(candidates.iter().filter(|&&b| b > a).map(|&b| vec![a, b]));
        }
    }
    let mut scored: Vec<(f64, Vec<usize>, f64)> = trials
        .into_iter()
        .map(|t| {
            let mut reversed = definite.to_vec();
            for &j in &t {
                reversed[j] = true;
            }
            let gap = gap_at_bounds(moves, &reversed);
            (form_residual(bounds, &gap, form), t, peak_to_peak(&gap))
        })
        .collect();
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    let best = scored[0].clone();
    let second = scored.iter().skip(1).find(|s| (s.2 - best.2).abs() > 0.25).cloned();
    (best, second)
}

#[cfg(test)]
mod tests {
    use super::super::count::count_fringes;
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    fn ptp(v: &[f64]) -> f64 {
        peak_to_peak(v)
    }

    /// Gaps that rise and fall by several fringes over a closed circle, with turning points
    /// anywhere (some right at fringe extrema): with the circle's form the unwrapped gap follows
    /// the truth (up to its sign) within the arccos floor, and within twice the excursion the
    /// hysteresis hides where the gap turns at a fringe extremum.
    #[test]
    fn the_unwrapped_gap_follows_a_gap_that_rises_and_falls() {
        let step = 390.0;
        let env = Envelope { offset: 1.0, amplitude: 0.5, sigma_amplitude: 1e-5, noise_sigma: 1e-3 };
        let cases = [(3.3, 0.4), (7.71, 2.0), (0.42, 1.1), (12.05, 5.0), (2.0, 0.0), (3.0, 0.3), (5.5, 1.0)];
        for (k, (amplitude, phase)) in cases.into_iter().enumerate() {
            let mut rng = rand::rngs::StdRng::seed_from_u64(k as u64);
            let noise = Normal::new(0.0, 1e-3).unwrap();
            let n = 40_000;
            let s = |i: usize| phase + std::f64::consts::TAU * i as f64 / (n - 1) as f64;
            let u: Vec<f64> = (0..n).map(|i| amplitude * s(i).cos()).collect();
            let signal: Vec<f64> =
                u.iter().map(|u| 1.0 + 0.5 * (std::f64::consts::PI * u).cos() + noise.sample(&mut rng)).collect();
            let count = count_fringes(&signal, Some((&|_| env, 0.0)));
            let basis = |i: usize| vec![1.0, s(i).cos(), s(i).sin()];
            let form = PathForm { basis: &basis, max_reversals: 2 };
            let d = unwrap_gap_nm(&signal, &|_| env, &count, step, Some(&form));
            let truth: Vec<f64> = u.iter().map(|v| (v - u[0]) * step).collect();
            let worst = |sign: f64| d.gap_nm.iter().zip(&truth).map(|(a, b)| (sign * a - b).abs()).fold(0.0, f64::max);
            let worst = worst(1.0).min(worst(-1.0));
            let (got, want) = (ptp(&d.gap_nm), ptp(&truth));
            let hidden = d.hidden_excursion_nm;
            eprintln!(
                "amplitude {amplitude}: ptp {got:.1} vs {want:.1} nm, worst {worst:.1} nm, hidden {hidden:.1} nm"
            );
            assert!(worst < 25.0 + 2.0 * hidden, "amplitude {amplitude}: {worst} nm off");
            assert!(
                (got - want).abs() < 0.01 * want + 15.0 + 2.0 * hidden,
                "amplitude {amplitude}: {got} vs {want} nm"
            );
        }
    }
}
