//! Identifiability and uncertainty of a weighted least-squares problem, rank-deficient or not: which parameters
//! the data determine, their standard uncertainties and correlations, and the combinations they cannot see, in words.
//!
//! Generic over the parameters: the input is a weighted Jacobian `J` (row `r` already divided by the standard
//! uncertainty σ_r of observation `r`, columns in the estimator's internal units, e.g. mrad and µm), the weighted
//! residual vector, and [`ParamInfo`] metadata (name, display unit, scale internal → display, free or masked,
//! a "useful" uncertainty bound). [`analyse`] returns an [`IdentifiabilityReport`] (docs/identification.md, "The verdict").
//!
//! # Method
//!
//! * **SVD.** `J_F = U·S·Vᵀ` over the free columns `F`, in internal units (the units are chosen so the columns are
//!   comparable: mrad and µm). When `J_F` has fewer
//!   rows than columns it is padded with zero rows, so `V` is always complete and the missing directions appear
//!   as zero singular values.
//! * **Numerical rank.** A direction `v_k` is *null* when `s_k ≤ relative_tolerance · s_max · max(m, n)`.
//! * **Covariance.** `C = f · Σ_{k not null} v_k v_kᵀ / s_k²`, the SVD pseudo-inverse of `JᵀJ` (defined for a
//!   rank-deficient `J`). `f = 1` gives the σ of the noise model alone ([`ParameterUncertainty::sigma_noise_model`]);
//!   the reported [`ParameterUncertainty::sigma`] uses `f = max(χ²_red, chi2_floor)` with
//!   `χ²_red = rss / (m − rank)`. The floor (default 1) is a deliberate choice: a fit that happens to leave residuals
//!   smaller than the noise model must not shrink σ below what the noise model promises; residuals larger than
//!   the noise model (model error, underestimated noise) do scale σ up. `chi2_floor = 0` gives the plain
//!   "scaled by the residual variance" convention. With no redundancy (`m ≤ rank`) `f = 1`.
//! * **Determined or not.** A direction `v_k` with singular value `s_k` contributes `f·(v_{k,i}/s_k)²` to
//!   `var(p_i)`. A free parameter is *not determined* when
//!   1. it has a component larger than `null_component_tolerance` in the null space: moving along a null
//!      combination changes it while leaving every prediction unchanged, so its variance is unbounded (the
//!      pseudo-inverse's finite number is then the minimum-norm convention, not information); or
//!   2. its σ (display units) exceeds its user-supplied useful bound ([`ParamInfo::useful_sigma`], e.g. 10 µm, 1°):
//!      its variance is dominated by directions the data see too weakly to be of use. The reason names the
//!      direction carrying the largest share of the variance.
//!
//!   A direction that is not null but alone gives some parameter a σ above its useful bound is *weak*; the
//!   number of directions neither null nor weak is the effective rank. A parameter that is not determined gets
//!   `sigma: None` and a reason: its value must never be shown as a bare number ([`ParameterUncertainty::format_value`]).
//! * **Correlations** `ρ_ij = C_ij / √(C_ii C_jj)` for parameters with a finite, non-zero variance; `None` (undefined)
//!   for masked parameters, parameters with a null-space component (infinite variance) or zero variance. A weakly
//!   determined parameter has a finite variance, so its correlations are given. `|ρ| > correlation_flag` is listed.
//! * **Base set.** Businger–Golub column-pivoted QR (pivot = largest remaining column norm) of `J_F` with each
//!   column scaled to "one useful bound" (internal bound = `useful_sigma / |scale|`, or one internal unit without a
//!   bound), so a column's norm is the data change, in σ, of a move of one useful bound. The first `effective_rank`
//!   pivots are the base set: the parameters to estimate if the others are held at nominal values. (nalgebra's
//!   `ColPivQR` pivots on the largest single *entry* of the remaining block, not the largest column norm, so its
//!   order is not the rank-revealing one; the few lines of pivoted Gram-Schmidt below are.)
//! * **Condition numbers** of `J_F` with every column scaled to unit norm (van der Sluis: close to the best
//!   diagonal scaling, and independent of units), for all free parameters and for the determined ones; a value
//!   above `condition_warning` (default 100) adds a warning sentence.
//! * **Unobservable combinations.** The null directions (an orthonormal basis of the null space, made sparse by
//!   Gauss-Jordan elimination with largest-entry pivoting) and the weak directions, each written as a sparse
//!   combination (largest |coefficient| normalised to +1, |coefficients| below `coefficient_cutoff` dropped) and
//!   described with their physical interpretations where the parameter names match (fiber
//!   direction β_wf/θ_wf, gap split y_wf/Z_et, beam origin x_wf/z_wf against beam angles), or a generic sentence.

mod analysis;
mod input;
mod numerics;
mod report;
mod words;

pub use analysis::analyse;
pub use input::{AnalysisError, Options, ParamInfo, DEFAULT_USEFUL_ANGLE_DEG, DEFAULT_USEFUL_LENGTH_UM};
pub use numerics::{pseudo_inverse_covariance, PseudoInverse};
pub use report::{Combination, CombinationKind, IdentifiabilityReport, ParameterUncertainty};

#[cfg(test)]
mod tests;
