//! The per-sample kernel of a Gauss-Newton step: the linearised model of every sample and
//! its sums into the normal equations, segment by segment, vectorised (AVX2/FMA when the CPU
//! has them).

use super::factor::Sym3;
use super::harmonic::Harmonic;
use crate::measure::signal::{madd, sincos_k};
use nalgebra::Vector3;

/// Normal equations of one Gauss-Newton step: per knot (δ, ΔA, ΔB) in a block-tridiagonal
/// matrix, bordered by one global unknown γ (relative hint-scale correction).
pub(super) struct NormalEq {
    pub(super) diag: Vec<Sym3>,
    pub(super) off: Vec<Sym3>,
    pub(super) rhs: Vec<Vector3<f64>>,
    /// Coupling of each knot's unknowns with γ.
    pub(super) border: Vec<Vector3<f64>>,
    /// γγ element.
    pub(super) s_gg: f64,
    /// γ right-hand side.
    pub(super) r_g: f64,
    pub(super) nu2: f64,
    pub(super) count: usize,
}

/// Current estimate: φ(k) = intercept + g·κ·(1 + γ)·(hint(k) - hint_ref) + δ(c_k), and the
/// envelope A, B per knot.
pub(super) struct State {
    /// Phase at zero hint, rad.
    pub(super) intercept: f64,
    /// The hint's phase per nm, g·κ, rad/nm.
    pub(super) rad_per_hint_nm: f64,
    /// The hint at the first sample, nm.
    pub(super) hint_ref: f64,
    /// Relative hint-scale correction γ.
    pub(super) gamma: f64,
    /// Phase correction δ per knot, rad.
    pub(super) delta: Vec<f64>,
    /// Envelope offset A per knot.
    pub(super) offset: Vec<f64>,
    /// Envelope amplitude B per knot.
    pub(super) amplitude: Vec<f64>,
}

/// Number of per-sample sums of one grid segment.
pub(super) const NACC: usize = 33;
/// Samples processed together (structure-of-arrays scratch).
pub(super) const CHUNK: usize = 128;

/// Per-segment constants of the linearisation point.
#[derive(Clone, Copy)]
pub(super) struct SegConst {
    pub(super) jf: f64,
    pub(super) d0: f64,
    pub(super) d1: f64,
    pub(super) a0: f64,
    pub(super) a1: f64,
    pub(super) b0: f64,
    pub(super) b1: f64,
    pub(super) intercept: f64,
    pub(super) rad_per_hint_nm: f64,
    pub(super) hint_ref: f64,
    pub(super) scale: f64,
    /// Fringe harmonics over the segment.
    pub(super) harm: Harmonic,
}

/// Scratch of one chunk: per-sample weights and model terms.
pub(super) struct Chunk {
    pub(super) w0: [f64; CHUNK],
    pub(super) w1: [f64; CHUNK],
    pub(super) f: [f64; CHUNK],
    pub(super) h: [f64; CHUNK],
    pub(super) nu: [f64; CHUNK],
    pub(super) hu: [f64; CHUNK],
    /// Per-sample model (shaped tracking only): cos 2φ, sin 2φ, cos 3φ, sin 3φ, r, ca.
    pub(super) hc2: [f64; CHUNK],
    pub(super) hs2: [f64; CHUNK],
    pub(super) hc3: [f64; CHUNK],
    pub(super) hs3: [f64; CHUNK],
    pub(super) r: [f64; CHUNK],
    pub(super) ca: [f64; CHUNK],
}

/// Model terms of a chunk (elementwise, vectorises): ψ, f(ψ), h = B·f'(ψ), ν, h·u, and the
/// hat-function weights (w0, w1, ν and u zero beyond `m`, so padding lanes add nothing).
/// `c`, `hint` and `y` hold the chunk's samples (at least `m` rounded up to 4 of them; the
/// padding lanes only need to be finite).
#[inline(always)]
#[allow(clippy::needless_range_loop)] // lane-indexed on purpose: it vectorises
pub(super) fn chunk_terms<const FMA: bool, const SHAPED: bool>(
    chunk: &mut Chunk,
    m: usize,
    seg: &SegConst,
    c: &[f64],
    hint: &[f64],
    y: &[f64],
) {
    let m4 = m.div_ceil(4) * 4;
    let (c, hint, y) = (&c[..m4], &hint[..m4], &y[..m4]);
    for i in 0..m4 {
        let harm = if SHAPED {
            Harmonic { cos_rel: chunk.hc2[i], sin_rel: chunk.hs2[i], cos3_rel: chunk.hc3[i], sin3_rel: chunk.hs3[i] }
        } else {
            seg.harm
        };
        let live = if i < m { 1.0 } else { 0.0 };
        let t = c[i] - seg.jf;
        let w0 = 1.0 - t;
        let u = seg.rad_per_hint_nm * (hint[i] - seg.hint_ref) * live;
        let psi = madd::<FMA>(u, seg.scale, madd::<FMA>(w0, seg.d0, madd::<FMA>(t, seg.d1, seg.intercept)));
        let (r, ca) = if SHAPED { (chunk.r[i], chunk.ca[i]) } else { (1.0, 0.0) };
        let aa = madd::<FMA>(w0, seg.a0, madd::<FMA>(t, seg.a1, ca));
        let bb = r * madd::<FMA>(w0, seg.b0, t * seg.b1);
        let (sn, co) = sincos_k::<FMA>(psi);
        let (f, fp) = harm.f_and_slope(sn, co);
        // h and f enter the sums only through w0, w1 or h·u (u = 0 on padding lanes)
        let h = bb * fp;
        let nu = (y[i] - madd::<FMA>(bb, f, aa)) * live;
        chunk.w0[i] = w0 * live;
        chunk.w1[i] = t * live;
        chunk.f[i] = r * f;
        chunk.h[i] = h;
        chunk.nu[i] = nu;
        chunk.hu[i] = h * u;
    }
}

/// Sums of a chunk into 4-lane accumulators: JᵀJ blocks (w0², w0·w1, w1² times vvᵀ,
/// v = (h, 1, f)), Jᵀν, the γ border, γγ, γν and ν².
///
/// Four passes over the chunk, each with at most 9 accumulators, so that they stay in
/// registers (33 do not fit); every accumulator lane still adds the same terms in the same
/// order as one pass would.
#[inline(always)]
#[allow(clippy::needless_range_loop)] // lane-indexed on purpose: it vectorises
pub(super) fn chunk_sums<const FMA: bool>(chunk: &Chunk, m: usize, acc: &mut [[f64; 4]; NACC]) {
    let m4 = m.div_ceil(4) * 4;
    let (w0, w1, f, h, nu, hu) = (&chunk.w0, &chunk.w1, &chunk.f, &chunk.h, &chunk.nu, &chunk.hu);
    // JᵀJ: for each weight (w0², w0·w1, w1²) the (h², h, h·f) and the (1, f, f²) columns
    for half in 0..2 {
        let idx: [usize; 9] = std::array::from_fn(|q| 3 * half + 6 * (q / 3) + q % 3);
        let mut a: [[f64; 4]; 9] = std::array::from_fn(|q| acc[idx[q]]);
        for i0 in (0..m4).step_by(4) {
            for l in 0..4 {
                let i = i0 + l;
                let (w00, w01, w11) = (w0[i] * w0[i], w0[i] * w1[i], w1[i] * w1[i]);
                let vv = if half == 0 { [h[i] * h[i], h[i], h[i] * f[i]] } else { [1.0, f[i], f[i] * f[i]] };
                for q in 0..3 {
                    a[q][l] = madd::<FMA>(w00, vv[q], a[q][l]);
                    a[3 + q][l] = madd::<FMA>(w01, vv[q], a[3 + q][l]);
                    a[6 + q][l] = madd::<FMA>(w11, vv[q], a[6 + q][l]);
                }
            }
        }
        for q in 0..9 {
            acc[idx[q]] = a[q];
        }
    }
    // Jᵀν (18..24) and ν² (32)
    {
        let mut a: [[f64; 4]; 7] = std::array::from_fn(|q| acc[if q < 6 { 18 + q } else { 32 }]);
        for i0 in (0..m4).step_by(4) {
            for l in 0..4 {
                let i = i0 + l;
                let v = [h[i], 1.0, f[i]];
                let (n0, n1) = (w0[i] * nu[i], w1[i] * nu[i]);
                for q in 0..3 {
                    a[q][l] = madd::<FMA>(n0, v[q], a[q][l]);
                    a[3 + q][l] = madd::<FMA>(n1, v[q], a[3 + q][l]);
                }
                a[6][l] = madd::<FMA>(nu[i], nu[i], a[6][l]);
            }
        }
        for q in 0..7 {
            acc[if q < 6 { 18 + q } else { 32 }] = a[q];
        }
    }
    // the γ border (24..30), γγ (30) and γν (31)
    {
        let mut a: [[f64; 4]; 8] = std::array::from_fn(|q| acc[24 + q]);
        for i0 in (0..m4).step_by(4) {
            for l in 0..4 {
                let i = i0 + l;
                let v = [h[i], 1.0, f[i]];
                let (g0, g1) = (w0[i] * hu[i], w1[i] * hu[i]);
                for q in 0..3 {
                    a[q][l] = madd::<FMA>(g0, v[q], a[q][l]);
                    a[3 + q][l] = madd::<FMA>(g1, v[q], a[3 + q][l]);
                }
                a[6][l] = madd::<FMA>(hu[i], hu[i], a[6][l]);
                a[7][l] = madd::<FMA>(hu[i], nu[i], a[7][l]);
            }
        }
        acc[24..32].copy_from_slice(&a);
    }
}

impl NormalEq {
    pub(super) fn new(n_knots: usize) -> Self {
        Self {
            diag: vec![[0.0; 6]; n_knots],
            off: vec![[0.0; 6]; n_knots],
            rhs: vec![Vector3::zeros(); n_knots],
            border: vec![Vector3::zeros(); n_knots],
            s_gg: 0.0,
            r_g: 0.0,
            nu2: 0.0,
            count: 0,
        }
    }

    pub(super) fn resize(&mut self, n_knots: usize) {
        self.diag.resize(n_knots, [0.0; 6]);
        self.off.resize(n_knots, [0.0; 6]);
        self.rhs.resize(n_knots, Vector3::zeros());
        self.border.resize(n_knots, Vector3::zeros());
    }

    pub(super) fn reset(&mut self) {
        self.diag.fill([0.0; 6]);
        self.off.fill([0.0; 6]);
        self.rhs.fill(Vector3::zeros());
        self.border.fill(Vector3::zeros());
        self.s_gg = 0.0;
        self.r_g = 0.0;
        self.nu2 = 0.0;
        self.count = 0;
    }
}

impl Default for NormalEq {
    fn default() -> Self {
        Self::new(0)
    }
}

/// The samples seen by [`accumulate`].
pub(super) struct Samples<'a> {
    pub(super) y: &'a [f64],
    pub(super) hint: &'a [f64],
    pub(super) c: &'a [f64],
    pub(super) seg_first: &'a [usize],
    /// Per-sample fringe model (shaped tracking), else the segments' harmonic profile.
    pub(super) shape: Option<ShapeView<'a>>,
}

/// The fringe model per sample as the kernel uses it: harmonics, the factor r that turns
/// the knots' linear interpolation of B into the model's shape (B = r·(w0·b0 + w1·b1)) and
/// the model's departure of A from linear within the segment (A = w0·a0 + w1·a1 + ca).
#[derive(Clone, Copy)]
pub(super) struct ShapeView<'a> {
    pub(super) harm: &'a [Harmonic],
    pub(super) r: &'a [f64],
    pub(super) ca: &'a [f64],
}

#[inline(always)]
pub(super) fn accumulate_kernel<const FMA: bool, const SHAPED: bool>(
    samples: &Samples,
    state: &State,
    seg_harm: &[Harmonic],
    normal: &mut NormalEq,
) {
    let (y, hint, c, seg_first) = (samples.y, samples.hint, samples.c, samples.seg_first);
    let n = y.len().min(hint.len()).min(c.len());
    let n_knots = state.delta.len();
    normal.reset();
    let mut chunk = Chunk {
        w0: [0.0; CHUNK],
        w1: [0.0; CHUNK],
        f: [0.0; CHUNK],
        h: [0.0; CHUNK],
        nu: [0.0; CHUNK],
        hu: [0.0; CHUNK],
        hc2: [0.0; CHUNK],
        hs2: [0.0; CHUNK],
        hc3: [0.0; CHUNK],
        hs3: [0.0; CHUNK],
        r: [1.0; CHUNK],
        ca: [0.0; CHUNK],
    };
    // grid coordinate, hint and intensity of a chunk at the very end of the data, padded
    // with zeros (the padding lanes of the others read the following samples in place)
    let mut tail = [[0.0; CHUNK]; 3];
    let shape = samples.shape.unwrap_or(ShapeView { harm: &[], r: &[], ca: &[] });
    for j in 0..n_knots - 1 {
        let (mut k, k1) = (seg_first[j], seg_first[j + 1]);
        if k >= k1 {
            continue;
        }
        let seg = SegConst {
            jf: j as f64,
            d0: state.delta[j],
            d1: state.delta[j + 1],
            a0: state.offset[j],
            a1: state.offset[j + 1],
            b0: state.amplitude[j],
            b1: state.amplitude[j + 1],
            intercept: state.intercept,
            rad_per_hint_nm: state.rad_per_hint_nm,
            hint_ref: state.hint_ref,
            scale: 1.0 + state.gamma,
            harm: seg_harm[j],
        };
        let mut acc = [[0.0f64; 4]; NACC];
        while k < k1 {
            let m = (k1 - k).min(CHUNK);
            let m4 = m.div_ceil(4) * 4;
            if SHAPED {
                for (i, h) in shape.harm[k..k + m].iter().enumerate() {
                    chunk.hc2[i] = h.cos_rel;
                    chunk.hs2[i] = h.sin_rel;
                    chunk.hc3[i] = h.cos3_rel;
                    chunk.hs3[i] = h.sin3_rel;
                }
                chunk.r[..m].copy_from_slice(&shape.r[k..k + m]);
                chunk.ca[..m].copy_from_slice(&shape.ca[k..k + m]);
            }
            // the samples in place (padding lanes read the next segment's, masked in the
            // kernel), except at the very end of the data: a zero-padded copy
            if k + m4 <= n {
                chunk_terms::<FMA, SHAPED>(&mut chunk, m, &seg, &c[k..], &hint[k..], &y[k..]);
            } else {
                for (v, src) in tail.iter_mut().zip([c, hint, y]) {
                    v[..m].copy_from_slice(&src[k..k + m]);
                    v[m..m4].fill(0.0);
                }
                let [tc, th, ty] = &tail;
                chunk_terms::<FMA, SHAPED>(&mut chunk, m, &seg, tc, th, ty);
            }
            chunk_sums::<FMA>(&chunk, m, &mut acc);
            normal.count += m;
            k += m;
        }
        let sum = |i: usize| acc[i].iter().sum::<f64>();
        for i in 0..6 {
            normal.diag[j][i] += sum(i);
            normal.off[j][i] += sum(6 + i);
            normal.diag[j + 1][i] += sum(12 + i);
        }
        normal.rhs[j] += Vector3::new(sum(18), sum(19), sum(20));
        normal.rhs[j + 1] += Vector3::new(sum(21), sum(22), sum(23));
        normal.border[j] += Vector3::new(sum(24), sum(25), sum(26));
        normal.border[j + 1] += Vector3::new(sum(27), sum(28), sum(29));
        normal.s_gg += sum(30);
        normal.r_g += sum(31);
        normal.nu2 += sum(32);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(super) fn accumulate_avx2(samples: &Samples, state: &State, seg_harm: &[Harmonic], normal: &mut NormalEq) {
    if samples.shape.is_some() {
        accumulate_kernel::<true, true>(samples, state, seg_harm, normal)
    } else {
        accumulate_kernel::<true, false>(samples, state, seg_harm, normal)
    }
}

/// Accumulate JᵀJ and Jᵀν of the linearised model
/// ν = I - A - B·f(ψ) ≈ h·δ + ΔA + f·ΔB + h·u·γ, h = B·f'(ψ), u = g·κ·(hint - hint_ref),
/// segment by segment (samples of segment j are `seg_first[j]..seg_first[j + 1]`), into
/// `normal`. Uses AVX2/FMA when the CPU has them.
pub(super) fn accumulate(samples: &Samples, state: &State, seg_harm: &[Harmonic], normal: &mut NormalEq) {
    #[cfg(test)]
    {
        if super::reference::USE_REFERENCE.get() {
            return super::reference::accumulate_reference(samples, state, seg_harm, normal);
        }
    }
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU features required by `accumulate_avx2` were detected above.
            return unsafe { accumulate_avx2(samples, state, seg_harm, normal) };
        }
    }
    if samples.shape.is_some() {
        accumulate_kernel::<false, true>(samples, state, seg_harm, normal)
    } else {
        accumulate_kernel::<false, false>(samples, state, seg_harm, normal)
    }
}

/// Every `d`-th sample, kept contiguous so that decimated passes stream through memory.
#[derive(Default)]
pub(super) struct Decimated {
    pub(super) y: Vec<f64>,
    pub(super) hint: Vec<f64>,
    pub(super) c: Vec<f64>,
    pub(super) seg_first: Vec<usize>,
    pub(super) shape: Vec<Harmonic>,
    pub(super) r: Vec<f64>,
    pub(super) ca: Vec<f64>,
    pub(super) shaped: bool,
}

impl Decimated {
    pub(super) fn samples(&self) -> Samples<'_> {
        Samples {
            y: &self.y,
            hint: &self.hint,
            c: &self.c,
            seg_first: &self.seg_first,
            shape: self.shaped.then_some(ShapeView { harm: &self.shape, r: &self.r, ca: &self.ca }),
        }
    }
}

impl Decimated {
    /// Empty, for a trace with (`shaped`) or without a fringe model.
    pub(super) fn reset(&mut self, shaped: bool) {
        self.y.clear();
        self.hint.clear();
        self.c.clear();
        self.seg_first.clear();
        self.shape.clear();
        self.r.clear();
        self.ca.clear();
        self.shaped = shaped;
    }
}
