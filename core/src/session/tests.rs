use super::*;
use crate::files;
use crate::trace::{Trace, TraceMeta};
use proptest::prelude::*;
use std::path::Path;

fn small_trace(label: &str, n: usize) -> Trace {
    let mut t = Trace::new(TraceMeta { label: label.into(), ..TraceMeta::default() });
    for i in 0..n {
        let x = i as f64;
        t.push_sample(x * 1e-3, [x * 0.1, 0.0, -3.0, 0.01 * x, 0.0, 0.0], 1560.0, 0.5 + 0.1 * (x * 0.3).sin());
    }
    t
}

/// A session with everything but a calibration (that one needs an identification: tested end to end).
pub(crate) fn sample_session(dir: &Path) -> Session {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let bench = BenchInfo {
        name: "virtual bench table2-ideal".into(),
        preset: Some("table2-ideal".into()),
        description: Some(preset.clone()),
        seed: Some(7),
    };
    let mut s = Session::new(bench, preset.robot_description().unwrap());
    s.plans = vec![Plan::strategy1()];
    s.add_trace(dir, &small_trace("first", 20), Some((0, 1)), true).unwrap();
    s.add_trace(dir, &small_trace("second: partial", 7), Some((0, 3)), false).unwrap();
    s.progress = Some(Progress { plan: 0, next_segment: 4, plan_start_display: [0.0, 0.0, -150.0, 0.0, 0.0, 0.0] });
    s.diagnosis = Some(DiagnosisRecord {
        effects: vec![EffectFinding {
            name: "joint-4 pivot offset along Y_w".into(),
            estimate: 19.7,
            unit: "µm".into(),
            sigma: Some(0.4),
            score: 812.0,
            score_kind: "ΔBIC".into(),
            absorbed_fraction: Some(0.2),
            note: String::new(),
        }],
        verdict: "residual at the noise floor after adding the joint-4 pivot offset".into(),
        // The extended model and its validation survive the round trip.
        model_effects: vec![crate::model::effects::Effect::PivotOffset {
            joint: "q4".into(),
            offset_world_um: [0.0, 19.7, 0.0],
        }],
        extrinsics: Some(crate::model::extrinsics::Extrinsics::nominal_design()),
        validation: vec![crate::diagnose::validation::EffectValidationRow {
            motion: "rotation 6° about X_f through P_r".into(),
            without_effect_nm: Some(310.0),
            with_effect_nm: Some(9.5),
            note: None,
            without_curve_nm: vec![0.0, 150.0, 310.0],
            with_curve_nm: vec![0.0, 4.0, 9.5],
        }],
    });
    s.notes = "lamella LiNbO₃ #12\nroom 20.3 °C".into();
    s
}

#[test]
fn save_load_round_trips_and_removes_the_autosave() {
    let dir = tempfile::tempdir().unwrap();
    let s = sample_session(dir.path());
    s.autosave(dir.path()).unwrap();
    assert_eq!(find_recovery(dir.path()).unwrap().unwrap().traces, 2);
    s.save(dir.path()).unwrap();
    assert!(!autosave_path(dir.path()).exists(), "saving removes the autosave");
    assert_eq!(find_recovery(dir.path()).unwrap(), None);
    let back = Session::load(dir.path()).unwrap();
    assert_eq!(back, s);
    // Only complete traces are used; both are kept and checked.
    let traces = back.load_traces(dir.path()).unwrap();
    assert_eq!(traces.len(), 1);
    assert_eq!(traces[0], small_trace("first", 20));
    assert_eq!(back.load_trace(dir.path(), &back.traces[1]).unwrap().len(), 7);
    let text = std::fs::read_to_string(session_path(dir.path())).unwrap();
    assert!(text.contains("format_version: 1"), "{text}");
}

#[test]
fn a_changed_or_truncated_trace_is_refused_with_its_reference() {
    let dir = tempfile::tempdir().unwrap();
    let s = sample_session(dir.path());
    let path = dir.path().join(&s.traces[0].file);
    let mut bytes = std::fs::read(&path).unwrap();
    // Same length, one digit changed.
    let k = bytes.len() - 3;
    bytes[k] = if bytes[k] == b'1' { b'2' } else { b'1' };
    std::fs::write(&path, &bytes).unwrap();
    let err = s.load_traces(dir.path()).unwrap_err().to_string();
    assert!(err.contains("000.csv: field `traces[0]`: CRC-32") && err.contains("expected"), "{err}");
    bytes.truncate(bytes.len() / 2);
    std::fs::write(&path, &bytes).unwrap();
    let err = s.load_traces(dir.path()).unwrap_err().to_string();
    assert!(err.contains(&format!("{} bytes, expected {}", bytes.len(), s.traces[0].bytes)), "{err}");
}

#[test]
fn trace_references_must_stay_inside_the_traces_folder() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = sample_session(dir.path());
    for bad in ["../x.csv", "/etc/passwd", "traces/../../x.csv", "traces/a/b.csv", "traces/x.txt", "traces\\x.csv"] {
        s.traces[0].file = bad.into();
        let err = s.validate().unwrap_err().to_string();
        assert!(err.starts_with("field `traces[0].file`: expected a path `traces/<name>.csv`"), "{bad}: {err}");
    }
}

#[test]
fn a_folder_from_before_sessions_is_refused_with_what_to_do() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("report.json"), "{}").unwrap();
    let err = Session::load(dir.path()).unwrap_err().to_string();
    assert!(err.contains("written by a photorobot from before sessions"), "{err}");
    assert!(err.contains("photorobot calibrate --traces"), "{err}");
}

/// Mutations of a valid session text in the fuzz test.
fn mutate(text: &str, cuts: &[(usize, usize, u8)]) -> Vec<u8> {
    let mut b = text.as_bytes().to_vec();
    for &(at, len, byte) in cuts {
        if b.is_empty() {
            break;
        }
        let a = at % b.len();
        match byte % 4 {
            0 => {
                let e = (a + len % 12).min(b.len());
                b.drain(a..e);
            }
            1 => b[a] = byte,
            2 => b.truncate(a),
            _ => {
                let tok: &[u8] = match len % 8 {
                    0 => b"(",
                    1 => b")",
                    2 => b"NaN",
                    3 => b"\"",
                    4 => b",",
                    5 => b"format_version: 2,",
                    6 => b"-inf",
                    _ => b"Some(",
                };
                b.splice(a..a, tok.iter().copied());
            }
        }
    }
    b
}

fn check_any(bytes: &[u8]) {
    let text = String::from_utf8_lossy(bytes);
    match Session::from_ron_str(&text, Path::new("fuzz.ron")) {
        Ok(s) => assert!(s.validate().is_ok()),
        Err(e) => assert!(e.to_string().starts_with("fuzz.ron"), "{e}"),
    }
}

thread_local! {
    static VALID: String = {
        let dir = tempfile::tempdir().unwrap();
        files::to_ron_string(&sample_session(dir.path()), Path::new("x")).unwrap()
    };
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn session_parser_never_panics_on_mutated_sessions(cuts in prop::collection::vec((any::<usize>(), any::<usize>(), any::<u8>()), 1..5)) {
        VALID.with(|v| check_any(&mutate(v, &cuts)));
    }

    #[test]
    fn session_parser_never_panics_on_arbitrary_text(text in "[(),:\"a-z_0-9 .\\-\\[\\]{}\n]{0,300}") {
        check_any(format!("Session({text}").as_bytes());
        check_any(text.as_bytes());
    }
}

/// Traces read from files in our format are copied as they are, the recording's own text kept;
/// a file changed since it was read, and an import through a mapping, are written from the
/// traces in memory. Either way the session's traces are those that were read.
#[test]
fn sourced_traces_are_copied_as_recorded_or_written_when_their_file_changed() {
    let src = tempfile::tempdir().unwrap();
    // Text the writer would not produce (a comment, a blank line, CRLF): copied as it is.
    let own = "# photorobot trace v1\n# label: by hand\nt_s,q1_um,q2_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,irradiance\r\n\
               0,0,0,0,0,0,0,1560,0.5\r\n# a comment\n\n0.001,0.1,0,0,0,0,0,1560,0.51\r\n";
    std::fs::write(src.path().join("a.csv"), own).unwrap();
    small_trace("changed after reading", 9).write_csv(&src.path().join("b.csv")).unwrap();
    let read = crate::trace::import::read_folder_sourced(src.path(), None).unwrap();
    assert!(read.files.iter().all(|s| s.native.is_some()));
    small_trace("changed after reading", 12).write_csv(&src.path().join("b.csv")).unwrap();
    let out = tempfile::tempdir().unwrap();
    let bench = BenchInfo { name: "recorded traces".into(), preset: None, description: None, seed: None };
    let mut s = Session::new(bench, BenchPreset::resolve("table2-ideal").unwrap().robot_description().unwrap());
    s.add_sourced_traces(out.path(), &read).unwrap();
    assert_eq!(std::fs::read_to_string(out.path().join(&s.traces[0].file)).unwrap(), own);
    let loaded = s.load_traces(out.path()).unwrap();
    assert_eq!(loaded, read.traces);
    assert_eq!(loaded[1].len(), 9, "the trace that was read, not the file as it is now");
}

/// More files than one group of copies: every file copied, referenced in the order read.
#[test]
fn many_sourced_traces_are_copied_in_groups_in_order() {
    let src = tempfile::tempdir().unwrap();
    for k in 0..300 {
        small_trace(&format!("trace {k}"), 3 + k % 5).write_csv(&src.path().join(format!("{k:04}.csv"))).unwrap();
    }
    let read = crate::trace::import::read_folder_sourced(src.path(), None).unwrap();
    let out = tempfile::tempdir().unwrap();
    let bench = BenchInfo { name: "recorded traces".into(), preset: None, description: None, seed: None };
    let mut s = Session::new(bench, BenchPreset::resolve("table2-ideal").unwrap().robot_description().unwrap());
    s.add_sourced_traces(out.path(), &read).unwrap();
    assert_eq!(s.traces.len(), 300);
    for (k, (reference, file)) in s.traces.iter().zip(&read.files).enumerate() {
        assert_eq!(reference.label, format!("trace {k}"));
        assert_eq!(std::fs::read(out.path().join(&reference.file)).unwrap(), std::fs::read(&file.path).unwrap());
    }
    assert_eq!(s.load_traces(out.path()).unwrap(), read.traces);
}

/// Traces recorded after a session by a recorder whose clock restarted join it on the session's
/// clock: their times move to start a pause after its end, their files are new ones referenced
/// after the session's, and the earlier files and references are untouched; traces whose clock
/// already continues the session's are copied as they are.
#[test]
fn later_traces_join_the_session_on_its_clock() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = sample_session(dir.path());
    s.save(dir.path()).unwrap();
    let before = s.traces.clone();
    let end_s = s.load_traces(dir.path()).unwrap().iter().map(|t| t.t_s[t.len() - 1]).fold(0.0, f64::max);
    let later_dir = dir.path().join("later");
    std::fs::create_dir_all(&later_dir).unwrap();
    small_trace("D q4 -4 -> +4°", 12).write_csv(&later_dir.join("001-a.csv")).unwrap();
    let sourced = crate::trace::import::read_folder_sourced(&later_dir, None).unwrap();
    let shift = s.add_later_traces(dir.path(), sourced, end_s, LATER_PAUSE_S).unwrap();
    assert!((shift - (end_s + LATER_PAUSE_S)).abs() < 1e-12, "a clock from 0 moves to after the end: {shift}");
    s.save(dir.path()).unwrap();
    let again = Session::load(dir.path()).unwrap();
    assert_eq!(&again.traces[..before.len()], &before[..]);
    assert_eq!(again.traces.len(), before.len() + 1);
    let added = again.load_trace(dir.path(), &again.traces[before.len()]).unwrap();
    assert_eq!(added.meta.label, "D q4 -4 -> +4°");
    assert!((added.t_s[0] - (end_s + LATER_PAUSE_S)).abs() < 1e-9, "{}", added.t_s[0]);
    for r in &again.traces {
        assert!(dir.path().join(&r.file).is_file(), "{} kept", r.file);
    }
    // On the session's clock already: copied byte for byte, no shift.
    let mut on_clock = small_trace("later still", 5);
    on_clock.t_s.iter_mut().for_each(|t| *t += 1000.0);
    let onward_dir = dir.path().join("onward");
    std::fs::create_dir_all(&onward_dir).unwrap();
    on_clock.write_csv(&onward_dir.join("a.csv")).unwrap();
    let sourced = crate::trace::import::read_folder_sourced(&onward_dir, None).unwrap();
    let mut s = again;
    assert_eq!(s.add_later_traces(dir.path(), sourced, end_s, LATER_PAUSE_S).unwrap(), 0.0);
    let r = s.traces.last().unwrap();
    assert_eq!(std::fs::read(dir.path().join(&r.file)).unwrap(), std::fs::read(onward_dir.join("a.csv")).unwrap());
}
