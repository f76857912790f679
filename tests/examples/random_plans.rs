//! Random plans through `simulate` then `calibrate --traces`: the success rate, the error of each
//! determined parameter in σ, the validation on the true bench. Asserts that no plan went
//! without a report and that every validation the forecast promised kept the true gap within
//! its target; the default run (`20 --validate`: four plans of each family, two on each bench)
//! asserts its tallies too (README, docs/identification.md).
//!
//!     cargo run --release -p photorobot-e2e --example random_plans -- [PLANS] [--from K] [--validate]
//!
//! PLANS random plans (default 20; from the K-th with --from) cycle through the random plan
//! families, on table2-ideal and on femto-lab with its hidden effects switched off (its noise
//! kept) alternately, plan seeds from 1000 on and bench seeds from 1 on.
//!
//!     cargo run --release -p photorobot-e2e --example random_plans -- write FAMILY SEED FILE
//!
//! writes one random plan (family `single-joints`, `several-joints`, `other-offsets`,
//! `rotations-only`, `chained`) to a plan file, to run with `photorobot simulate --plan FILE`.

use photorobot_core::model::extrinsics::PARAMETER_NAMES;
use photorobot_core::plan::random::Family;
use photorobot_e2e::random::{outcome_line, run_random_plan, PlanOutcome};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("write") {
        write_plan(&args[1..]);
        return;
    }
    let from: usize = args.iter().position(|a| a == "--from").and_then(|i| args.get(i + 1)?.parse().ok()).unwrap_or(0);
    let plans: usize = args
        .iter()
        .enumerate()
        .filter(|(i, _)| *i == 0 || args[i - 1] != "--from")
        .find_map(|(_, a)| a.parse().ok())
        .unwrap_or(PINNED.plans);
    let validate = args.iter().any(|a| a == "--validate");
    let mut outcomes: Vec<PlanOutcome> = Vec::new();
    for k in from..from + plans {
        let family = Family::ALL[k % Family::ALL.len()];
        let bench = if (k / Family::ALL.len()) % 2 == 0 { "table2-ideal" } else { "femto-lab-clean" };
        let t0 = std::time::Instant::now();
        let o = run_random_plan(bench, family, 1000 + k as u64, 1 + k as u64, validate);
        println!("{}  ({:.0} s)", outcome_line(&o), t0.elapsed().as_secs_f64());
        outcomes.push(o);
    }
    let tally = summary(&outcomes);
    tally.check();
    if (from, plans, validate) == (0, PINNED.plans, true) {
        assert_eq!(tally, PINNED, "the default run's tallies (README, docs/identification.md)");
        println!("\nthe tallies are those the README states");
    }
}

/// What a run of random plans came to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Tally {
    plans: usize,
    fits: usize,
    refused: usize,
    ambiguous: usize,
    no_report: usize,
    /// Parameters reported determined, and of them beyond 3σ of the truth.
    determined: usize,
    beyond_3_sigma: usize,
    /// Validation motions run on the accepted plans, promised within target by the forecast,
    /// and of those, kept within it.
    validations: usize,
    promised: usize,
    kept: usize,
}

/// The default run's tallies, as the README and docs/identification.md state them.
const PINNED: Tally = Tally {
    plans: 20,
    fits: 15,
    refused: 5,
    ambiguous: 0,
    no_report: 0,
    determined: 117,
    beyond_3_sigma: 1,
    validations: 60,
    promised: 40,
    kept: 40,
};

impl Tally {
    /// What every run must show: a report for every plan, every promised validation kept, and
    /// no more determined parameters beyond 3σ than a Gaussian's tail and its spread allow.
    fn check(&self) {
        assert_eq!(self.no_report, 0, "plans without a report");
        assert_eq!(self.kept, self.promised, "validations promised and not kept");
        let expected = 0.0027 * self.determined as f64;
        let allowed = (expected + 3.0 * expected.sqrt() + 1.0).floor() as usize;
        assert!(
            self.beyond_3_sigma <= allowed,
            "{} beyond 3σ, a Gaussian puts {expected:.1} there",
            self.beyond_3_sigma
        );
    }
}

fn write_plan(args: &[String]) {
    let [family, seed, file] = args else {
        eprintln!("usage: random_plans write FAMILY SEED FILE");
        std::process::exit(2);
    };
    let Some(family) = Family::from_name(family) else {
        eprintln!("unknown family {family}");
        std::process::exit(2);
    };
    let plan = photorobot_core::plan::random::random_plan(family, seed.parse().expect("a seed"));
    plan.save(std::path::Path::new(file)).expect("the plan written");
}

fn summary(outcomes: &[PlanOutcome]) -> Tally {
    let n = outcomes.len();
    let count = |v: &str| outcomes.iter().filter(|o| o.verdict == v).count();
    let wrong = outcomes.iter().filter(|o| o.confidently_wrong()).count();
    println!("\n{n} random plans:");
    println!(
        "  fits (a calibration):           {:>3} ({:.0} %)",
        count("fits"),
        100.0 * count("fits") as f64 / n as f64
    );
    println!("  does not fit (refused):         {:>3}", count("does_not_fit"));
    println!("  ambiguous (ties reported):      {:>3}", count("ambiguous"));
    println!(
        "  no report:                      {:>3}",
        outcomes.iter().filter(|o| o.verdict.starts_with("error")).count()
    );
    println!("  confidently wrong (determined, beyond 3σ): {wrong}");
    println!("\nerror of the determined parameters, in σ (over the plans that determine them):");
    for (name, _) in PARAMETER_NAMES {
        let e: Vec<f64> =
            outcomes.iter().flat_map(|o| o.errors_sigma.iter().filter(|x| x.0 == name).map(|x| x.1)).collect();
        if e.is_empty() {
            println!("  {name:<9} never determined");
            continue;
        }
        let rms = (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt();
        let worst = e.iter().map(|v| v.abs()).fold(0.0, f64::max);
        println!("  {name:<9} determined in {:>3} plans, rms {rms:.2}σ, worst {worst:.2}σ", e.len());
    }
    let scored: usize = outcomes.iter().map(|o| o.errors_sigma.len()).sum();
    let beyond = |k: f64| outcomes.iter().flat_map(|o| &o.errors_sigma).filter(|e| e.1.abs() > k).count();
    println!(
        "  {scored} determined parameters scored: {} beyond 3σ (a Gaussian puts {:.1} there), {} beyond 4σ",
        beyond(3.0),
        0.0027 * scored as f64,
        beyond(4.0)
    );
    // Every validation run: (true gap, forecast, target), nm.
    let runs: Vec<(f64, f64, f64)> = outcomes
        .iter()
        .flat_map(|o| {
            o.validation_nm.iter().map(move |(m, _, t)| {
                let f = o.forecast_nm.iter().find(|f| &f.0 == m);
                (*t, f.map_or(f64::NAN, |f| f.1), f.map_or(f64::NAN, |f| f.2))
            })
        })
        .collect();
    let count = |keep: &dyn Fn(&(f64, f64, f64)) -> bool| runs.iter().filter(|r| keep(r)).count();
    println!(
        "\nvalidation motions run on the accepted plans: {}; promised by the forecast {}, of which kept {}; \
         true gap beyond target {}, of which forecast beyond target {}",
        runs.len(),
        count(&|r| r.1 <= r.2),
        count(&|r| r.1 <= r.2 && r.0 <= r.2),
        count(&|r| r.0 > r.2),
        count(&|r| r.0 > r.2 && r.1 > r.2)
    );
    let wrongly: Vec<String> = outcomes.iter().flat_map(|o| o.validation_wrongly_promised()).collect();
    println!("  promised and not kept: {}", if wrongly.is_empty() { "none".to_string() } else { wrongly.join("; ") });
    let wrong: Vec<String> =
        outcomes.iter().filter(|o| o.confidently_wrong()).map(|o| format!("\n  {}", outcome_line(o))).collect();
    println!("\ndetermined beyond 3σ:{}", if wrong.is_empty() { " none".to_string() } else { wrong.concat() });
    println!("\nvalidation on the true bench, worst over the accepted plans (fringe figure / true gap, nm):");
    for bench in ["table2-ideal", "femto-lab"] {
        let mut by_motion: Vec<(String, f64, f64)> = Vec::new();
        for (m, v, t) in outcomes.iter().filter(|o| o.bench.starts_with(bench)).flat_map(|o| o.validation_nm.iter()) {
            match by_motion.iter_mut().find(|x| &x.0 == m) {
                Some(x) => (x.1, x.2) = (x.1.max(*v), x.2.max(*t)),
                None => by_motion.push((m.clone(), *v, *t)),
            }
        }
        for (m, v, t) in by_motion {
            println!("  {bench:<13} {m:<52} {v:6.1} / {t:5.1}");
        }
    }
    let outcome = |v: &str| outcomes.iter().filter(|o| o.verdict == v).count();
    Tally {
        plans: n,
        fits: outcome("fits"),
        refused: outcome("does_not_fit"),
        ambiguous: outcome("ambiguous"),
        no_report: outcomes.iter().filter(|o| o.verdict.starts_with("error")).count(),
        determined: scored,
        beyond_3_sigma: beyond(3.0),
        validations: runs.len(),
        promised: count(&|r| r.1 <= r.2),
        kept: count(&|r| r.1 <= r.2 && r.0 <= r.2),
    }
}
