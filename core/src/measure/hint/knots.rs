//! A smooth function of the joints along a trace, evaluated exactly at knots and interpolated
//! between them where the interpolation is shown to hold: the model's hint and fringe shape cost
//! a few hundred ns per sample (kinematics, cavity geometry, multi-beam sums), and a recorded
//! motion is smooth over many samples.

use crate::trace::Trace;

/// Samples between knots.
pub(super) const KNOT_SAMPLES: usize = 16;

/// How far a joint may be off its interpolant and the interval still count as smooth: 0.1 pm
/// for the stages in µm, 1e-9° for the goniometers and the rotary stage (1.7e-5 nm of gap at a
/// 1 mm lever arm). A recording whose joints are quantised or noisy at the sample scale fails
/// this and is evaluated at every sample.
const JOINT_TOL: [f64; 6] = [1e-7, 1e-7, 1e-7, 1e-9, 1e-9, 1e-9];

/// `eval(i)` for every sample i of `trace`: exact at every [`KNOT_SAMPLES`]-th sample, the last,
/// and the middle of every interval; cubic Lagrange interpolation through the four nearest
/// knots elsewhere, kept only where every joint at every sample of the interval lies within
/// [`JOINT_TOL`] of its own interpolant and the value's interpolant at the middle is within
/// `tol` of `eval` there; each value is checked on its own, so a value's samples do not depend
/// on the other values. A value failing either check is taken from `eval` at every sample of
/// the interval, as are all on a trace too short for four knots. The first error of `eval` is
/// returned.
pub(super) fn along_trace<const V: usize, E>(
    trace: &Trace,
    tol: &[f64; V],
    mut eval: impl FnMut(usize) -> Result<[f64; V], E>,
) -> Result<Vec<[f64; V]>, E> {
    let n = trace.len();
    let mut out = vec![[0.0; V]; n];
    let knots: Vec<usize> =
        (0..n).step_by(KNOT_SAMPLES).chain((n > 0 && (n - 1) % KNOT_SAMPLES != 0).then_some(n - 1)).collect();
    if knots.len() < 4 {
        for (i, o) in out.iter_mut().enumerate() {
            *o = eval(i)?;
        }
        return Ok(out);
    }
    for &k in &knots {
        out[k] = eval(k)?;
    }
    let joints: [&[f64]; 6] = std::array::from_fn(|j| trace.joint_column(j));
    // Interior intervals share their nodes' layout, hence their weights.
    let (mut layout, mut weights) = (None, Vec::new());
    for j in 0..knots.len() - 1 {
        let (a, b) = (knots[j], knots[j + 1]);
        if b - a < 2 {
            continue;
        }
        let s = j.saturating_sub(1).min(knots.len() - 4);
        let nodes: [usize; 4] = std::array::from_fn(|l| knots[s + l]);
        let this_layout = (nodes.map(|k| k as isize - a as isize), b - a);
        if layout != Some(this_layout) {
            weights = (a + 1..b).map(|i| lagrange_weights(&nodes, i)).collect();
            layout = Some(this_layout);
        }
        let smooth = (a + 1..b).zip(&weights).all(|(i, w)| {
            joints.iter().zip(JOINT_TOL).all(|(q, tol)| (q[i] - dot(w, nodes.map(|k| q[k]))).abs() <= tol)
        });
        let at_knots: [[f64; V]; 4] = nodes.map(|k| out[k]);
        let interpolant = |w: &[f64; 4]| -> [f64; V] { std::array::from_fn(|v| dot(w, at_knots.map(|x| x[v]))) };
        let mid = (a + b) / 2;
        let at_mid = eval(mid)?;
        let at_mid_fit = interpolant(&weights[mid - a - 1]);
        let fits: [bool; V] = std::array::from_fn(|v| smooth && (at_mid_fit[v] - at_mid[v]).abs() <= tol[v]);
        for (i, w) in (a + 1..b).zip(&weights) {
            out[i] = if i == mid {
                at_mid
            } else if fits.iter().all(|&f| f) {
                interpolant(w)
            } else {
                let (exact, fit) = (eval(i)?, interpolant(w));
                std::array::from_fn(|v| if fits[v] { fit[v] } else { exact[v] })
            };
        }
    }
    Ok(out)
}

/// The cubic Lagrange weights of `nodes` (sample indices) at sample `i`.
fn lagrange_weights(nodes: &[usize; 4], i: usize) -> [f64; 4] {
    let x = i as f64;
    let xs = nodes.map(|k| k as f64);
    std::array::from_fn(|l| (0..4).filter(|&m| m != l).map(|m| (x - xs[m]) / (xs[l] - xs[m])).product())
}

fn dot(w: &[f64; 4], v: [f64; 4]) -> f64 {
    w[0] * v[0] + w[1] * v[1] + w[2] * v[2] + w[3] * v[3]
}
