//! Measures the discrepancy workflow from virtual-bench traces, one hidden library effect at a
//! time at its typical size (SPEC section 9): records the short calibration-like session of
//! `tests/cli_diagnose.rs` on `table2-ideal` with the effect hidden, runs
//! `photorobot diagnose <session> --bench <that bench> --json`, and prints what was named,
//! its estimate against the hidden value, and the residual before and after.
//!
//!     cargo run --release -p photorobot-e2e --example diagnose_scan [-- INDEX...] [--seed N]
//!
//! Without an index, every effect of `photorobot_e2e::library_effects_at_typical_size`.

use photorobot_core::bench::{run_plan, BenchPreset, RunControl, VirtualBench};
use photorobot_core::files::save_ron;
use photorobot_e2e::{library_effects_at_typical_size, session_plan};
use std::sync::atomic::AtomicBool;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut seed = 5u64;
    let mut picks = Vec::new();
    let mut i = 0;
    while i < args.len() {
        if args[i] == "--seed" {
            seed = args.get(i + 1).and_then(|s| s.parse().ok()).expect("--seed N");
            i += 2;
        } else {
            picks.push(args[i].parse::<usize>().expect("an effect index"));
            i += 1;
        }
    }
    let all = library_effects_at_typical_size();
    if picks.is_empty() {
        picks = (0..all.len()).collect();
    }
    for k in picks {
        let (name, hidden, hidden_effects) = &all[k];
        let t0 = std::time::Instant::now();
        let mut preset = BenchPreset::resolve("table2-ideal").expect("embedded preset");
        preset.name = format!("hidden {name}");
        preset.effects = hidden_effects.clone();
        let dir = tempfile::tempdir().expect("temporary folder");
        let bench_file = dir.path().join("bench.ron");
        save_ron(&bench_file, &preset).expect("bench file");
        let mut bench = VirtualBench::new(&preset, Some(seed)).expect("bench");
        let cancel = AtomicBool::new(false);
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        let run = run_plan(&mut bench, &session_plan(), &mut control);
        run.outcome.expect("plan runs");
        std::fs::create_dir_all(dir.path().join("traces")).expect("traces folder");
        for (i, t) in run.traces.iter().enumerate() {
            t.write_csv(&dir.path().join("traces").join(format!("{i:03}.csv"))).expect("trace");
        }
        save_ron(&dir.path().join("extrinsics.ron"), &preset.truth).expect("extrinsics");
        let mut out = Vec::new();
        let seed_s = seed.to_string();
        let args = [
            "photorobot",
            "diagnose",
            dir.path().to_str().expect("utf-8 path"),
            "--bench",
            bench_file.to_str().expect("utf-8 path"),
            "--seed",
            &seed_s,
            "--json",
        ];
        if let Err(e) = photorobot_app::cli::run(args, &mut out) {
            println!("[{k}] {name}: diagnose failed: {e}");
            continue;
        }
        let v: serde_json::Value = serde_json::from_slice(&out).expect("JSON");
        if let Ok(p) = std::env::var("DIAGNOSE_SCAN_DUMP") {
            std::fs::write(format!("{p}-{k}.json"), &out).expect("dump");
        }
        let named: Vec<String> = v["effects"]
            .as_array()
            .map(|a| {
                a.iter()
                    .map(|e| {
                        format!(
                            "{} = {:.4} ± {:.4} {}",
                            e["name"].as_str().unwrap_or("?"),
                            e["estimate"].as_f64().unwrap_or(f64::NAN),
                            e["sigma"].as_f64().unwrap_or(f64::NAN),
                            e["unit"].as_str().unwrap_or("")
                        )
                    })
                    .collect()
            })
            .unwrap_or_default();
        let first_ok = v["effects"][0]["name"].as_str() == Some(name);
        let listed = |field: &str| v[field].as_array().is_some_and(|a| a.iter().any(|n| n.as_str() == Some(name)));
        let reported = [
            ("not_detectable", "not detectable at typical size"),
            ("not_seen", "seen by no observation"),
            ("equivalent_to_extrinsics", "equivalent to an extrinsic change"),
        ]
        .iter()
        .filter(|(f, _)| listed(f))
        .map(|(_, what)| format!("; reported as {what}"))
        .collect::<String>();
        let z = (v["effects"][0]["estimate"].as_f64().unwrap_or(f64::NAN) - hidden)
            / v["effects"][0]["sigma"].as_f64().unwrap_or(f64::NAN);
        println!(
            "[{k}] hidden {name} = {hidden:.4}: verdict {}, {:.2}σ → {:.2}σ, first named {} ({}){reported}, {:.1} s\n      {}",
            v["verdict"],
            v["residual_rms_before_sigma"].as_f64().unwrap_or(f64::NAN),
            v["residual_rms_after_sigma"].as_f64().unwrap_or(f64::NAN),
            if first_ok { "right" } else { "WRONG" },
            if first_ok { format!("{z:+.2}σ from the hidden value") } else { String::new() },
            t0.elapsed().as_secs_f64(),
            named.join("; ")
        );
    }
}
