//! [`analyse`] in stages: the SVD of the free columns, the null and weak directions, the verdict on
//! each parameter, correlations, the base set, condition numbers and the warning sentences.
//! The method is in the documentation of [`super`].

use super::input::{AnalysisError, Options, ParamInfo};
use super::numerics::{pivot_order, pseudo_inverse_covariance, scaled_condition_number, sparsify, PseudoInverse};
use super::report::{Combination, CombinationKind, IdentifiabilityReport, ParameterUncertainty};
use super::words::{coefficient_text, describe, pretty, sparse_coefficients, three_significant};
use nalgebra::{DMatrix, DVector};

/// Analyse the identifiability of a weighted least-squares problem.
///
/// * `j`: m × n Jacobian of the predictions with respect to the parameters, row `r` divided by the standard
///   uncertainty of observation `r`, column `i` in the internal unit of parameter `i`.
/// * `weighted_residuals`: the m residuals (measured − predicted) divided by their σ; pass zeros for a design
///   study (the σ are then those of the noise model).
/// * `params`: one description per column; masked (`free: false`) columns are ignored.
/// * `options`: thresholds ([`Options::default`] for the documented defaults).
///
/// See the module documentation for the method. Errors only on inconsistent or non-finite input.
pub fn analyse(
    j: &DMatrix<f64>,
    weighted_residuals: &DVector<f64>,
    params: &[ParamInfo],
    options: &Options,
) -> Result<IdentifiabilityReport, AnalysisError> {
    check_input(j, weighted_residuals, params, options)?;
    let problem = free_problem(j, weighted_residuals, params, options);
    let (s, tol) = (&problem.pinv.singular_values, problem.pinv.tolerance);
    let nf = problem.free.len();
    let m = problem.m;
    let rank = problem.pinv.rank;
    let residual_rms = (m > 0).then(|| (problem.rss / m as f64).sqrt());

    let null: Vec<usize> = (0..nf).filter(|&k| s[k] <= tol).collect();
    let weak = weak_directions(&problem);
    let effective_rank = rank - weak.len();
    let combinations = combinations(&problem, &null, &weak);
    let verdicts = parameter_verdicts(&problem, &null, &combinations);
    let (correlation, strong_correlations) = correlations(&problem, &verdicts);
    let base_set = base_set(&problem, effective_rank);

    let jf = &problem.jf;
    let condition_number = scaled_condition_number(jf);
    let det_cols: Vec<usize> = (0..nf).filter(|&a| verdicts.determined_f[a]).collect();
    let condition_number_determined = scaled_condition_number(&jf.select_columns(det_cols.iter()));
    let warnings =
        warnings(&problem, &verdicts.parameters, condition_number, condition_number_determined, &strong_correlations);

    Ok(IdentifiabilityReport {
        n_observations: m,
        singular_values: s.clone(),
        rank,
        effective_rank,
        condition_number,
        condition_number_determined,
        base_set,
        parameters: verdicts.parameters,
        correlation,
        strong_correlations,
        unobservable: combinations.unobservable,
        reduced_chi2: problem.reduced_chi2,
        covariance_scale: problem.covariance_scale,
        residual_rms,
        warnings,
    })
}

/// Sizes that agree, finite entries, usable parameter descriptions and thresholds.
fn check_input(
    j: &DMatrix<f64>,
    r: &DVector<f64>,
    params: &[ParamInfo],
    options: &Options,
) -> Result<(), AnalysisError> {
    if r.len() != j.nrows() || params.len() != j.ncols() {
        return Err(AnalysisError::Shape {
            rows: j.nrows(),
            cols: j.ncols(),
            residuals: r.len(),
            params: params.len(),
        });
    }
    if let Some(index) = j.iter().position(|x| !x.is_finite()) {
        return Err(AnalysisError::NonFinite { what: "Jacobian", index });
    }
    if let Some(index) = r.iter().position(|x| !x.is_finite()) {
        return Err(AnalysisError::NonFinite { what: "residuals", index });
    }
    for p in params {
        let bad = |problem: String| Err(AnalysisError::BadParameter { name: p.name.clone(), problem });
        if !(p.scale.is_finite() && p.scale != 0.0) {
            return bad(format!("scale must be finite and non-zero, found {}", p.scale));
        }
        if let Some(b) = p.useful_sigma {
            if !(b.is_finite() && b > 0.0) {
                return bad(format!("useful_sigma must be finite and positive, found {b}"));
            }
        }
    }
    let o = options;
    let ok = o.relative_tolerance >= 0.0
        && o.null_component_tolerance >= 0.0
        && o.chi2_floor >= 0.0
        && o.correlation_flag >= 0.0
        && o.condition_warning >= 0.0
        && o.coefficient_cutoff >= 0.0;
    if !ok {
        return Err(AnalysisError::BadParameter { name: "options".into(), problem: "thresholds must be ≥ 0".into() });
    }
    Ok(())
}

/// The free columns of the problem, their SVD and the covariance scale: what every stage reads.
struct FreeProblem<'a> {
    params: &'a [ParamInfo],
    options: &'a Options,
    /// Number of observations (rows).
    m: usize,
    /// Index in `params` of each free column.
    free: Vec<usize>,
    /// Name of each free parameter.
    names: Vec<&'a str>,
    /// The free columns of the Jacobian.
    jf: DMatrix<f64>,
    /// SVD, rank and noise-model covariance of `jf`.
    pinv: PseudoInverse,
    /// Weighted residual sum of squares.
    rss: f64,
    /// `rss / (m − rank)`; `None` without redundancy.
    reduced_chi2: Option<f64>,
    /// `f` of the module documentation: the factor on the noise-model covariance.
    covariance_scale: f64,
    /// |scale| of each free parameter (display per internal unit).
    scale_f: Vec<f64>,
    /// Useful bound of each free parameter (display units).
    bound_f: Vec<Option<f64>>,
}

/// SVD, rank and covariance of the free columns.
fn free_problem<'a>(
    j: &DMatrix<f64>,
    weighted_residuals: &DVector<f64>,
    params: &'a [ParamInfo],
    options: &'a Options,
) -> FreeProblem<'a> {
    let m = j.nrows();
    let free: Vec<usize> = (0..params.len()).filter(|&i| params[i].free).collect();
    let names: Vec<&str> = free.iter().map(|&i| params[i].name.as_str()).collect();
    let jf = j.select_columns(free.iter());
    let pinv = pseudo_inverse_covariance(&jf, options.relative_tolerance);
    let rank = pinv.rank;
    let rss = weighted_residuals.norm_squared();
    let reduced_chi2 = (m > rank).then(|| rss / (m - rank) as f64);
    let covariance_scale = reduced_chi2.map_or(1.0, |c| c.max(options.chi2_floor));
    let scale_f: Vec<f64> = free.iter().map(|&i| params[i].scale.abs()).collect();
    let bound_f: Vec<Option<f64>> = free.iter().map(|&i| params[i].useful_sigma).collect();
    FreeProblem { params, options, m, free, names, jf, pinv, rss, reduced_chi2, covariance_scale, scale_f, bound_f }
}

/// A direction the data see, but so weakly that alone it gives a parameter a σ above its useful bound.
struct WeakDirection {
    /// Index of the direction (column of `V`).
    direction: usize,
    /// The free parameter it hurts most relative to its bound (index among the free ones).
    parameter: usize,
    /// That parameter's σ (display units) from this direction alone.
    sigma: f64,
}

/// The weak directions, in the order of the singular values.
fn weak_directions(problem: &FreeProblem) -> Vec<WeakDirection> {
    let (s, v, tol) = (&problem.pinv.singular_values, &problem.pinv.v, problem.pinv.tolerance);
    let f = problem.covariance_scale;
    let nf = problem.free.len();
    let mut weak = Vec::new();
    for k in (0..nf).filter(|&k| s[k] > tol) {
        let along = f.sqrt() / s[k];
        let mut worst: Option<(usize, f64, f64)> = None; // (i, ratio, σ_i)
        for i in 0..nf {
            if let Some(b) = problem.bound_f[i] {
                let sigma_i = v[(i, k)].abs() * along * problem.scale_f[i];
                let ratio = sigma_i / b;
                if ratio > 1.0 && worst.is_none_or(|w| ratio > w.1) {
                    worst = Some((i, ratio, sigma_i));
                }
            }
        }
        if let Some((i, _, sigma_i)) = worst {
            weak.push(WeakDirection { direction: k, parameter: i, sigma: sigma_i });
        }
    }
    weak
}

/// The combinations the data do not see or see only weakly, and where to find each.
struct Combinations {
    /// Not seen, then weak ([`IdentifiabilityReport::unobservable`]).
    unobservable: Vec<Combination>,
    /// Each sparse null combination scaled to largest entry 1, in the order of the `NotSeen` entries
    /// that open `unobservable`.
    null_rows: Vec<DVector<f64>>,
    /// For each direction: its index in `unobservable` when it is weak.
    weak_combination: Vec<Option<usize>>,
}

/// A sparse basis of the null space, then the weak directions, as combinations with their sentences.
fn combinations(problem: &FreeProblem, null: &[usize], weak: &[WeakDirection]) -> Combinations {
    let (s, v) = (&problem.pinv.singular_values, &problem.pinv.v);
    let f = problem.covariance_scale;
    let nf = problem.free.len();
    let cutoff = problem.options.coefficient_cutoff;
    let mut unobservable = Vec::new();
    let mut null_rows: Vec<DVector<f64>> = Vec::new();
    if !null.is_empty() {
        let basis = DMatrix::from_fn(null.len(), nf, |r, i| v[(i, null[r])]);
        for row in sparsify(basis).row_iter() {
            let c: DVector<f64> = row.transpose();
            let coefficients = sparse_coefficients(&c, &problem.names, cutoff);
            if coefficients.is_empty() {
                continue;
            }
            let singular_value = (&problem.jf * &c).norm() / c.norm();
            let description = describe(&coefficients, CombinationKind::NotSeen);
            unobservable.push(Combination {
                coefficients,
                singular_value,
                kind: CombinationKind::NotSeen,
                sigma_along: None,
                description,
            });
            null_rows.push(&c / c[c.iamax()]);
        }
    }
    let mut weak_combination: Vec<Option<usize>> = vec![None; nf];
    for w in weak {
        let k = w.direction;
        let c: DVector<f64> = v.column(k).into_owned();
        let coefficients = sparse_coefficients(&c, &problem.names, cutoff);
        let p = &problem.params[problem.free[w.parameter]];
        let description = format!(
            "{} (standard uncertainty along it {} in internal units, which alone gives {} {} {}, above the useful {} {})",
            describe(&coefficients, CombinationKind::Weak),
            three_significant(f.sqrt() / s[k]),
            pretty(&p.name),
            three_significant(w.sigma),
            p.unit,
            three_significant(p.useful_sigma.unwrap_or(f64::NAN)),
            p.unit
        );
        weak_combination[k] = Some(unobservable.len());
        unobservable.push(Combination {
            coefficients,
            singular_value: s[k],
            kind: CombinationKind::Weak,
            sigma_along: Some(f.sqrt() / s[k]),
            description,
        });
    }
    Combinations { unobservable, null_rows, weak_combination }
}

/// What the data say about each parameter, with the bookkeeping the later stages need.
struct ParameterVerdicts {
    /// One per parameter, in input order.
    parameters: Vec<ParameterUncertainty>,
    /// Per parameter: a finite, non-zero variance, so its correlations are defined.
    correlatable: Vec<bool>,
    /// Per free parameter: determined.
    determined_f: Vec<bool>,
    /// Per parameter: its index among the free ones, `None` when masked.
    pos_in_f: Vec<Option<usize>>,
}

/// Each parameter determined or not, with its σ or the reason.
fn parameter_verdicts(problem: &FreeProblem, null: &[usize], combinations: &Combinations) -> ParameterVerdicts {
    let v = &problem.pinv.v;
    let nf = problem.free.len();
    let c_noise = &problem.pinv.covariance;
    let f = problem.covariance_scale;
    let null_share: Vec<f64> = (0..nf).map(|i| null.iter().map(|&k| v[(i, k)].powi(2)).sum()).collect();
    let n_all = problem.params.len();
    let mut parameters = Vec::with_capacity(n_all);
    let mut correlatable = vec![false; n_all];
    let mut determined_f = vec![false; nf];
    let mut pos_in_f = vec![None; n_all];
    for (a, &i) in problem.free.iter().enumerate() {
        pos_in_f[i] = Some(a);
    }
    for (i, p) in problem.params.iter().enumerate() {
        let mut out = ParameterUncertainty {
            name: p.name.clone(),
            unit: p.unit.clone(),
            sigma: None,
            sigma_noise_model: None,
            determined: false,
            reason: None,
        };
        let Some(a) = pos_in_f[i] else {
            out.reason = Some("held fixed (masked): not estimated, so its value is an assumption, not a result".into());
            parameters.push(out);
            continue;
        };
        let column_zero = problem.jf.column(a).iter().all(|&x| x == 0.0);
        let noise_sigma = c_noise[(a, a)].max(0.0).sqrt() * problem.scale_f[a];
        let sigma = f.sqrt() * noise_sigma;
        if column_zero {
            out.reason = Some(format!(
                "the data do not depend on {} at all (its Jacobian column is zero): whatever a solver returns for \
                 it is its starting point, not data",
                pretty(&p.name)
            ));
        } else if null_share[a].sqrt() > problem.options.null_component_tolerance {
            out.reason = Some(not_seen_reason(p, a, combinations));
        } else if let Some(b) = p.useful_sigma.filter(|&b| sigma > b) {
            out.reason = Some(too_weak_reason(problem, p, a, sigma, b, combinations));
            correlatable[i] = sigma > 0.0;
        } else {
            out.determined = true;
            out.sigma = Some(sigma);
            out.sigma_noise_model = Some(noise_sigma);
            determined_f[a] = true;
            correlatable[i] = sigma > 0.0;
        }
        parameters.push(out);
    }
    ParameterVerdicts { parameters, correlatable, determined_f, pos_in_f }
}

/// Why free parameter `a` (`p`) is not determined when it has a null-space component: the sparse null
/// combination in which it weighs most.
fn not_seen_reason(p: &ParamInfo, a: usize, combinations: &Combinations) -> String {
    let (r, coef) = combinations
        .null_rows
        .iter()
        .enumerate()
        .map(|(r, c)| (r, c[a]))
        .max_by(|x, y| x.1.abs().total_cmp(&y.1.abs()))
        .unwrap_or((0, f64::NAN));
    let text = combinations.unobservable.get(r).map_or_else(String::new, |c| format!(": {}", c.description));
    format!(
        "{} enters (coefficient {}{}) a combination the data do not see{text}",
        pretty(&p.name),
        if coef >= 0.0 { "+" } else { "" },
        three_significant(coef)
    )
}

/// Why free parameter `a` (`p`) is not determined when its σ exceeds its useful bound `b`: the
/// direction that carries most of its variance.
fn too_weak_reason(
    problem: &FreeProblem,
    p: &ParamInfo,
    a: usize,
    sigma: f64,
    b: f64,
    combinations: &Combinations,
) -> String {
    let (s, v, tol) = (&problem.pinv.singular_values, &problem.pinv.v, problem.pinv.tolerance);
    let nf = problem.free.len();
    let contributions: Vec<(usize, f64)> =
        (0..nf).filter(|&k| s[k] > tol).map(|k| (k, (v[(a, k)] / s[k]).powi(2))).collect();
    let total: f64 = contributions.iter().map(|x| x.1).sum();
    let (k, share) =
        contributions.iter().copied().max_by(|x, y| x.1.total_cmp(&y.1)).map_or((0, 0.0), |(k, c)| (k, c / total));
    let which = match combinations.weak_combination.get(k).copied().flatten() {
        Some(u) => combinations.unobservable[u].description.clone(),
        None => format!(
            "the combination ({}) with singular value {}",
            coefficient_text(&sparse_coefficients(
                &v.column(k).into_owned(),
                &problem.names,
                problem.options.coefficient_cutoff
            )),
            three_significant(s[k])
        ),
    };
    format!(
        "its standard uncertainty, {} {}, exceeds the useful bound {} {}; {:.0} % of its variance comes from \
         a direction the data see weakly: {which}",
        three_significant(sigma),
        p.unit,
        three_significant(b),
        p.unit,
        100.0 * share
    )
}

/// Correlation matrix over all parameters (`None` where undefined) and the pairs above the flag.
#[allow(clippy::type_complexity)]
fn correlations(
    problem: &FreeProblem,
    verdicts: &ParameterVerdicts,
) -> (Vec<Vec<Option<f64>>>, Vec<(String, String, f64)>) {
    let c_noise = &problem.pinv.covariance;
    let (correlatable, pos_in_f) = (&verdicts.correlatable, &verdicts.pos_in_f);
    let n_all = problem.params.len();
    let mut correlation = vec![vec![None; n_all]; n_all];
    let mut strong_correlations = Vec::new();
    for i in 0..n_all {
        for k in 0..n_all {
            if let (true, true, Some(a), Some(b)) = (correlatable[i], correlatable[k], pos_in_f[i], pos_in_f[k]) {
                let rho = (c_noise[(a, b)] / (c_noise[(a, a)] * c_noise[(b, b)]).sqrt()).clamp(-1.0, 1.0);
                correlation[i][k] = Some(if i == k { 1.0 } else { rho });
                if k > i && rho.abs() > problem.options.correlation_flag {
                    strong_correlations.push((problem.params[i].name.clone(), problem.params[k].name.clone(), rho));
                }
            }
        }
    }
    (correlation, strong_correlations)
}

/// The base set: the first `effective_rank` pivots of a pivoted QR with columns in "useful bounds".
fn base_set(problem: &FreeProblem, effective_rank: usize) -> Vec<String> {
    let mut jb = problem.jf.clone();
    for (a, mut col) in jb.column_iter_mut().enumerate() {
        if let Some(b) = problem.bound_f[a] {
            col *= b / problem.scale_f[a];
        }
    }
    pivot_order(&jb).into_iter().take(effective_rank).map(|a| problem.names[a].to_string()).collect()
}

/// The sentences for the user: conditioning, undetermined parameters, the residuals against the
/// noise model, strong correlations.
fn warnings(
    problem: &FreeProblem,
    parameters: &[ParameterUncertainty],
    condition_number: Option<f64>,
    condition_number_determined: Option<f64>,
    strong_correlations: &[(String, String, f64)],
) -> Vec<String> {
    let options = problem.options;
    let params = problem.params;
    let nf = problem.free.len();
    let mut warnings = Vec::new();
    let thr = options.condition_warning;
    if let Some(c) = condition_number.filter(|&c| c > thr) {
        let what = if c.is_finite() {
            format!("has condition number {}, above {}", three_significant(c), three_significant(thr))
        } else {
            "is singular (infinite condition number)".to_string()
        };
        warnings.push(format!(
            "The Jacobian (columns scaled to unit norm) {what}: some parameters trade off against each other, and \
             small errors in the data move them a lot."
        ));
    }
    if let Some(c) = condition_number_determined.filter(|&c| c > thr) {
        warnings.push(format!(
            "Even restricted to the determined parameters the condition number is {}, above {}: their estimates are \
             strongly coupled.",
            three_significant(c),
            three_significant(thr)
        ));
    }
    let undetermined: Vec<String> =
        problem.free.iter().filter(|&&i| !parameters[i].determined).map(|&i| pretty(&params[i].name)).collect();
    if !undetermined.is_empty() {
        warnings.push(format!(
            "{} of {} free parameters are not determined by these data ({}): their values are not results and must \
             not be reported as numbers.",
            undetermined.len(),
            nf,
            undetermined.join(", ")
        ));
    }
    warnings.extend(residual_warning(problem));
    if !strong_correlations.is_empty() {
        let pairs: Vec<String> =
            strong_correlations.iter().map(|(a, b, r)| format!("{}/{} ({r:+.2})", pretty(a), pretty(b))).collect();
        warnings.push(format!(
            "Strong correlations (|ρ| > {}): {}.",
            three_significant(options.correlation_flag),
            pairs.join(", ")
        ));
    }
    warnings
}

/// The residuals against the noise model: no redundancy to test it, or a reduced χ² outside its
/// 3-sigma spread.
fn residual_warning(problem: &FreeProblem) -> Option<String> {
    let (m, rank, rss, f) = (problem.m, problem.pinv.rank, problem.rss, problem.covariance_scale);
    let nf = problem.free.len();
    match problem.reduced_chi2 {
        None if nf > 0 => Some(format!(
            "No redundancy ({m} observations for rank {rank}): the residuals cannot test the model, and the \
             uncertainties are those of the noise model alone."
        )),
        Some(c) => {
            let dof = (m - rank) as f64;
            let spread = 3.0 * (2.0 / dof).sqrt();
            if c > 1.0 + spread {
                Some(format!(
                    "The residuals are {} times the noise floor (reduced χ² = {} over {} degrees of freedom): the \
                     model or the noise model is incomplete; the uncertainties were scaled up by √χ² = {}.",
                    three_significant(c.sqrt()),
                    three_significant(c),
                    m - rank,
                    three_significant(f.sqrt())
                ))
            } else if rss > 0.0 && c < 1.0 - spread {
                Some(format!(
                    "The residuals are smaller than the noise model predicts (reduced χ² = {}): the stated σ of the \
                     observations may be too large; the uncertainties use max(χ², {}).",
                    three_significant(c),
                    three_significant(problem.options.chi2_floor)
                ))
            } else {
                None
            }
        }
        None => None,
    }
}
