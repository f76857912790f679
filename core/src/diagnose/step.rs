//! The steps of the workflow as shown to a person: a title and a few lines each.

use crate::diagnose::replay::ResidualGroup;
use crate::diagnose::result::{NamedEffect, Verdict};
use crate::diagnose::scoring::CandidateScore;
use crate::model::extrinsics::Extrinsics;
use serde::{Deserialize, Serialize};

/// One step of the workflow, for display.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Step {
    /// The extrinsics refitted without effects.
    Baseline {
        /// Observations fitted and held out.
        fitted: usize,
        /// Held-out observations.
        held_out: usize,
        /// Whitened rms.
        rms_sigma: f64,
        /// Gap-change rms (nm).
        rms_nm: f64,
        /// Worst residual groups.
        worst: Vec<ResidualGroup>,
        /// Candidates no observation and no pool motion can see (dropped), and, from traces, the
        /// fringe nonlinearity (never named; it stays among the design's targets).
        invisible: Vec<String>,
    },
    /// Candidates scored, best first.
    Scored {
        /// The scores.
        scores: Vec<CandidateScore>,
    },
    /// Discriminating motions designed (and run).
    Designed {
        /// Candidates the data could not see at typical size.
        needy: Vec<String>,
        /// Motions chosen.
        motions: Vec<String>,
        /// Whether they ran, and on what.
        ran_on: Option<String>,
        /// Observations added.
        added_observations: usize,
        /// Whitened rms of the baseline refitted with them.
        rms_sigma: f64,
        /// Pool motions left out because the gap turns inside them ([`motions::gap_turns`](crate::diagnose::motions::gap_turns)):
        /// their tracking can miss by many σ.
        #[serde(default)]
        avoided: Vec<String>,
        /// Pool motions left out because the gap travels under
        /// [`motions::MIN_FRINGES`](crate::diagnose::motions::MIN_FRINGES) fringes in them: their
        /// fringes cannot be analysed.
        #[serde(default)]
        short: Vec<String>,
        /// Pool motions left out because the observations hold them already.
        #[serde(default)]
        recorded: Vec<String>,
    },
    /// An effect added and the model refitted.
    Added {
        /// The effect.
        effect: NamedEffect,
        /// Whitened rms before and after.
        rms_sigma: [f64; 2],
        /// Held-out rms before and after.
        held_out_rms_sigma: [f64; 2],
        /// Whether the held-out motions confirm it (their rms did not grow) and the refit keeps
        /// it beyond [`REMOVE_BELOW_SIGMA`](crate::diagnose::settings::REMOVE_BELOW_SIGMA).
        confirmed: bool,
    },
    /// An added effect removed: tested again on the final analysis of the data, the model
    /// does not need it (estimate within [`REMOVE_BELOW_SIGMA`](crate::diagnose::settings::REMOVE_BELOW_SIGMA) of neutral, χ² not lower by the
    /// BIC margin, or the held-out motions worse with it).
    Removed {
        /// The effect, with its estimate and σ in the fit that included it last.
        effect: NamedEffect,
        /// Whitened rms with it and without it.
        rms_sigma: [f64; 2],
        /// Why the model does not need it.
        #[serde(default)]
        reason: String,
    },
    /// Another branch of the extrinsics (the calibration's, or where an earlier diagnosis ended) fits
    /// better and replaces them.
    Branch {
        /// The extrinsics left.
        from: Extrinsics,
        /// The extrinsics of the branch taken, refitted with the named effects.
        to: Extrinsics,
        /// χ² before and after.
        chi2: [f64; 2],
        /// Whitened rms before and after.
        rms_sigma: [f64; 2],
    },
    /// The traces analysed again with the model (its named effects in the fringe tracking's
    /// motion hint), and that analysis refused: the model fits it worse than the analysis it
    /// would replace, so the hint led the tracking astray (optics unlike the model's, or an
    /// effect named wrongly), and the earlier analysis is kept.
    ReanalysisRefused {
        /// Whitened rms of the model on the earlier analysis and on the refused one.
        rms_sigma: [f64; 2],
    },
    /// The verdict.
    Finished {
        /// The verdict.
        verdict: Verdict,
    },
}

impl Step {
    /// A short title.
    pub fn title(&self) -> &'static str {
        match self {
            Step::Baseline { .. } => "1. replay: baseline fit of the extrinsics",
            Step::Scored { .. } => "2. candidates scored",
            Step::Added { .. } => "3. effect added, refitted, checked on held-out motions",
            Step::Removed { .. } => "3. effect removed: the final model does not need it",
            Step::Branch { .. } => "3. another branch of the extrinsics fits better",
            Step::Designed { .. } => "4. discriminating motions",
            Step::ReanalysisRefused { .. } => "3. traces analysed again with the model: refused",
            Step::Finished { .. } => "5. verdict",
        }
    }

    /// A few lines for a person.
    pub fn summary(&self) -> String {
        match self {
            Step::Baseline { fitted, held_out, rms_sigma, rms_nm, worst, invisible } => {
                let mut s = format!(
                    "{fitted} observations fitted, {held_out} held out; residual rms {rms_sigma:.2}× the noise ({rms_nm:.2} nm on gap changes)"
                );
                for g in worst.iter().take(4) {
                    s += &format!(
                        "\n  worst {} `{}`: rms {:.2}σ, mean {:+.2}σ (n = {})",
                        g.by, g.key, g.rms_sigma, g.mean_sigma, g.count
                    );
                }
                if !invisible.is_empty() {
                    s += &format!("\n  no observation can see: {}", invisible.join(", "));
                }
                s
            }
            Step::Scored { scores } => {
                let mut s = String::new();
                for c in scores.iter().take(6) {
                    s += &format!(
                        "{}{:<36} F {:>9.1}  ΔBIC {:>8.1}  est {:+.4} ± {:.4} {}  absorbed {:.1} %\n",
                        if c.significant { "* " } else { "  " },
                        c.name,
                        c.score,
                        c.delta_bic,
                        c.estimate,
                        c.sigma,
                        c.unit,
                        100.0 * c.absorbed_share
                    );
                }
                s.trim_end().to_string()
            }
            Step::Designed { needy, motions, ran_on, added_observations, rms_sigma, avoided, short, recorded } => {
                let mut s = format!(
                    "candidates the data cannot see at typical size: {}",
                    if needy.is_empty() { "none".into() } else { needy.join(", ") }
                );
                s += &format!("\nmotions chosen ({}): {}", motions.len(), motions.join("; "));
                if !avoided.is_empty() {
                    s += &format!("\navoided, the gap turns inside them: {}", avoided.join("; "));
                }
                if !short.is_empty() {
                    s += &format!(
                        "\navoided, the gap moves under {} fringes in them: {}",
                        crate::diagnose::motions::MIN_FRINGES,
                        short.join("; ")
                    );
                }
                if !recorded.is_empty() {
                    s += &format!("\nrecorded already: {}", recorded.join("; "));
                }
                match ran_on {
                    Some(b) => {
                        s += &format!(
                        "\nran on {b}: {added_observations} observations added; baseline refitted, rms {rms_sigma:.2}σ"
                    )
                    }
                    None if motions.is_empty() => {
                        s += "\nno motion of the pool would show them better than the data already do"
                    }
                    None => s += "\nno bench to run them: they are proposed, not run",
                }
                s
            }
            Step::Added { effect, rms_sigma, held_out_rms_sigma, confirmed } => format!(
                "{} = {:+.4} ± {} {} (F {:.1}, absorbed {:.1} %){}\nrms {:.2}σ → {:.2}σ; held-out {:.2}σ → {:.2}σ: {}",
                effect.name,
                effect.estimate,
                effect.sigma.map_or("undetermined".into(), |s| format!("{s:.4}")),
                effect.unit,
                effect.score,
                100.0 * effect.absorbed_share,
                if effect.ambiguous_with.is_empty() {
                    String::new()
                } else {
                    format!("; cannot be told apart from {}", effect.ambiguous_with.join(", "))
                },
                rms_sigma[0],
                rms_sigma[1],
                held_out_rms_sigma[0],
                held_out_rms_sigma[1],
                if *confirmed { "confirmed" } else { "NOT confirmed (removed)" }
            ),
            Step::Removed { effect, rms_sigma, reason } => format!(
                "{} = {:+.4} ± {} {} on the final analysis: {reason}\nrms {:.2}σ with it, {:.2}σ without",
                effect.name,
                effect.estimate,
                effect.sigma.map_or("undetermined".into(), |s| format!("{s:.4}")),
                effect.unit,
                rms_sigma[0],
                rms_sigma[1],
            ),
            Step::Branch { from, to, chi2, rms_sigma } => {
                let angles = |e: &Extrinsics| {
                    format!(
                        "β_wf {:+.3}°, θ_wf {:+.3}°, β_et {:+.3}°, θ_et {:+.3}°",
                        e.beta_wf_deg, e.theta_wf_deg, e.beta_et_deg, e.theta_et_deg
                    )
                };
                format!(
                    "from {}
to   {}
χ² {:.1} → {:.1}; rms {:.2}σ → {:.2}σ",
                    angles(from),
                    angles(to),
                    chi2[0],
                    chi2[1],
                    rms_sigma[0],
                    rms_sigma[1]
                )
            }
            Step::ReanalysisRefused { rms_sigma } => format!(
                "the model fits the new analysis worse (rms {:.2}σ → {:.2}σ): the earlier analysis is kept",
                rms_sigma[0], rms_sigma[1]
            ),
            Step::Finished { verdict } => match verdict {
                Verdict::Named => "named: the effects above bring the residual to the noise floor".into(),
                Verdict::None => "no significant missing effect".into(),
                Verdict::Unexplained => {
                    "unexplained structure remains: no candidate of the library explains the residual".into()
                }
            },
        }
    }
}
