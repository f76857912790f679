//! The block-tridiagonal solver of the Gauss-Newton steps: one 3×3 block per knot, written
//! out (symmetric blocks as [`Sym3`]).

use nalgebra::{Matrix3, Vector3};

/// Symmetric 3×3 stored as (00, 01, 02, 11, 12, 22).
pub(super) type Sym3 = [f64; 6];

pub(super) fn sym_to_mat(s: &Sym3) -> Matrix3<f64> {
    Matrix3::new(s[0], s[1], s[2], s[1], s[3], s[4], s[2], s[4], s[5])
}

/// General 3×3 matrix, row-major.
pub(super) type Mat3 = [[f64; 3]; 3];

/// Symmetric part of the inverse of a 3×3 (nearly symmetric: a Schur complement), by its
/// cofactors; None if singular (zero determinant). The operations of nalgebra's 3×3 inverse
/// and `0.5·(S⁻¹ + S⁻ᵀ)`, in the same order: the same numbers.
#[inline(always)]
pub(super) fn sym_inverse(m: &Mat3) -> Option<Sym3> {
    let [[m11, m12, m13], [m21, m22, m23], [m31, m32, m33]] = *m;
    let minor_11 = m22 * m33 - m32 * m23;
    let minor_12 = m21 * m33 - m31 * m23;
    let minor_13 = m21 * m32 - m31 * m22;
    let det = m11 * minor_11 - m12 * minor_12 + m13 * minor_13;
    if det == 0.0 {
        return None;
    }
    let sym = |a: f64, b: f64| 0.5 * (a / det + b / det);
    Some([
        minor_11 / det,
        sym(m13 * m32 - m33 * m12, -minor_12),
        sym(m12 * m23 - m22 * m13, minor_13),
        (m11 * m33 - m31 * m13) / det,
        sym(m13 * m21 - m23 * m11, m12 * m31 - m32 * m11),
        (m11 * m22 - m21 * m12) / det,
    ])
}

/// Row `i` of a symmetric 3×3.
#[inline(always)]
pub(super) fn sym_row(s: &Sym3, i: usize) -> [f64; 3] {
    match i {
        0 => [s[0], s[1], s[2]],
        1 => [s[1], s[3], s[4]],
        _ => [s[2], s[4], s[5]],
    }
}

/// a·b for symmetric a and b (the product is general).
#[inline(always)]
pub(super) fn sym_mul(a: &Sym3, b: &Sym3) -> Mat3 {
    let bc = [sym_row(b, 0), sym_row(b, 1), sym_row(b, 2)];
    std::array::from_fn(|r| {
        let ar = sym_row(a, r);
        std::array::from_fn(|c| ar[0] * bc[0][c] + ar[1] * bc[1][c] + ar[2] * bc[2][c])
    })
}

/// d - c·g for symmetric d and c (c·g = c·S⁻¹·c is symmetric up to rounding).
#[inline(always)]
pub(super) fn sym_sub_mul(d: &Sym3, c: &Sym3, g: &Mat3) -> Mat3 {
    std::array::from_fn(|r| {
        let (dr, cr) = (sym_row(d, r), sym_row(c, r));
        std::array::from_fn(|col| dr[col] - (cr[0] * g[0][col] + cr[1] * g[1][col] + cr[2] * g[2][col]))
    })
}

/// s·v for symmetric s.
#[inline(always)]
pub(super) fn sym_mul_vec(s: &Sym3, v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(
        s[0] * v[0] + s[1] * v[1] + s[2] * v[2],
        s[1] * v[0] + s[3] * v[1] + s[4] * v[2],
        s[2] * v[0] + s[4] * v[1] + s[5] * v[2],
    )
}

/// g·v.
#[inline(always)]
pub(super) fn mat_mul_vec(g: &Mat3, v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::from_fn(|r, _| g[r][0] * v[0] + g[r][1] * v[1] + g[r][2] * v[2])
}

/// gᵀ·v.
#[inline(always)]
pub(super) fn mat_tr_mul_vec(g: &Mat3, v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::from_fn(|c, _| g[0][c] * v[0] + g[1][c] * v[1] + g[2][c] * v[2])
}

/// Block LDLᵀ factor of a block-tridiagonal matrix: S_j⁻¹ and G_j = S_j⁻¹·C_j, with
/// scratch space for the forward sweeps. Buffers are reused between factorisations. The
/// 3×3 blocks are written out (symmetric ones as [`Sym3`]): generic small-matrix code
/// cost more than the arithmetic on long traces (one block per fringe).
pub(super) struct Factor {
    pub(super) s_inv: Vec<Sym3>,
    pub(super) multiplier: Vec<Mat3>,
    pub(super) forward: Vec<Vector3<f64>>,
    pub(super) forward2: Vec<Vector3<f64>>,
}

// Recursions over neighbouring blocks read clearest with explicit indices.
#[allow(clippy::needless_range_loop)]
impl Factor {
    pub(super) fn new(n_knots: usize) -> Self {
        Self {
            s_inv: vec![[0.0; 6]; n_knots],
            multiplier: vec![[[0.0; 3]; 3]; n_knots],
            forward: vec![Vector3::zeros(); n_knots],
            forward2: vec![Vector3::zeros(); n_knots],
        }
    }

    pub(super) fn resize(&mut self, n_knots: usize) {
        self.s_inv.resize(n_knots, [0.0; 6]);
        self.multiplier.resize(n_knots, [[0.0; 3]; 3]);
        self.forward.resize(n_knots, Vector3::zeros());
        self.forward2.resize(n_knots, Vector3::zeros());
    }

    /// Factorise; false if a pivot block is singular.
    pub(super) fn factor(&mut self, diag: &[Sym3], off: &[Sym3]) -> bool {
        let n_knots = diag.len();
        let mut s = std::array::from_fn(|r| sym_row(&diag[0], r));
        for j in 0..n_knots {
            let Some(si) = sym_inverse(&s) else {
                return false;
            };
            self.s_inv[j] = si;
            if j + 1 < n_knots {
                let gj = sym_mul(&si, &off[j]);
                s = sym_sub_mul(&diag[j + 1], &off[j], &gj);
                self.multiplier[j] = gj;
            } else {
                self.multiplier[j] = [[0.0; 3]; 3];
            }
        }
        true
    }

    pub(super) fn solve_into(&mut self, r: &[Vector3<f64>], x: &mut [Vector3<f64>]) {
        let n_knots = r.len();
        self.forward[0] = r[0];
        for j in 1..n_knots {
            self.forward[j] = r[j] - mat_tr_mul_vec(&self.multiplier[j - 1], &self.forward[j - 1]);
        }
        x[n_knots - 1] = sym_mul_vec(&self.s_inv[n_knots - 1], &self.forward[n_knots - 1]);
        for j in (0..n_knots - 1).rev() {
            x[j] = sym_mul_vec(&self.s_inv[j], &self.forward[j]) - mat_mul_vec(&self.multiplier[j], &x[j + 1]);
        }
    }

    /// Solve for two right-hand sides in one sweep.
    pub(super) fn solve2_into(
        &mut self,
        r: &[Vector3<f64>],
        q: &[Vector3<f64>],
        x: &mut [Vector3<f64>],
        z: &mut [Vector3<f64>],
    ) {
        let n_knots = r.len();
        self.forward[0] = r[0];
        self.forward2[0] = q[0];
        for j in 1..n_knots {
            let g = &self.multiplier[j - 1];
            self.forward[j] = r[j] - mat_tr_mul_vec(g, &self.forward[j - 1]);
            self.forward2[j] = q[j] - mat_tr_mul_vec(g, &self.forward2[j - 1]);
        }
        x[n_knots - 1] = sym_mul_vec(&self.s_inv[n_knots - 1], &self.forward[n_knots - 1]);
        z[n_knots - 1] = sym_mul_vec(&self.s_inv[n_knots - 1], &self.forward2[n_knots - 1]);
        for j in (0..n_knots - 1).rev() {
            let (si, g) = (&self.s_inv[j], &self.multiplier[j]);
            x[j] = sym_mul_vec(si, &self.forward[j]) - mat_mul_vec(g, &x[j + 1]);
            z[j] = sym_mul_vec(si, &self.forward2[j]) - mat_mul_vec(g, &z[j + 1]);
        }
    }

    /// Solve the bordered system [[T, B],[Bᵀ, s]]·[x; γ] = [r; r_γ] by the Schur
    /// complement: x and z = T⁻¹B are written out; returns (γ, schur = s - Bᵀz).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn solve_bordered(
        &mut self,
        r: &[Vector3<f64>],
        border: &[Vector3<f64>],
        s_gg: f64,
        r_g: f64,
        min_schur: f64,
        x: &mut [Vector3<f64>],
        z: &mut [Vector3<f64>],
    ) -> (f64, f64) {
        self.solve2_into(r, border, x, z);
        let bz: f64 = border.iter().zip(z.iter()).map(|(a, b)| a.dot(b)).sum();
        let by: f64 = border.iter().zip(x.iter()).map(|(a, b)| a.dot(b)).sum();
        // Exact arithmetic keeps the Schur complement above the prior precision of γ; on
        // noise-free data with dense knots, cancellation between huge sums can lose that.
        let schur = (s_gg - bz).max(min_schur);
        let gamma = (r_g - by) / schur;
        for (xi, zi) in x.iter_mut().zip(z.iter()) {
            *xi -= zi * gamma;
        }
        (gamma, schur)
    }

    /// δδ element of the diagonal blocks of the inverse, into `out`.
    pub(super) fn delta_variances_into(&self, out: &mut Vec<f64>) {
        let n_knots = self.s_inv.len();
        out.clear();
        out.resize(n_knots, 0.0);
        let mut sig = sym_to_mat(&self.s_inv[n_knots - 1]);
        out[n_knots - 1] = sig[(0, 0)];
        for j in (0..n_knots - 1).rev() {
            let g = Matrix3::from_fn(|r, c| self.multiplier[j][r][c]);
            sig = sym_to_mat(&self.s_inv[j]) + g * sig * g.transpose();
            out[j] = sig[(0, 0)];
        }
    }
}

impl Default for Factor {
    fn default() -> Self {
        Self::new(0)
    }
}

/// Add `sign`·p to the diagonal of a symmetric 3×3.
pub(super) fn add_diag(m: &mut Sym3, p: &Vector3<f64>, sign: f64) {
    m[0] += sign * p[0];
    m[3] += sign * p[1];
    m[5] += sign * p[2];
}
