//! Replay and localisation: the residuals (measured − predicted) of every observation under a
//! model state, grouped by motion, by the joints a motion moves, by direction and by time.
//! Owns where the residual lives.

use crate::identify::discrepancy::Family;
use crate::identify::{Observation, ObservationKind};
use nalgebra::DVector;
use serde::{Deserialize, Serialize};

/// The residual of a group of observations.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResidualGroup {
    /// What the grouping is by: "motion", "joints", "direction" or "time".
    pub by: String,
    /// The group (a motion label, "q4", "q3+", "second quarter of the run", …).
    pub key: String,
    /// Number of observations.
    pub count: usize,
    /// RMS of the whitened residuals (1 = at the noise floor).
    pub rms_sigma: f64,
    /// Mean of the whitened residuals (a bias).
    pub mean_sigma: f64,
}

/// The residual of one family of observations before and after the named effects.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FamilyResidual {
    /// The family (gap changes of translations or rotations, absolute gaps, fringe amplitudes).
    pub family: Family,
    /// Its observations.
    pub count: usize,
    /// RMS of its whitened residuals with the baseline model (1 = noise floor).
    pub before_sigma: f64,
    /// The same with the final model.
    pub after_sigma: f64,
}

/// The whitened RMS of each family of `obs` present, under the residuals `before` and `after`.
pub fn by_family(obs: &[Observation], before: &DVector<f64>, after: &DVector<f64>) -> Vec<FamilyResidual> {
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    Family::ALL
        .iter()
        .filter_map(|&family| {
            let rows: Vec<usize> = (0..obs.len()).filter(|&i| Family::of(&obs[i]) == family).collect();
            if rows.is_empty() {
                return None;
            }
            let pick = |r: &DVector<f64>| rows.iter().map(|&i| r[i]).collect::<Vec<f64>>();
            Some(FamilyResidual {
                family,
                count: rows.len(),
                before_sigma: rms(&pick(before)),
                after_sigma: rms(&pick(after)),
            })
        })
        .collect()
}

fn moved(o: &Observation) -> Option<Vec<(usize, f64)>> {
    match o.kind {
        ObservationKind::GapChange { from_display, to_display, .. } => Some(
            (0..6)
                .filter(|&j| (to_display[j] - from_display[j]).abs() > 1e-9)
                .map(|j| (j, to_display[j] - from_display[j]))
                .collect(),
        ),
        _ => None,
    }
}

fn groups_of(keys: Vec<(String, String, f64)>) -> Vec<ResidualGroup> {
    let mut out: Vec<ResidualGroup> = Vec::new();
    for (by, key, r) in keys {
        match out.iter_mut().find(|g| g.by == by && g.key == key) {
            Some(g) => {
                g.count += 1;
                g.rms_sigma += r * r;
                g.mean_sigma += r;
            }
            None => out.push(ResidualGroup { by, key, count: 1, rms_sigma: r * r, mean_sigma: r }),
        }
    }
    for g in &mut out {
        g.rms_sigma = (g.rms_sigma / g.count as f64).sqrt();
        g.mean_sigma /= g.count as f64;
    }
    out
}

/// Where the whitened residual `r` of `obs` lives: groups by motion label, by the joints moved
/// (gap changes), by the sign of the move of a single joint, and by quarter of the run; the
/// worst groups first.
pub fn localise(obs: &[Observation], r: &DVector<f64>) -> Vec<ResidualGroup> {
    let t_end = obs.iter().map(|o| o.time_s[1]).fold(0.0, f64::max).max(1e-9);
    let names = ["q1", "q2", "q3", "q4", "q5", "q6"];
    let quarters = ["first", "second", "third", "last"];
    let mut keys = Vec::new();
    for (o, &ri) in obs.iter().zip(r.iter()) {
        keys.push(("motion".to_string(), o.label.clone(), ri));
        let kind = match (&o.kind, moved(o)) {
            (ObservationKind::GapChange { .. }, Some(m)) if m.is_empty() => "none (dwell)".to_string(),
            (ObservationKind::GapChange { .. }, Some(m)) => {
                m.iter().map(|(j, _)| names[*j]).collect::<Vec<_>>().join("+")
            }
            (ObservationKind::AbsoluteGap { .. }, _) => "absolute gaps".to_string(),
            _ => "fringe amplitudes".to_string(),
        };
        keys.push(("joints".to_string(), kind, ri));
        if let Some(m) = moved(o) {
            if let [(j, d)] = m.as_slice() {
                keys.push(("direction".to_string(), format!("{}{}", names[*j], if *d > 0.0 { "+" } else { "-" }), ri));
            }
        }
        let q = ((o.time_s[1] / t_end * 4.0) as usize).min(3);
        keys.push(("time".to_string(), format!("{} quarter of the run", quarters[q]), ri));
    }
    let mut g = groups_of(keys);
    g.sort_by(|a, b| b.rms_sigma.total_cmp(&a.rms_sigma));
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gap_change(label: &str, j: usize, d: f64, t: f64) -> Observation {
        let mut to = [0.0; 6];
        to[j] = d;
        Observation {
            label: label.into(),
            kind: ObservationKind::GapChange { from_display: [0.0; 6], to_display: to, dl_nm: 0.0 },
            sigma: 1.0,
            wavelength_nm: 1560.0,
            time_s: [t, t + 1.0],
            approach: Default::default(),
        }
    }

    #[test]
    fn a_biased_motion_is_found_first() {
        let mk = gap_change;
        let obs = vec![mk("a", 2, 100.0, 0.0), mk("a", 2, 100.0, 1.0), mk("b", 3, -4.0, 10.0), mk("b", 3, -4.0, 11.0)];
        let r = DVector::from_vec(vec![0.1, -0.1, 5.0, 5.0]);
        let g = localise(&obs, &r);
        assert_eq!(g[0].rms_sigma, 5.0);
        assert!(g.iter().any(|x| x.by == "motion" && x.key == "b" && x.mean_sigma == 5.0));
        assert!(g.iter().any(|x| x.by == "direction" && x.key == "q4-" && x.count == 2));
        assert!(g.iter().any(|x| x.by == "time" && x.key == "last quarter of the run" && x.rms_sigma == 5.0));
    }

    /// Each family's RMS is that of its own rows only (computed by hand here); families with no
    /// observation are left out.
    #[test]
    fn each_family_keeps_its_own_residual() {
        let obs = vec![gap_change("t", 0, 50.0, 0.0), gap_change("r", 4, 2.0, 1.0), gap_change("r", 5, -3.0, 2.0)];
        let before = DVector::from_vec(vec![3.0, 4.0, 2.0]);
        let after = DVector::from_vec(vec![0.5, 1.0, -1.0]);
        let f = by_family(&obs, &before, &after);
        assert_eq!(f.len(), 2, "{f:?}");
        assert_eq!((f[0].family, f[0].count, f[0].before_sigma, f[0].after_sigma), (Family::Translations, 1, 3.0, 0.5));
        assert_eq!((f[1].family, f[1].count), (Family::Rotations, 2));
        assert!((f[1].before_sigma - 10f64.sqrt()).abs() < 1e-12 && (f[1].after_sigma - 1.0).abs() < 1e-12, "{f:?}");
    }
}
