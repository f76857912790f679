//! Clean recordings from another simulator (`photorobot_e2e::independent`: its own chain, optics
//! and recorder, no imperfection hidden), one per seed, through the path users run:
//! `photorobot calibrate --bench table2-ideal --traces DIR`, `photorobot diagnose S --bench none
//! --json`, and, when that proposes motions, those recorded by the same simulator, added with
//! `diagnose --add` and diagnosed again. Counts the seeds where anything was named, before and
//! after the proposed motions, and asserts that nothing was named in at least 95 % of them.
//!
//!     cargo run --release -p photorobot-e2e --example independent_null [-- --seeds 1..21]

use photorobot_e2e::independent::Hidden;
use photorobot_e2e::recordings::independent_calibrate_and_diagnose;
use serde_json::Value;

/// The names of what a diagnosis named (as effects, or tried and kept as partial).
fn named(v: &Value) -> Vec<String> {
    ["effects", "partial"]
        .iter()
        .flat_map(|k| v[*k].as_array().cloned().unwrap_or_default())
        .map(|e| format!("{} = {:.4} ± {:.4}", e["name"], e["estimate"], e["sigma"]))
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let seeds = photorobot_e2e::range_arg(&args, "--seeds", 1..21);
    let (mut runs, mut alarms) = (0usize, 0usize);
    for seed in seeds {
        let t0 = std::time::Instant::now();
        let (first, second) = independent_calibrate_and_diagnose(Hidden::default(), seed);
        let after = second.as_ref().map(named);
        let before = named(&first);
        let any = !before.is_empty() || after.as_ref().is_some_and(|a| !a.is_empty());
        runs += 1;
        alarms += usize::from(any);
        println!(
            "seed {seed}: verdict {} ({:.2}σ){}; named {:?}{}, {:.0} s",
            first["verdict"],
            first["residual_rms_after_sigma"].as_f64().unwrap_or(f64::NAN),
            second.as_ref().map_or(String::new(), |v| format!(", after the proposed motions {}", v["verdict"])),
            before,
            after.map_or(String::new(), |a| format!(", then {a:?}")),
            t0.elapsed().as_secs_f64()
        );
    }
    println!("{runs} seeds: something named in {alarms}");
    assert!(alarms as f64 <= 0.05 * runs as f64, "something named in {alarms} of {runs} seeds (at most 5 % allowed)");
}
