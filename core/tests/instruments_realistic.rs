//! The drivers against emulators as strict and as imperfect as the instruments: a sweep timed by a
//! noisy, quantised wavelength monitor or by the laser's trigger output on a late-starting laser
//! measures the gap the virtual bench measures; the E-712 moves at the velocity set only with
//! velocity control on, connects without `FRF?`, records a long segment whole and at the servo
//! cycle it reads, and reads the quantity it records; the MCS types its channels by their sensors
//! and says when one is locked; the MCS2 is driven as its public drivers drive it.
//!
//! Emulated clocks run faster than real time where only bench time matters (the sweeps at rest,
//! the recorder, the E-712's motion); polled joints are not involved.

use photorobot_core::bench::{run_plan, Bench, BenchPreset, RunControl, VirtualBench};
use photorobot_core::hardware::controller_bench::{ControllerKind, Laser, LaserConfig, LaserFamily};
use photorobot_core::hardware::emulator::local::LocalEmulators;
use photorobot_core::hardware::emulator::smaract::ChannelKind;
use photorobot_core::hardware::emulator::{
    EmuClock, Fault, FaultSpec, LaserEmulator, LaserEmulatorConfig, Mcs2Emulator, Mcs2EmulatorConfig, PiEmulator,
    PiEmulatorConfig, SmarActEmulator, SmarActEmulatorConfig,
};
use photorobot_core::hardware::laser::connect_laser;
use photorobot_core::hardware::{
    ControllerBench, HardwareConfig, HwError, PiGcs, RecordTrigger, RecorderRequest, SmarActMcs, SmarActMcs2,
    StageController,
};
use photorobot_core::measure::{self, Measurement};
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::model::robot::RobotDescription;
use photorobot_core::plan::{JointTarget, Plan, Segment};
use photorobot_core::trace::Trace;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::Duration;

fn preset() -> BenchPreset {
    let mut p = BenchPreset::resolve("table2-ideal").unwrap();
    p.detector.sample_rate_hz = 2000.0;
    p
}

fn model(preset: &BenchPreset) -> PhaseModel {
    PhaseModel::new(
        RobotDescription::femto_6dof(),
        preset.truth,
        preset.optics,
        &preset.ambient,
        preset.laser.wavelength_nm,
    )
    .unwrap()
}

fn run(bench: &mut dyn Bench, plan: &Plan) -> photorobot_core::bench::PlanRun {
    let cancel = AtomicBool::new(false);
    let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
    run_plan(bench, plan, &mut control)
}

fn plan(segments: Vec<Segment>) -> Plan {
    Plan { name: "p".into(), description: String::new(), segments }
}

/// A realistic optical bench on a clock `scale` times real time: the emulated stages, a laser of
/// `family` behind its driver, the sweeps timed by the monitor or (`trigger`) the trigger output.
fn optical_bench(family: LaserFamily, trigger: bool, scale: f64) -> (LocalEmulators, LaserEmulator, ControllerBench) {
    let preset = preset();
    let robot = preset.robot_description().unwrap();
    let mut config = HardwareConfig { time_scale: scale, ..HardwareConfig::femto() };
    if trigger {
        config.photodiode.wavelength_input = None;
        config.photodiode.laser_trigger_input = Some("1".into());
    }
    let emus = LocalEmulators::start(&preset, 5, &robot, &config, 0, 0).unwrap();
    let laser_emu = LaserEmulator::start_on(0, emus.emu_laser(), LaserEmulatorConfig::new(family)).unwrap();
    let a = emus.addresses();
    config = config.with_addresses(&[(a[0].0.as_str(), a[0].1.clone()), (a[1].0.as_str(), a[1].1.clone())]);
    config.laser = Some(LaserConfig { family, address: laser_emu.addr().to_string(), timeout_s: 1.0 });
    let laser: Box<dyn Laser> = connect_laser(&config, preset.laser.wavelength_nm).unwrap();
    let bench = ControllerBench::connect(robot, config, preset.motion, preset.ambient, laser, emus.clock()).unwrap();
    (emus, laser_emu, bench)
}

fn gap_um(t: &Trace, m: &PhaseModel) -> (f64, f64) {
    match measure::analyse(t, m).unwrap_or_else(|e| panic!("{}: {e}", t.meta.label)) {
        Measurement::Sweep(s) => (s.gap.gap_um, s.gap.sigma_um),
        _ => panic!("a sweep expected"),
    }
}

/// The same sweep on the virtual bench and on the realistic emulated one measures the same gap:
/// a late start (40-60 ms, hundreds of pm at 20 nm/s) mistimed would put it L·Δλ/λ ≈ 50 nm off.
fn sweep_matches_the_virtual_bench(family: LaserFamily, trigger: bool, from_nm: f64, to_nm: f64) {
    let preset = preset();
    let m = model(&preset);
    let p = plan(vec![Segment::Sweep { from_nm, to_nm, rate_nm_per_s: 20.0, label: "sweep".into() }]);
    let virt = run(&mut VirtualBench::new(&preset, Some(5)).unwrap(), &p);
    virt.outcome.unwrap();
    let (_emus, _laser, mut bench) = optical_bench(family, trigger, 5.0);
    let hw = run(&mut bench, &p);
    hw.outcome.unwrap_or_else(|e| panic!("{family:?}: {e}"));
    let w = &hw.traces[0].wavelength_nm;
    assert!(w.windows(2).all(|p| (p[1] - p[0]) * (w[w.len() - 1] - w[0]) > 0.0), "{family:?}: strictly monotonic");
    let ((gh, sh), (gv, sv)) = (gap_um(&hw.traces[0], &m), gap_um(&virt.traces[0], &m));
    let diff_nm = (gh - gv) * 1e3;
    eprintln!("{family:?} (trigger {trigger}): gap {gh:.5} µm (σ {:.2} nm) vs virtual {gv:.5} µm (σ {:.2} nm): {diff_nm:+.2} nm", sh * 1e3, sv * 1e3);
    assert!(diff_nm.abs() < 3.0, "{family:?}: {diff_nm} nm off the virtual bench's gap");
}

#[test]
fn a_sweep_timed_by_a_noisy_quantised_wavelength_monitor_measures_the_gap() {
    sweep_matches_the_virtual_bench(LaserFamily::Keysight, false, 1540.0, 1580.0);
}

#[test]
fn a_sweep_timed_by_the_trigger_output_of_a_late_laser_measures_the_gap() {
    // The Santec starts 60 ms late and sweeps down as asked.
    sweep_matches_the_virtual_bench(LaserFamily::Santec, true, 1580.0, 1540.0);
}

/// On a clock 100× real time a turn of the loop that follows a segment (its polls, recorder reads
/// and the live view) lasts longer than a short sweep's run-out or a move's settling: the end of each segment
/// is stamped when the laser or the controller says it is done, so that every sweep is recorded to
/// its stop (the monitor gives its whole constant-speed part) and every move to its target.
#[test]
fn on_a_fast_clock_every_sweep_reaches_its_stop_and_every_move_its_target() {
    let (_emus, _laser, mut bench) = optical_bench(LaserFamily::Keysight, false, 100.0);
    let mut segments = vec![];
    for k in 0..4 {
        segments.push(Segment::Sweep { from_nm: 1550.0, to_nm: 1551.0, rate_nm_per_s: 10.0, label: format!("s{k}") });
        let to = JointTarget::default().with(2, if k % 2 == 0 { 10.0 } else { 0.0 });
        segments.push(Segment::Move { to, record: true, label: format!("m{k}"), through: false });
    }
    // A host as busy as a live view makes it: 3 ms of real time (0.3 s of bench time) spent on
    // the samples in every turn of the loop, between its clock reading and its questions.
    let cancel = AtomicBool::new(false);
    let mut slow_view = |_: &Trace, _: usize| std::thread::sleep(Duration::from_millis(3));
    let mut control = RunControl { cancel: &cancel, on_samples: &mut slow_view, on_progress: &mut |_| {} };
    let hw = run_plan(&mut bench, &plan(segments), &mut control);
    hw.outcome.unwrap();
    assert_eq!(hw.traces.len(), 8);
    // Two samples at 10 nm/s and 0.5 ms, and the monitor's noise.
    let tol_nm = 0.012;
    for (k, t) in hw.traces.iter().enumerate() {
        if k % 2 == 0 {
            let (lo, hi) = (t.wavelength_nm[0], *t.wavelength_nm.last().unwrap());
            assert!((lo - 1550.0).abs() < tol_nm && (hi - 1551.0).abs() < tol_nm, "{}: {lo}..{hi} nm", t.meta.label);
        } else {
            let want = if k % 4 == 1 { 10.0 } else { 0.0 };
            let last = *t.q3_um.last().unwrap();
            assert!((last - want).abs() < 0.01, "{}: ends at q3 = {last} µm, target {want}", t.meta.label);
        }
    }
}

/// A bench whose laser has neither its monitor nor its trigger output wired cannot time a sweep:
/// it says so and runs its plans without sweeps rather than guess from the start command.
#[test]
fn a_laser_without_a_time_base_sweeps_nothing() {
    let preset = preset();
    let robot = preset.robot_description().unwrap();
    let mut config = HardwareConfig::femto();
    config.photodiode.wavelength_input = None;
    let emus = LocalEmulators::start(&preset, 5, &robot, &config, 0, 0).unwrap();
    let laser_emu =
        LaserEmulator::start_on(0, emus.emu_laser(), LaserEmulatorConfig::new(LaserFamily::Keysight)).unwrap();
    let a = emus.addresses();
    config = config.with_addresses(&[(a[0].0.as_str(), a[0].1.clone()), (a[1].0.as_str(), a[1].1.clone())]);
    config.laser =
        Some(LaserConfig { family: LaserFamily::Keysight, address: laser_emu.addr().to_string(), timeout_s: 1.0 });
    let laser = connect_laser(&config, preset.laser.wavelength_nm).unwrap();
    let mut bench =
        ControllerBench::connect(robot, config, preset.motion, preset.ambient, laser, emus.clock()).unwrap();
    assert!(!bench.tunable_laser());
    let p = plan(vec![Segment::Sweep { from_nm: 1550.0, to_nm: 1551.0, rate_nm_per_s: 10.0, label: "s".into() }]);
    let e = run(&mut bench, &p).outcome.unwrap_err().to_string();
    assert!(e.contains("this bench cannot time a sweep"), "{e}");
}

fn pi(config: PiEmulatorConfig, scale: f64) -> (PiEmulator, PiGcs) {
    let emu = PiEmulator::start(EmuClock::new(scale), config).unwrap();
    let pi = PiGcs::connect("PI E-712", &emu.addr().to_string(), 1.0).unwrap();
    (emu, pi)
}

/// `VEL` acts with velocity control on: a 20 µm move at 10 µm/s is half-way after 1 s, not a step.
#[test]
fn the_e712_moves_at_the_velocity_set() {
    let (_emu, mut pi) = pi(PiEmulatorConfig::default(), 10.0);
    pi.set_velocity(1, 10.0).unwrap();
    pi.move_absolute(&[(1, 170.0)]).unwrap();
    std::thread::sleep(Duration::from_millis(100));
    let p = pi.positions(&[1]).unwrap()[0];
    assert!(p > 155.0 && p < 166.0, "about half-way (160 µm) after 1 s of bench time: {p} µm");
}

/// An E-712 that does not know `FRF?` (absolute sensors) connects, its axes referenced.
#[test]
fn an_e712_without_frf_connects_referenced() {
    let (_emu, mut pi) = pi(PiEmulatorConfig::default(), 10.0);
    assert!((0..3).all(|a| pi.is_referenced(a).unwrap()));
}

/// The recorder's input is read as it is recorded: `read_input` (`TNS?`) equals the recorded
/// samples of a constant input to the ADC's resolution.
#[test]
fn an_input_reads_what_the_recorder_records() {
    let (emu, mut pi) = pi(PiEmulatorConfig::default(), 10.0);
    emu.set_photodiode(Arc::new(|_| 2.0));
    let rec = pi.recorder().unwrap();
    let request = RecorderRequest {
        axes: vec![0],
        inputs: vec!["5".into()],
        sample_period_s: 0.0005,
        duration_s: 1.0,
        trigger: RecordTrigger::NextMove,
    };
    rec.arm(&request).unwrap();
    pi.move_absolute(&[(0, 150.0)]).unwrap();
    std::thread::sleep(Duration::from_millis(20));
    let rec = pi.recorder().unwrap();
    let n = rec.recorded_len().unwrap().min(100);
    let recorded = rec.read(0, n).unwrap().inputs[0].iter().sum::<f64>() / n as f64;
    let now = rec.read_input("5").unwrap();
    assert!((recorded - 2.0).abs() < 1e-3 && (now - recorded).abs() < 1e-3, "recorded {recorded}, read {now}");
}

/// A recorded dwell of `seconds` on realistic emulators whose E-712 has a `servo_s` servo cycle.
fn record_dwell(seconds: f64, servo_s: f64) -> Trace {
    let preset = preset();
    let robot = preset.robot_description().unwrap();
    let config = HardwareConfig { time_scale: 20.0, ..HardwareConfig::femto() };
    let emus = LocalEmulators::start(&preset, 5, &robot, &config, 0, 0).unwrap();
    let pi_config = PiEmulatorConfig { servo_cycle_s: servo_s, ..PiEmulatorConfig::default() };
    let pi = PiEmulator::start(emus.clock(), pi_config).unwrap();
    let a = emus.addresses();
    let config = config.with_addresses(&[("PI E-712", pi.addr().to_string()), (a[1].0.as_str(), a[1].1.clone())]);
    let mut bench =
        ControllerBench::connect(robot, config, preset.motion, preset.ambient, emus.laser(), emus.clock()).unwrap();
    let got = run(&mut bench, &plan(vec![Segment::Dwell { duration_s: seconds, record: true, label: "dwell".into() }]));
    got.outcome.unwrap();
    got.traces.into_iter().next().unwrap()
}

/// A 20 s recording at 0.5 ms is 40 000 samples: more than a table holds while the memory is split
/// in 8 (32 768), fewer once it is split in the 5 tables recorded (52 428). A 60 s one is recorded
/// whole at a slower rate. And the sample period follows the servo cycle the controller reports.
#[test]
fn long_recordings_fit_the_recorder_and_run_at_the_servo_cycle_read() {
    for (seconds, servo_s) in [(20.0, 20e-6), (60.0, 20e-6), (2.0, 50e-6)] {
        let t = record_dwell(seconds, servo_s);
        let span = t.t_s[t.len() - 1] - t.t_s[0];
        let dt = span / (t.len() - 1) as f64;
        eprintln!("{seconds} s, servo {servo_s} s: {} samples every {:.3} ms over {span:.3} s", t.len(), dt * 1e3);
        assert!((span - seconds).abs() < 0.02 * seconds, "{seconds} s recorded as {span} s");
        if seconds < 30.0 {
            assert!((dt - 0.0005).abs() < 1e-9, "{dt}");
        }
    }
}

/// The MCS's channels are typed by their sensors (`:GST`), not probed by error; a locked channel
/// (status 9) is a clear error, one opening an end effector (status 8) is not on target.
#[test]
fn mcs_channels_are_typed_by_their_sensors_and_a_locked_one_is_named() {
    let config = SmarActEmulatorConfig {
        channels: vec![(ChannelKind::Linear, 0.0, -5e6, 5e6), (ChannelKind::Rotary, 0.0, -12e6, 12e6)],
        sensor_types: vec![6, 16],
        ..SmarActEmulatorConfig::default()
    };
    let emu = SmarActEmulator::start(EmuClock::new(10.0), config).unwrap();
    let transcript = Arc::new(Mutex::new(Vec::new()));
    let mut mcs = SmarActMcs::connect("MCS", &emu.addr().to_string(), 1.0, &[]).unwrap();
    assert_eq!(mcs.sensor_types(), [6, 16]);
    assert_eq!(mcs.axes()[0].unit.symbol(), "µm");
    assert_eq!(mcs.axes()[1].unit.symbol(), "°");
    assert!(mcs.identification().contains("linear sensor 6, rotary sensor 16"), "{}", mcs.identification());
    mcs.set_transcript(Some(transcript.clone()));
    mcs.reconnect().unwrap();
    let t = transcript.lock().unwrap().clone();
    assert!(
        t.iter().any(|l| l == "> :GST1") && !t.iter().any(|l| l.starts_with("> :GP") || l.starts_with("> :GA")),
        "{t:?}"
    );
    emu.set_locked(1, true);
    let e = mcs.on_target(&[1]).unwrap_err().to_string();
    assert!(e.contains("MCS error 146") && e.contains("Movement locked"), "{e}");
    let e = mcs.move_absolute(&[(1, 1.0)]).unwrap_err().to_string();
    assert!(e.contains("Movement locked"), "{e}");
}

/// The MCS2 over its ASCII interface: channels typed, absolute moves in n°, the state bits, a
/// stop on an end stop named, refused commands reported from the error queue.
#[test]
fn the_mcs2_moves_reports_and_refuses_as_its_drivers_describe() {
    let emu = Mcs2Emulator::start(EmuClock::new(10.0), Mcs2EmulatorConfig::default()).unwrap();
    let mut mcs = SmarActMcs2::connect("MCS2", &emu.addr().to_string(), 1.0, &[(-12.0, 12.0); 3]).unwrap();
    assert_eq!(mcs.axes().len(), 3);
    assert!(mcs.axes().iter().all(|a| a.unit.symbol() == "°"));
    assert_eq!(mcs.identification(), "SmarAct MCS2, serial MCS2-00001234, 3 channels (rotary, rotary, rotary)");
    mcs.set_velocity(0, 2.0).unwrap();
    mcs.move_absolute(&[(0, -4.0)]).unwrap();
    assert_eq!(mcs.on_target(&[0]).unwrap(), [false]);
    mcs.wait_on_target(&[0], 5.0).unwrap();
    assert!((mcs.positions(&[0]).unwrap()[0] + 4.0).abs() < 1e-9);
    assert!(mcs.is_referenced(0).unwrap());
    let e = mcs.move_absolute(&[(0, 20.0)]).unwrap_err().to_string();
    assert!(e.contains("outside the travel range"), "{e}");
    emu.inject(FaultSpec::on_command(":CHAN1:STAT?", 1, Fault::Limit));
    mcs.move_absolute(&[(1, 3.0)]).unwrap();
    let e = loop {
        match mcs.on_target(&[1]) {
            Ok(_) => std::thread::sleep(Duration::from_millis(5)),
            Err(e) => break e,
        }
    };
    assert!(matches!(e, HwError::LimitReached { .. }) && e.to_string().contains("end stop reached"), "{e}");
    mcs.stop().unwrap();
    assert!(!emu.any_moving());
}

/// A bench on an MCS2 (the hardware file's `kind: SmarActMcs2`) moves its wrist joints.
#[test]
fn a_bench_on_an_mcs2_moves_its_wrist() {
    let preset = preset();
    let robot = preset.robot_description().unwrap();
    let mut config = HardwareConfig { time_scale: 5.0, ..HardwareConfig::femto() };
    config.controllers[1].kind = ControllerKind::SmarActMcs2;
    let emus = LocalEmulators::start(&preset, 5, &robot, &config, 0, 0).unwrap();
    let a = emus.addresses();
    let config = config.with_addresses(&[(a[0].0.as_str(), a[0].1.clone()), (a[1].0.as_str(), a[1].1.clone())]);
    let mut bench =
        ControllerBench::connect(robot, config, preset.motion, preset.ambient, emus.laser(), emus.clock()).unwrap();
    assert!(
        bench.identification().iter().any(|(_, id)| id.starts_with("SmarAct MCS2")),
        "{:?}",
        bench.identification()
    );
    let to = [0.0, 0.0, 0.0, 1.0, -1.0, 2.0];
    let got = run(
        &mut bench,
        &plan(vec![Segment::Move { to: JointTarget::all(to), record: true, label: "wrist".into(), through: false }]),
    );
    got.outcome.unwrap();
    let q = bench.position_display();
    assert!((3..6).all(|j| (q[j] - to[j]).abs() < 1e-6), "{q:?}");
}

/// Where an axis's move that started after `after_s` stands a tenth of the way through its
/// duration, as a fraction of its distance (emulated time, read from the emulator's own axis): a
/// straight ramp gives 0.1, a move that first accelerates less.
fn fraction_at_a_tenth(axes: &photorobot_core::hardware::emulator::SharedAxes, axis: usize, after_s: f64) -> f64 {
    let axes = axes.lock().unwrap();
    let a = &axes[axis];
    let (from, to) = (a.position_at(after_s), a.target_at(after_s + 1e3));
    let bisect = |mut lo: f64, mut hi: f64, moved: &dyn Fn(f64) -> bool| {
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if moved(mid) {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        hi
    };
    let start = bisect(after_s, after_s + 1e3, &|t| a.position_at(t) != from);
    let end = bisect(start, start + 1e3, &|t| !a.moving_at(t));
    (a.position_at(start + 0.1 * (end - start)) - from) / (to - from)
}

/// Every stage moves as a straight ramp at the speed set, so that the joints of one segment,
/// each given a speed in proportion to its distance, stay on their straight line in joint space
/// between two waypoints: the E-712's target ramps at its slew rate (it has no acceleration), and
/// the MCS and MCS2 drivers switch acceleration control off at connect and read it back. (With a
/// goniometer accelerating at 20 °/s² beside the piezo stage's ramps, a validation rotation's gap
/// swung 180 nm between waypoints.)
#[test]
fn every_stage_moves_as_a_straight_ramp_at_the_speed_set() {
    let (emu, mut pi) = pi(PiEmulatorConfig::default(), 1.0);
    let clock = EmuClock::new(1.0);
    pi.set_velocity(0, 100.0).unwrap();
    let t0 = clock.now_s();
    pi.move_absolute(&[(0, 170.0)]).unwrap();
    let f = fraction_at_a_tenth(&emu.axes(), 0, t0 - 1.0);
    assert!((f - 0.1).abs() < 0.005, "E-712, 20 µm at 100 µm/s: {f} of the way a tenth through");

    let emu = SmarActEmulator::start(EmuClock::new(1.0), SmarActEmulatorConfig::default()).unwrap();
    let transcript = Arc::new(Mutex::new(Vec::new()));
    let mut mcs = SmarActMcs::connect("MCS", &emu.addr().to_string(), 1.0, &[]).unwrap();
    mcs.set_transcript(Some(transcript.clone()));
    mcs.reconnect().unwrap();
    let t = transcript.lock().unwrap().clone();
    assert!(t.iter().any(|l| l == "> :SCLA0,0") && t.iter().any(|l| l == "< :CLA0,0"), "set and read back: {t:?}");
    mcs.set_velocity(0, 1.0).unwrap();
    mcs.move_absolute(&[(0, 0.24)]).unwrap();
    let f = fraction_at_a_tenth(&emu.axes(), 0, 0.0);
    assert!((f - 0.1).abs() < 0.005, "MCS goniometer, 0.24° at 1 °/s: {f} of the way a tenth through");

    let emu = Mcs2Emulator::start(EmuClock::new(1.0), Mcs2EmulatorConfig::default()).unwrap();
    let mut mcs2 = SmarActMcs2::connect("MCS2", &emu.addr().to_string(), 1.0, &[(-12.0, 12.0); 3]).unwrap();
    mcs2.set_velocity(1, 1.0).unwrap();
    mcs2.move_absolute(&[(1, 0.24)]).unwrap();
    let f = fraction_at_a_tenth(&emu.axes(), 1, 0.0);
    assert!((f - 0.1).abs() < 0.005, "MCS2 goniometer, 0.24° at 1 °/s: {f} of the way a tenth through");
}
