use super::*;
use crate::bench::{run_plan, PlanRun};
use crate::model::air::air_index_ciddor;
use crate::model::kinematics::Chain;
use crate::model::optics::OpticalParams;
use crate::model::robot::JointType;
use crate::plan::{JointTarget, Plan, Segment};
use std::sync::atomic::AtomicBool;

fn run(bench: &mut VirtualBench, plan: &Plan) -> PlanRun {
    let cancel = AtomicBool::new(false);
    let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
    run_plan(bench, plan, &mut control)
}

fn plan(segments: Vec<Segment>) -> Plan {
    Plan { name: "test".into(), description: String::new(), segments }
}

fn mv(target: JointTarget, record: bool) -> Segment {
    Segment::Move { to: target, record, label: "move".into(), through: false }
}

fn dwell(s: f64) -> Segment {
    Segment::Dwell { duration_s: s, record: true, label: "dwell".into() }
}

#[test]
fn same_seed_gives_the_same_trace_and_another_seed_other_noise() {
    let p = plan(vec![mv(JointTarget::default().with(1, 5.0), true)]);
    let a = run(&mut VirtualBench::from_preset_name("table2-ideal", Some(3)).unwrap(), &p);
    let b = run(&mut VirtualBench::from_preset_name("table2-ideal", Some(3)).unwrap(), &p);
    let c = run(&mut VirtualBench::from_preset_name("table2-ideal", Some(4)).unwrap(), &p);
    assert_eq!(a.traces[0].irradiance, b.traces[0].irradiance);
    assert_ne!(a.traces[0].irradiance, c.traces[0].irradiance);
    assert!(a.outcome.is_ok());
}

#[test]
fn a_trace_holds_only_what_a_real_bench_records() {
    let p = plan(vec![mv(JointTarget::default().with(2, 50.0), true)]);
    let r = run(&mut VirtualBench::from_preset_name("femto-lab", None).unwrap(), &p);
    let t = &r.traces[0];
    assert!(t.extra.is_empty(), "no hidden columns");
    let csv = String::from_utf8(t.to_csv_bytes(std::path::Path::new("t.csv")).unwrap()).unwrap();
    // Text (header, metadata) must not contain a secret; a number may by chance start with
    // the digits of one (q3 passing 0.7440… µm), so numeric fields must just differ from it.
    let is_number = |f: &str| f.trim().parse::<f64>().is_ok();
    for secret in ["112.4", "113.3", "0.744", "ThermalDrift", "PivotOffset", "truth"] {
        for line in csv.lines() {
            let fields: Vec<&str> = line.split(',').collect();
            if fields.iter().all(|f| is_number(f)) {
                assert!(fields.iter().all(|f| f.trim() != secret), "the trace leaks `{secret}`: {line}");
            } else {
                assert!(!line.contains(secret), "the trace leaks `{secret}`: {line}");
            }
        }
    }
    // Encoders read the joints with noise (femto-lab): the recorded q3 is near, not at, the command.
    let last = t.q3_um.last().unwrap();
    assert!((last - 50.0).abs() < 0.02 && *last != 50.0, "q3 = {last}");
}

#[test]
fn motion_is_velocity_limited_and_sampled_at_the_preset_rate() {
    let mut b = VirtualBench::from_preset_name("table2-ideal", None).unwrap();
    let p = plan(vec![mv(JointTarget::default().with(2, 100.0), true)]);
    let r = run(&mut b, &p);
    let t = &r.traces[0];
    let dt = t.t_s[1] - t.t_s[0];
    assert!((dt - 1e-4).abs() < 1e-12, "10 kHz");
    // 100 µm at 100 µm/s with 1000 µm/s² ramps: 1.1 s, plus 0.05 s settling.
    let span = t.t_s.last().unwrap() - t.t_s[0];
    assert!((span - 1.15).abs() < 2e-4, "duration {span}");
    let max_speed = t.q3_um.windows(2).map(|w| (w[1] - w[0]) / dt).fold(0.0, f64::max);
    assert!(max_speed <= 100.0 + 1e-6, "max speed {max_speed} µm/s");
    assert_eq!(b.position_display()[2], 100.0);
}

/// Fringe count of a 20 µm move along the beam against the truth computed independently
/// from the extrinsics: 2·n·Δd/λ fringes, with d the perpendicular gap.
#[test]
fn fringes_of_an_axial_move_match_the_truth() {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let mut b = VirtualBench::new(&preset, None).unwrap();
    let p =
        plan(vec![mv(JointTarget::default().with(1, -10.0), false), mv(JointTarget::default().with(1, 10.0), true)]);
    let r = run(&mut b, &p);
    let t = &r.traces[0];
    let chain = Chain::femto_6dof();
    let d = |q2: f64| {
        let c = preset.truth.cavity(&chain.end_effector(&[0.0, q2, 0.0, 0.0, 0.0, 0.0])).unwrap();
        c.length_um.abs() * c.tilt_rad.cos()
    };
    let n = air_index_ciddor(1560.0, &preset.ambient).unwrap();
    let fringes = 2.0 * n * (d(10.0) - d(-10.0)).abs() / 1.560;
    // Count maxima crossing the mean: each fringe gives one upward crossing.
    let mean = t.irradiance.iter().sum::<f64>() / t.len() as f64;
    let crossings = t.irradiance.windows(2).filter(|w| w[0] < mean && w[1] >= mean).count();
    assert!((crossings as f64 - fringes).abs() <= 1.0, "{crossings} crossings, {fringes:.2} fringes expected");
    assert!(fringes > 25.0);
}

#[test]
fn detector_noise_is_the_preset_fraction_of_the_fringe_amplitude() {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let mut b = VirtualBench::new(&preset, Some(11)).unwrap();
    let r = run(&mut b, &plan(vec![dwell(1.0)]));
    let v = &r.traces[0].irradiance;
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt();
    let c = preset.truth.cavity(&Chain::femto_6dof().end_effector(&[0.0; 6])).unwrap();
    let n = air_index_ciddor(1560.0, &preset.ambient).unwrap();
    let b_amp =
        FabryPerot::new(&preset.optics, 1560.0, n).unwrap().two_beam(c.length_um.abs(), c.tilt_rad).amplitude_mw;
    assert!((sd / b_amp - 1e-3).abs() < 0.05e-3, "σ/B = {}", sd / b_amp);
}

#[test]
fn hidden_thermal_drift_moves_the_fringes_at_rest() {
    let mut preset = BenchPreset::resolve("table2-ideal").unwrap();
    preset.effects = vec![Effect::ThermalDrift { nm_per_s: 200.0, nm_per_s2: 0.0 }];
    let mut b = VirtualBench::new(&preset, None).unwrap();
    let r = run(&mut b, &plan(vec![dwell(8.0)]));
    // A 50 ms boxcar (the fringe period here is ~3.9 s) removes the noise chatter.
    let v: Vec<f64> = r.traces[0].irradiance.chunks(500).map(|c| c.iter().sum::<f64>() / c.len() as f64).collect();
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let crossings = v.windows(2).filter(|w| (w[0] < mean) != (w[1] < mean)).count();
    // 1.6 µm of drift = 2·1.6/1.56 ≈ 2.05 fringes: about 4 mean crossings.
    assert!((3..=5).contains(&crossings), "{crossings} crossings");
}

/// Hidden optical effects are the optics they describe: a bench hiding "no Gouy phase" and a
/// back face gives the power of a bench whose optics have them; a hidden cyclic error moves
/// the gap by a·cos φ, as a drift of that much at the same instant does.
#[test]
fn hidden_optical_and_cyclic_effects_act_on_the_signal() {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let back = crate::model::optics::BackFace { reflectance: 0.04, inverted: true, ..Default::default() };
    let mut hidden = preset.clone();
    hidden.effects = vec![
        Effect::GouyPhase { scale_error: -1.0 },
        Effect::LamellaBackFace {
            amplitude_reflectance: -0.2,
            thickness_um: back.thickness_um,
            phase_index: back.phase_index,
            group_index: back.group_index,
        },
    ];
    let mut explicit = preset.clone();
    explicit.optics.gouy_phase = false;
    explicit.optics.back_face = Some(back);
    let (a, b) = (VirtualBench::new(&hidden, None).unwrap(), VirtualBench::new(&explicit, None).unwrap());
    let plain = VirtualBench::new(&preset, None).unwrap();
    let chain = Chain::new(preset.robot_description().unwrap());
    for q in [[0.0; 6], [30.0, -40.0, 120.0, 2.0, -3.0, 10.0], [-150.0, 150.0, 0.0, -4.0, 4.0, -45.0]] {
        let (pa, pb) = (a.reflected_power_mw(3.0, &q, 1560.0).unwrap(), b.reflected_power_mw(3.0, &q, 1560.0).unwrap());
        assert!((pa - pb).abs() < 1e-12, "{q:?}: {pa} vs {pb}");
        let p0 = plain.reflected_power_mw(3.0, &q, 1560.0).unwrap();
        assert!((pa - p0).abs() > 1e-4 * p0, "{q:?}: the effects change nothing");

        // The cyclic error against a drift of the same size at t = 2 s.
        let (t_s, amplitude_nm) = (2.0, 3.0);
        let q_rad: Vec<f64> = (0..6).map(|i| if i >= 3 { q[i].to_radians() } else { q[i] }).collect();
        let gap_um = preset.truth.cavity(&chain.end_effector(&q_rad)).unwrap().length_um.abs();
        let phase = 2.0 * std::f64::consts::PI * gap_um / plain.truth.fp.fringe_period_um();
        let mut cyclic = preset.clone();
        cyclic.effects = vec![Effect::FringeNonlinearity { in_phase_nm: amplitude_nm, quadrature_nm: 0.0 }];
        let mut drift = preset.clone();
        drift.effects = vec![Effect::ThermalDrift { nm_per_s: amplitude_nm * phase.cos() / t_s, nm_per_s2: 0.0 }];
        let pc = VirtualBench::new(&cyclic, None).unwrap().reflected_power_mw(t_s, &q, 1560.0).unwrap();
        let pd = VirtualBench::new(&drift, None).unwrap().reflected_power_mw(t_s, &q, 1560.0).unwrap();
        assert!((pc - pd).abs() < 1e-12, "{q:?}: {pc} vs {pd}");
    }
}

#[test]
fn cancelling_keeps_the_samples_recorded_so_far() {
    let mut b = VirtualBench::from_preset_name("table2-ideal", None).unwrap();
    let p = plan(vec![dwell(0.5), dwell(2.0)]);
    let cancel = AtomicBool::new(false);
    let mut seen = 0usize;
    let mut on_samples = |t: &Trace, _from: usize| {
        seen = t.len();
        if t.t_s.last().copied().unwrap_or(0.0) > 1.0 {
            cancel.store(true, std::sync::atomic::Ordering::Relaxed);
        }
    };
    let mut control = RunControl { cancel: &cancel, on_samples: &mut on_samples, on_progress: &mut |_| {} };
    let r = run_plan(&mut b, &p, &mut control);
    assert!(matches!(
        r.outcome,
        Err(crate::bench::RunError::Segment { segment: 1, error: BenchError::Cancelled { .. }, .. })
    ));
    assert_eq!(r.traces.len(), 2, "the finished dwell and the partial one");
    assert!(r.traces[1].len() > 1000 && r.traces[1].len() < 20001);
    assert!(seen > 0);
}

#[test]
fn a_plan_out_of_limits_moves_nothing() {
    let mut b = VirtualBench::from_preset_name("table2-ideal", None).unwrap();
    let p = plan(vec![mv(JointTarget::default().with(2, 50.0), true), mv(JointTarget::default().with(3, 12.0), true)]);
    let r = run(&mut b, &p);
    assert!(r.traces.is_empty());
    assert_eq!(b.position_display(), [0.0; 6]);
    let msg = r.outcome.unwrap_err().to_string();
    assert!(msg.contains("q4 = 12.000 ° is 2.000 ° above its upper limit 10.000 °"), "{msg}");
}

/// Largest |fast - exact| irradiance over every recorded sample of `plan`, as a fraction of
/// the local two-beam fringe amplitude, with the detector noise and the ADC off (the
/// stage jitter, encoder noise, drift, intrinsic errors and gain drift stay).
fn fast_vs_exact(preset_name: &str, plan: &Plan) -> Vec<(String, f64)> {
    fast_vs_exact_with(preset_name, plan, |_| {})
}

fn fast_vs_exact_with(preset_name: &str, plan: &Plan, modify: impl Fn(&mut BenchPreset)) -> Vec<(String, f64)> {
    let mut preset = BenchPreset::resolve(preset_name).unwrap();
    modify(&mut preset);
    preset.detector.white_noise_rel_fringe = 0.0;
    preset.detector.shot_noise_mw_at_1mw = 0.0;
    preset.detector.adc_bits = 0;
    preset.laser.rin_rel = 0.0;
    let mut fast = VirtualBench::new(&preset, Some(5)).unwrap();
    let mut exact = VirtualBench::new(&preset, Some(5)).unwrap();
    exact.set_exact(true);
    let (a, b) = (run(&mut fast, plan), run(&mut exact, plan));
    assert!(a.outcome.is_ok() && b.outcome.is_ok());
    assert_eq!(a.traces.len(), b.traces.len());
    let chain = Chain::new(effects::apply_all(&preset.effects, &preset.robot_description().unwrap()).unwrap());
    let rev = |i: usize| chain.description().links[i].joint == JointType::Revolute;
    let fp = &exact.truth.fp;
    a.traces
        .iter()
        .zip(&b.traces)
        .map(|(ta, tb)| {
            assert_eq!(ta.len(), tb.len());
            assert_eq!(ta.q6_deg, tb.q6_deg, "same noise draws");
            let mut worst: f64 = 0.0;
            for j in 0..ta.len() {
                let q_display = [ta.q1_um[j], ta.q2_um[j], ta.q3_um[j], ta.q4_deg[j], ta.q5_deg[j], ta.q6_deg[j]];
                let q: Vec<f64> =
                    (0..6).map(|i| if rev(i) { q_display[i].to_radians() } else { q_display[i] }).collect();
                let c = preset.truth.cavity(&chain.end_effector(&q)).unwrap();
                // With no lamella reflection there is no fringe: relative to the power.
                let amplitude = fp.two_beam(c.length_um, c.tilt_rad).amplitude_mw.max(1e-3 * tb.irradiance[j]);
                worst = worst.max((ta.irradiance[j] - tb.irradiance[j]).abs() / amplitude);
            }
            (ta.meta.label.clone(), worst)
        })
        .collect()
}

/// The fast path against the exact per-sample model on strategy-1 moves (300 µm
/// translations across and along the beam, 20 µm along it), strategy-2 rotations (±4°),
/// a 45° turn of q6, a move of all joints and a wavelength sweep, on both presets
/// (femto-lab: stage jitter, drift, intrinsic errors, cleave angle).
#[test]
fn fast_path_matches_the_exact_path() {
    let at = |q: [f64; 6]| JointTarget::all(q);
    let labelled = |target: JointTarget, label: &str| Segment::Move {
        to: target,
        record: true,
        label: label.into(),
        through: false,
    };
    let p = plan(vec![
        mv(at([150.0, 0.0, -150.0, 0.0, 0.0, 0.0]), false),
        labelled(JointTarget::default().with(2, 150.0), "S1 X_w 300 µm at q1 = 150"),
        mv(at([-150.0, -150.0, 0.0, 0.0, 0.0, 0.0]), false),
        labelled(JointTarget::default().with(0, 150.0), "S1 Z_w 300 µm at q2 = -150"),
        mv(at([0.0, -150.0, 0.0, 0.0, 0.0, 0.0]), false),
        labelled(JointTarget::default().with(1, 150.0), "Y_w 300 µm along the beam"),
        mv(at([0.0, -10.0, 150.0, 0.0, 0.0, 0.0]), false),
        labelled(JointTarget::default().with(1, 10.0), "S1 Y_w 20 µm at q3 = 150"),
        mv(at([0.0, 0.0, 0.0, -4.0, -4.0, 0.0]), false),
        labelled(JointTarget::default().with(3, 4.0), "S2 q4 -4 -> 4° at q5 = -4°"),
        mv(at([0.0, 0.0, 0.0, 4.0, -4.0, 0.0]), false),
        labelled(JointTarget::default().with(4, 4.0), "S2 q5 -4 -> 4° at q4 = 4°"),
        mv(at([0.0; 6]), false),
        labelled(JointTarget::default().with(5, 45.0), "q6 0 -> 45°"),
        labelled(at([100.0, 20.0, 100.0, 3.0, -3.0, 10.0]), "all joints"),
        Segment::Sweep { from_nm: 1555.0, to_nm: 1565.0, rate_nm_per_s: 2.0, label: "sweep 10 nm".into() },
        dwell(2.0),
    ]);
    for preset in ["table2-ideal", "femto-lab"] {
        for (label, worst) in fast_vs_exact(preset, &p) {
            eprintln!("{preset}: {label}: max |fast - exact| = {worst:.2e} of the fringe amplitude");
            // 1e-6 is required; FAST_PATH_TOLERANCE (3e-8) gives at most ~2e-8.
            assert!(worst < 1e-7, "{preset}: {label}: {worst:e}");
        }
    }
}

/// Other optics on the fast path: no lamella reflection (no beam), one beam, a back face,
/// many beams of a silicon lamella, no Gouy phase.
#[test]
fn fast_path_matches_the_exact_path_for_other_optics() {
    let p = plan(vec![
        mv(JointTarget::all([0.0, -20.0, 30.0, -2.0, 1.0, 0.0]), false),
        mv(JointTarget::all([10.0, 20.0, -30.0, 2.0, -1.0, 20.0]), true),
        Segment::Sweep { from_nm: 1555.0, to_nm: 1557.0, rate_nm_per_s: 2.0, label: "sweep".into() },
    ]);
    type Change = fn(&mut OpticalParams);
    let cases: [(&str, Change); 6] = [
        ("no reflection", |o| o.lamella_reflectance = 0.0),
        ("half the Gouy phase", |o| o.gouy_scale_error = -0.5),
        ("one beam", |o| o.beams = 1),
        ("back face", |o| o.back_face = Some(crate::model::optics::BackFace::default())),
        ("silicon, 40 beams", |o| {
            o.lamella_reflectance = 0.306;
            o.beams = 40
        }),
        ("no Gouy phase", |o| o.gouy_phase = false),
    ];
    for (name, change) in cases {
        for (label, worst) in fast_vs_exact_with("femto-lab", &p, |preset| change(&mut preset.optics)) {
            eprintln!("{name}: {label}: max |fast - exact| = {worst:.2e} of the fringe amplitude");
            assert!(worst < 1e-7, "{name}: {label}: {worst:e}");
        }
    }
}

/// `fill` gives the deviates of successive `sample` calls, however they are grouped.
#[test]
fn gaussian_fill_equals_successive_samples() {
    let tables = ziggurat_tables();
    let mut a = Gaussian::seed_from_u64(9);
    let mut b = Gaussian::seed_from_u64(9);
    let one_by_one: Vec<f64> = (0..100_000).map(|_| a.sample(tables)).collect();
    let mut filled = vec![0.0; 100_000];
    let mut at = 0;
    for size in (1..).cycle() {
        let end = (at + size % 37).min(filled.len());
        b.fill(tables, &mut filled[at..end]);
        at = end;
        if at == filled.len() {
            break;
        }
    }
    assert_eq!(one_by_one, filled);
}

/// erfc to a relative 1.2e-7 (Numerical Recipes' erfcc), for the test below.
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let p = -1.26551223
        + t * (1.00002368
            + t * (0.37409196
                + t * (0.09678418
                    + t * (-0.18628806
                        + t * (0.27886807
                            + t * (-1.13520398 + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277))))))));
    let ans = t * (-z * z + p).exp();
    if x >= 0.0 {
        ans
    } else {
        2.0 - ans
    }
}

/// The ziggurat deviates against the standard normal: moments, a χ² over 72 bins, the tails
/// out to 4.5σ (the slow paths) and the correlation of the two deviates of a 64-bit draw.
#[test]
fn gaussian_deviates_follow_the_standard_normal_distribution() {
    let tables = ziggurat_tables();
    for seed in [1, 987_654_321] {
        let mut g = Gaussian::seed_from_u64(seed);
        let n = 4_000_000;
        let (width, half) = (0.125, 36usize); // bins over [-4.5, 4.5]
        let mut bins = vec![0u64; 2 * half + 2];
        let (mut s1, mut s2, mut s3, mut s4, mut lag, mut prev) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        let (mut beyond_3_5, mut beyond_4_5) = (0u64, 0u64);
        for _ in 0..n {
            let x = g.sample(tables);
            let x2 = x * x;
            (s1, s2, s3, s4) = (s1 + x, s2 + x2, s3 + x2 * x, s4 + x2 * x2);
            lag += x * prev;
            prev = x;
            beyond_3_5 += u64::from(x.abs() > 3.5);
            beyond_4_5 += u64::from(x.abs() > 4.5);
            let b = ((x / width).floor() + half as f64).clamp(-1.0, 2.0 * half as f64) + 1.0;
            bins[b as usize] += 1;
        }
        let nf = n as f64;
        let (mean, var) = (s1 / nf, s2 / nf - (s1 / nf).powi(2));
        assert!(mean.abs() < 5.0 / nf.sqrt(), "mean {mean}");
        assert!((var - 1.0).abs() < 5.0 * (2.0 / nf).sqrt(), "variance {var}");
        assert!((s3 / nf).abs() < 5.0 * (15.0 / nf).sqrt(), "third moment {}", s3 / nf);
        assert!((s4 / nf - 3.0).abs() < 5.0 * (96.0 / nf).sqrt(), "fourth moment {}", s4 / nf);
        assert!((lag / nf).abs() < 5.0 / nf.sqrt(), "lag-1 correlation {}", lag / nf);
        let cdf = |x: f64| 0.5 * erfc(-x / std::f64::consts::SQRT_2);
        let mut chi2 = 0.0;
        for (b, &count) in bins.iter().enumerate() {
            let lo = if b == 0 { f64::NEG_INFINITY } else { (b as f64 - 1.0 - half as f64) * width };
            let hi = if b == bins.len() - 1 { f64::INFINITY } else { (b as f64 - half as f64) * width };
            let expected = nf * (cdf(hi) - cdf(lo));
            chi2 += (count as f64 - expected).powi(2) / expected;
        }
        let dof = (bins.len() - 1) as f64;
        eprintln!("seed {seed}: mean {mean:.2e} var-1 {:.2e} m3 {:.2e} m4-3 {:.2e} lag {:.2e} χ² {chi2:.1}/{dof} tails {beyond_3_5} {beyond_4_5}", var - 1.0, s3 / nf, s4 / nf - 3.0, lag / nf);
        assert!(chi2 < dof + 6.0 * (2.0 * dof).sqrt(), "χ² = {chi2} for {dof} degrees of freedom");
        for (count, p) in
            [(beyond_3_5, erfc(3.5 / std::f64::consts::SQRT_2)), (beyond_4_5, erfc(4.5 / std::f64::consts::SQRT_2))]
        {
            let expected = nf * p;
            assert!((count as f64 - expected).abs() < 5.0 * expected.sqrt(), "{count} beyond, {expected} expected");
        }
    }
}

#[test]
fn presets_are_valid_and_errors_name_fields() {
    for (name, _) in crate::bench::preset::EMBEDDED {
        VirtualBench::from_preset_name(name, None).unwrap();
    }
    let text = crate::bench::preset::EMBEDDED[0].1.replace("sample_rate_hz: 10000.0", "sample_rate_hz: -1.0");
    let err = BenchPreset::from_ron_str(&text, std::path::Path::new("b.ron")).unwrap_err().to_string();
    assert_eq!(err, "b.ron: field `detector.sample_rate_hz`: expected a positive number, found -1");
    let err = BenchPreset::resolve("no-such-bench").unwrap_err().to_string();
    assert!(err.contains("expected one of: table2-ideal, femto-lab"), "{err}");
}
