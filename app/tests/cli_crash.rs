//! The crash guarantee of `photorobot calibrate` as the README states it, on the binary: killed
//! (SIGKILL) at seeded random moments, it loses at most the segment in hand, every segment its
//! log reported is kept byte for byte, `--resume` finishes, and the finished session equals an
//! uninterrupted run's (`support/crash.rs` says how). A second photorobot on the folder is
//! refused with the first's process id; a write refused in the middle of a file loses nothing
//! recorded. `cargo run --release -p photorobot --example crash_kills` runs more kills, and a
//! disk that really fills.

#[path = "support/crash.rs"]
mod crash;

use crash::{
    check_finished, check_interrupted, compare_calibration, kill_chain, late_moment, log_path, moments, reported,
    Calibrate, Reference, Seen, State,
};
use std::os::unix::process::CommandExt;
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_photorobot");
const SMALL_PLAN: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/fixtures/small-plan.ron");

/// Joint calibration from the short test plan (14 segments, 9 recorded; about 7 s in all).
fn small_calibration(seed: u64) -> Calibrate {
    let args = ["--bench", "table2-ideal", "--seed", &seed.to_string(), "--mode", "joint", "--plan", SMALL_PLAN];
    Calibrate { bin: BIN.into(), args: args.iter().map(|s| s.to_string()).collect() }
}

#[test]
fn calibrate_killed_at_seeded_moments_keeps_every_reported_segment_and_resumes_to_the_same_calibration() {
    let tmp = tempfile::tempdir().unwrap();
    let calibrate = small_calibration(7);
    let reference = Reference::run(&calibrate, &tmp.path().join("reference"), "table2-ideal", 7);
    let (mut kills, mut late) = (0, 0);
    for chain_seed in 1..=3u64 {
        // Nine kills within the measurement, then one in the identification or the validation,
        // or one while the session is written.
        let mut moments = moments(chain_seed, 9);
        moments.extend((chain_seed < 3).then(|| late_moment(chain_seed, chain_seed == 2, &reference)));
        let dir = tmp.path().join(format!("chain-{chain_seed}"));
        let chain = kill_chain(&calibrate, &dir, &moments, &reference);
        eprintln!("chain {chain_seed}: {chain:?}");
        kills += chain.kills;
        late += chain.after_measurement;
    }
    assert!(kills >= 20 && late > 0, "{kills} kills, {late} after the measurement");
}

/// Wait until `calibrate` into `dir` has begun measuring (it holds the folder's lock by then).
fn wait_for_measuring(dir: &std::path::Path, child: &mut std::process::Child) {
    let start = Instant::now();
    while !std::fs::read_to_string(log_path(dir)).unwrap_or_default().contains("measuring plan") {
        assert!(child.try_wait().unwrap().is_none(), "calibrate ended before measuring");
        assert!(start.elapsed() < Duration::from_secs(120), "not measuring after two minutes");
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn a_second_calibrate_on_the_folder_is_refused_with_the_first_ones_process_and_resumes_once_it_is_gone() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("session");
    let mut calibrate = small_calibration(7);
    calibrate.args.push("--no-validation".into());
    let mut first = calibrate.command(&dir, false).spawn().unwrap();
    wait_for_measuring(&dir, &mut first);
    let expected = format!("the session folder is open in another photorobot (process {})", first.id());
    for resume in [false, true] {
        let second = calibrate.command(&dir, resume).output().unwrap();
        let stderr = String::from_utf8_lossy(&second.stderr);
        assert_eq!(second.status.code(), Some(3), "resume {resume}: {stderr}");
        assert!(stderr.contains(&expected), "resume {resume}: no `{expected}` in {stderr}");
    }
    // The first goes on undisturbed until it is killed; the lock dies with it.
    first.kill().unwrap();
    first.wait().unwrap();
    let log = std::fs::read_to_string(log_path(&dir)).unwrap();
    assert_eq!(log.matches("calibrate into").count(), 1, "the refused runs wrote nothing, not even their log");
    calibrate.finish(&dir, true);
    let session = photorobot_core::session::Session::load(&dir).unwrap();
    assert_eq!(session.traces.len(), 9);
    session.load_traces(&dir).unwrap();
}

#[test]
fn a_write_refused_in_the_middle_of_a_trace_file_loses_nothing_recorded_and_resume_finishes() {
    let tmp = tempfile::tempdir().unwrap();
    let calibrate = small_calibration(7);
    let reference = Reference::run(&calibrate, &tmp.path().join("reference"), "table2-ideal", 7);
    // A file-size limit refuses a write past 2 MB, as a disk that fills refuses one: the first
    // trace above it (the fourth sweep's, 2.4 MB) fails in the middle of its file.
    const LIMIT_BYTES: u64 = 2_000_000;
    let largest_before = reference.bytes.values().map(Vec::len).take_while(|&n| n as u64 <= LIMIT_BYTES).count();
    assert!(largest_before > 0 && largest_before < reference.bytes.len(), "the limit falls within the plan");
    let dir = tmp.path().join("session");
    let mut cmd = calibrate.command(&dir, false);
    // SAFETY: setrlimit(2) and signal(2) are async-signal-safe; the closure allocates nothing.
    unsafe {
        cmd.pre_exec(|| {
            let limit = libc::rlimit { rlim_cur: LIMIT_BYTES, rlim_max: LIMIT_BYTES };
            libc::setrlimit(libc::RLIMIT_FSIZE, &limit);
            // Refused with EFBIG rather than killed by SIGXFSZ.
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            Ok(())
        });
    }
    let out = cmd.output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("traces/") && stderr.contains("File too large"), "the file and the reason: {stderr}");
    let mut seen = Seen::default();
    assert!(matches!(
        check_interrupted(&dir, &mut seen, true, &reference, "after the refused write"),
        State::Measuring
    ));
    let log = std::fs::read_to_string(log_path(&dir)).unwrap();
    let kept = reported(&log).iter().filter(|r| r.trace.is_some()).count();
    assert_eq!(kept, largest_before, "every trace before the refused one reported and kept");
    calibrate.finish(&dir, true);
    let redrawn = check_finished(&dir, &seen, &reference, true, "resumed after the refused write");
    compare_calibration(&dir, &reference, redrawn, "resumed after the refused write");
}
