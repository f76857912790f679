//! The `photorobot` binary as a process: no progress bars or escape codes on a piped stderr,
//! `--quiet`, Ctrl-C during `calibrate` (the session saved, exit 130, the printed `--resume`
//! command finishes it) and the session's `photorobot.log`.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_photorobot");

/// Escape codes or bar characters a progress display would leave.
fn has_bar_output(stderr: &str) -> bool {
    stderr.contains('\x1b') || stderr.contains('\r') || stderr.contains("[=") || stderr.contains("=>")
}

#[test]
fn a_piped_stderr_gets_no_progress_bar_and_quiet_is_accepted() {
    let dir = tempfile::tempdir().unwrap();
    for quiet in [false, true] {
        let out = dir.path().join(format!("traces-{quiet}"));
        let mut cmd = Command::new(BIN);
        if quiet {
            cmd.arg("--quiet");
        }
        let run = cmd
            .args(["simulate", "--bench", "table2-ideal", "--plan", "strategy1", "--out"])
            .arg(&out)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(run.status.success(), "quiet {quiet}: {stderr}");
        assert!(!has_bar_output(&stderr), "quiet {quiet}: stderr has progress output: {stderr:?}");
        assert!(String::from_utf8_lossy(&run.stdout).contains("traces"), "the result is printed on stdout");
    }
    // -q after the command too (a global flag), and -v.
    let run = Command::new(BIN).args(["frames", "-q", "-v"]).output().unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
}

/// Wait until `dir/traces` holds a trace: the first segment has been saved and autosaved.
fn wait_for_first_trace(dir: &Path, child: &mut std::process::Child) {
    let start = Instant::now();
    loop {
        let n = std::fs::read_dir(dir.join("traces")).map(|d| d.count()).unwrap_or(0);
        if n > 0 && dir.join("session.autosave.ron").exists() {
            return;
        }
        assert!(child.try_wait().unwrap().is_none(), "calibrate ended before its first trace");
        assert!(start.elapsed() < Duration::from_secs(120), "no trace after two minutes");
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn ctrl_c_stops_calibrate_saved_and_the_printed_resume_command_finishes_it() {
    let dir = tempfile::tempdir().unwrap();
    let session = dir.path().join("session");
    let mut child = Command::new(BIN)
        .args(["calibrate", "--bench", "table2-ideal", "--seed", "7", "--out"])
        .arg(&session)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_for_first_trace(&session, &mut child);
    // SAFETY: kill(2) on the pid of a child this test spawned and has not waited for yet.
    assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) }, 0);
    let run = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(130), "exit code of an interrupted run; stderr: {stderr}");
    assert!(!session.join("session.ron").exists(), "an interrupted run is not a finished session");
    assert!(session.join("session.autosave.ron").exists(), "the measurement so far is saved");
    let expected =
        format!("photorobot calibrate --bench table2-ideal --mode joint --seed 7 --out {} --resume", session.display());
    let line = stderr.lines().find(|l| l.trim() == expected).unwrap_or_else(|| panic!("no `{expected}` in: {stderr}"));
    // The printed command, run as printed, finishes the session.
    let mut words = line.split_whitespace().skip(1);
    let resumed = Command::new(BIN).args(&mut words).output().unwrap();
    let resumed_err = String::from_utf8_lossy(&resumed.stderr);
    assert!(resumed.status.success(), "resume: {resumed_err}");
    assert!(session.join("session.ron").exists() && session.join("report.json").exists());
    // The session's log: both runs, their milestones, the interruption.
    let log = std::fs::read_to_string(session.join("photorobot.log")).unwrap();
    for milestone in [
        "calibrate into",
        "measuring plan",
        "segment done, autosaved",
        "measurement interrupted",
        "measurement done",
        "identification",
        "validation done",
        "session written",
    ] {
        assert!(log.contains(milestone), "no `{milestone}` in the session log:\n{log}");
    }
    assert!(log.contains("resume=true"), "the resumed run appends to the same log");
}
