//! Replay and localisation: the residuals (measured − predicted) of every observation under a
//! model state, grouped by motion, by the joints a motion moves, by direction and by time.
//! Owns where the residual lives.

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

    #[test]
    fn a_biased_motion_is_found_first() {
        let mk = |label: &str, j: usize, d: f64, t: f64| {
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
        };
        let obs = vec![mk("a", 2, 100.0, 0.0), mk("a", 2, 100.0, 1.0), mk("b", 3, -4.0, 10.0), mk("b", 3, -4.0, 11.0)];
        let r = DVector::from_vec(vec![0.1, -0.1, 5.0, 5.0]);
        let g = localise(&obs, &r);
        assert_eq!(g[0].rms_sigma, 5.0);
        assert!(g.iter().any(|x| x.by == "motion" && x.key == "b" && x.mean_sigma == 5.0));
        assert!(g.iter().any(|x| x.by == "direction" && x.key == "q4-" && x.count == 2));
        assert!(g.iter().any(|x| x.by == "time" && x.key == "last quarter of the run" && x.rms_sigma == 5.0));
    }
}
