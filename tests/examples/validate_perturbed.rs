//! `photorobot validate` on extrinsics moved off the bench's truth on purpose: the figure each
//! motion reports against the true change of the cavity length along it, and the verdict.
//!
//!     cargo run --release -p photorobot-e2e --example validate_perturbed -- [N] [--fixed]
//!
//! N random perturbations (default 50; seeds 1..=N, [`random_perturbation`]), or with `--fixed`
//! the acceptance's sixteen (β_et, θ_et, β_wf, θ_wf by 0.01°, 0.1°, 1°; x_wf, z_wf by 1 and
//! 10 µm), on table2-ideal. Fails (exit 1) when a motion reports less than 90 % of the true
//! change (less 2 nm) without being contradicted.

use photorobot_core::bench::BenchPreset;
use photorobot_core::validate::ValidationMotion;
use photorobot_e2e::validation::{motions, perturbations, random_perturbation, run_validate, true_peak_to_peak_nm};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let fixed = args.iter().any(|a| a == "--fixed");
    let n: u64 = args.iter().find_map(|a| a.parse().ok()).unwrap_or(50);
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let truth = preset.truth;
    let cases: Vec<(String, photorobot_core::model::extrinsics::Extrinsics)> = if fixed {
        perturbations(&truth).into_iter().map(|(name, d, e)| (format!("{name} {d:+}"), e)).collect()
    } else {
        (1..=n).map(|s| (format!("random {s}"), random_perturbation(&truth, s))).collect()
    };
    let dir = tempfile::tempdir().unwrap();
    let (mut silent_under, mut under, mut contradicted, mut rows) = (0, 0, 0, 0);
    let mut worst_confirmed: f64 = 0.0;
    for (k, (name, e)) in cases.iter().enumerate() {
        let t0 = std::time::Instant::now();
        let (code, doc) = run_validate("table2-ideal", e, 1 + k as u64, &[], dir.path());
        for (m, (motion, measured, verdict, within)) in ValidationMotion::ALL.iter().zip(motions(&doc)) {
            let true_nm = true_peak_to_peak_nm(&preset, e, *m);
            let low = measured < 0.9 * true_nm - 2.0;
            rows += 1;
            under += low as usize;
            contradicted += (verdict == "contradicted") as usize;
            silent_under += (low && verdict != "contradicted") as usize;
            if verdict == "confirmed" {
                worst_confirmed = worst_confirmed.max((measured - true_nm).abs() / true_nm.max(20.0));
            }
            println!(
                "{name:<16} {motion:<52} true {true_nm:9.1} nm  reported {measured:9.1} nm  {verdict:<12} {}{}",
                if within { "within target" } else { "" },
                if low { "  UNDER-REPORTED" } else { "" }
            );
        }
        println!("{name}: exit {code} ({:.0} s)", t0.elapsed().as_secs_f64());
    }
    println!(
        "{} cases, {rows} motions: {contradicted} contradicted, {under} under-reported by more than 10 % (2 nm), \
         {silent_under} of them not contradicted; confirmed figures within {:.1} % of the truth (of 20 nm at least)",
        cases.len(),
        100.0 * worst_confirmed
    );
    if silent_under > 0 {
        std::process::exit(1);
    }
}
