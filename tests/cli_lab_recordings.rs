//! Recordings whose optics are not ours, calibrated through `photorobot calibrate --traces`: the
//! CI-sized version of the `lab_recordings` example. Random plans recorded by the independent
//! simulator with its multi-beam optics and with the two-beam model, each with a random truth, in
//! plain CSV files without our header lines. A parameter reported as determined lies within 3
//! total σ of the simulator's hidden truth (at least 95 % of them), no validation motion that the
//! report forecast within its target moves the true gap beyond it, and a recording the model
//! cannot fit is refused as no calibration, with its residual against what noise allows.

use photorobot_e2e::lab_recordings::{optics, CaseOutcome, LabCase};

#[test]
fn random_plans_recorded_with_other_optics_are_right_within_their_total_sigma() {
    let mut outcomes: Vec<CaseOutcome> = Vec::new();
    for plan in [5000, 5001, 5002] {
        for two_beam in [false, true] {
            let o = LabCase::random(plan, 100 * (plan - 5000) + 1, optics(two_beam)).calibrate();
            eprintln!("plan {plan}  {}", o.line());
            outcomes.push(o);
        }
    }
    let determined: usize = outcomes.iter().map(|o| o.determined.len()).sum();
    let beyond: usize = outcomes.iter().map(|o| o.beyond(3.0).len()).sum();
    let broken: Vec<String> = outcomes.iter().flat_map(|o| o.broken_promises()).collect();
    eprintln!("{determined} parameters determined, {beyond} beyond 3 total σ; broken validation promises: {broken:?}");
    assert!(determined >= 8, "the plans determine parameters: {determined}");
    assert!(beyond * 20 <= determined, "{beyond} of {determined} determined parameters beyond 3σ");
    assert!(broken.is_empty(), "{broken:?}");
    // Every recording is calibrated, or refused as no calibration with the reason: never a
    // failure of another kind.
    for o in &outcomes {
        let refused = o.verdict.contains("not a calibration");
        assert!(refused || ["fits", "ambiguous"].contains(&o.verdict.as_str()), "{}", o.line());
        assert_eq!(o.determined.is_empty(), refused, "a refusal determines nothing: {}", o.line());
    }
}
