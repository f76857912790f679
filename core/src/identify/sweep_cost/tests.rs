use super::*;
use crate::identify::observability::{analyse, Options, ParamInfo};
use crate::identify::signs::SignEvidence;
use crate::identify::verdict::{BranchSummary, Verdict};
use nalgebra::{DMatrix, DVector};

/// The analysis of a synthetic Jacobian over the eight extrinsics: 12 rows of independent
/// columns, or with `gap_columns_equal` the Z_et and y_wf columns made equal (the data then see
/// their sum only, as fringe data without an absolute gap): the oracle is that null direction.
fn report(gap_columns_equal: bool) -> IdentifiabilityReport {
    let mut j = DMatrix::from_fn(12, 8, |r, c| ((r * 7 + c * 3) % 11) as f64 + if r == c { 20.0 } else { 0.0 });
    if gap_columns_equal {
        let z = j.column(4).clone_owned();
        j.set_column(6, &z);
    }
    analyse(&j, &DVector::zeros(12), &ParamInfo::extrinsics(), &Options::default()).unwrap()
}

fn sign(label: &str, sources: &[SignSource]) -> TranslationSign {
    TranslationSign {
        label: label.into(),
        dl_nm: 100.0,
        sigma_nm: 1.0,
        evidence: sources.iter().map(|&source| SignEvidence { source, sign: 1 }).collect(),
        fixed_by: sources.first().copied(),
        agrees: true,
    }
}

fn branch(beta_wf_deg: f64, chi2: f64) -> BranchSummary {
    let mut e = Extrinsics::table2();
    e.beta_wf_deg = beta_wf_deg;
    BranchSummary { start: "s".into(), extrinsics: e, chi2, rms_sigma: 1.0, skipped_traces: 0, hint_led_traces: 0 }
}

#[test]
fn the_cost_names_what_the_analysis_without_sweeps_loses() {
    let (with, without) = (report(false), report(true));
    assert!(with.parameters.iter().all(|p| p.determined), "the full-rank oracle determines everything");
    let both = [SignSource::SweepsBeforeAndAfter, SignSource::FittedModel];
    let with_signs = [sign("X_w 1", &both), sign("X_w 2", &[SignSource::SweepsBeforeAndAfter]), sign("Z_w", &[])];
    let without_signs = [sign("X_w 1", &[SignSource::FittedModel]), sign("X_w 2", &[]), sign("Z_w", &[])];
    let fit = FitCheck {
        verdict: Verdict::Ambiguous,
        rms_sigma: 1.0,
        threshold_sigma: 1.5,
        worst_traces: vec![],
        branches: vec![branch(0.5, 10.0), branch(-0.5, 10.1), branch(-0.4, 90.0)],
        tied_branches: vec![1],
        ambiguous_parameters: vec!["beta_wf".into()],
        summary: String::new(),
    };
    let cost = SweepCost::assess(
        Evidence { identifiability: &with, signs: &with_signs },
        Evidence { identifiability: &without, signs: &without_signs },
        Some(&fit),
        false,
    );
    let lost: Vec<&str> = cost.undetermined.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(lost, ["Z_et", "y_wf"], "exactly the two columns made equal");
    assert!(cost.undetermined.iter().all(|p| !p.reason.is_empty()));
    assert_eq!(cost.unseen.len(), 1, "one null direction: {:?}", cost.unseen);
    assert_eq!(cost.sign_open, ["beta_wf"], "only the tied branch counts, and only a sign change");
    assert_eq!(cost.signed_by_sweeps, ["X_w 1", "X_w 2"]);
    assert_eq!(cost.unsigned, ["X_w 2"], "X_w 1 keeps the fitted model's sign");
    let text = cost.sentences().join("\n");
    assert!(text.contains("Z_et, y_wf are not determined"), "{text}");
    assert!(text.contains("the sign of beta_wf is not fixed"), "{text}");
    assert!(text.contains("2 translation(s) would get the sign of their gap change from sweeps before and after: 1 rest on the model fitted to all the data, 1 on nothing"), "{text}");
    assert!(!cost.is_free());
}

#[test]
fn data_that_need_no_sweeps_cost_nothing() {
    let r = report(false);
    let signs = [sign("X_w", &[SignSource::FittedModel])];
    let e = Evidence { identifiability: &r, signs: &signs };
    let cost = SweepCost::assess(e, e, None, true);
    assert!(cost.is_free(), "{cost:?}");
    assert_eq!(cost.sentences(), ["leaving the sweeps out loses no parameter and no sign these plans determine"]);
}
