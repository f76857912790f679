//! Fuzzing of every file format and reply the program reads: the shipped RON files (plan, robot,
//! bench preset, extrinsics, hardware bench, column mapping) mutated at random (bytes deleted,
//! inserted or replaced, numbers swapped for extreme ones, the text cut short), and arbitrary
//! SmarAct MCS reply lines. Each must parse or fail with an error naming the file: never panic.
//! A bench preset that parses must also build a virtual bench or say why it cannot.
//!
//! 1000 cases per format here; more with `PROPTEST_CASES=10000 cargo test -p photorobot-core
//! --test fuzz_parsers`. A failing case is kept in `proptest-regressions/` and replayed first.

use photorobot_core::bench::{BenchPreset, VirtualBench};
use photorobot_core::hardware::controller_bench::HardwareConfig;
use photorobot_core::hardware::smaract::parse_reply;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::robot::RobotDescription;
use photorobot_core::plan::Plan;
use photorobot_core::trace::import::ColumnMapping;
use proptest::prelude::*;
use std::path::Path;

const ASSETS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../assets");

fn asset(path: &str) -> String {
    std::fs::read_to_string(Path::new(ASSETS).join(path)).unwrap()
}

/// The column mapping `bad_inputs.rs` reads foreign traces with.
const MAPPING: &str = include_str!("fixtures/foreign-mapping.ron");

/// One edit of a text.
#[derive(Debug, Clone)]
enum Edit {
    Delete {
        at: usize,
        len: usize,
    },
    Insert {
        at: usize,
        text: String,
    },
    /// The `nth` number in the text replaced.
    Number {
        nth: usize,
        with: &'static str,
    },
    Truncate {
        at: usize,
    },
}

fn edit() -> impl Strategy<Value = Edit> {
    let numbers = prop::sample::select(vec![
        "0",
        "-0",
        "1e308",
        "-1e308",
        "NaN",
        "inf",
        "-inf",
        "1e-320",
        "-1",
        "999999999999999999999",
        "0.0",
        "-5",
    ]);
    prop_oneof![
        (any::<usize>(), 1usize..40).prop_map(|(at, len)| Edit::Delete { at, len }),
        (any::<usize>(), "[(){}\\[\\],:\"a-z0-9 .\\-]{1,12}|\\PC{1,4}")
            .prop_map(|(at, text)| Edit::Insert { at, text }),
        (any::<usize>(), numbers).prop_map(|(nth, with)| Edit::Number { nth, with }),
        any::<usize>().prop_map(|at| Edit::Truncate { at }),
    ]
}

/// The nearest char boundary at or below `at % (len + 1)`.
fn boundary(s: &str, at: usize) -> usize {
    let mut i = at % (s.len() + 1);
    while !s.is_char_boundary(i) {
        i -= 1;
    }
    i
}

/// The text with every edit applied in turn, each at a char boundary.
fn apply(text: &str, edits: &[Edit]) -> String {
    let mut mutated = text.to_string();
    for edit in edits {
        match edit {
            Edit::Delete { at, len } => {
                let a = boundary(&mutated, *at);
                let b = boundary(&mutated, (a + len).min(mutated.len()));
                if b > a {
                    mutated.replace_range(a..b, "");
                }
            }
            Edit::Insert { at, text } => {
                let a = boundary(&mutated, *at);
                mutated.insert_str(a, text);
            }
            Edit::Number { nth, with } => {
                let spans: Vec<(usize, usize)> = number_spans(&mutated);
                if !spans.is_empty() {
                    let (a, b) = spans[nth % spans.len()];
                    mutated.replace_range(a..b, with);
                }
            }
            Edit::Truncate { at } => {
                let a = boundary(&mutated, *at);
                mutated.truncate(a);
            }
        }
    }
    mutated
}

/// Byte spans of the decimal numbers in `s`.
fn number_spans(s: &str) -> Vec<(usize, usize)> {
    let b = s.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i].is_ascii_digit() {
            let start = i;
            while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.' || b[i] == b'e' || b[i] == b'-') {
                i += 1;
            }
            out.push((start, i));
        } else {
            i += 1;
        }
    }
    out
}

/// 1000 cases, or `PROPTEST_CASES`.
fn config() -> ProptestConfig {
    ProptestConfig::with_cases(std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(1000))
}

/// An error names the file it came from.
fn names_the_file<E: std::fmt::Display>(r: Result<impl Sized, E>, file: &str) -> Result<(), TestCaseError> {
    if let Err(e) = r {
        let msg = e.to_string();
        prop_assert!(msg.contains(file), "error does not name {file}: {msg}");
    }
    Ok(())
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn mutated_plans_parse_or_fail_clearly(edits in prop::collection::vec(edit(), 1..6)) {
        let text = apply(&asset("plans/strategy2.ron"), &edits);
        names_the_file(Plan::from_ron_str(&text, Path::new("fuzz-plan.ron")), "fuzz-plan.ron")?;
    }

    #[test]
    fn mutated_robots_parse_or_fail_clearly(edits in prop::collection::vec(edit(), 1..6)) {
        let text = apply(&asset("robots/femto-6dof.ron"), &edits);
        names_the_file(RobotDescription::from_ron_str(&text, Path::new("fuzz-robot.ron")), "fuzz-robot.ron")?;
    }

    #[test]
    fn mutated_presets_parse_and_build_or_fail_clearly(edits in prop::collection::vec(edit(), 1..6)) {
        let text = apply(&asset("benches/femto-lab.ron"), &edits);
        let parsed = BenchPreset::from_ron_str(&text, Path::new("fuzz-bench.ron"));
        if let Ok(preset) = &parsed {
            // Building the bench (robot, optics, detector, motion) refuses what it cannot use.
            let _ = VirtualBench::new(preset, Some(1));
        }
        names_the_file(parsed, "fuzz-bench.ron")?;
    }

    #[test]
    fn mutated_extrinsics_parse_or_fail_clearly(edits in prop::collection::vec(edit(), 1..6)) {
        let text = apply(&asset("extrinsics/table2.ron"), &edits);
        let parsed = Extrinsics::from_ron_str(&text, Path::new("fuzz-extrinsics.ron"));
        if let Ok(e) = &parsed {
            prop_assert!(e.to_array().iter().all(|v| v.is_finite()), "accepted a non-finite value: {e:?}");
        }
        names_the_file(parsed, "fuzz-extrinsics.ron")?;
    }

    #[test]
    fn mutated_hardware_benches_parse_or_fail_clearly(edits in prop::collection::vec(edit(), 1..6)) {
        let text = apply(&asset("benches/femto-hardware.ron"), &edits);
        names_the_file(HardwareConfig::from_ron_str(&text, Path::new("fuzz-hw.ron")), "fuzz-hw.ron")?;
    }

    #[test]
    fn mutated_column_mappings_parse_or_fail_clearly(edits in prop::collection::vec(edit(), 1..6)) {
        let text = apply(MAPPING, &edits);
        names_the_file(ColumnMapping::from_ron_str(&text, Path::new("fuzz-mapping.ron")), "fuzz-mapping.ron")?;
    }

    #[test]
    fn any_smaract_reply_parses_or_is_refused(line in "\\PC{0,24}|:[A-Z]{1,3}[-0-9,]{0,16}") {
        let _ = parse_reply(&line);
    }
}
