//! The knot grid along the motion: its coordinate c = path/Δs + k/T (one knot per fringe of
//! travel or per [`T_KNOT`] samples of time), the start refinement, and the one full pass
//! over the hint that builds it.

use super::coordinates::{envelope_coordinate, refine_start, unrefine_start, T_KNOT};
use super::harmonic::Harmonic;
use super::inputs::TrackScale;
use super::kernel::Decimated;
use crate::measure::extrema::Extremum;
use crate::measure::signal::FringeError;

/// Knot grid along c = path/Δs + k/T: knot j sits at c = j.
#[derive(Default)]
pub(super) struct Grid {
    /// Sample position of each knot (fractional).
    pub(super) knot_k: Vec<f64>,
    /// Path at each knot, nm.
    pub(super) knot_s: Vec<f64>,
    /// First sample of each segment [j, j+1) (n for the last, virtual knot).
    pub(super) seg_first: Vec<usize>,
}

/// The hint's path travelled, read back from the grid coordinate: s = (c - k/T)·Δs.
pub(super) struct PathView<'a> {
    pub(super) c: &'a [f64],
    pub(super) ds: f64,
    /// Knot intervals over the first unit of the plain coordinate ([`refine_start`]).
    pub(super) refine: f64,
}

impl PathView<'_> {
    pub(super) fn at(&self, k: usize) -> f64 {
        (unrefine_start(self.c[k], self.refine) - k as f64 / T_KNOT) * self.ds
    }

    /// The envelope's coordinate at sample `k`: [`envelope_coordinate`] of its path.
    pub(super) fn envelope_at(&self, k: usize) -> f64 {
        envelope_coordinate(self.at(k), k as f64, self.ds)
    }

    /// First index whose path does not satisfy `pred` (true on a prefix).
    pub(super) fn partition_point(&self, pred: impl Fn(f64) -> bool) -> usize {
        let (mut lo, mut hi) = (0usize, self.c.len());
        while lo < hi {
            let mid = (lo + hi) / 2;
            if pred(self.at(mid)) {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        lo
    }
}

/// Motion windows: spans of about `width_nm` of hint travel. Returns (start window,
/// end window, reference index of the start = last sample before motion).
pub(super) fn motion_windows(path: &PathView, width_nm: f64) -> ((usize, usize), (usize, usize), usize) {
    let n = path.c.len();
    let total = path.at(n - 1);
    let i_ref = path.partition_point(|p| p <= 1e-9).saturating_sub(1);
    let start = path.at(i_ref);
    let i1 = (path.partition_point(|p| p < start + width_nm) + 1).min(n);
    let e_ref = path.partition_point(|p| p < total - 1e-9).min(n - 1);
    let e0 = path.partition_point(|p| p <= total - width_nm).saturating_sub(1);
    ((i_ref, i1.max(i_ref + 1)), (e0.min(e_ref), e_ref + 1), i_ref)
}

/// Samples per block of the grid pass.
const BLOCK: usize = 512;

/// The running state of the grid pass, carried from one block of samples to the next.
struct GridScan {
    /// Path travelled by the hint so far, nm.
    path_nm: f64,
    /// The hint at the last sample seen.
    prev_hint: f64,
    /// Whether some hint sample is not finite.
    non_finite: bool,
    /// Grid coordinate of the next knot.
    next_knot: f64,
    /// Grid coordinate at the last sample of the previous block.
    c_last: f64,
    /// Path at the last sample of the previous block, nm.
    s_last: f64,
    /// Largest hint change over one sample, nm.
    max_step: f64,
    /// Next extremum whose hint and path are to be recorded.
    next_extremum: usize,
    /// Largest hint so far, nm.
    hint_max: f64,
    /// Smallest hint so far, nm.
    hint_min: f64,
}

impl GridScan {
    /// Steps from the previous sample into `path` (the first sample's step is 0), and the
    /// block's finite check, hint extremes and largest step: branch-free in four fixed lanes
    /// (compare-and-select, it vectorises). A non-finite hint is caught by `non_finite` and
    /// rejected after the pass, so NaN handling does not matter here.
    #[inline(always)]
    fn block_steps(&mut self, hint_block: &[f64], path: &mut [f64]) {
        let mb = hint_block.len();
        path[0] = (hint_block[0] - self.prev_hint).abs();
        for (p, w) in path[1..mb].iter_mut().zip(hint_block.windows(2)) {
            *p = (w[1] - w[0]).abs();
        }
        self.prev_hint = hint_block[mb - 1];
        let (mut lmax, mut lmin, mut lstep, mut lbad) =
            ([self.hint_max; 4], [self.hint_min; 4], [self.max_step; 4], [0.0f64; 4]);
        let mut lane = |l: usize, h: f64, step: f64| {
            lbad[l] += h * 0.0;
            lmax[l] = if h > lmax[l] { h } else { lmax[l] };
            lmin[l] = if h < lmin[l] { h } else { lmin[l] };
            lstep[l] = if step > lstep[l] { step } else { lstep[l] };
        };
        let (hq, pq) = (hint_block.chunks_exact(4), path[..mb].chunks_exact(4));
        for (l, (&h, &step)) in hq.remainder().iter().zip(pq.remainder()).enumerate() {
            lane(l, h, step);
        }
        for (h4, p4) in hq.zip(pq) {
            for l in 0..4 {
                lane(l, h4[l], p4[l]);
            }
        }
        self.non_finite |= lbad.iter().any(|b| b.is_nan());
        self.hint_max = lmax.iter().fold(self.hint_max, |m, &v| m.max(v));
        self.hint_min = lmin.iter().fold(self.hint_min, |m, &v| m.min(v));
        self.max_step = lstep.iter().fold(self.max_step, |m, &v| m.max(v));
    }

    /// The running path (the one serial chain) into `path` and the grid coordinate onto
    /// `cgrid`; k/T is exact, and the start refinement is the identity unless set.
    #[inline(always)]
    fn block_path(&mut self, path: &mut [f64], k0: usize, inv_ds: f64, refine: f64, cgrid: &mut Vec<f64>) {
        let mut acc = self.path_nm;
        let mut kf = k0 as f64;
        if refine == 1.0 {
            cgrid.extend(path.iter_mut().map(|p| {
                acc += *p;
                *p = acc;
                let c = acc * inv_ds + kf * (1.0 / T_KNOT);
                kf += 1.0;
                c
            }));
        } else {
            cgrid.extend(path.iter_mut().map(|p| {
                acc += *p;
                *p = acc;
                let c = refine_start(acc * inv_ds + kf * (1.0 / T_KNOT), refine);
                kf += 1.0;
                c
            }));
        }
        self.path_nm = acc;
    }

    /// Knots exactly at c = j within the block: (s, k) interpolated between the two samples
    /// around each (c increases strictly, so the first sample at or beyond a knot is a binary
    /// search).
    #[inline(always)]
    fn block_knots(&mut self, grid: &mut Grid, cb: &[f64], path: &[f64], k0: usize) {
        let mb = cb.len();
        let mut from = 0usize;
        while cb[mb - 1] >= self.next_knot {
            let i = from + cb[from..].partition_point(|&ck| ck < self.next_knot);
            let ck = cb[i];
            let k = k0 + i;
            let (c_prev, s_prev) = if i > 0 { (cb[i - 1], path[i - 1]) } else { (self.c_last, self.s_last) };
            while ck >= self.next_knot {
                let lam = (self.next_knot - c_prev) / (ck - c_prev);
                grid.knot_s.push(s_prev + lam * (path[i] - s_prev));
                grid.knot_k.push(k as f64 - 1.0 + lam);
                grid.seg_first.push(k);
                self.next_knot += 1.0;
            }
            from = i + 1;
        }
    }
}

/// Where the tracker records things during the grid pass.
pub(super) struct GridRecord<'a> {
    /// The knots.
    pub(super) grid: &'a mut Grid,
    /// The extrema found in the intensity, in sample order.
    pub(super) extrema: &'a [Extremum],
    /// The hint at each extremum.
    pub(super) ext_hint: &'a mut Vec<f64>,
    /// The path at each extremum.
    pub(super) ext_path: &'a mut Vec<f64>,
    /// Every `decimation`-th sample's hint, grid coordinate and fringe shape.
    pub(super) decimated: &'a mut Decimated,
    /// The grid coordinate of every sample.
    pub(super) cgrid: &'a mut Vec<f64>,
}

/// The one full pass over the hint, block by block: a branch-free pass over the steps
/// (finite check, extremes, largest step), the running path and grid coordinate, then the
/// rare events of the block (knots, extrema, decimated samples) from the block's path
/// buffer; the same operations in the same order as one sample loop. The extrema are found
/// beforehand: this pass records the hint and the path at each of them, so nothing later reads
/// the big arrays at random. Returns the hint's largest excursion from its first sample.
#[inline(always)]
pub(super) fn grid_pass(
    rec: GridRecord,
    hint_dl_nm: &[f64],
    shape: Option<&[Harmonic]>,
    scale: &TrackScale,
) -> Result<f64, FringeError> {
    let GridRecord { grid, extrema, ext_hint, ext_path, decimated, cgrid } = rec;
    let (n, refine, knot_ds, dec) = (scale.n, scale.refine, scale.fringe_nm, scale.decimation);
    grid.knot_k.clear();
    grid.knot_s.clear();
    grid.seg_first.clear();
    grid.knot_k.push(0.0);
    grid.knot_s.push(0.0);
    grid.seg_first.push(0);
    let h0 = hint_dl_nm[0];
    let mut scan = GridScan {
        path_nm: 0.0,
        prev_hint: h0,
        non_finite: false,
        next_knot: 1.0,
        c_last: 0.0,
        s_last: 0.0,
        max_step: 0f64,
        next_extremum: 0,
        hint_max: h0,
        hint_min: h0,
    };
    let inv_ds = 1.0 / knot_ds;
    let mut path_blk = [0.0f64; BLOCK];
    cgrid.reserve(n);
    for k0 in (0..n).step_by(BLOCK) {
        let k1 = (k0 + BLOCK).min(n);
        let path = &mut path_blk[..k1 - k0];
        scan.block_steps(&hint_dl_nm[k0..k1], path);
        scan.block_path(path, k0, inv_ds, refine, cgrid);
        let cb = &cgrid[k0..k1];
        scan.block_knots(grid, cb, path, k0);
        while let Some(e) = extrema.get(scan.next_extremum).filter(|e| e.index < k1) {
            ext_hint.push(hint_dl_nm[e.index]);
            ext_path.push(path[e.index - k0]);
            scan.next_extremum += 1;
        }
        if dec > 1 {
            for k in (k0.next_multiple_of(dec)..k1).step_by(dec) {
                decimated.hint.push(hint_dl_nm[k]);
                decimated.c.push(cgrid[k]);
                if let Some(sh) = shape {
                    decimated.shape.push(sh[k]);
                }
            }
        }
        scan.c_last = cb[k1 - k0 - 1];
        scan.s_last = scan.path_nm;
    }
    let excursion = (scan.hint_max - h0).abs().max((scan.hint_min - h0).abs());
    check_motion(&scan, hint_dl_nm, scale.fringe_nm)?;
    // virtual last knot beyond the data, continued along the path
    grid.knot_s
        .push(scan.path_nm + (unrefine_start(scan.next_knot, refine) - unrefine_start(scan.c_last, refine)) * knot_ds);
    grid.knot_k.push((n - 1) as f64);
    grid.seg_first.push(n);
    Ok(excursion)
}

/// The hint after the grid pass: finite, moving, and by less than a quarter fringe per sample.
#[inline(always)]
fn check_motion(scan: &GridScan, hint_dl_nm: &[f64], fringe_nm: f64) -> Result<(), FringeError> {
    if scan.non_finite {
        let index = hint_dl_nm.iter().position(|v| !v.is_finite()).unwrap_or(0);
        return Err(FringeError::NonFinite { what: "motion hint", index, value: hint_dl_nm[index] });
    }
    if scan.path_nm <= 0.0 {
        return Err(FringeError::NoMotion);
    }
    if scan.max_step > 0.25 * fringe_nm {
        let index = hint_dl_nm.windows(2).position(|w| (w[1] - w[0]).abs() > 0.25 * fringe_nm).map_or(0, |i| i + 1);
        return Err(FringeError::Undersampled {
            index,
            step_nm: (hint_dl_nm[index] - hint_dl_nm[index.saturating_sub(1)]).abs(),
            max_nm: 0.25 * fringe_nm,
        });
    }
    Ok(())
}
