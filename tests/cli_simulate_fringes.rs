//! End to end: `photorobot simulate` writes CSV traces from a plan on a bench preset, and
//! `photorobot fringes` reads one back and measures dL (or the gap of a sweep).

use photorobot_app::cli::{run, CliError, Outcome};

fn cli(args: &[&str]) -> Result<String, CliError> {
    let mut out = Vec::new();
    let mut argv = vec!["photorobot"];
    argv.extend_from_slice(args);
    assert_eq!(run(argv, &mut out)?, Outcome::Done);
    Ok(String::from_utf8(out).unwrap())
}

const PLAN: &str = r#"Plan(
    name: "axial and sweep",
    description: "a 20 µm move along the beam, then a 40 nm sweep",
    segments: [
        Move(to: (q2_um: -10.0), record: false, label: "start"),
        Move(to: (q2_um: 10.0), label: "Y_w +20 um"),
        Sweep(from_nm: 1540.0, to_nm: 1580.0, rate_nm_per_s: 100.0, label: "sweep"),
    ],
)"#;

#[test]
fn simulate_then_measure_a_move_and_a_sweep() {
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("plan.ron");
    std::fs::write(&plan, PLAN).unwrap();
    let out = dir.path().join("traces");
    let text = cli(&[
        "simulate",
        "--bench",
        "table2-ideal",
        "--plan",
        plan.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--seed",
        "4",
    ])
    .unwrap();
    assert!(text.contains("2 traces"), "{text}");
    let mut files: Vec<_> = std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    assert_eq!(files.len(), 2);
    let header = std::fs::read_to_string(&files[0]).unwrap();
    assert!(header.lines().any(|l| l == "t_s,q1_um,q2_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,irradiance"));

    let json = cli(&["fringes", files[0].to_str().unwrap(), "--json"]).unwrap();
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["kind"], "motion");
    // +q2 brings the lamella 20 µm toward the fiber: the gap shrinks by about 20 µm × cos γ.
    let dl = v["dl_um"].as_f64().unwrap();
    assert!((dl + 20.0).abs() < 0.05, "dL = {dl} µm");
    assert!(v["sigma_um"].as_f64().unwrap() < 0.005);
    // 20 µm is 2·n·20/1.56 = 25.6 fringes, i.e. 51 extrema (λ/4 steps).
    let count = v["fringe_count"].as_i64().unwrap();
    assert!((-52..=-50).contains(&count), "{count} λ/4 steps: {json}");
    assert!((v["count_dl_um"].as_f64().unwrap() - dl).abs() < 0.39, "counting within one step of tracking");

    let text = cli(&["fringes", files[1].to_str().unwrap()]).unwrap();
    assert!(text.contains("is a wavelength sweep"), "{text}");
    // The sweep runs after the move, at q2 = +10 µm: 10 µm less than the 898.66 µm at q = 0.
    assert!(text.contains("absolute gap: 888.66"), "{text}");

    let text = cli(&["fringes", files[0].to_str().unwrap(), "--temperature-c", "25"]).unwrap();
    assert!(text.contains("phase tracking: dL = "), "{text}");
}

#[test]
fn simulate_refuses_bad_inputs_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("t");
    let e =
        cli(&["simulate", "--bench", "no-such", "--plan", "strategy2", "--out", out.to_str().unwrap()]).unwrap_err();
    assert!(
        e.to_string().contains("not an embedded preset (expected one of: table2-ideal, femto-lab, hidden-pivot)"),
        "{e}"
    );
    let bad_plan = dir.path().join("bad.ron");
    std::fs::write(&bad_plan, PLAN.replace("q2_um: 10.0", "q2_um: 400.0")).unwrap();
    let e = cli(&[
        "simulate",
        "--bench",
        "table2-ideal",
        "--plan",
        bad_plan.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ])
    .unwrap_err()
    .to_string();
    assert!(e.contains("q2 = 400.000 µm is 250.000 µm above its upper limit 150.000 µm"), "{e}");
    assert!(!out.exists() || std::fs::read_dir(&out).unwrap().next().is_none(), "nothing recorded, nothing moved");
    let e = cli(&[
        "simulate",
        "--bench",
        "table2-ideal",
        "--plan",
        "strategy2",
        "--out",
        dir.path().join("one.csv").to_str().unwrap(),
    ])
    .unwrap_err()
    .to_string();
    assert!(e.contains("give a directory"), "{e}");
}

#[test]
fn fringes_refuses_a_bad_trace_with_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.csv");
    std::fs::write(&p, "t_s,q1_um,q2_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,irradiance\n0,0,0,0,0,0,0,1560,0.1\n0,0,0,0,0,0,0,1560,NaN\n").unwrap();
    let e = cli(&["fringes", p.to_str().unwrap()]).unwrap_err().to_string();
    assert!(e.contains("bad.csv:3"), "{e}");
}
