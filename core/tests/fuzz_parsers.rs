//! Fuzzing of every file format, reply and command the program or its emulators read: the shipped
//! RON files (plan, robot, bench preset, extrinsics, hardware bench, column mapping), a session file
//! and a trace CSV mutated at random (text deleted, inserted or cut short, numbers swapped for
//! extreme ones, bytes flipped or replaced by non-UTF-8 ones); the PI GCS and SmarAct MCS replies
//! of a recorded exchange mutated the same way; and the commands of that exchange sent to the PI
//! and MCS emulators. Each must parse or fail with an error naming the file (or the controller and
//! command): never panic. A bench preset that parses must also build a virtual bench or say why not.
//!
//! 1000 cases per parser here (a few seconds); the deep run is 10 000 per parser:
//! `PROPTEST_CASES=10000 cargo test -p photorobot-core --test fuzz_parsers`. A failing
//! case is kept in `proptest-regressions/` and replayed first.

use photorobot_core::bench::{BenchPreset, VirtualBench};
use photorobot_core::hardware::controller_bench::HardwareConfig;
use photorobot_core::hardware::emulator::{
    EmuClock, PiEmulator, PiEmulatorConfig, SmarActEmulator, SmarActEmulatorConfig,
};
use photorobot_core::hardware::pi_replies as replies;
use photorobot_core::hardware::smaract::{angle_from_mcs, parse_reply, McsReply};
use photorobot_core::hardware::HwError;
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::robot::RobotDescription;
use photorobot_core::plan::Plan;
use photorobot_core::session::Session;
use photorobot_core::trace::import::ColumnMapping;
use photorobot_core::trace::Trace;
use proptest::prelude::*;
use std::path::Path;
use std::sync::OnceLock;

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
        "4294967296",
        "9223372036854775808",
        "-9223372036854775809",
        "18446744073709551616",
        "1e999",
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

/// One edit of the bytes, after the text edits: what a noisy line or a foreign file brings.
#[derive(Debug, Clone)]
enum ByteEdit {
    /// XOR one byte with a mask.
    Flip { at: usize, mask: u8 },
    /// Bytes inserted, often ≥ 0x80 (not UTF-8 on their own).
    Insert { at: usize, bytes: Vec<u8> },
}

fn byte_edit() -> impl Strategy<Value = ByteEdit> {
    prop_oneof![
        (any::<usize>(), 1u8..=255).prop_map(|(at, mask)| ByteEdit::Flip { at, mask }),
        (any::<usize>(), prop::collection::vec(prop_oneof![0x80u8..=0xff, any::<u8>()], 1..5))
            .prop_map(|(at, bytes)| ByteEdit::Insert { at, bytes }),
    ]
}

/// Text edits then byte edits: the mutated bytes (possibly not UTF-8).
fn mutate(text: &str, edits: &[Edit], byte_edits: &[ByteEdit]) -> Vec<u8> {
    let mut bytes = apply(text, edits).into_bytes();
    for edit in byte_edits {
        match edit {
            ByteEdit::Flip { at, mask } => {
                if !bytes.is_empty() {
                    let i = at % bytes.len();
                    bytes[i] ^= mask;
                }
            }
            ByteEdit::Insert { at, bytes: b } => {
                let i = at % (bytes.len() + 1);
                bytes.splice(i..i, b.iter().copied());
            }
        }
    }
    bytes
}

/// Text and byte edits of a seed: up to 5 text edits and up to 3 byte edits (at least one in all).
fn edits() -> impl Strategy<Value = (Vec<Edit>, Vec<ByteEdit>)> {
    (prop::collection::vec(edit(), 0..5), prop::collection::vec(byte_edit(), 0..3))
        .prop_filter("at least one edit", |(e, b)| !e.is_empty() || !b.is_empty())
}

/// What a line reader makes of received bytes (the links decode replies this way).
fn lossy(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A valid trace file with an extra column.
const TRACE: &str = "# photorobot trace v1\n\
t_s,q1_um,q2_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,irradiance,temp_C\n\
0,0,0,0,0,0,0,1560,0.5,21.5\n0.1,1.5,0,0,0,0,0,1560.001,0.45,21.5\n0.2,3,0,0,0,0,0,1560.002,0.4,21.6\n";

/// A valid session with a plan, as RON text.
fn session_text() -> String {
    use photorobot_core::session::{BenchInfo, Session};
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let info = BenchInfo {
        name: "virtual bench".into(),
        preset: Some("table2-ideal".into()),
        description: None,
        seed: Some(1),
    };
    let mut session = Session::new(info, preset.robot_description().unwrap());
    session.plans = vec![Plan::strategy2()];
    session.notes = "aligned at 21 °C".into();
    photorobot_core::files::to_ron_string(&session, Path::new("session.ron")).unwrap()
}

/// The commands (`> `) and replies (`< `) of a recorded controller exchange.
fn exchange(transcript: &str) -> (Vec<String>, Vec<String>) {
    let pick = |p: &str| transcript.lines().filter_map(|l| l.strip_prefix(p)).map(str::to_string).collect();
    (pick("> "), pick("< "))
}

const PI_EXCHANGE: &str = include_str!("fixtures/pi_session.txt");
const MCS_EXCHANGE: &str = include_str!("fixtures/smaract_session.txt");

/// A `DRR?` data block of two tables, as the E-712 sends it.
const DRR_BLOCK: &str = "# REM E-712\n# VERSION = 1\n# DIM = 2\n# SAMPLE_TIME = 0.0005\n# NDATA = 3\n\
# NAME0 = Actual Position of 2\n# END_HEADER\n150.000000000 1.0e-1\n150.5 2.0e-1\n151.000000000 -3.0e-1";

/// The PI reply parsers on one mutated reply (its lines split as the driver reads them).
fn pi_parsers_refuse_or_accept(reply: &str) -> Result<(), TestCaseError> {
    let lines: Vec<String> = reply.split('\n').map(|l| l.trim_end().to_string()).collect();
    let ids = ["1".to_string(), "2".to_string()];
    let named = |r: Result<(), HwError>, command: &str| -> Result<(), TestCaseError> {
        if let Err(e) = r {
            let msg = e.to_string();
            prop_assert!(msg.starts_with("pi") && msg.contains(command), "error does not name pi and {command}: {msg}");
        }
        Ok(())
    };
    named(replies::identity("pi", &lines).map(drop), "*IDN?")?;
    named(replies::axis_ids("pi", &lines).map(drop), "SAI?")?;
    named(replies::error_code("pi", &lines).map(drop), "ERR?")?;
    let per_axis = replies::per_axis("pi", "POS? 1 2", &lines, &ids);
    if let Ok(values) = &per_axis {
        named(replies::flags("pi", "ONT?", values).map(drop), "ONT?")?;
    }
    named(per_axis.map(drop), "POS? 1 2")?;
    named(replies::count("pi", "DRL?", &lines).map(drop), "DRL?")?;
    named(replies::input_value("pi", "TSP? 5", &lines).map(drop), "TSP? 5")?;
    let block = replies::data_block("pi", "DRR? 1 3 1 2", &lines, 2);
    if let Ok(columns) = &block {
        prop_assert!(columns.iter().flatten().all(|v| v.is_finite()), "accepted a non-finite sample: {columns:?}");
        prop_assert!(columns.len() == 2 && columns[0].len() == columns[1].len(), "ragged columns: {columns:?}");
    }
    named(block.map(drop), "DRR? 1 3 1 2")
}

/// One PI and one MCS emulator for all cases (slow clock: the recorder stays small).
fn emulators() -> &'static (PiEmulator, SmarActEmulator) {
    static EMU: OnceLock<(PiEmulator, SmarActEmulator)> = OnceLock::new();
    EMU.get_or_init(|| {
        let clock = EmuClock::new(1.0);
        let pi = PiEmulator::start(clock.clone(), PiEmulatorConfig::default()).unwrap();
        let mcs = SmarActEmulator::start(clock, SmarActEmulatorConfig::default()).unwrap();
        (pi, mcs)
    })
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn mutated_sessions_parse_or_fail_clearly(e in edits()) {
        let text = lossy(&mutate(&session_text(), &e.0, &e.1));
        names_the_file(Session::from_ron_str(&text, Path::new("fuzz-session.ron")), "fuzz-session.ron")?;
    }

    #[test]
    fn mutated_traces_parse_or_fail_clearly(e in edits()) {
        // Raw bytes: the CSV reader meets non-UTF-8 itself.
        let bytes = mutate(TRACE, &e.0, &e.1);
        let parsed = Trace::from_csv_reader(bytes.as_slice(), Path::new("fuzz-trace.csv"));
        if let Ok(trace) = &parsed {
            prop_assert!(trace.columns().all(|(_, c)| c.iter().all(|v| v.is_finite())), "accepted a non-finite value");
        }
        names_the_file(parsed, "fuzz-trace.csv")?;
    }

    #[test]
    fn mutated_pi_replies_parse_or_are_refused(k in any::<prop::sample::Index>(), e in edits()) {
        let (_, replies) = exchange(PI_EXCHANGE);
        let mut seeds: Vec<String> = replies;
        seeds.push(DRR_BLOCK.to_string());
        seeds.push("1=150 \n2=160".to_string());
        let seed = k.get(&seeds);
        pi_parsers_refuse_or_accept(&lossy(&mutate(seed, &e.0, &e.1)))?;
    }

    #[test]
    fn mutated_mcs_replies_parse_or_are_refused(k in any::<prop::sample::Index>(), e in edits()) {
        let (_, replies) = exchange(MCS_EXCHANGE);
        let line = lossy(&mutate(k.get::<String>(&replies), &e.0, &e.1));
        // What the driver does with a reply: an angle split back into degrees stays finite.
        if let Some(McsReply::Angle { micro_deg, revolution, .. }) = parse_reply(&line) {
            prop_assert!(angle_from_mcs(micro_deg, revolution).is_finite());
        }
    }

    #[test]
    fn mutated_commands_to_the_pi_emulator_get_a_reply_or_an_error(k in any::<prop::sample::Index>(), e in edits()) {
        let (commands, _) = exchange(PI_EXCHANGE);
        let command = lossy(&mutate(k.get::<String>(&commands), &e.0, &e.1));
        let (pi, _) = emulators();
        for line in command.split('\n') {
            let _ = pi.reply_to(line.trim_end_matches('\r'));
        }
        // The emulator still answers after any input.
        prop_assert!(pi.reply_to("ERR?").is_some_and(|r| r.trim().parse::<i64>().is_ok()));
    }

    #[test]
    fn mutated_commands_to_the_mcs_emulator_get_a_reply_or_an_error(k in any::<prop::sample::Index>(), e in edits()) {
        let (commands, _) = exchange(MCS_EXCHANGE);
        let command = lossy(&mutate(k.get::<String>(&commands), &e.0, &e.1));
        let (_, mcs) = emulators();
        for line in command.split('\n') {
            if let Some(reply) = mcs.reply_to(line.trim_end_matches('\r')) {
                prop_assert!(reply.is_empty() || parse_reply(&reply).is_some(), "the emulator sent `{reply}` for `{line}`");
            }
        }
        prop_assert!(mcs.reply_to(":GNC").is_some_and(|r| parse_reply(&r).is_some()));
    }
}

/// A `DRR?` asking for more points than a machine word holds is refused with GCS error 77 (not
/// enough recorded data), not an end index that overflows and panics the emulator's thread.
#[test]
fn the_pi_emulator_refuses_a_data_request_past_the_word_size() {
    // Its own emulator: the fuzzing tests send the shared one anything, in parallel.
    let pi = PiEmulator::start(EmuClock::new(1.0), PiEmulatorConfig::default()).unwrap();
    assert_eq!(pi.reply_to("DRC 1 1 2").as_deref(), Some(""));
    assert_eq!(pi.reply_to("ERR?").as_deref(), Some("0\n"));
    assert_eq!(pi.reply_to(&format!("DRR? 2 {} 1", usize::MAX)).as_deref(), Some(""));
    assert_eq!(pi.reply_to("ERR?").as_deref(), Some("77\n"));
}

/// Over TCP, a command with bytes that are not UTF-8 is refused as the controller would refuse an
/// unknown command, and the connection stays open.
#[test]
fn the_emulators_refuse_non_utf8_commands_and_keep_the_connection() {
    use std::io::{BufRead, BufReader, Write};
    let clock = EmuClock::new(1.0);
    let pi = PiEmulator::start(clock.clone(), PiEmulatorConfig::default()).unwrap();
    let mcs = SmarActEmulator::start(clock, SmarActEmulatorConfig::default()).unwrap();
    let exchange = |addr: std::net::SocketAddr, bytes: &[u8]| -> String {
        let mut s = std::net::TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(std::time::Duration::from_secs(5))).unwrap();
        s.write_all(bytes).unwrap();
        let mut line = String::new();
        BufReader::new(s).read_line(&mut line).unwrap();
        line
    };
    // PI: no reply to the command, then `ERR?` says 2 (unknown command).
    assert_eq!(exchange(pi.addr(), b"MOV\xff\xfe 1 2\nERR?\n"), "2\n");
    // MCS: `:` then bytes >= 0x80 is an unknown command, error 2.
    assert_eq!(exchange(mcs.addr(), b":\x80\xc3GP0\n"), ":E-1,2\n");
}
