//! Another simulator's recordings (`independent.rs`: its own chain, optics and recorder), one
//! imperfection hidden at a time, through the path users run: `photorobot calibrate --bench
//! table2-ideal --traces`, `photorobot diagnose S --bench none`, the proposed motions recorded by
//! the same simulator later on the same clock and added (`diagnose --add`), and the diagnosis
//! again (`recordings::independent_loop_with`; `--optics two-beam` records with the model farther
//! from ours). Each case and seed says what was named before and after the proposed motions, and
//! scores the last: named (the hidden effect, or an equivalent the result lists with it, within
//! 3σ), named with a remainder unexplained (kept within 3σ as the part of the residual it
//! explains, the verdict `unexplained`: optics unlike the model's leave a misfit), listed (in a list of what the data could not tell: equivalent, need motions, not
//! detectable, not seen, a cancelling pair, a named effect's ambiguity set), bounded (not named,
//! its size under the bound the result gives: it cannot tell), wrong (a bound under the hidden
//! size), missed, and anything named that is not there.
//!
//!     cargo run --release -p photorobot-e2e --example independent_hidden [-- --seeds 1..4] [--only TEXT] [--optics two-beam] [--keep DIR]

use photorobot_e2e::independent::Hidden;
use photorobot_e2e::recordings::{independent_loop_in, independent_loop_with};
use serde_json::Value;

/// A hidden imperfection: its label, the simulator's setting, the names that state it (the first
/// is the library's own, the others equivalents) and its size in their unit (compared by
/// magnitude when `abs`).
struct Case {
    label: &'static str,
    hidden: Hidden,
    names: &'static [&'static str],
    value: f64,
    abs: bool,
}

fn cases() -> Vec<Case> {
    let h = Hidden::default;
    vec![
        Case {
            label: "q4 zero offset 0.07°",
            hidden: Hidden { joint_offset: [0.0, 0.0, 0.0, 0.07, 0.0, 0.0], ..h() },
            names: &["joint zero offset q4"],
            value: 0.07,
            abs: false,
        },
        Case {
            label: "q5 zero offset 0.05°",
            hidden: Hidden { joint_offset: [0.0, 0.0, 0.0, 0.0, 0.05, 0.0], ..h() },
            names: &["joint zero offset q5"],
            value: 0.05,
            abs: false,
        },
        Case {
            label: "q3 axis tilt 1 mrad toward y",
            hidden: Hidden { q3_tilt_mrad: [0.0, 1.0], ..h() },
            names: &["axis tilt q3 toward link y"],
            value: 1.0,
            abs: false,
        },
        Case {
            label: "q3 axis tilt 1 mrad toward x",
            hidden: Hidden { q3_tilt_mrad: [1.0, 0.0], ..h() },
            names: &["axis tilt q3 toward link x"],
            value: 1.0,
            abs: true,
        },
        Case {
            label: "q2 scale 500 ppm",
            hidden: Hidden { joint_scale_ppm: [0.0, 500.0, 0.0], ..h() },
            names: &["joint scale error q2"],
            value: 500.0,
            abs: false,
        },
        Case {
            label: "q1 scale 500 ppm",
            hidden: Hidden { joint_scale_ppm: [500.0, 0.0, 0.0], ..h() },
            names: &["joint scale error q1"],
            value: 500.0,
            abs: false,
        },
        Case {
            label: "q1 scale 1500 ppm",
            hidden: Hidden { joint_scale_ppm: [1500.0, 0.0, 0.0], ..h() },
            names: &["joint scale error q1"],
            value: 1500.0,
            abs: false,
        },
        Case {
            label: "q4 pivot 15 µm (joint frame x)",
            hidden: Hidden { pivot_offset_um: [[15.0, 0.0, 0.0], [0.0; 3]], ..h() },
            names: &[
                "pivot offset q4 along X_w",
                "pivot offset q4 along Y_w",
                "pivot offset q4 along Z_w",
                "pivot offset q5 along Y_w",
                "pivot offset q6 along X_w",
                "pivot offset q6 along Y_w",
                "pivot offset q6 along Z_w",
            ],
            value: 15.0,
            abs: true,
        },
        Case {
            label: "drift 0.3 nm/s",
            hidden: Hidden { drift_nm_per_s: 0.3, ..h() },
            names: &["thermal drift rate"],
            value: 0.3,
            abs: false,
        },
    ]
}

/// The effects of the list `field` of a diagnosis: name, estimate, σ, ambiguity set.
fn effects_in(v: &Value, field: &str) -> Vec<(String, f64, f64, Vec<String>)> {
    v[field]
        .as_array()
        .into_iter()
        .flatten()
        .map(|e| {
            let amb = e["ambiguous_with"].as_array().into_iter().flatten().filter_map(|n| n.as_str()).map(String::from);
            (
                e["name"].as_str().unwrap_or("?").to_string(),
                e["estimate"].as_f64().unwrap_or(f64::NAN),
                e["sigma"].as_f64().unwrap_or(f64::NAN),
                amb.collect(),
            )
        })
        .collect()
}

/// What a diagnosis named: its effects, and the effects an unexplained verdict kept (partial).
fn named(v: &Value) -> Vec<(String, f64, f64, Vec<String>)> {
    let mut all = effects_in(v, "effects");
    all.extend(effects_in(v, "partial"));
    all
}

/// The last diagnosis against the case: (score word, what was named that is not there).
fn score(v: &Value, c: &Case) -> (String, Vec<String>) {
    let effects = named(v);
    let within = |e: &(String, f64, f64, Vec<String>)| {
        let est = if c.abs { e.1.abs() } else { e.1 };
        c.names.contains(&e.0.as_str()) && (est - c.value).abs() <= 3.0 * e.2
    };
    let wrong: Vec<String> = effects
        .iter()
        .filter(|e| !c.names.contains(&e.0.as_str()) && !e.3.iter().any(|a| c.names.contains(&a.as_str())))
        .map(|e| format!("{} = {:.4} ± {:.4}", e.0, e.1, e.2))
        .collect();
    let word = if v["verdict"] == "named" && effects.iter().any(within) {
        "named".to_string()
    } else if effects.iter().any(within) {
        format!("named, a remainder unexplained ({})", v["verdict"])
    } else if let Some(e) = effects.iter().find(|e| c.names.contains(&e.0.as_str())) {
        format!("named beyond 3σ ({} = {:.4} ± {:.4})", e.0, e.1, e.2)
    } else {
        let name = c.names[0];
        let holds = |f: &str| v[f].as_array().is_some_and(|a| a.iter().any(|n| n.as_str() == Some(name)));
        let lists = ["equivalent_to_extrinsics", "need_motions", "not_detectable", "not_seen"];
        let paired = v["cancelling_pairs"]
            .as_array()
            .into_iter()
            .flatten()
            .any(|p| p.as_array().is_some_and(|p| p.iter().any(|n| n.as_str() == Some(name))));
        let ambiguous = effects.iter().any(|e| e.3.iter().any(|a| a == name));
        let bound = v["ruled_out_above"]
            .as_array()
            .into_iter()
            .flatten()
            .find(|b| b["name"].as_str() == Some(name))
            .and_then(|b| b["below"].as_f64());
        match lists.iter().find(|f| holds(f)) {
            Some(f) => format!("listed ({f})"),
            None if bound.is_some_and(|b| c.value.abs() < b) => {
                format!("bounded (below {:.4}, above the hidden size: cannot tell)", bound.unwrap_or_default())
            }
            None if bound.is_some() => {
                format!("WRONG (bounded below {:.4}, under the hidden size)", bound.unwrap_or_default())
            }
            None if paired => "listed (cancelling pair)".into(),
            None if ambiguous => "listed (ambiguous with a named effect)".into(),
            None => "missed".into(),
        }
    };
    (word, wrong)
}

fn summary(v: &Value) -> String {
    let effects: Vec<String> = named(v).iter().map(|e| format!("{} = {:.4} ± {:.4}", e.0, e.1, e.2)).collect();
    format!(
        "{} ({:.2}σ → {:.2}σ) [{}]",
        v["verdict"],
        v["residual_rms_before_sigma"].as_f64().unwrap_or(f64::NAN),
        v["residual_rms_after_sigma"].as_f64().unwrap_or(f64::NAN),
        effects.join("; ")
    )
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let seeds = photorobot_e2e::range_arg(&args, "--seeds", 1..4);
    let optics = photorobot_e2e::optics_arg(&args);
    let mut tally: std::collections::BTreeMap<String, usize> = Default::default();
    let (mut runs, mut wrong_runs) = (0, 0);
    // `--only TEXT`: the cases whose label holds TEXT.
    let only = args.iter().position(|a| a == "--only").and_then(|k| args.get(k + 1)).cloned();
    // `--keep DIR`: each case's recordings and session kept in DIR/<case>-seed-<seed>.
    let keep = args.iter().position(|a| a == "--keep").and_then(|k| args.get(k + 1)).map(std::path::PathBuf::from);
    for c in cases().into_iter().filter(|c| only.as_deref().is_none_or(|o| c.label.contains(o))) {
        for seed in seeds.clone() {
            let t0 = std::time::Instant::now();
            let mut passes = match &keep {
                Some(k) => {
                    let dir = k.join(format!("{}-seed-{seed}", c.label.replace([' ', '/'], "-")));
                    std::fs::create_dir_all(&dir).expect("the --keep folder");
                    independent_loop_in(&dir, &optics, c.hidden, 300 + seed, 2)
                }
                None => independent_loop_with(&optics, c.hidden, 300 + seed, 2),
            }
            .into_iter();
            let (first, second) = (passes.next().expect("a first pass"), passes.next());
            let last = second.as_ref().unwrap_or(&first);
            let (word, wrong) = score(last, &c);
            println!(
                "{} seed {seed}: {word}; before the proposed motions {}; after {}; {:.0} s",
                c.label,
                summary(&first),
                second.as_ref().map_or("none proposed".into(), summary),
                t0.elapsed().as_secs_f64()
            );
            for w in &wrong {
                println!("    NAMED, NOT THERE: {w}");
            }
            runs += 1;
            wrong_runs += usize::from(!wrong.is_empty());
            let key = word.split(" (").next().unwrap_or(&word).to_string();
            *tally.entry(key).or_default() += 1;
        }
    }
    let parts: Vec<String> = tally.iter().map(|(k, n)| format!("{k} {n}")).collect();
    println!("{runs} runs: {}; something named that is not there in {wrong_runs}", parts.join(", "));
}
