//! Random plans recorded by the independent simulator with both its optics models (multi-beam,
//! and the deliberately different two-beam model of `two_beam.rs`), in plain CSV files without
//! our header lines, calibrated through `photorobot calibrate --bench table2-ideal --traces` and
//! scored against the simulator's hidden truth:
//!
//!     cargo run --release -p photorobot-e2e --example lab_recordings -- [PLANS] [--seeds N] [--from K]
//!
//! PLANS random plans (default 16; from the K-th with --from), each with a random truth, recorded
//! with N noise seeds (default 2) by each optics model. Asserts that at least 95 % of the
//! parameters reported determined lie within 3 total σ of the truth, and that no validation motion
//! planned with a result whose report forecast it within its target moves the true gap beyond it.

use photorobot_e2e::lab_recordings::{optics, CaseOutcome, LabCase};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |flag: &str| args.iter().position(|a| a == flag).and_then(|i| args.get(i + 1)?.parse::<u64>().ok());
    let from = value("--from").unwrap_or(0);
    let seeds = value("--seeds").unwrap_or(2);
    let plans = args.first().and_then(|a| a.parse::<u64>().ok()).unwrap_or(16);
    let mut outcomes: Vec<CaseOutcome> = Vec::new();
    for k in from..from + plans {
        for two_beam in [false, true] {
            for s in 0..seeds {
                let t0 = std::time::Instant::now();
                let o = LabCase::random(5000 + k, 100 * k + s + 1, optics(two_beam)).calibrate();
                println!("plan {:>3}  {}  ({:.0} s)", 5000 + k, o.line(), t0.elapsed().as_secs_f64());
                outcomes.push(o);
            }
        }
    }
    if !summary(&outcomes) {
        std::process::exit(1);
    }
}

/// The figures over all outcomes, per optics model and together; whether they meet the targets.
fn summary(outcomes: &[CaseOutcome]) -> bool {
    let mut ok = true;
    for optics in ["multi-beam", "two-beam", "both"] {
        let of: Vec<&CaseOutcome> = outcomes.iter().filter(|o| optics == "both" || o.optics == optics).collect();
        let count = |v: &str| of.iter().filter(|o| o.verdict == v).count();
        let determined: usize = of.iter().map(|o| o.determined.len()).sum();
        let beyond: usize = of.iter().map(|o| o.beyond(3.0).len()).sum();
        let beyond_noise: usize = of
            .iter()
            .flat_map(|o| &o.determined)
            .filter(|p| p.in_noise_sigma().is_nan() || p.in_noise_sigma().abs() > 3.0)
            .count();
        let motions: usize = of.iter().map(|o| o.validation.len()).sum();
        let kept = |o: &&CaseOutcome| o.validation.iter().filter(|(_, t, _, target)| t <= target).count();
        let within: usize = of.iter().map(kept).sum();
        let said: usize =
            of.iter().flat_map(|o| &o.validation).filter(|(_, t, f, target)| t > target && f > target).count();
        let broken: Vec<String> = of.iter().flat_map(|o| o.broken_promises()).collect();
        let share = 1.0 - beyond as f64 / determined.max(1) as f64;
        println!(
            "\n{optics}: {} recordings: {} fit, {} refused, {} ambiguous, {} other",
            of.len(),
            count("fits"),
            count("does_not_fit"),
            count("ambiguous"),
            of.len() - count("fits") - count("does_not_fit") - count("ambiguous")
        );
        println!(
            "  {determined} parameters determined: {beyond} beyond 3 total σ ({:.1} % within), {beyond_noise} beyond 3 noise σ",
            100.0 * share
        );
        println!(
            "  validation motions planned with the results: {motions}; true gap within target {within}, \
             beyond it and forecast so {said}, beyond it though forecast within {}",
            broken.len()
        );
        for b in &broken {
            println!("    {b}");
        }
        if optics == "both" {
            ok = share >= 0.95 && broken.is_empty();
        }
    }
    println!("\n{}", if ok { "targets met" } else { "TARGETS NOT MET" });
    ok
}
