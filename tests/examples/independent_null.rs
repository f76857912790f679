//! Clean recordings from another simulator (`photorobot_e2e::independent`: its own chain, optics
//! and recorder, no imperfection hidden), one per seed, through the path users run:
//! `photorobot calibrate --bench table2-ideal --traces DIR`, `photorobot diagnose S --bench none
//! --json`, and, when that proposes motions, those recorded by the same simulator, added with
//! `diagnose --add` and diagnosed again; with `--passes N`, the loop goes on while a plan is
//! proposed, up to N diagnoses, and says after how many passes the result was `settled`. Counts
//! the seeds where anything was named in any pass, and asserts that nothing was named in at
//! least 95 % of them. `--optics two-beam` records with the model farther from ours.
//!
//!     cargo run --release -p photorobot-e2e --example independent_null [-- --seeds 1..21] [--passes 2] [--optics two-beam]

use photorobot_e2e::independent::Hidden;
use photorobot_e2e::recordings::independent_loop_with;
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
    let optics = photorobot_e2e::optics_arg(&args);
    let max_passes = args.iter().position(|a| a == "--passes").and_then(|k| args.get(k + 1)?.parse().ok()).unwrap_or(2);
    let (mut runs, mut alarms, mut settled) = (0usize, 0usize, 0usize);
    let mut when: std::collections::BTreeMap<usize, usize> = Default::default();
    for seed in seeds {
        let t0 = std::time::Instant::now();
        let passes = independent_loop_with(&optics, Hidden::default(), seed, max_passes);
        let names: Vec<Vec<String>> = passes.iter().map(named).collect();
        let any = names.iter().any(|n| !n.is_empty());
        let last = passes.last().expect("a first pass");
        let done = last["settled"] == true || last["proposed_plan_file"].is_null();
        runs += 1;
        alarms += usize::from(any);
        settled += usize::from(done);
        if done {
            *when.entry(passes.len()).or_default() += 1;
        }
        let verdicts: Vec<String> = passes
            .iter()
            .map(|v| format!("{} ({:.2}σ)", v["verdict"], v["residual_rms_after_sigma"].as_f64().unwrap_or(f64::NAN)))
            .collect();
        println!(
            "seed {seed}: {} passes: {}; named {:?}; {}, {:.0} s",
            passes.len(),
            verdicts.join(", "),
            names,
            if done { "settled" } else { "still proposing" },
            t0.elapsed().as_secs_f64()
        );
    }
    let after: Vec<String> = when.iter().map(|(k, n)| format!("{n} after {k}")).collect();
    println!("{runs} seeds: something named in {alarms}; settled in {settled} ({})", after.join(", "));
    assert!(alarms as f64 <= 0.05 * runs as f64, "something named in {alarms} of {runs} seeds (at most 5 % allowed)");
}
