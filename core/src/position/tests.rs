//! Moves on the virtual bench planned with its true extrinsics: the truth reached, the proof's
//! measurement against it, and the refusals that move nothing.

use super::*;
use crate::bench::{BenchPreset, VirtualBench};
use std::sync::atomic::AtomicBool;

fn placement(preset: &BenchPreset) -> Placement {
    let model = PhaseModel::of_preset(preset, preset.truth).unwrap();
    let exact = Uncertainty { sigma: [Some(0.0); 8], correlation: [[0.0; 8]; 8] };
    Placement::new(&model, preset.truth, Some(exact), &[], "the bench's truth").unwrap()
}

fn run(bench: &mut VirtualBench, p: &Placement, target: &Target, refs: &[Reference]) -> Result<MoveRecord, MoveError> {
    run_with(bench, p, target, refs, ProofOptions::default())
}

fn run_with(
    bench: &mut VirtualBench,
    p: &Placement,
    target: &Target,
    refs: &[Reference],
    options: ProofOptions,
) -> Result<MoveRecord, MoveError> {
    let cancel = AtomicBool::new(false);
    let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
    move_to(bench, p, target, false, refs, options, &mut control)
}

/// The true gap and tilt at the bench's joints (the preset's hidden truth).
fn truth(preset: &BenchPreset, bench: &VirtualBench) -> (f64, f64) {
    let m = PhaseModel::of_preset(preset, preset.truth).unwrap();
    m.gap_and_tilt(&bench.position_display()).unwrap()
}

/// Planned with the truth, the lamella reaches the target exactly (the IGM's round-off), and
/// the sweep at the end measures its gap within 3σ of the truth: the move is confirmed.
#[test]
fn a_move_with_the_true_extrinsics_reaches_its_target_and_the_sweep_confirms_it() {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let p = placement(&preset);
    let mut bench = VirtualBench::new(&preset, Some(5)).unwrap();
    for target in [
        Target { gap_um: 850.0, tilt_deg: [0.0, 0.0], lateral_um: [-50.0, -60.0], rotation_deg: 0.0 },
        Target { gap_um: 960.0, tilt_deg: [1.5, -1.0], lateral_um: [-120.0, -20.0], rotation_deg: 20.0 },
    ] {
        let r = run(&mut bench, &p, &target, &[]).unwrap();
        let (gap_um, tilt_rad) = truth(&preset, &bench);
        let m = r.measurement.clone().unwrap();
        eprintln!("{}: true gap {gap_um:.6} µm; {}", target.describe(), r.note);
        assert!((gap_um - target.gap_um).abs() < 1e-6, "true gap {gap_um}");
        // acos near 1 loses half the digits: 1e-8 rad at a zero tilt.
        assert!((tilt_rad - target.tilt_angle_rad()).abs() < 1e-7, "{tilt_rad}");
        assert!((m.gap_um - gap_um).abs() * 1e3 < 3.0 * m.sigma_nm, "measured {} ± {} nm", m.gap_um, m.sigma_nm);
        assert_eq!(r.verdict, Verdict::Confirmed, "{}", r.note);
        let t = r.tilt.expect("the tilt measured at the end pose");
        eprintln!(
            "tilt from the contrast {:.5} ± {:.5}° ({:?} ± {:?}), true {:.5}°",
            t.tilt_deg,
            t.sigma_deg,
            t.components_deg,
            t.components_sigma_deg,
            tilt_rad.to_degrees()
        );
        assert!((t.tilt_deg - tilt_rad.to_degrees()).abs() <= 3.0 * t.sigma_deg, "{t:?}");
    }
}

/// A target out of the stages' reach and a tilt beyond the goniometers are refused with the
/// joint and its limit, and the bench does not move (its joints and its clock unchanged).
#[test]
fn a_target_out_of_reach_is_refused_and_nothing_moves() {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let p = placement(&preset);
    let mut bench = VirtualBench::new(&preset, Some(5)).unwrap();
    let far = Target { gap_um: 50.0, tilt_deg: [0.0, 0.0], lateral_um: [0.0, 0.0], rotation_deg: 0.0 };
    let e = run(&mut bench, &p, &far, &[]).unwrap_err().to_string();
    assert!(
        e.contains("joint q2") && e.contains("above its upper limit 150.000 µm") && e.contains("nothing moved"),
        "{e}"
    );
    let steep = Target { gap_um: 900.0, tilt_deg: [14.0, 0.0], ..far };
    let e = run(&mut bench, &p, &steep, &[]).unwrap_err().to_string();
    assert!(e.contains("joint q4") || e.contains("goniometers"), "{e}");
    assert_eq!(bench.position_display(), [0.0; 6]);
    assert_eq!(bench.clock_s(), 0.0);
}

/// Without a tunable laser the path starts at a pose whose gap a sweep measured, and the
/// fringes along it give the gap at the end, within 3σ of the truth.
#[test]
fn without_a_tunable_laser_the_fringes_from_a_measured_pose_prove_the_move() {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let p = placement(&preset);
    // The reference: a sweep at q = 0 on the bench with its laser.
    let mut bench = VirtualBench::new(&preset, Some(6)).unwrap();
    let sweep = Plan {
        name: "sweep".into(),
        description: String::new(),
        segments: vec![Segment::Sweep { from_nm: 1520.0, to_nm: 1600.0, rate_nm_per_s: 20.0, label: "sweep".into() }],
    };
    let cancel = AtomicBool::new(false);
    let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
    let traces = run_plan(&mut bench, &sweep, &mut control).traces;
    let reference = Reference::of_sweep(&traces[0], &p.model, "a test sweep").unwrap();
    let mut fixed = preset.clone();
    fixed.laser.tunable = false;
    let mut bench = VirtualBench::new(&fixed, Some(7)).unwrap();
    let target = Target { gap_um: 870.0, tilt_deg: [0.5, 0.0], lateral_um: [-90.0, -80.0], rotation_deg: 0.0 };
    let r = run(&mut bench, &p, &target, std::slice::from_ref(&reference)).unwrap();
    let (gap_um, _) = truth(&preset, &bench);
    let m = r.measurement.clone().unwrap();
    eprintln!("reference {:.4} ± {:.2} nm; {}", reference.gap_um, reference.sigma_nm, r.note);
    assert!(m.method.starts_with("fringes along the path"), "{}", m.method);
    assert!(
        (m.gap_um - gap_um).abs() * 1e3 < 3.0 * m.sigma_nm,
        "measured {} ± {} nm, true {gap_um}",
        m.gap_um,
        m.sigma_nm
    );
    assert_eq!(r.verdict, Verdict::Confirmed, "{}", r.note);
}

/// A tilt near the goniometers' travel leaves no room for the rotations that read it: the gap is
/// read at the requested tilt, the record says so, and the stages stand at the target.
#[test]
fn a_tilt_the_rotations_cannot_reach_is_read_at_the_request_and_said_so() {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let p = placement(&preset);
    let mut bench = VirtualBench::new(&preset, Some(5)).unwrap();
    let target = Target { gap_um: 900.0, tilt_deg: [8.5, 0.0], lateral_um: [-60.0, -60.0], rotation_deg: 0.0 };
    let r = run(&mut bench, &p, &target, &[]).unwrap();
    eprintln!("{}", r.note);
    assert!(r.tilt.is_none());
    assert!(r.note.contains("the gap read at the requested tilt, which was not measured: "), "{}", r.note);
    assert!(r.note.contains("above its upper limit"), "{}", r.note);
    assert_eq!(r.model_only, MODEL_ONLY);
    assert_eq!(r.verdict, Verdict::Confirmed, "{}", r.note);
    let (gap_um, _) = truth(&preset, &bench);
    assert!((gap_um - target.gap_um).abs() < 1e-6, "true gap {gap_um}");
}

/// Stopped while the tilt is measured (after the sweep at the end): the move is recorded as
/// stopped, and the gap the sweep measured is kept in the record.
#[test]
fn a_stop_during_the_tilt_measurement_keeps_the_measured_gap() {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let p = placement(&preset);
    let mut bench = VirtualBench::new(&preset, Some(5)).unwrap();
    let target = Target { gap_um: 880.0, tilt_deg: [0.5, 0.0], lateral_um: [-60.0, -60.0], rotation_deg: 0.0 };
    let cancel = AtomicBool::new(false);
    let (end_nm, last_sample) = (proof::SWEEP_NM.1, std::cell::Cell::new(0.0));
    let mut on_samples = |t: &Trace, _: usize| {
        if t.meta.label == proof::SWEEP_LABEL {
            last_sample.set(t.wavelength_nm.last().copied().unwrap_or(0.0));
        }
    };
    // The stop comes from the first check after the sweep's last sample.
    let mut on_progress = |_: f64| {
        if last_sample.get() >= end_nm - 1e-9 {
            cancel.store(true, std::sync::atomic::Ordering::Relaxed);
        }
    };
    let mut control = RunControl { cancel: &cancel, on_samples: &mut on_samples, on_progress: &mut on_progress };
    let r = move_to(&mut bench, &p, &target, false, &[], ProofOptions::default(), &mut control).unwrap();
    eprintln!("{:?}: {}", r.verdict, r.note);
    assert_eq!(r.verdict, Verdict::Stopped, "{}", r.note);
    assert!(r.note.starts_with("stopped while the tilt was measured at the end pose; measured gap"), "{}", r.note);
    let m = r.measurement.expect("the sweep's gap kept");
    assert!((m.gap_um - 880.0).abs() < 0.01, "{m:?}");
    assert!(r.tilt.is_none());
}

/// Asked not to measure the tilt, a move reads its gap at the requested tilt and says so, in
/// less bench time.
#[test]
fn a_move_asked_not_to_measure_the_tilt_reads_the_gap_at_the_request() {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let p = placement(&preset);
    let target = Target { gap_um: 880.0, tilt_deg: [0.5, 0.0], lateral_um: [-60.0, -60.0], rotation_deg: 0.0 };
    let mut times = Vec::new();
    for tilt in [true, false] {
        let mut bench = VirtualBench::new(&preset, Some(5)).unwrap();
        let r = run_with(&mut bench, &p, &target, &[], ProofOptions { sweeps: true, tilt }).unwrap();
        assert_eq!(r.verdict, Verdict::Confirmed, "{}", r.note);
        assert_eq!(r.tilt.is_some(), tilt);
        assert_eq!(r.note.contains("the gap read at the requested tilt, which was not measured: not asked for"), !tilt);
        times.push(r.bench_time_s);
    }
    eprintln!("bench time with the tilt measured {:.1} s, without {:.1} s", times[0], times[1]);
    assert!(times[1] < times[0] - 5.0, "{times:?}");
}
