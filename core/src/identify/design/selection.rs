//! The selection problem in general: candidates with informations and costs, criteria on the σ
//! of linear combinations, and the greedy, pruning and exchange that pick the cheapest set
//! meeting them ([`select`]), with the brute-force oracle ([`select_exhaustive`]).

use super::error::DesignError;
use super::pilot::Scatter;
use nalgebra::{DMatrix, DVector};

/// A criterion of the generic selection: σ of `c` (internal units) with only the `free`
/// parameters estimated and only the candidates in `members` counted must be ≤ `tau`.
#[derive(Debug, Clone, PartialEq)]
pub struct Criterion {
    /// Coefficients (internal units).
    pub c: DVector<f64>,
    /// Bound on σ (internal units of the combination).
    pub tau: f64,
    /// Parameters estimated (others fixed); `None`: all.
    pub free: Option<Vec<bool>>,
    /// Candidates counted; `None`: all.
    pub members: Option<Vec<bool>>,
}

/// A generic selection problem: pick candidates (informations `F_k`, costs) so that every
/// criterion holds at least cost.
#[derive(Debug, Clone)]
pub struct SelectionProblem {
    /// Information of each candidate (n × n, symmetric positive semi-definite).
    pub information: Vec<DMatrix<f64>>,
    /// Cost of each candidate (s), positive.
    pub cost: Vec<f64>,
    /// Prior information (n × n, positive definite), added to every design.
    pub prior: DMatrix<f64>,
    /// The criteria.
    pub criteria: Vec<Criterion>,
    /// Residual-variance scaling as the identifier's report applies it, or `None` (σ from the
    /// noise model alone): per candidate (expected Σr², observations, nuisance parameters);
    /// the σ of a criterion counting every candidate is multiplied by
    /// `√max(1, Σ expected Σr² / (Σ observations − parameters − Σ nuisance))`.
    pub scatter: Option<Vec<Scatter>>,
}

/// A selection and what it reaches.
#[derive(Debug, Clone, PartialEq)]
pub struct Selection {
    /// Chosen candidates, ascending.
    pub chosen: Vec<usize>,
    /// Their total cost.
    pub cost: f64,
    /// Predicted σ per criterion (internal units).
    pub sigma: Vec<f64>,
}

impl SelectionProblem {
    pub(super) fn check(&self) -> Result<usize, DesignError> {
        let n = self.prior.nrows();
        if self.prior.ncols() != n || self.information.len() != self.cost.len() {
            return Err(DesignError::Input("selection: sizes of prior, informations and costs disagree".into()));
        }
        for (k, (f, c)) in self.information.iter().zip(&self.cost).enumerate() {
            if f.shape() != (n, n) || !f.iter().all(|v| v.is_finite()) {
                return Err(DesignError::Input(format!("candidate {k}: information is not a finite {n}×{n} matrix")));
            }
            if !(c.is_finite() && *c > 0.0) {
                return Err(DesignError::Input(format!("candidate {k}: cost {c} s is not a finite positive number")));
            }
        }
        for (t, cr) in self.criteria.iter().enumerate() {
            let sizes_ok = cr.free.as_ref().is_none_or(|f| f.len() == n)
                && cr.members.as_ref().is_none_or(|m| m.len() == self.cost.len());
            if cr.c.len() != n || !(cr.tau.is_finite() && cr.tau > 0.0) || !sizes_ok {
                return Err(DesignError::Input(format!(
                    "criterion {t}: expected {n} coefficients, a positive bound and masks of the right sizes"
                )));
            }
        }
        Ok(n)
    }

    fn member(&self, criterion: usize, k: usize) -> bool {
        self.criteria[criterion].members.as_ref().is_none_or(|m| m[k])
    }

    /// Per criterion: the prior plus the information of the chosen candidates it counts.
    fn sums(&self, chosen: &[bool]) -> Vec<DMatrix<f64>> {
        (0..self.criteria.len())
            .map(|t| {
                let mut s = self.prior.clone();
                for (k, f) in self.information.iter().enumerate() {
                    if chosen[k] && self.member(t, k) {
                        s += f;
                    }
                }
                s
            })
            .collect()
    }

    /// The residual-variance factor of [`SelectionProblem::scatter`] for a set given as `sums`'
    /// chosen set (recomputed from `chosen`) with `add` and `remove`.
    fn scatter_factor(&self, chosen: &[bool], add: &[usize], remove: &[usize]) -> f64 {
        let Some(sc) = &self.scatter else { return 1.0 };
        let n = self.prior.nrows() as f64;
        let (mut chi2, mut m, mut nuisance) = (0.0, 0.0, 0.0);
        for k in 0..chosen.len() {
            let inside = (chosen[k] || add.contains(&k)) && !remove.contains(&k);
            if inside {
                chi2 += sc[k].0;
                m += sc[k].1;
                nuisance += sc[k].2;
            }
        }
        let dof = m - n - nuisance;
        if dof > 0.0 {
            (chi2 / dof).max(1.0)
        } else {
            1.0
        }
    }

    /// σ of every criterion for the set behind `sums` with `add` added and `remove` removed.
    fn sigmas_with(&self, chosen: &[bool], sums: &[DMatrix<f64>], add: &[usize], remove: &[usize]) -> Vec<f64> {
        self.sigmas_scaled(sums, add, remove, self.scatter_factor(chosen, add, remove))
    }

    fn sigmas_scaled(&self, sums: &[DMatrix<f64>], add: &[usize], remove: &[usize], factor: f64) -> Vec<f64> {
        let n = self.prior.nrows();
        self.criteria
            .iter()
            .enumerate()
            .map(|(t, cr)| {
                let mut info = sums[t].clone();
                for &k in add {
                    if self.member(t, k) {
                        info += &self.information[k];
                    }
                }
                for &k in remove {
                    if self.member(t, k) {
                        info -= &self.information[k];
                    }
                }
                let idx: Vec<usize> = (0..n).filter(|&i| cr.free.as_ref().is_none_or(|f| f[i])).collect();
                let sub = DMatrix::from_fn(idx.len(), idx.len(), |a, b| info[(idx[a], idx[b])]);
                let c = DVector::from_fn(idx.len(), |a, _| cr.c[idx[a]]);
                let f = if cr.members.is_none() { factor } else { 1.0 };
                match sub.cholesky() {
                    Some(ch) => (f * c.dot(&ch.solve(&c))).max(0.0).sqrt(),
                    None => f64::INFINITY,
                }
            })
            .collect()
    }

    /// Predicted σ of every criterion for a set of candidates (mask).
    pub fn sigmas(&self, chosen: &[bool]) -> Vec<f64> {
        self.sigmas_scaled(&self.sums(chosen), &[], &[], self.scatter_factor(chosen, &[], &[]))
    }

    fn deficiency_of(&self, sigmas: &[f64]) -> f64 {
        sigmas.iter().zip(&self.criteria).map(|(s, cr)| (2.0 * (s / cr.tau).ln()).max(0.0)).sum()
    }

    fn feasible_of(&self, sigmas: &[f64]) -> bool {
        sigmas.iter().zip(&self.criteria).all(|(s, cr)| *s <= cr.tau)
    }

    fn feasible(&self, chosen: &[bool]) -> bool {
        self.feasible_of(&self.sigmas(chosen))
    }

    fn cost_of(&self, chosen: &[bool]) -> f64 {
        (0..chosen.len()).filter(|&k| chosen[k]).map(|k| self.cost[k]).sum()
    }

    fn selection(&self, chosen: &[bool]) -> Selection {
        let idx: Vec<usize> = (0..chosen.len()).filter(|&k| chosen[k]).collect();
        Selection { cost: idx.iter().map(|&k| self.cost[k]).sum(), chosen: idx, sigma: self.sigmas(chosen) }
    }

    /// Greedy from `chosen`: add the candidate with the largest decrease of the deficiency per
    /// second until every criterion holds.
    fn greedy(&self, chosen: &mut [bool]) {
        let n = chosen.len();
        let mut sums = self.sums(chosen);
        let mut f = self.deficiency_of(&self.sigmas_with(chosen, &sums, &[], &[]));
        while f > 0.0 {
            let mut best: Option<(usize, f64, f64)> = None;
            for k in (0..n).filter(|&k| !chosen[k]) {
                let fk = self.deficiency_of(&self.sigmas_with(chosen, &sums, &[k], &[]));
                let score = (f - fk) / self.cost[k];
                if f - fk > 1e-12 && best.is_none_or(|b| score > b.1) {
                    best = Some((k, score, fk));
                }
            }
            // No single candidate lowers the deficiency (a target needing two candidates
            // together): add the cheapest remaining one.
            let k = match best {
                Some((k, _, _)) => k,
                None => match (0..n).filter(|&k| !chosen[k]).min_by(|&a, &b| self.cost[a].total_cmp(&self.cost[b])) {
                    Some(k) => k,
                    None => return,
                },
            };
            chosen[k] = true;
            sums = self.sums(chosen);
            f = self.deficiency_of(&self.sigmas_with(chosen, &sums, &[], &[]));
        }
    }

    /// Local search on a feasible set: drop what is not needed (most expensive first), then
    /// swap one chosen for one cheaper unchosen, or two chosen for one cheaper than both,
    /// while the criteria hold; repeat until nothing improves.
    fn improve(&self, chosen: &mut [bool]) {
        let n = chosen.len();
        for _ in 0..10 * n.max(1) {
            // Drop.
            let mut ins: Vec<usize> = (0..n).filter(|&k| chosen[k]).collect();
            ins.sort_by(|&a, &b| self.cost[b].total_cmp(&self.cost[a]));
            for &k in &ins {
                let sums = self.sums(chosen);
                if self.feasible_of(&self.sigmas_with(chosen, &sums, &[], &[k])) {
                    chosen[k] = false;
                }
            }
            let sums = self.sums(chosen);
            let ins: Vec<usize> = (0..n).filter(|&k| chosen[k]).collect();
            let outs: Vec<usize> = (0..n).filter(|&k| !chosen[k]).collect();
            // The best improving move of either kind.
            let mut best: Option<(f64, Vec<usize>, usize)> = None;
            for (a, &k) in ins.iter().enumerate() {
                for &j in &outs {
                    let gain = self.cost[k] - self.cost[j];
                    if gain > 1e-12
                        && best.as_ref().is_none_or(|b| gain > b.0)
                        && self.feasible_of(&self.sigmas_with(chosen, &sums, &[j], &[k]))
                    {
                        best = Some((gain, vec![k], j));
                    }
                }
                for &k2 in &ins[a + 1..] {
                    for &j in &outs {
                        let gain = self.cost[k] + self.cost[k2] - self.cost[j];
                        if gain > 1e-12
                            && best.as_ref().is_none_or(|b| gain > b.0)
                            && self.feasible_of(&self.sigmas_with(chosen, &sums, &[j], &[k, k2]))
                        {
                            best = Some((gain, vec![k, k2], j));
                        }
                    }
                }
            }
            match best {
                Some((_, removed, added)) => {
                    for k in removed {
                        chosen[k] = false;
                    }
                    chosen[added] = true;
                }
                None => return,
            }
        }
    }
}

/// Cost-weighted greedy selection followed by local search (drop, 1-for-1 and 2-for-1
/// exchanges), started from the empty set and from each of the best first picks; the cheapest
/// result wins (see the module documentation).
pub fn select(problem: &SelectionProblem) -> Result<Selection, DesignError> {
    problem.check()?;
    let n = problem.cost.len();
    let all = vec![true; n];
    let s_all = problem.sigmas(&all);
    if !problem.feasible_of(&s_all) {
        let missed: Vec<String> = s_all
            .iter()
            .zip(&problem.criteria)
            .enumerate()
            .filter(|(_, (s, cr))| **s > cr.tau)
            .map(|(t, (s, cr))| {
                format!("criterion {t}: σ {s:.3e} > {:.3e} (internal units) with every candidate", cr.tau)
            })
            .collect();
        return Err(DesignError::Unreachable(missed.join("; ")));
    }
    // Starts: the empty set, and each of the (at most 8) best first picks forced in.
    let empty = vec![false; n];
    let sums = problem.sums(&empty);
    let f0 = problem.deficiency_of(&problem.sigmas_with(&empty, &sums, &[], &[]));
    let mut firsts: Vec<(usize, f64)> = (0..n)
        .map(|k| (k, (f0 - problem.deficiency_of(&problem.sigmas_with(&empty, &sums, &[k], &[]))) / problem.cost[k]))
        .collect();
    firsts.sort_by(|a, b| b.1.total_cmp(&a.1));
    let mut best: Option<Vec<bool>> = None;
    for start in std::iter::once(None).chain(firsts.iter().take(8).map(|f| Some(f.0))) {
        let mut chosen = empty.clone();
        if let Some(k) = start {
            chosen[k] = true;
        }
        problem.greedy(&mut chosen);
        problem.improve(&mut chosen);
        if problem.feasible(&chosen)
            && best.as_ref().is_none_or(|b| problem.cost_of(&chosen) < problem.cost_of(b) - 1e-12)
        {
            best = Some(chosen);
        }
    }
    let chosen = best.ok_or_else(|| DesignError::Unreachable("no start reached the targets".into()))?;
    Ok(problem.selection(&chosen))
}

/// The cheapest feasible selection by enumerating every subset (pools of at most 20): the
/// oracle for [`select`]. `None` when no subset is feasible.
pub fn select_exhaustive(problem: &SelectionProblem) -> Result<Option<Selection>, DesignError> {
    problem.check()?;
    let n = problem.cost.len();
    if n > 20 {
        return Err(DesignError::Input(format!("exhaustive selection over {n} candidates (at most 20)")));
    }
    let mut best: Option<(f64, u32)> = None;
    for mask in 0u32..(1 << n) {
        let cost: f64 = (0..n).filter(|k| mask >> k & 1 == 1).map(|k| problem.cost[k]).sum();
        if best.is_some_and(|b| cost >= b.0) {
            continue;
        }
        let chosen: Vec<bool> = (0..n).map(|k| mask >> k & 1 == 1).collect();
        if problem.feasible(&chosen) {
            best = Some((cost, mask));
        }
    }
    Ok(best.map(|(_, mask)| problem.selection(&(0..n).map(|k| mask >> k & 1 == 1).collect::<Vec<_>>())))
}
