//! The words of the analysis: parameter names, numbers and combinations as they appear in its sentences.

use super::report::CombinationKind;
use nalgebra::DVector;

/// `beta_wf` → `β_wf`, `theta_et` → `θ_et`; other names unchanged.
pub(super) fn pretty(name: &str) -> String {
    if let Some(rest) = name.strip_prefix("beta") {
        format!("β{rest}")
    } else if let Some(rest) = name.strip_prefix("theta") {
        format!("θ{rest}")
    } else {
        name.to_string()
    }
}

/// A number with about three significant digits, in plain or scientific notation.
pub(super) fn three_significant(x: f64) -> String {
    if !x.is_finite() {
        return if x > 0.0 { "infinite".into() } else { format!("{x}") };
    }
    let a = x.abs();
    if a == 0.0 {
        "0".into()
    } else if (1e-3..1e5).contains(&a) {
        let decimals = (2 - a.log10().floor() as i64).max(0) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.2e}")
    }
}

/// `+1.00·y_wf +1.00·Z_et`.
pub(super) fn coefficient_text(coefficients: &[(String, f64)]) -> String {
    coefficients.iter().map(|(n, c)| format!("{c:+.2}·{n}")).collect::<Vec<_>>().join(" ")
}

/// Normalise `c` (one entry per free parameter) to largest |c| = +1, drop small entries, sort.
pub(super) fn sparse_coefficients(c: &DVector<f64>, names: &[&str], cutoff: f64) -> Vec<(String, f64)> {
    let k_max = c.iamax();
    let top = c[k_max];
    if top == 0.0 {
        return Vec::new();
    }
    let mut out: Vec<(usize, f64)> =
        c.iter().enumerate().map(|(i, &x)| (i, x / top)).filter(|(_, x)| x.abs() >= cutoff).collect();
    out.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()).then(a.0.cmp(&b.0)));
    out.into_iter().map(|(i, x)| (names[i].to_string(), x)).collect()
}

/// A sentence for a combination: the physical readings when the names match, else generic.
pub(super) fn describe(coefficients: &[(String, f64)], kind: CombinationKind) -> String {
    let cs = coefficient_text(coefficients);
    let names: Vec<&str> = coefficients.iter().map(|(n, _)| n.as_str()).collect();
    let has = |n: &str| names.contains(&n);
    let seen = kind == CombinationKind::NotSeen;
    let within = |allowed: &[&str]| names.iter().all(|n| allowed.contains(n));
    let ratio_near_one = |a: f64, b: f64| (0.8..=1.25).contains(&(a / b).abs());

    // Fiber direction: β_wf, θ_wf only.
    if !names.is_empty() && within(&["beta_wf", "theta_wf"]) {
        return if seen {
            format!(
                "the direction of n_f about n_t (β_wf, θ_wf) is not seen ({cs}): the data see the fiber axis only \
                 through its angle to the lamella normal, so whatever a solver returns along this combination is its \
                 starting point, not data (tilt scans of the reflected power locate n_f)"
            )
        } else {
            format!(
                "the fiber direction n_f (β_wf, θ_wf) is seen only weakly ({cs}): the angle between n_t and n_f \
                 enters the gap changes at second order only (tilt scans of the reflected power locate n_f)"
            )
        };
    }
    // Gap split between the fiber origin along the beam and the lamella offset.
    if names.len() == 2 && has("y_wf") && has("Z_et") {
        let (a, b) = (coefficients[0].1, coefficients[1].1);
        if a * b > 0.0 && ratio_near_one(a, b) {
            let (cy, cz) = if coefficients[0].0 == "y_wf" { (a, b) } else { (b, a) };
            let cs = format!("{cy:+.2}·y_wf {cz:+.2}·Z_et");
            return if seen {
                format!(
                    "y_wf and Z_et move together ({cs}): the data see only their difference, the gap along the \
                     beam; how it splits between the fiber origin and the lamella offset is not seen (absolute gaps \
                     fix the difference; only rotations split it, at second order in the angle)"
                )
            } else {
                format!(
                    "y_wf and Z_et moving together ({cs}) is seen only weakly: the split of the gap between the fiber \
                     origin and the lamella offset shows at second order in the rotation angle only (it hardly \
                     matters: a pivot error δ along the beam changes the gap by δ·φ²/2 during a rotation φ)"
                )
            };
        }
    }
    // Beam origin against beam angles: the beam turns about its hit point on the lamella.
    if within(&["x_wf", "y_wf", "z_wf", "beta_wf", "theta_wf"])
        && (has("x_wf") || has("z_wf"))
        && (has("beta_wf") || has("theta_wf"))
    {
        let verb = if seen { "trade off" } else { "are separated only weakly" };
        return format!(
            "the beam origin (x_wf, z_wf) and the beam angles (β_wf, θ_wf) {verb} ({cs}): the beam turns about the \
             point where it meets the lamella, so the data see the hit point but not the beam's origin and \
             direction separately"
        );
    }
    // Generic sentences.
    match coefficients {
        [(p, _)] => {
            let p = pretty(p);
            if seen {
                format!("{p} is not seen by these data ({cs}): whatever a solver returns for it is its starting point, not data")
            } else {
                format!("{p} is seen only weakly by these data ({cs})")
            }
        }
        [(p, a), (q, b)] if ratio_near_one(*a, *b) => {
            let (p, q) = (pretty(p), pretty(q));
            let (how, what) = if a * b > 0.0 { ("move together", "difference") } else { ("move in opposition", "sum") };
            if seen {
                format!("{p} and {q} {how} ({cs}): the data see only their {what}")
            } else {
                format!("{p} and {q} {how} ({cs}), and the data separate them only weakly")
            }
        }
        _ => {
            if seen {
                format!(
                    "the data do not see the combination ({cs}): moving the parameters along it leaves every \
                     prediction unchanged to first order, so whatever a solver returns along it is its starting \
                     point, not data"
                )
            } else {
                format!("the data see the combination ({cs}) only weakly")
            }
        }
    }
}
