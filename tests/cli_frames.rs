//! End to end: `photorobot frames` from the command line to printed numbers, text and JSON.

use photorobot_app::cli::{run, CliError, Outcome};

fn frames(args: &[&str]) -> Result<String, CliError> {
    let mut out = Vec::new();
    let mut argv = vec!["photorobot", "frames"];
    argv.extend_from_slice(args);
    assert_eq!(run(argv, &mut out)?, Outcome::Done);
    Ok(String::from_utf8(out).unwrap())
}

#[test]
fn no_arguments_starts_the_gui() {
    let mut out = Vec::new();
    assert_eq!(run(["photorobot"], &mut out).unwrap(), Outcome::StartGui);
    assert!(out.is_empty());
}

#[test]
fn text_output_at_zero_gives_the_spec_cavity() {
    let text = frames(&[]).unwrap();
    assert!(text.contains("signed cavity length L = -898.830 µm (gap |L| = 898.830 µm)"), "{text}");
    assert!(text.contains("reflection point P_r in world = (104.243, 1.280, 101.818) µm"), "{text}");
    for name in
        ["world", "link 1 (q1)", "link 6 (q6)", "end effector", "tool (lamella)", "fiber", "reflection point P_r"]
    {
        assert!(text.contains(name), "missing frame {name}:\n{text}");
    }
}

#[test]
fn json_output_at_a_general_pose() {
    let text = frames(&["--q", "10,-20,30,1,-2,3", "--json"]).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let l = v["cavity_length_um"].as_f64().unwrap();
    assert!((l - -923.295).abs() < 1e-3, "L = {l}");
    assert_eq!(v["frames"].as_array().unwrap().len(), 11);
    assert_eq!(v["q"][3]["unit"], "°");
    assert_eq!(v["q"][0]["unit"], "µm");
    let tool_z = v["reflection_point_tool_um"][2].as_f64().unwrap();
    assert!(tool_z.abs() < 1e-9);
}

#[test]
fn extrinsics_file_is_used() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("e.ron");
    let text = photorobot_core::model::extrinsics::TABLE2_RON.replace("y_wf_um: 900.0", "y_wf_um: 500.0");
    std::fs::write(&path, text).unwrap();
    let out = frames(&["--extrinsics", path.to_str().unwrap(), "--json"]).unwrap();
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(v["gap_um"].as_f64().unwrap() < 500.0);
}

#[test]
fn bad_inputs_give_clear_errors() {
    let e = frames(&["--q", "1,2,3"]).unwrap_err().to_string();
    assert_eq!(e, "argument --q: expected 6 comma-separated joint values (q1,q2,q3,q4,q5,q6), found 3");
    let e = frames(&["--q", "0,0,0,0,0,200"]).unwrap_err().to_string();
    assert_eq!(e, "argument --q: joint q6 = 200.000 ° is 20.000 ° above its upper limit 180.000 °");
    let e = frames(&["--q", "0,0,0,0,0,NaN"]).unwrap_err().to_string();
    assert_eq!(e, "argument --q: joint q6 must be a finite number, found NaN");
    let e = frames(&["--extrinsics", "/nonexistent/e.ron"]).unwrap_err().to_string();
    assert!(e.starts_with("/nonexistent/e.ron: cannot read"), "{e}");
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.ron");
    std::fs::write(&bad, "Extrinsics(x_wf_um: 1.0)").unwrap();
    let e = frames(&["--extrinsics", bad.to_str().unwrap()]).unwrap_err().to_string();
    assert!(e.contains("bad.ron:1:") && e.contains("y_wf_um"), "{e}");
    assert!(matches!(frames(&["--q", "a,b"]), Err(CliError::Usage(_))));
}
