//! The tunable-laser emulators and driver on loopback: an independent client (a plain
//! `TcpStream`, not the driver) checks each emulator's replies as the manuals describe them, the
//! driver runs sweeps against each realistic emulator (its latency, run-up, allowed speeds and
//! direction rules), and a fault matrix checks that every laser fault gives a clear error in
//! bounded time, with the stages stopped and the recorded samples kept when a bench run is
//! involved.

use photorobot_core::bench::{run_plan, BenchError, BenchPreset, RunControl, RunError};
use photorobot_core::hardware::controller_bench::{Laser, LaserConfig, LaserFamily};
use photorobot_core::hardware::emulator::{
    EmuClock, Fault, FaultSpec, LaserEmulator, LaserEmulatorConfig, LocalEmulators, Trigger,
};
use photorobot_core::hardware::laser::{connect_laser, ScpiLaser};
use photorobot_core::hardware::{ControllerBench, HardwareConfig, HwError};
use photorobot_core::plan::{Plan, Segment};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// A raw SCPI client written from the manuals, independent of the driver.
struct Raw {
    w: TcpStream,
    r: BufReader<TcpStream>,
    /// The terminator of commands and replies: LF (Keysight), CR (Santec over LAN).
    end: u8,
}

impl Raw {
    fn new(emu: &LaserEmulator, end: u8) -> Self {
        let s = TcpStream::connect(emu.addr()).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        Raw { w: s.try_clone().unwrap(), r: BufReader::new(s), end }
    }
    fn send(&mut self, c: &str) {
        self.w.write_all(&[c.as_bytes(), &[self.end]].concat()).unwrap();
    }
    fn ask(&mut self, c: &str) -> String {
        self.send(c);
        let mut l = Vec::new();
        self.r.read_until(self.end, &mut l).unwrap();
        assert_eq!(l.last(), Some(&self.end), "{c}: {l:?}");
        assert!(!l[..l.len() - 1].contains(&b'\n'), "{c}: one terminator only: {l:?}");
        String::from_utf8(l).unwrap().trim_end().to_string()
    }
    /// `#<n><len><bytes>\n`, parsed by hand.
    fn ask_block(&mut self, c: &str) -> Vec<u8> {
        self.send(c);
        let mut head = [0u8; 2];
        self.r.read_exact(&mut head).unwrap();
        assert_eq!(head[0], b'#');
        let n = (head[1] - b'0') as usize;
        let mut len = vec![0u8; n];
        self.r.read_exact(&mut len).unwrap();
        let len: usize = std::str::from_utf8(&len).unwrap().parse().unwrap();
        let mut data = vec![0u8; len];
        self.r.read_exact(&mut data).unwrap();
        // The Keysight ends the block with its terminator; the Santec sends nothing after it.
        if self.end == b'\n' {
            let mut end = [0u8];
            self.r.read_exact(&mut end).unwrap();
            assert_eq!(end[0], b'\n');
        }
        data
    }
    fn wait_sweep(&mut self, q: &str, idle: &str) {
        let start = Instant::now();
        while self.ask(q) != idle {
            assert!(start.elapsed() < Duration::from_secs(5), "sweep never ended");
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

fn emulator(family: LaserFamily, scale: f64) -> LaserEmulator {
    LaserEmulator::start(EmuClock::new(scale), 1550.0, LaserEmulatorConfig::new(family)).unwrap()
}

/// The Keysight as its programming guide describes it: units on the numbers, lambda logging only
/// with the trigger output at STF and amplitude modulation off, a start below the stop, the log
/// ready once `FLAG?` is even.
#[test]
fn an_independent_client_drives_the_keysight_emulator() {
    let emu = emulator(LaserFamily::Keysight, 10.0);
    let mut c = Raw::new(&emu, b'\n');
    assert!(c.ask("*IDN?").starts_with("Keysight Technologies,8164B"));
    assert_eq!(c.ask(":SYST:ERR?"), "+0,\"No error\"");
    c.send(":SOUR0:WAV:FROB 1");
    c.send(":SOUR0:WAV 9e-6");
    assert_eq!(c.ask(":SYST:ERR?"), "-113,\"Undefined header\"");
    assert_eq!(c.ask(":SYST:ERR?"), "-222,\"Data out of range\"");
    assert_eq!(c.ask(":SYST:ERR?"), "+0,\"No error\"");
    c.send(":SOUR0:WAV 1.5405e-6");
    assert_eq!(c.ask(":SOUR0:WAV?").parse::<f64>().unwrap(), 1.5405e-6);
    // "1500NM, 1.5UM and 1.5E-6M are all equivalent" (guide, chapter 1).
    c.send(":SOUR0:WAV 1555.5NM");
    assert_eq!(c.ask(":SYST:ERR?"), "+0,\"No error\"");
    assert!((c.ask(":SOUR0:WAV?").parse::<f64>().unwrap() - 1.5555e-6).abs() < 1e-15);
    let configure = [
        ":SOUR0:WAV:SWE:MODE CONT",
        ":SOUR0:WAV:SWE:REP ONEW",
        ":SOUR0:WAV:SWE:STAR 1540NM",
        ":SOUR0:WAV:SWE:STOP 1.541e-6",
        ":SOUR0:WAV:SWE:SPE 1NM/S",
        ":SOUR0:WAV:SWE:STEP 10PM",
        ":SOUR0:WAV:SWE:CYCL 1",
        ":TRIG0:OUTP STF",
        ":SOUR0:WAV:SWE:LLOG 1",
        ":SOUR0:POW 1.5MW",
    ];
    for cmd in configure {
        c.send(cmd);
        assert_eq!(c.ask(":SYST:ERR?"), "+0,\"No error\"", "{cmd}");
    }
    // Amplitude modulation is on: lambda logging refuses, and the start says so.
    assert!(c.ask(":SOUR0:WAV:SWE:CHEC?").starts_with("5,"), "modulation on");
    c.send(":SOUR0:WAV:SWE 1");
    assert_eq!(c.ask(":SYST:ERR?"), "-221,\"Settings conflict\"");
    assert_eq!(c.ask(":SOUR0:WAV:SWE:LLOG?"), "0", "lambda logging turned off by the refused start");
    for cmd in [":SOUR0:AM:STAT OFF", ":SOUR0:WAV:SWE:LLOG 1"] {
        c.send(cmd);
    }
    assert_eq!(c.ask(":SOUR0:WAV:SWE:CHEC?"), "0,OK");
    c.send(":SOUR0:WAV:SWE 1");
    assert_eq!(c.ask(":SYST:ERR?"), "+0,\"No error\"");
    assert_eq!(c.ask(":SOUR0:WAV:SWE?"), "+1");
    assert_eq!(c.ask(":SOUR0:WAV:SWE:FLAG?"), "+0");
    c.wait_sweep(":SOUR0:WAV:SWE?", "+0");
    // The log is ready after the sweep's post-processing, when FLAG? turns even and non-zero.
    c.wait_sweep(":SOUR0:WAV:SWE:FLAG?", "+2");
    assert_eq!(c.ask(":SOUR0:WAV:SWE:LLOG?"), "0", "lambda logging is disabled at the end of a sweep");
    assert_eq!(c.ask(":SOUR0:READ:POIN? LLOG"), "+101");
    let data = c.ask_block(":SOUR0:READ:DATA? LLOG");
    assert_eq!(data.len(), 101 * 8);
    let m: Vec<f64> = data.chunks(8).map(|b| f64::from_le_bytes(b.try_into().unwrap())).collect();
    assert!((m[0] - 1.540e-6).abs() < 1e-15 && (m[100] - 1.541e-6).abs() < 1e-15, "{} {}", m[0], m[100]);
    assert!(m.windows(2).all(|w| ((w[1] - w[0]) - 1e-11).abs() < 1e-15));
    assert_eq!(c.ask(":SOUR0:POW?"), "1.5");
    // A sweep down (start above stop) is refused.
    for cmd in [":SOUR0:WAV:SWE:STAR 1541NM", ":SOUR0:WAV:SWE:STOP 1540NM"] {
        c.send(cmd);
    }
    assert!(c.ask(":SOUR0:WAV:SWE:CHEC?").starts_with("2,"));
}

/// The Santec as its samples and QMI describe it: replies ended by a bare CR, the SCPI command set
/// (metres) until Legacy is selected (nm), its eight sweep speeds, the log as 0.1 pm integers.
#[test]
fn an_independent_client_drives_the_santec_emulator() {
    let emu = emulator(LaserFamily::Santec, 10.0);
    let mut c = Raw::new(&emu, b'\r');
    assert!(c.ask("*IDN?").starts_with("SANTEC,TSL-570"));
    assert_eq!(c.ask(":SYST:ERR?"), "0,\"No error\"");
    assert_eq!(c.ask(":SYST:COMM:COD?"), "1", "the SCPI command set: unitless values are metres");
    c.send(":WAV 1550");
    assert_eq!(c.ask(":SYST:ERR?"), "-222,\"Data out of range\"", "1550 m");
    c.send(":SYST:COMM:COD 0");
    assert_eq!(c.ask(":SYST:COMM:COD?"), "0");
    c.send(":SOUR0:WAV 1550");
    assert_eq!(c.ask(":SYST:ERR?"), "-113,\"Undefined header\"");
    c.send(":WAV:SWE:STAT 1");
    assert_eq!(c.ask(":SYST:ERR?"), "-221,\"Settings conflict\"", "a sweep before its mode is set");
    c.send(":WAVelength 1551.25");
    assert_eq!(c.ask(":WAV?"), "1551.25");
    c.send(":WAV:SWE:SPE 3");
    assert_eq!(c.ask(":SYST:ERR?"), "-222,\"Data out of range\"", "3 nm/s is not one of its speeds");
    for cmd in [
        ":WAV:SWE:MOD 1",
        ":WAV:SWE:STAR 1541.0000",
        ":WAV:SWE:STOP 1540.0000",
        ":WAV:SWE:SPE 1",
        ":TRIG:OUTP 3",
        ":TRIG:OUTP:STEP 0.0100",
        ":POW:UNIT 1",
        ":POW 2",
        ":WAV:SWE:STAT 1",
    ] {
        c.send(cmd);
        assert_eq!(c.ask(":SYST:ERR?"), "0,\"No error\"", "{cmd}");
    }
    assert_ne!(c.ask(":WAV:SWE:STAT?"), "0", "preparing or running");
    c.wait_sweep(":WAV:SWE:STAT?", "0");
    assert_eq!(c.ask(":READout:POINts?"), "101");
    let data = c.ask_block(":READout:DATa?");
    let v: Vec<u32> = data.chunks(4).map(|b| u32::from_le_bytes(b.try_into().unwrap())).collect();
    assert_eq!(v.len(), 101);
    // Units of 0.1 pm, sweeping down.
    assert_eq!((v[0], v[1], v[100]), (15_410_000, 15_409_900, 15_400_000));
}

/// The driver against each realistic emulator: a wavelength set and read back, a sweep set up by
/// the family's rules and read back (the Keysight sweeps a downward span upwards; the Santec takes
/// the allowed speed below the one asked; both keep the log under their trigger rate), its log.
#[test]
fn the_driver_sweeps_each_emulated_laser_and_reads_its_log() {
    for (family, rate, want_rate, want_from) in
        [(LaserFamily::Keysight, 50.0, 50.0, 1555.0), (LaserFamily::Santec, 60.0, 50.0, 1560.0)]
    {
        let emu = emulator(family, 10.0);
        let mut laser = ScpiLaser::connect(family, &emu.addr().to_string(), 1.0, 1550.0).unwrap();
        laser.set_wavelength(1547.1234).unwrap();
        assert!((laser.wavelength_nm().unwrap() - 1547.1234).abs() < 1e-9, "{family:?}");
        laser.set_power_mw(1.0).unwrap();
        let setup = laser.prepare_sweep(1560.0, 1555.0, rate).unwrap();
        assert_eq!((setup.from_nm, setup.rate_nm_per_s), (want_from, want_rate), "{family:?}");
        let max_trigger_hz = if family == LaserFamily::Keysight { 40e3 } else { 20e3 };
        assert!(setup.rate_nm_per_s / setup.step_nm <= max_trigger_hz, "{family:?}: {setup:?}");
        laser.start_sweep(setup.from_nm, setup.to_nm, setup.rate_nm_per_s).unwrap();
        assert!(laser.sweep_running().unwrap());
        let t = Instant::now();
        while laser.sweep_running().unwrap() {
            assert!(t.elapsed() < Duration::from_secs(5));
        }
        let log = laser.lambda_log().unwrap().unwrap();
        assert_eq!(log.step_nm, setup.step_nm);
        assert_eq!(log.wavelengths_nm.len(), log.expected_points(), "{family:?}");
        assert!((log.wavelengths_nm[0] - setup.from_nm).abs() < 1e-9, "{family:?}");
        assert!((log.wavelengths_nm.last().unwrap() - setup.to_nm).abs() <= log.step_nm, "{family:?}");
        // Half-way through in time is half-way through in wavelength.
        let mid = log.wavelength_at(0.5 * 5.0 / setup.rate_nm_per_s).unwrap();
        assert!((mid - 1557.5).abs() < 1e-6, "{family:?}: {mid}");
    }
}

/// Each laser fault gives a clear error naming the laser and the command, in bounded time.
#[test]
fn laser_faults_give_clear_errors_in_bounded_time() {
    type Check = fn(&HwError) -> bool;
    let cases: [(&str, Fault, [&str; 2], Check); 4] = [
        ("drop", Fault::DropConnection, [":SOUR0:WAV:SWE 1", ":WAV:SWE:STAT 1"], |e| {
            matches!(e, HwError::Disconnected { .. })
        }),
        ("no reply", Fault::NoReply, [":SYST:ERR?", ":SYST:ERR?"], |e| matches!(e, HwError::Timeout { .. })),
        ("error code", Fault::ErrorCode(-222), [":SOUR0:WAV:SWE:STAR", ":WAV:SWE:STAR"], |e| {
            e.to_string().contains("failed: laser error -222, \"Injected error\"")
        }),
        ("silent query", Fault::ErrorCode(-221), [":SOUR0:WAV:SWE?", ":WAV:SWE:STAT?"], |e| {
            e.to_string().contains("laser error -221")
        }),
    ];
    for family in [LaserFamily::Keysight, LaserFamily::Santec] {
        for (what, fault, at, check) in &cases {
            let emu = emulator(family, 10.0);
            let mut laser = ScpiLaser::connect(family, &emu.addr().to_string(), 0.3, 1550.0).unwrap();
            let at = at[usize::from(family == LaserFamily::Santec)].to_string();
            emu.inject(FaultSpec::on_command(&at, 0, fault.clone()));
            let t = Instant::now();
            let r = laser.start_sweep(1550.0, 1551.0, 10.0).and_then(|()| laser.sweep_running().map(|_| ()));
            let e = r.expect_err(what);
            assert!(t.elapsed() < Duration::from_secs(2), "{family:?} {what}: took {:?}", t.elapsed());
            assert!(check(&e), "{family:?} {what}: {e}");
            assert!(e.to_string().starts_with(&format!("{family:?} laser: ")), "{e}");
            assert_eq!(emu.fired().len(), 1, "{family:?} {what}");
        }
    }
    // The wrong family is refused at connection, naming what was expected.
    let emu = emulator(LaserFamily::Keysight, 1.0);
    let e = ScpiLaser::connect(LaserFamily::Santec, &emu.addr().to_string(), 0.5, 1550.0).err().unwrap();
    assert!(e.to_string().contains("an identification naming santec"), "{e}");
}

/// The emulated stages and an emulated laser of `family` behind its driver, on one optical bench.
fn bench(family: LaserFamily) -> (LocalEmulators, LaserEmulator, ControllerBench) {
    let preset = BenchPreset::resolve("table2-ideal").unwrap();
    let robot = preset.robot_description().unwrap();
    let mut config = HardwareConfig::femto();
    // No wavelength monitor: the laser's trigger output on the E-712's digital input 1 starts the
    // recorder at its first logged point, and the samples take their wavelength from the log.
    config.photodiode.wavelength_input = None;
    config.photodiode.laser_trigger_input = Some("1".into());
    let emus = LocalEmulators::start(&preset, 3, &robot, &config, 0, 0).unwrap();
    let laser_emu = LaserEmulator::start_on(0, emus.emu_laser(), LaserEmulatorConfig::new(family)).unwrap();
    let a = emus.addresses();
    config = config.with_addresses(&[(a[0].0.as_str(), a[0].1.clone()), (a[1].0.as_str(), a[1].1.clone())]);
    config.laser = Some(LaserConfig { family, address: laser_emu.addr().to_string(), timeout_s: 0.5 });
    let laser: Box<dyn Laser> = connect_laser(&config, preset.laser.wavelength_nm).unwrap();
    let bench = ControllerBench::connect(robot, config, preset.motion, preset.ambient, laser, emus.clock()).unwrap();
    (emus, laser_emu, bench)
}

fn sweep_plan() -> Plan {
    Plan {
        name: "sweep".into(),
        description: String::new(),
        segments: vec![Segment::Sweep { from_nm: 1552.0, to_nm: 1550.0, rate_nm_per_s: 10.0, label: "sweep".into() }],
    }
}

#[test]
fn a_sweep_on_the_emulated_bench_takes_its_wavelengths_from_the_laser_log() {
    let (_emus, _laser, mut bench) = bench(LaserFamily::Keysight);
    let cancel = AtomicBool::new(false);
    let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
    let run = run_plan(&mut bench, &sweep_plan(), &mut control);
    run.outcome.unwrap();
    let t = &run.traces[0];
    let w = &t.wavelength_nm;
    assert!(t.len() > 300, "{} samples over 0.2 s at 2 kHz", t.len());
    // The Keysight sweeps a span upwards only: 1550 → 1552 nm.
    assert!((w[0] - 1550.0).abs() < 0.01 && (w[w.len() - 1] - 1552.0).abs() < 0.01, "{} .. {}", w[0], w[w.len() - 1]);
    assert!(w.windows(2).all(|p| p[1] > p[0]), "the sweep is strictly monotonic");
    // The same CSV columns as a trace of the virtual bench.
    let csv = String::from_utf8(t.to_csv_bytes(Path::new("sweep.csv")).unwrap()).unwrap();
    let header = csv.lines().find(|l| !l.starts_with('#')).unwrap();
    assert!(header.starts_with("t_s,q1_um,q2_um,q3_um,q4_deg,q5_deg,q6_deg,wavelength_nm,"), "{header}");
}

#[test]
fn laser_faults_during_a_bench_sweep_stop_the_stages_and_keep_the_samples() {
    for (what, family, fault) in [
        ("aborted", LaserFamily::Santec, None),
        ("dropped", LaserFamily::Keysight, Some(FaultSpec::on_command(":SOUR0:WAV:SWE?", 0, Fault::DropConnection))),
        ("no reply", LaserFamily::Santec, Some(FaultSpec::on_command(":READout:DATa?", 0, Fault::NoReply))),
    ] {
        let (emus, laser, mut bench) = bench(family);
        match fault {
            Some(f) => laser.inject(f),
            None => {
                laser.inject(FaultSpec { trigger: Trigger::AtTime(emus.clock().now_s() + 0.5), fault: Fault::Limit })
            }
        }
        let cancel = AtomicBool::new(false);
        let mut control = RunControl { cancel: &cancel, on_samples: &mut |_, _| {}, on_progress: &mut |_| {} };
        let plan = Plan {
            segments: vec![Segment::Sweep {
                from_nm: 1550.0,
                to_nm: 1560.0,
                rate_nm_per_s: 10.0,
                label: "long sweep".into(),
            }],
            ..sweep_plan()
        };
        let t = Instant::now();
        let run = run_plan(&mut bench, &plan, &mut control);
        assert!(t.elapsed() < Duration::from_secs(4), "{what}: {:?}", t.elapsed());
        let err = run.outcome.expect_err(what);
        let RunError::Segment { error: BenchError::Interrupted { fault, partial }, .. } = &err else {
            panic!("{what}: {err:?}")
        };
        let partial = partial.as_deref().or(run.traces.last());
        assert!(fault.contains(&format!("{family:?} laser")), "{what}: {fault}");
        assert!(fault.contains("PI E-712: stopped, SmarAct MCS: stopped"), "{what}: {fault}");
        let kept = partial.expect("the samples recorded before the fault");
        assert!(kept.len() > 500, "{what}: {} samples kept", kept.len());
        if what == "aborted" {
            assert!(fault.contains("aborted by the laser"), "{fault}");
            assert!(!laser.sweeping());
        }
        assert_eq!(laser.fired().len(), 1, "{what}");
        // After a reconnect the bench sweeps again.
        bench.reconnect().unwrap();
        run_plan(&mut bench, &sweep_plan(), &mut control).outcome.unwrap();
    }
}
