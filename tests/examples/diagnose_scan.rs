//! Measures the discrepancy workflow from virtual-bench traces, one hidden library effect at a
//! time at its typical size, through the path users run: the short calibration-like session of
//! `tests/cli_diagnose.rs` measured on `table2-ideal` with the effect hidden by `photorobot
//! calibrate --bench <that bench> --plan <it> --seed N --out <session>`, then `photorobot diagnose
//! <session> --bench <that bench> --seed N --json`; prints what was named, its estimate against
//! the hidden value, and the residual before and after.
//!
//!     cargo run --release -p photorobot-e2e --example diagnose_scan [-- INDEX...] [--seed N | --seeds A..B]
//!
//! Without an index, every effect of `photorobot_e2e::library_effects_at_typical_size`.
//! `I+J` hides two effects at once. `--seeds A..B` runs every seed from A to B − 1 and ends
//! each pick with a tally: in how many seeds anything was named (false alarms, for index 0),
//! and in how many every hidden effect was named within 3σ of its value. `--at-most-named K`
//! asserts that a tally's seeds with anything named are at most K (the null figure the docs
//! give; 0 by default where nothing is hidden), `--at-least-found K` that every hidden effect
//! was named in at least K of them. `DIAGNOSE_SCAN_DUMP=<prefix>` writes each diagnosis' JSON
//! to `<prefix>-<index>.json`; `DIAGNOSE_SCAN_KEEP=1` keeps each bench file, plan and session
//! folder (their path is printed).

use photorobot_core::bench::BenchPreset;
use photorobot_core::files::save_ron;
use photorobot_core::model::effects::Effect;
use photorobot_e2e::{library_effects_at_typical_size, session_plan};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut seeds = 5u64..6;
    let mut picks: Vec<Vec<usize>> = Vec::new();
    let (mut at_most_named, mut at_least_found) = (None, None);
    let mut i = 0;
    while i < args.len() {
        if args[i] == "--at-most-named" || args[i] == "--at-least-found" {
            let k: usize = args.get(i + 1).and_then(|s| s.parse().ok()).expect("a count");
            if args[i] == "--at-most-named" {
                at_most_named = Some(k);
            } else {
                at_least_found = Some(k);
            }
            i += 2;
        } else if args[i] == "--seed" {
            let seed = args.get(i + 1).and_then(|s| s.parse().ok()).expect("--seed N");
            seeds = seed..seed + 1;
            i += 2;
        } else if args[i] == "--seeds" {
            let range = args.get(i + 1).expect("--seeds A..B");
            let (a, b) = range.split_once("..").expect("--seeds A..B");
            seeds = a.parse().expect("--seeds A..B")..b.parse().expect("--seeds A..B");
            i += 2;
        } else {
            picks.push(args[i].split('+').map(|k| k.parse::<usize>().expect("an effect index")).collect());
            i += 1;
        }
    }
    let all = library_effects_at_typical_size();
    if picks.is_empty() {
        picks = (0..all.len()).map(|k| vec![k]).collect();
    }
    for pick in picks {
        let label = pick.iter().map(|k| k.to_string()).collect::<Vec<_>>().join("+");
        // (seeds run, seeds with anything named, seeds with every hidden effect named within 3σ)
        let mut tally = (0usize, 0usize, 0usize);
        for seed in seeds.clone() {
            let hidden: Vec<(&str, f64)> =
                pick.iter().filter(|k| !all[**k].2.is_empty()).map(|k| (all[*k].0, all[*k].1)).collect();
            let t0 = std::time::Instant::now();
            let Some(v) = diagnose(&all, &pick, seed) else {
                println!("[{label}] seed {seed}: diagnose failed");
                continue;
            };
            tally.0 += 1;
            let effects = v["effects"].as_array().cloned().unwrap_or_default();
            if !effects.is_empty() || v["verdict"] == "named" {
                tally.1 += 1;
            }
            let found = |name: &str, value: f64| {
                effects.iter().any(|e| {
                    e["name"].as_str() == Some(name)
                        && ((e["estimate"].as_f64().unwrap_or(f64::NAN) - value).abs()
                            <= 3.0 * e["sigma"].as_f64().unwrap_or(f64::NAN))
                })
            };
            if !hidden.is_empty() && hidden.iter().all(|(n, v)| found(n, *v)) {
                tally.2 += 1;
            }
            print_row(&label, seed, &hidden, &v, t0);
        }
        if seeds.end - seeds.start > 1 {
            println!(
                "[{label}] over {} seeds: something named in {}, every hidden effect named within 3σ in {}",
                tally.0, tally.1, tally.2
            );
        }
        assert_eq!(tally.0 as u64, seeds.end - seeds.start, "[{label}] every seed runs");
        // With nothing hidden, nothing may be named unless a bound is given (the README's figure).
        let nothing_hidden = pick.iter().all(|k| all[*k].2.is_empty());
        if let Some(k) = at_most_named.or(nothing_hidden.then_some(0)) {
            assert!(tally.1 <= k, "[{label}] something named in {} seeds, at most {k} expected", tally.1);
        }
        if let Some(k) = at_least_found {
            assert!(tally.2 >= k, "[{label}] every hidden effect named in {} seeds, at least {k} expected", tally.2);
        }
    }
}

/// Records the session on a bench with the library effects `pick` hidden and diagnoses it
/// through the CLI; the JSON result.
fn diagnose(all: &[(&'static str, f64, Vec<Effect>)], pick: &[usize], seed: u64) -> Option<serde_json::Value> {
    let mut preset = BenchPreset::resolve("table2-ideal").expect("embedded preset");
    preset.name = format!("hidden {}", pick.iter().map(|k| all[*k].0).collect::<Vec<_>>().join(" + "));
    preset.effects = pick.iter().flat_map(|k| all[*k].2.clone()).collect();
    let mut dir = tempfile::tempdir().expect("temporary folder");
    if std::env::var("DIAGNOSE_SCAN_KEEP").is_ok() {
        dir.disable_cleanup(true);
        println!("kept in {}", dir.path().display());
    }
    let bench_file = dir.path().join("bench.ron");
    save_ron(&bench_file, &preset).expect("bench file");
    let plan = dir.path().join("session-plan.ron");
    session_plan().save(&plan).expect("the plan");
    let session = dir.path().join("session");
    let seed_s = seed.to_string();
    let (b, p, s) = (
        bench_file.to_str().expect("utf-8 path"),
        plan.to_str().expect("utf-8 path"),
        session.to_str().expect("utf-8 path"),
    );
    // The session is written whether or not the model fits (a hidden effect can keep it from
    // fitting): the diagnosis starts from its extrinsics either way.
    let calibrate = ["photorobot", "calibrate", "--bench", b, "--plan", p, "--seed", &seed_s, "--out", s, "--json"];
    let _ = photorobot_app::cli::run(calibrate, &mut Vec::new());
    if !session.join("extrinsics.ron").exists() {
        println!("calibrate wrote no session");
        return None;
    }
    let mut out = Vec::new();
    let args = ["photorobot", "diagnose", s, "--bench", b, "--seed", &seed_s, "--json"];
    if let Err(e) = photorobot_app::cli::run(args, &mut out) {
        println!("diagnose failed: {e}");
        return None;
    }
    if let Ok(p) = std::env::var("DIAGNOSE_SCAN_DUMP") {
        let label = pick.iter().map(|k| k.to_string()).collect::<Vec<_>>().join("+");
        std::fs::write(format!("{p}-{label}.json"), &out).expect("dump");
    }
    Some(serde_json::from_slice(&out).expect("JSON"))
}

/// One line per diagnosis: the verdict, the residual before and after, whether the first
/// named effect is the hidden one (one hidden effect) and how far from its value, how the
/// result reports a hidden effect it did not name, and every named effect.
fn print_row(label: &str, seed: u64, hidden: &[(&str, f64)], v: &serde_json::Value, t0: std::time::Instant) {
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
    let (name, value) = hidden.first().copied().unwrap_or(("nothing", 0.0));
    let first_ok = v["effects"][0]["name"].as_str() == Some(name);
    // An exact equivalent (a pivot offset of another joint) named with the hidden one in its
    // ambiguity set.
    let equivalent = !first_ok
        && v["effects"][0]["ambiguous_with"].as_array().is_some_and(|a| a.iter().any(|n| n.as_str() == Some(name)));
    let listed = |field: &str| v[field].as_array().is_some_and(|a| a.iter().any(|n| n.as_str() == Some(name)));
    let reported = [
        ("not_detectable", "not detectable at typical size"),
        ("not_seen", "seen by no observation"),
        ("equivalent_to_extrinsics", "equivalent to an extrinsic change"),
    ]
    .iter()
    .filter(|(f, _)| !equivalent && listed(f))
    .map(|(_, what)| format!("; reported as {what}"))
    .collect::<String>();
    let z = (v["effects"][0]["estimate"].as_f64().unwrap_or(f64::NAN) - value)
        / v["effects"][0]["sigma"].as_f64().unwrap_or(f64::NAN);
    let hidden_text = if hidden.is_empty() {
        "nothing = 0.0000".to_string()
    } else {
        hidden.iter().map(|(n, v)| format!("{n} = {v:.4}")).collect::<Vec<_>>().join(" + ")
    };
    println!(
        "[{label}] seed {seed}: hidden {hidden_text}: verdict {}, {:.2}σ → {:.2}σ, first named {} ({}){reported}, {:.1} s\n      {}",
        v["verdict"],
        v["residual_rms_before_sigma"].as_f64().unwrap_or(f64::NAN),
        v["residual_rms_after_sigma"].as_f64().unwrap_or(f64::NAN),
        if hidden.is_empty() {
            "(nothing hidden)"
        } else if first_ok {
            "right"
        } else if equivalent {
            "its equivalent, the hidden one in its ambiguity set"
        } else {
            "WRONG"
        },
        if first_ok { format!("{z:+.2}σ from the hidden value") } else { String::new() },
        t0.elapsed().as_secs_f64(),
        named.join("; ")
    );
}
