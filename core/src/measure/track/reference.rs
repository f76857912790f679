//! A straightforward reference of the Gauss-Newton kernel (test only): one scalar loop over
//! the samples with the library's sine and cosine, the harmonics from sin/cos of 2ψ and 3ψ,
//! and each sample's Jacobian row summed into the normal equations as written. The
//! optimised kernel ([`super::kernel::accumulate`]) is checked against it, alone and inside
//! the whole tracker.

use super::harmonic::Harmonic;
use super::kernel::{NormalEq, Samples, State};
use nalgebra::Vector3;
use std::cell::Cell;

thread_local! {
    /// When set, [`super::kernel::accumulate`] runs [`accumulate_reference`] on this thread.
    pub(super) static USE_REFERENCE: Cell<bool> = const { Cell::new(false) };
}

/// `f(ψ)` and `f'(ψ)` from the harmonic's definition.
fn f_and_slope(h: &Harmonic, psi: f64) -> (f64, f64) {
    let (s1, c1) = psi.sin_cos();
    let (s2, c2) = (2.0 * psi).sin_cos();
    let (s3, c3) = (3.0 * psi).sin_cos();
    let f = c1 + h.cos_rel * c2 + h.sin_rel * s2 + h.cos3_rel * c3 + h.sin3_rel * s3;
    let fp = -s1 - 2.0 * h.cos_rel * s2 + 2.0 * h.sin_rel * c2 - 3.0 * h.cos3_rel * s3 + 3.0 * h.sin3_rel * c3;
    (f, fp)
}

/// Add `w`·v·vᵀ to a symmetric block stored as (00, 01, 02, 11, 12, 22).
fn add_outer(m: &mut [f64; 6], w: f64, a: &Vector3<f64>, b: &Vector3<f64>) {
    let idx = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];
    for (e, (r, c)) in m.iter_mut().zip(idx) {
        *e += w * a[r] * b[c];
    }
}

/// The normal equations of the linearised model
/// ν = I - A - B·f(ψ) ≈ h·δ + ΔA + r·f·ΔB + h·u·γ, sample by sample.
#[allow(clippy::needless_range_loop)] // knots j and j + 1 of several per-knot arrays
pub(super) fn accumulate_reference(samples: &Samples, state: &State, seg_harm: &[Harmonic], normal: &mut NormalEq) {
    normal.reset();
    let n_knots = state.delta.len();
    for j in 0..n_knots - 1 {
        for k in samples.seg_first[j]..samples.seg_first[j + 1] {
            let (harm, r, ca) = match &samples.shape {
                Some(sh) => (sh.harm[k], sh.r[k], sh.ca[k]),
                None => (seg_harm[j], 1.0, 0.0),
            };
            let (w0, w1) = (1.0 - (samples.c[k] - j as f64), samples.c[k] - j as f64);
            let u = state.rad_per_hint_nm * (samples.hint[k] - state.hint_ref);
            let psi = state.intercept + u * (1.0 + state.gamma) + w0 * state.delta[j] + w1 * state.delta[j + 1];
            let a = w0 * state.offset[j] + w1 * state.offset[j + 1] + ca;
            let b = r * (w0 * state.amplitude[j] + w1 * state.amplitude[j + 1]);
            let (f, fp) = f_and_slope(&harm, psi);
            let nu = samples.y[k] - a - b * f;
            // the derivatives of the model by (δ, A, B) at a knot, before the hat weight
            let v = Vector3::new(b * fp, 1.0, r * f);
            let hu = b * fp * u;
            add_outer(&mut normal.diag[j], w0 * w0, &v, &v);
            add_outer(&mut normal.off[j], w0 * w1, &v, &v);
            add_outer(&mut normal.diag[j + 1], w1 * w1, &v, &v);
            normal.rhs[j] += v * (w0 * nu);
            normal.rhs[j + 1] += v * (w1 * nu);
            normal.border[j] += v * (w0 * hu);
            normal.border[j + 1] += v * (w1 * hu);
            normal.s_gg += hu * hu;
            normal.r_g += hu * nu;
            normal.nu2 += nu * nu;
            normal.count += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::kernel::{accumulate, ShapeView};
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// The optimised kernel's normal equations equal the reference's within rounding, on
        /// random segments (lengths across chunk and lane boundaries), states, harmonics and
        /// fringe models.
        #[test]
        fn kernel_matches_the_reference(
            seg_len in proptest::collection::vec(0usize..300, 1..6),
            seed in 0u64..10_000,
            shaped in proptest::bool::ANY,
        ) {
            use rand::{Rng, SeedableRng};
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let n_knots = seg_len.len() + 1;
            let mut seg_first = vec![0usize];
            let mut c = Vec::new();
            for (j, &m) in seg_len.iter().enumerate() {
                c.extend((0..m).map(|i| j as f64 + (i as f64 + 0.5) / m as f64));
                seg_first.push(c.len());
            }
            let n = c.len();
            let y: Vec<f64> = (0..n).map(|_| rng.random_range(-0.5..2.5)).collect();
            let hint: Vec<f64> = (0..n).map(|k| 3.0 * k as f64 + rng.random_range(-1.0..1.0)).collect();
            let mut harm = || Harmonic {
                cos_rel: rng.random_range(-0.05..0.05),
                sin_rel: rng.random_range(-0.05..0.05),
                cos3_rel: rng.random_range(-0.01..0.01),
                sin3_rel: rng.random_range(-0.01..0.01),
            };
            let seg_harm: Vec<Harmonic> = (0..n_knots).map(|_| harm()).collect();
            let sh: Vec<Harmonic> = (0..n).map(|_| harm()).collect();
            let r: Vec<f64> = (0..n).map(|_| rng.random_range(0.5..2.0)).collect();
            let ca: Vec<f64> = (0..n).map(|_| rng.random_range(-0.1..0.1)).collect();
            let state = State {
                intercept: rng.random_range(-10.0..10.0),
                rad_per_hint_nm: 0.008,
                hint_ref: hint.first().copied().unwrap_or(0.0),
                gamma: rng.random_range(-0.01..0.01),
                delta: (0..n_knots).map(|_| rng.random_range(-1.0..1.0)).collect(),
                offset: (0..n_knots).map(|_| rng.random_range(0.5..1.5)).collect(),
                amplitude: (0..n_knots).map(|_| rng.random_range(0.1..0.5)).collect(),
            };
            let shape = shaped.then_some(ShapeView { harm: &sh, r: &r, ca: &ca });
            let samples = Samples { y: &y, hint: &hint, c: &c, seg_first: &seg_first, shape };
            let (mut fast, mut slow) = (NormalEq::new(n_knots), NormalEq::new(n_knots));
            accumulate(&samples, &state, &seg_harm, &mut fast);
            accumulate_reference(&samples, &state, &seg_harm, &mut slow);
            prop_assert_eq!(fast.count, slow.count);
            // rounding of sums of `count` terms of magnitude up to (B·u)² (u ≤ 0.008·3n rad)
            let umax = 1.0 + 0.024 * n as f64;
            let tol = 1e-13 * (1 + n) as f64 * umax * umax;
            let close = |a: f64, b: f64| (a - b).abs() <= tol;
            for j in 0..n_knots {
                for i in 0..6 {
                    prop_assert!(close(fast.diag[j][i], slow.diag[j][i]), "diag {j} {i}");
                    prop_assert!(close(fast.off[j][i], slow.off[j][i]), "off {j} {i}");
                }
                for i in 0..3 {
                    prop_assert!(close(fast.rhs[j][i], slow.rhs[j][i]), "rhs {j} {i}");
                    prop_assert!(close(fast.border[j][i], slow.border[j][i]), "border {j} {i}");
                }
            }
            prop_assert!(close(fast.s_gg, slow.s_gg) && close(fast.r_g, slow.r_g) && close(fast.nu2, slow.nu2));
        }
    }
}
