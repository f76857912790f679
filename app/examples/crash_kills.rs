//! The crash guarantee at length: `photorobot calibrate` killed (SIGKILL) at many seeded
//! moments, every kill checked as `tests/cli_crash.rs` checks its own (`tests/support/crash.rs`),
//! and, where the machine lets us mount one, a real disk (a small tmpfs) that fills in the
//! middle of a write. Asserts every check and prints the tallies.
//!
//!     cargo build --release -p photorobot
//!     cargo run --release -p photorobot --example crash_kills -- [CHAINS] [--seed N] [--tmpfs]
//!
//! CHAINS chains of ten kills each (default 10) on bench seed N (default 7); `--tmpfs` (root)
//! adds the full disk.

#[path = "../tests/support/crash.rs"]
mod crash;

use crash::{
    check_finished, check_interrupted, compare_calibration, kill_chain, late_moment, log_path, moments, reported,
    Calibrate, Reference, Seen, State,
};
use std::path::{Path, PathBuf};
use std::process::Command;

const SMALL_PLAN: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/fixtures/small-plan.ron");

/// The `photorobot` binary of the same build (target/<profile>/photorobot beside examples/).
fn binary() -> PathBuf {
    let exe = std::env::current_exe().expect("current exe");
    let bin = exe.parent().and_then(Path::parent).expect("target/<profile>").join("photorobot");
    assert!(bin.is_file(), "{} not built: run `cargo build --release -p photorobot` first", bin.display());
    bin
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let chains: u64 = args.first().filter(|a| !a.starts_with("--")).map_or(10, |a| a.parse().expect("CHAINS"));
    let seed: u64 = args.iter().position(|a| a == "--seed").map_or(7, |i| args[i + 1].parse().expect("--seed N"));
    let args_of = |seed: u64| {
        ["--bench", "table2-ideal", "--seed", &seed.to_string(), "--mode", "joint", "--plan", SMALL_PLAN]
            .iter()
            .map(|s| s.to_string())
            .collect::<Vec<_>>()
    };
    let calibrate = Calibrate { bin: binary(), args: args_of(seed) };
    let tmp = tempfile::tempdir().expect("temporary folder");
    let reference = Reference::run(&calibrate, &tmp.path().join("reference"), "table2-ideal", seed);
    let (mut kills, mut late, mut nothing, mut worst) = (0, 0, 0, 0.0f64);
    for chain_seed in 1..=chains {
        let mut m = moments(1000 + chain_seed, 9);
        m.push(late_moment(1000 + chain_seed, chain_seed % 2 == 0, &reference));
        let chain = kill_chain(&calibrate, &tmp.path().join(format!("chain-{chain_seed}")), &m, &reference);
        println!("chain {chain_seed}: {chain:?}");
        kills += chain.kills;
        late += chain.after_measurement;
        nothing += chain.before_any_autosave;
        worst = worst.max(chain.worst_parameter_sigma);
    }
    println!(
        "{kills} kills in {chains} chains ({late} after the measurement, {nothing} before the first autosave): \
         every reported segment kept byte for byte, at most the segment in hand lost, every chain resumed to the \
         uninterrupted run's steps; parameters within {worst:.3} σ of it (tolerance {:.3} σ)",
        crash::PARAMETER_TOLERANCE_SIGMA
    );
    assert!(kills as u64 >= 9 * chains, "{kills} kills");
    if args.iter().any(|a| a == "--tmpfs") {
        full_disk(&calibrate, &reference, tmp.path());
    }
}

/// Run `mount` with `args`; it must succeed.
fn mount(args: &[&str], at: &Path) {
    let status = Command::new("mount").args(args).arg(at).status().expect("mount");
    assert!(status.success(), "mount {args:?} {}: {status} (root is needed for --tmpfs)", at.display());
}

/// A session on a 6 MB tmpfs: the disk fills in the middle of the measurement; `calibrate`
/// fails naming the file and the reason, keeps every reported segment, and once the disk has
/// room again `--resume` finishes to the uninterrupted run's session.
fn full_disk(calibrate: &Calibrate, reference: &Reference, tmp: &Path) {
    let disk = tmp.join("disk");
    std::fs::create_dir_all(&disk).expect("mount point");
    mount(&["-t", "tmpfs", "-o", "size=6m", "tmpfs"], &disk);
    let dir = disk.join("session");
    let out = calibrate.command(&dir, false).output().expect("start photorobot");
    let stderr = String::from_utf8_lossy(&out.stderr);
    let checked = std::panic::catch_unwind(|| {
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(stderr.contains("No space left on device") && stderr.contains(&*dir.to_string_lossy()), "{stderr}");
        let mut seen = Seen::default();
        let state = check_interrupted(&dir, &mut seen, true, reference, "the full disk");
        assert!(matches!(state, State::Measuring), "an autosave to resume");
        let log = std::fs::read_to_string(log_path(&dir)).unwrap_or_default();
        let kept = reported(&log).iter().filter(|r| r.trace.is_some()).count();
        mount(&["-o", "remount,size=64m"], &disk);
        calibrate.finish(&dir, true);
        let redrawn = check_finished(&dir, &seen, reference, true, "resumed after the full disk");
        compare_calibration(&dir, reference, redrawn, "resumed after the full disk");
        println!("full disk: {} reported before it filled; {stderr}", kept);
    });
    let _ = Command::new("umount").arg(&disk).status();
    if let Err(panic) = checked {
        std::panic::resume_unwind(panic);
    }
}
