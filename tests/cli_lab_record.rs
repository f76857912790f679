//! End to end: `photorobot calibrate` with the lab-record flags writes the operator, the ambient
//! conditions, the start time and the virtual bench's identification into session.ron, and
//! `photorobot report` shows them; an out-of-range value is refused with exit code 2 and a message
//! naming the flag and the range.

use photorobot_app::cli::{run, Outcome};
use photorobot_core::session::Session;

const PLAN: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/small-plan.ron");

fn args(extra: &[&str], out: &str) -> Vec<String> {
    let base = ["photorobot", "calibrate", "--bench", "table2-ideal", "--seed", "7", "--plan", PLAN, "--out", out];
    base.iter().chain(extra).map(|s| s.to_string()).collect()
}

#[test]
fn calibrate_records_the_lab_record_in_the_session_and_the_report() {
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("session");
    let out = dir.display().to_string();
    let lab = [
        "--operator",
        "Ada Lovelace",
        "--ambient-temperature-c",
        "-2.5",
        "--pressure-hpa",
        "987.6",
        "--humidity-percent",
        "41",
    ];
    let mut printed = Vec::new();
    // The short plan may not determine every parameter: the session is written either way.
    let outcome = run(args(&lab, &out), &mut printed);
    assert!(matches!(outcome, Ok(Outcome::Done)) || dir.join("session.ron").exists(), "{:?}", outcome.err());
    let session = Session::load(&dir).unwrap();
    assert_eq!(session.lab.operator.as_deref(), Some("Ada Lovelace"));
    assert_eq!(session.lab.ambient_temperature_c, Some(-2.5));
    assert_eq!(session.lab.pressure_hpa, Some(987.6));
    assert_eq!(session.lab.relative_humidity_percent, Some(41.0));
    let at = session.lab.measured_at_utc.clone().expect("the start time is recorded");
    assert!(at.len() == 20 && at.ends_with('Z') && at.as_bytes()[10] == b'T', "{at}");
    assert_eq!(session.lab.controllers.len(), 1);
    assert!(session.lab.controllers[0].identification.contains("virtual bench table2-ideal"));
    let text = std::fs::read_to_string(dir.join("session.ron")).unwrap();
    assert!(text.contains("operator: Some(\"Ada Lovelace\")"), "{text}");
    // The printed fit lists every start tried with how it stands, as the session's verdict says.
    let printed = String::from_utf8(printed).unwrap();
    let fit = session.calibration.as_ref().and_then(|c| c.fit.clone()).expect("a verdict");
    let lines: Vec<&str> = printed.lines().filter(|l| l.trim_start().starts_with("branch from")).collect();
    assert_eq!(lines.len(), fit.branches.len(), "{printed}");
    for (k, line) in lines.iter().enumerate() {
        assert!(line.contains(&format!(" σ  {} ", fit.standing(k).word())), "{line}");
    }
    assert!(lines[0].contains(" σ  chosen "), "{printed}");

    let html = root.path().join("report.html");
    let argv = ["photorobot", "report", &out, "--out", &html.display().to_string()];
    assert_eq!(run(argv.iter().map(|s| s.to_string()), &mut Vec::new()).unwrap(), Outcome::Done);
    let html = std::fs::read_to_string(html).unwrap();
    for want in ["Lab record", "Ada Lovelace", "-2.50 °C", "987.60 hPa", "41.0 %", at.as_str(), "n_air"] {
        assert!(html.contains(want), "the report lacks {want}");
    }
}

#[test]
fn out_of_range_lab_values_exit_2_naming_the_flag_and_the_range() {
    let root = tempfile::tempdir().unwrap();
    let out = root.path().join("s").display().to_string();
    for (flag, value, range) in [
        ("--humidity-percent", "140", "0 to 100 %"),
        ("--pressure-hpa", "20", "500 to 1100 hPa"),
        ("--ambient-temperature-c", "-80", "-40 to 60 °C"),
        ("--humidity-percent", "wet", "expected a number"),
    ] {
        let e = run(args(&[flag, value], &out), &mut Vec::new()).expect_err(flag);
        assert_eq!(e.exit_code(), 2, "{flag} {value}");
        let msg = e.to_string();
        assert!(msg.contains(flag) && msg.contains(value) && msg.contains(range), "{msg}");
        assert!(!root.path().join("s").exists(), "nothing written for {flag} {value}");
    }
}
