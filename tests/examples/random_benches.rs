//! Benches nobody designed the diagnosis for: table2-ideal hiding 2 to 4 library effects on random
//! joints at random sizes (`photorobot_e2e::multi_effect::random_effects`), through the path users
//! run: `photorobot calibrate --bench FILE --seed S --plan optimised --out D`, then `photorobot
//! diagnose D --bench FILE --json`. Each bench's line says what was named within 3σ, what was
//! missed (and how the result reports it) and what was wrongly named; the tally ends the run,
//! which asserts that every bench goes through both commands.
//!
//!     cargo run --release -p photorobot-e2e --example random_benches [-- --benches 0..20]

use photorobot_core::bench::BenchPreset;
use photorobot_core::files::save_ron;
use photorobot_e2e::multi_effect::{calibrate_then_diagnose, random_effects, score};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let benches = photorobot_e2e::range_arg(&args, "--benches", 0..20);
    let (mut hidden, mut named, mut equivalent, mut wrong, mut failed) = (0, 0, 0, 0, 0);
    for b in benches.clone() {
        let t0 = std::time::Instant::now();
        let mut preset = BenchPreset::resolve("table2-ideal").expect("the embedded preset");
        preset.name = format!("random bench {b}");
        preset.effects = random_effects(b);
        let dir = tempfile::tempdir().expect("a temporary folder");
        let file = dir.path().join("bench.ron");
        save_ron(&file, &preset).expect("the bench file");
        let run = match calibrate_then_diagnose(&file, 10 + b, &["--plan", "optimised"], dir.path()) {
            Ok(r) => r,
            Err(e) => {
                failed += 1;
                println!("bench {b}: {e}");
                continue;
            }
        };
        let s = score(&run.diagnosis, &preset.effects);
        hidden += preset.effects.len();
        named += s.named.len();
        equivalent += s.equivalent.len();
        wrong += s.wrong.len();
        println!(
            "bench {b}: calibration {}, diagnosis {} ({:.2}σ → {:.2}σ), {:.0} s: {} of {} named",
            run.calibration,
            run.diagnosis["verdict"],
            run.diagnosis["residual_rms_before_sigma"].as_f64().unwrap_or(f64::NAN),
            run.diagnosis["residual_rms_after_sigma"].as_f64().unwrap_or(f64::NAN),
            t0.elapsed().as_secs_f64(),
            s.named.len(),
            preset.effects.len()
        );
        for n in &s.named {
            println!("    named {n}");
        }
        for (m, why) in &s.missed {
            println!("    missed {m}: {why}");
        }
        for e in &s.equivalent {
            println!("    named an equivalent {e}");
        }
        for w in &s.wrong {
            println!("    WRONGLY named {w}");
        }
    }
    let n = benches.end - benches.start;
    println!(
        "{n} benches, {hidden} hidden effects: {named} named within 3σ, {} missed, {equivalent} equivalents named \
         beside a hidden effect, {wrong} wrongly named; {failed} runs failed",
        hidden - named
    );
    assert_eq!(failed, 0, "every bench runs through calibrate and diagnose");
}
