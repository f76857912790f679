//! Diagnosis of another simulator's recordings (`independent.rs`: its own chain, optics and
//! recorder) with an imperfection hidden from its readings, through the path users run:
//! `photorobot calibrate --bench table2-ideal --traces DIR`, then `photorobot diagnose S --bench
//! none --json`. When the diagnosis proposes motions (a plan file), that simulator records them
//! on the same bench, later on the same clock, the traces join the session's, and the diagnosis
//! runs again (`diagnose --add`).

use photorobot_e2e::independent::Hidden;
use photorobot_e2e::recordings::{assert_named, independent_loop};
use serde_json::Value;

use photorobot_e2e::recordings::independent_calibrate_and_diagnose as from_recordings;

/// What the recordings alone name is the hidden effect, or lists it among those it cannot be
/// told apart from: never a different effect claimed as the only explanation.
fn assert_not_misnamed(v: &Value, name: &str) {
    if v["verdict"] == "named" {
        let first = &v["effects"][0];
        let listed = first["ambiguous_with"].as_array().unwrap().iter().any(|n| n.as_str() == Some(name));
        assert!(first["name"] == name || listed, "{name} neither named nor listed as equivalent: {v}");
    }
}

/// Clean recordings name nothing in any pass of the loop a technician follows, and the loop ends:
/// measured on 20 seeds, the third pass says `settled` and writes no plan.
#[test]
fn another_simulators_clean_recordings_name_nothing_and_the_loop_ends() {
    let passes = independent_loop(Hidden::default(), 21, 4);
    for (k, v) in passes.iter().enumerate() {
        assert_eq!(v["verdict"], "none", "pass {}: {v}", k + 1);
    }
    let last = passes.last().unwrap();
    assert!(passes.len() <= 3, "settled by the third pass: {last}");
    assert_eq!(last["settled"], true, "{last}");
    assert!(last["proposed_plan_file"].is_null(), "{last}");
}

#[test]
fn another_simulators_hidden_q4_zero_offset_is_named() {
    let hidden = Hidden { joint_offset: [0.0, 0.0, 0.0, 0.07, 0.0, 0.0], ..Hidden::default() };
    let (first, second) = from_recordings(hidden, 22);
    assert_not_misnamed(&first, "joint zero offset q4");
    assert_named(second.as_ref().unwrap_or(&first), &["joint zero offset q4"], 0.07, false);
}

#[test]
fn another_simulators_hidden_stage_axis_tilt_is_named() {
    let hidden = Hidden { q3_tilt_mrad: [0.0, 1.0], ..Hidden::default() };
    let (first, second) = from_recordings(hidden, 23);
    // Measured: the recordings alone name a q1 reversal of 0.07 µm that cannot be told apart
    // from this tilt; the proposed motions tell them apart.
    assert_not_misnamed(&first, "axis tilt q3 toward link y");
    assert_named(second.as_ref().unwrap_or(&first), &["axis tilt q3 toward link y"], 1.0, false);
}

/// A q1 scale of 500 ppm, 0.6 of the candidate's typical size: after the proposed motions the
/// diagnosis names nothing (it stays under the naming threshold), and must not read as "absent":
/// the size it rules out for that candidate lies above the hidden one.
#[test]
fn another_simulators_q1_scale_too_small_to_name_is_bounded_above_its_size() {
    let hidden = Hidden { joint_scale_ppm: [500.0, 0.0, 0.0], ..Hidden::default() };
    let (first, second) = from_recordings(hidden, 24);
    let v = second.as_ref().unwrap_or(&first);
    assert_eq!(v["verdict"], "none", "{v}");
    let bound = v["ruled_out_above"]
        .as_array()
        .unwrap()
        .iter()
        .find(|b| b["name"] == "joint scale error q1")
        .unwrap_or_else(|| panic!("no bound for the q1 scale: {}", v["ruled_out_above"]));
    let below = bound["below"].as_f64().unwrap();
    println!("the q1 scale is ruled out above {below:.0} ppm");
    assert!(below > 500.0, "the q1 scale ruled out above {below} ppm, under the hidden 500 ppm: {bound}");
    assert_eq!(bound["unit"], "ppm");
}

/// A q4 pivot offset of 15 µm along its own frame's x (Y_w at q = 0). The calibration, whose model
/// lacks it, chooses the mirrored branch and is refused; the recordings alone name the pivot on
/// the other branch. The proposed motions (q4, q5 and q6 turns) show the calibration's branch
/// 17σ off, so the second pass starts where the first ended and names the pivot again (measured
/// on seed 301: 15 µm read as 14.9 ± 0.5 µm; started from the calibration's branch, twelve wrong
/// effects were tried in half an hour and the verdict was "unexplained" at 12σ).
#[test]
fn another_simulators_hidden_q4_pivot_is_named_again_after_the_proposed_motions() {
    let hidden = Hidden { pivot_offset_um: [[15.0, 0.0, 0.0], [0.0; 3]], ..Hidden::default() };
    let (first, second) = from_recordings(hidden, 301);
    let names = ["pivot offset q4 along Y_w", "pivot offset q5 along Y_w"];
    assert_named(&first, &names, 15.0, true);
    let second = second.expect("the recordings alone propose motions");
    assert_named(&second, &names, 15.0, true);
    assert!(second["warnings"].to_string().contains("refused"), "{second}");
}

/// Recordings made with the two-beam optics (a fringe unlike the model's: the calibration
/// refuses every one, and clean ones end `unexplained` with nothing named), the q4 zero offset
/// of 0.07° hidden: after the proposed motions the diagnosis keeps that offset, within 3σ, as
/// the part of the residual it explains (held-out motions 14.7σ → 2.0σ), names nothing else, and
/// leaves the rest unexplained rather than bending another effect to it.
#[test]
fn under_optics_unlike_the_models_a_hidden_q4_zero_offset_is_kept_and_the_rest_left_open() {
    use photorobot_e2e::independent::OpticsModel;
    use photorobot_e2e::recordings::independent_loop_with;
    let hidden = Hidden { joint_offset: [0.0, 0.0, 0.0, 0.07, 0.0, 0.0], ..Hidden::default() };
    let passes = independent_loop_with(&OpticsModel::TwoBeam(Default::default()), hidden, 301, 2);
    let last = passes.last().unwrap();
    assert_eq!(passes.len(), 2, "motions proposed after the recordings: {}", passes[0]);
    assert_eq!(last["verdict"], "unexplained", "{last}");
    assert!(last["effects"].as_array().unwrap().is_empty(), "{last}");
    let kept = last["partial"].as_array().unwrap();
    assert_eq!(kept.len(), 1, "only the hidden offset kept: {last}");
    assert_eq!(kept[0]["name"], "joint zero offset q4", "{last}");
    let (est, sigma) = (kept[0]["estimate"].as_f64().unwrap(), kept[0]["sigma"].as_f64().unwrap());
    assert!((est - 0.07).abs() <= 3.0 * sigma, "{est} ± {sigma}°, hidden 0.07°");
    // The residual it leaves is the optics' misfit, as on clean two-beam recordings (6.2-6.4σ).
    let after = last["residual_rms_after_sigma"].as_f64().unwrap();
    assert!(after < 7.0, "residual {after}σ with the offset kept");
    // Where: the offset explains the gap changes (measured 17.6σ → 1.4σ on translations,
    // 16.6σ → 2.1σ on rotations); the fringe amplitudes, which the coupling law of these optics
    // shapes, stay where they were (6.7σ) and are the family furthest off.
    let family = |name: &str| {
        let f = last["residual_by_family"].as_array().unwrap().iter().find(|f| f["family"] == name).cloned();
        let f = f.unwrap_or_else(|| panic!("no {name} in {last}"));
        (f["before_sigma"].as_f64().unwrap(), f["after_sigma"].as_f64().unwrap())
    };
    for name in ["translations", "rotations"] {
        let (before, after) = family(name);
        eprintln!("{name}: {before:.2}σ → {after:.2}σ");
        assert!(after < before / 4.0 && after < 3.0, "{name}: {before}σ → {after}σ");
    }
    let (before, after) = family("fringe_amplitudes");
    eprintln!("fringe amplitudes: {before:.2}σ → {after:.2}σ");
    assert!(after > 4.0 && after > 0.9 * before, "fringe amplitudes: {before}σ → {after}σ");
    let worst = last["residual_by_family"].as_array().unwrap().iter().map(|f| f["after_sigma"].as_f64().unwrap());
    assert_eq!(worst.fold(0.0, f64::max), after, "the amplitudes furthest off: {last}");
}
