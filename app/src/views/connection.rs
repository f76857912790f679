//! Connection view: choose the bench (a virtual preset, or the stage controllers over TCP), the
//! controllers' addresses and ports, Identify, the q1..q6 axis mapping, Connect/Disconnect, local
//! emulators to try it without hardware, and the live status of every joint axis.
//! Owns the panel's runtime state; its settings persist with [`crate::settings::Settings`]. Network I/O
//! (identify, connect) runs on background threads, status polls in the worker: never on the UI thread.

use crate::dialogs::NativeDialogs;
use crate::settings::{default_port, mapping_of, ConnectionSettings, ControllerAddress};
use crate::state::AppState;
use crate::worker::{Command, Worker};
use egui::{Color32, RichText};
use photorobot_core::bench::{AxisStatus, AxisUnit, BenchPreset};
use photorobot_core::hardware::controller_bench::{ControllerKind, HardwareConfig, LaserConfig};
use photorobot_core::hardware::emulator::{EmuClock, LaserEmulator, LocalEmulators};
use photorobot_core::hardware::probe::{identify, Identity};
use photorobot_core::hardware::{ControllerBench, HwError};
use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::phase::PhaseModel;
use photorobot_core::model::robot::{Drive, RobotDescription};

mod laser;
pub use crate::hardware_bench::LaserIdentity;
use crate::hardware_bench::{at_address, open_hardware_bench};
use laser::laser_row;

use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn kind_name(kind: ControllerKind) -> &'static str {
    match kind {
        ControllerKind::PiGcs => "PI GCS 2",
        ControllerKind::SmarActMcs => "SmarAct MCS ASCII",
        ControllerKind::SmarActMcs2 => "SmarAct MCS2 ASCII",
    }
}

/// The protocols a controller of `kind` may be switched to: the SmarAct ones to each other (an
/// MCS or, bought today, an MCS2 in the same place of the bench).
fn kind_choices(kind: ControllerKind) -> &'static [ControllerKind] {
    match kind {
        ControllerKind::PiGcs => &[ControllerKind::PiGcs],
        ControllerKind::SmarActMcs | ControllerKind::SmarActMcs2 => {
            &[ControllerKind::SmarActMcs, ControllerKind::SmarActMcs2]
        }
    }
}

/// What a background job reports.
enum Done {
    Identified(usize, Result<Identity, String>),
    Connected(Result<Box<(ControllerBench, PhaseModel, Option<LaserIdentity>)>, String>),
    LaserIdentified(Result<LaserIdentity, String>),
}

/// The bench the worker runs on, as the panel connected it.
#[derive(Debug, Clone, PartialEq)]
pub struct Connected {
    /// The bench's name (the worker's).
    pub bench_name: String,
    /// (controller name, host:port).
    pub addresses: Vec<(String, String)>,
    /// On the local emulators.
    pub emulated: bool,
}

/// The panel's runtime state.
pub struct ConnectionPanel {
    /// The local emulators, while running.
    pub emulators: Option<LocalEmulators>,
    /// The local laser emulator (on the emulators' optical bench), while running.
    pub laser_emulator: Option<LaserEmulator>,
    /// What the laser answered (Identify, or at Connect).
    pub laser_identity: Option<Result<LaserIdentity, String>>,
    laser_identifying: bool,
    /// Identify result per controller (index into the settings' controllers).
    pub identities: Vec<Option<Result<Identity, String>>>,
    identifying: Vec<bool>,
    /// A connection is being opened.
    pub connecting: bool,
    /// The hardware bench the worker runs on, if it does.
    pub connected: Option<Connected>,
    /// The last outcome: `Ok` message or `Err` message.
    pub message: Option<Result<String, String>>,
    /// Connecting would drop unsaved work: asking first.
    confirm: bool,
    status_asked: Option<Instant>,
    jobs: (Sender<Done>, Receiver<Done>),
}

impl Default for ConnectionPanel {
    fn default() -> Self {
        Self {
            emulators: None,
            laser_emulator: None,
            laser_identity: None,
            laser_identifying: false,
            identities: vec![],
            identifying: vec![],
            connecting: false,
            connected: None,
            message: None,
            confirm: false,
            status_asked: None,
            jobs: channel(),
        }
    }
}

/// How often the status table is refreshed (s).
pub const STATUS_PERIOD_S: f64 = 0.25;

const GOOD: Color32 = Color32::from_rgb(60, 180, 90);
const BAD: Color32 = Color32::from_rgb(230, 90, 70);

/// The hardware configuration the settings describe.
fn hardware_config(c: &ConnectionSettings) -> HardwareConfig {
    let mut config = HardwareConfig::femto();
    for k in &mut config.controllers {
        if let Some(a) = c.controllers.iter().find(|a| a.name == k.name) {
            k.address = a.address();
            k.kind = a.kind;
        }
        k.timeout_s = c.timeout_s;
    }
    config.laser = Some(LaserConfig { family: c.laser.family, address: c.laser.address(), timeout_s: c.timeout_s });
    config
}

/// `robot` with the settings' mapping in its `drive` fields.
fn mapped(mut robot: RobotDescription, c: &ConnectionSettings) -> RobotDescription {
    for l in &mut robot.links {
        if let Some(m) = c.mapping.iter().find(|m| m.joint == l.name) {
            l.drive = Some(Drive { controller: m.controller.clone(), channel: m.channel.trim().to_string() });
        }
    }
    robot
}

impl ConnectionPanel {
    /// Apply what the background jobs finished (called every frame by the window).
    pub fn poll(&mut self, s: &mut AppState, ctx: &egui::Context) {
        while let Ok(done) = self.jobs.1.try_recv() {
            match done {
                Done::Identified(i, r) => {
                    if let Some(b) = self.identifying.get_mut(i) {
                        *b = false;
                    }
                    if i < self.identities.len() {
                        self.identities[i] = Some(r);
                    }
                }
                Done::LaserIdentified(r) => {
                    self.laser_identifying = false;
                    self.laser_identity = Some(r);
                }
                Done::Connected(r) => {
                    self.connecting = false;
                    match r {
                        Ok(opened) => {
                            let (bench, nominal, laser) = *opened;
                            self.laser_identity = laser.map(Ok);
                            let name = photorobot_core::bench::Bench::name(&bench);
                            let ctx2 = ctx.clone();
                            let worker = Worker::start(
                                Box::new(bench),
                                nominal,
                                s.settings.pace(),
                                Box::new(move || ctx2.request_repaint()),
                            );
                            swap_worker(s, worker);
                            let c = &s.settings.connection;
                            let addresses: Vec<(String, String)> =
                                c.controllers.iter().map(|a| (a.name.clone(), a.address())).collect();
                            let emulated =
                                self.emulators.as_ref().is_some_and(|e| same_addresses(&e.addresses(), &addresses));
                            self.connected = Some(Connected { bench_name: name.clone(), addresses, emulated });
                            self.message = Some(Ok(format!("connected: {name}")));
                            s.status = format!("connected to {name}");
                        }
                        Err(e) => {
                            self.message = Some(Err(format!("not connected: {e}")));
                            s.status = "connection failed (see the Connection tab)".into();
                        }
                    }
                }
            }
        }
    }

    fn identify(&mut self, i: usize, c: &ConnectionSettings, ctx: &egui::Context) {
        let a = c.controllers[i].clone();
        let timeout_s = c.timeout_s;
        let tx = self.jobs.0.clone();
        let ctx = ctx.clone();
        self.identifying[i] = true;
        self.identities[i] = None;
        std::thread::spawn(move || {
            let address = a.address();
            let r = identify(a.kind, &a.name, &address, timeout_s)
                .map_err(|e: HwError| at_address(&e.to_string(), &a.name, &address));
            let _ = tx.send(Done::Identified(i, r));
            ctx.request_repaint();
        });
    }

    fn connect(&mut self, s: &mut AppState, ctx: &egui::Context) {
        let c = s.settings.connection.clone();
        let preset_name = s.settings.preset.clone();
        let addresses: Vec<(String, String)> = c.controllers.iter().map(|a| (a.name.clone(), a.address())).collect();
        // On the local emulators the bench shares their clock; on real controllers the clock is
        // the wall clock. The laser is the one the settings name, on either.
        let local = self.emulators.as_ref().filter(|e| same_addresses(&e.addresses(), &addresses)).map(|e| e.clock());
        let tx = self.jobs.0.clone();
        let ctx = ctx.clone();
        self.connecting = true;
        self.message = None;
        let list: Vec<String> = addresses.iter().map(|(n, a)| format!("{n} at {a}")).collect();
        s.status = format!("connecting to {}", list.join(", "));
        std::thread::spawn(move || {
            let r = open_bench(&preset_name, &c, local).map_err(|e| {
                let mut e = e;
                for (name, address) in &addresses {
                    if e.contains(name.as_str()) && !e.contains(address.as_str()) {
                        e = at_address(&e, name, address);
                    }
                }
                e
            });
            let _ = tx.send(Done::Connected(r));
            ctx.request_repaint();
        });
    }

    fn disconnect(&mut self, s: &mut AppState, ctx: &egui::Context) {
        let ctx2 = ctx.clone();
        match Worker::virtual_bench(
            &s.settings.preset,
            Some(s.settings.seed),
            s.settings.pace(),
            Box::new(move || ctx2.request_repaint()),
        ) {
            Ok(w) => {
                swap_worker(s, w);
                self.connected = None;
                self.message = Some(Ok(format!("disconnected; back on {}", s.worker.bench_name)));
            }
            Err(e) => self.message = Some(Err(format!("the virtual bench does not start: {e}"))),
        }
    }

    fn start_emulators(&mut self, s: &mut AppState) {
        let c = &s.settings.connection;
        let port = |kinds: &[ControllerKind]| {
            c.controllers.iter().find(|a| kinds.contains(&a.kind)).map_or(default_port(kinds[0]), |a| a.port)
        };
        let ports = (port(&[ControllerKind::PiGcs]), port(&[ControllerKind::SmarActMcs, ControllerKind::SmarActMcs2]));
        let config = hardware_config(c);
        let started = BenchPreset::resolve(&s.settings.preset).map_err(|e| e.to_string()).and_then(|preset| {
            let robot = preset.robot_description().map_err(|e| e.to_string())?;
            LocalEmulators::start_with(&preset, s.settings.seed, &robot, &config, ports, true)
        });
        match started {
            Ok(e) => {
                let mut moved = vec![];
                for (name, address) in e.addresses() {
                    if let Some(a) = s.settings.connection.controllers.iter_mut().find(|a| a.name == name) {
                        let (host, port) = address.rsplit_once(':').unwrap_or((address.as_str(), "0"));
                        let port: u16 = port.parse().unwrap_or(0);
                        if port != a.port {
                            moved.push(format!("{name} on port {port} ({} is taken)", a.port));
                        }
                        a.host = host.to_string();
                        a.port = port;
                    }
                }
                let list: Vec<String> = e.addresses().iter().map(|(n, a)| format!("{n} at {a}")).collect();
                let mut msg = format!(
                    "local emulators running (real time, optics of {}): {}",
                    s.settings.preset,
                    list.join(", ")
                );
                if !moved.is_empty() {
                    msg.push_str(&format!("; {}", moved.join(", ")));
                }
                match self.start_laser_emulator(s, &e) {
                    Ok(m) => msg.push_str(&format!("; {m}")),
                    Err(m) => msg.push_str(&format!("; no laser emulator: {m}")),
                }
                self.message = Some(Ok(msg));
                self.emulators = Some(e);
            }
            Err(e) => self.message = Some(Err(e)),
        }
    }
}

fn same_addresses(a: &[(String, String)], b: &[(String, String)]) -> bool {
    let norm = |x: &str| x.replace("localhost", "127.0.0.1");
    a.iter().all(|(n, addr)| b.iter().any(|(m, baddr)| m == n && norm(baddr) == norm(addr)))
}

/// Connect a [`ControllerBench`] (on a background thread: this is network I/O).
fn open_bench(
    preset_name: &str,
    c: &ConnectionSettings,
    local: Option<Arc<EmuClock>>,
) -> Result<Box<(ControllerBench, PhaseModel, Option<LaserIdentity>)>, String> {
    let preset = BenchPreset::resolve(preset_name).map_err(|e| e.to_string())?;
    let robot = mapped(preset.robot_description().map_err(|e| e.to_string())?, c);
    let clock = local.unwrap_or_else(|| EmuClock::new(1.0));
    let nominal = PhaseModel::new(
        robot.clone(),
        Extrinsics::nominal_design(),
        preset.optics,
        &preset.ambient,
        preset.laser.wavelength_nm,
    )?;
    let (bench, identity) = open_hardware_bench(&preset, robot, hardware_config(c), clock)?;
    Ok(Box::new((bench, nominal, identity)))
}

/// Put `worker` in place of the running one: a new session on the new bench (as changing the
/// bench in the settings does). The old worker is stopped and joined off the UI thread.
fn swap_worker(s: &mut AppState, worker: Worker) {
    let settings = s.settings.clone();
    let dialogs = std::mem::replace(&mut s.dialogs, Box::new(NativeDialogs));
    let old = std::mem::replace(s, AppState::new(settings, worker, dialogs));
    let AppState { worker: old_worker, .. } = old;
    std::thread::spawn(move || drop(old_worker));
}

fn position(v: Option<f64>, unit: AxisUnit) -> String {
    v.map_or("–".into(), |v| format!("{v:.4} {}", unit.symbol()))
}

/// Draw the connection view.
pub fn ui(ui: &mut egui::Ui, s: &mut AppState, p: &mut ConnectionPanel) {
    let ctx = ui.ctx().clone();
    // The settings window may have put a virtual bench in place of the hardware one.
    if p.connected.as_ref().is_some_and(|c| c.bench_name != s.worker.bench_name) {
        p.connected = None;
    }
    let n = s.settings.connection.controllers.len();
    p.identities.resize(n, None);
    p.identifying.resize(n, false);
    let idle = s.busy.is_none() && s.wizard.running.is_none();
    egui::ScrollArea::vertical().show(ui, |ui| {
        ui.heading("Connection");
        ui.horizontal(|ui| {
            ui.label(RichText::new("running on:").strong());
            ui.label(&s.worker.bench_name);
        });
        ui.horizontal(|ui| {
            ui.radio_value(&mut s.settings.connection.hardware, false, "Virtual bench (simulated)");
            ui.radio_value(&mut s.settings.connection.hardware, true, "Hardware: stage controllers over TCP");
        });
        ui.separator();
        if s.settings.connection.hardware {
            hardware(ui, s, p, &ctx, idle);
        } else {
            virtual_bench(ui, s, p, &ctx, idle);
        }
    });
}

fn virtual_bench(ui: &mut egui::Ui, s: &mut AppState, p: &mut ConnectionPanel, ctx: &egui::Context, idle: bool) {
    ui.label(
        "The virtual bench simulates the robot, the optics and the detector of a preset. The preset also \
         gives the hardware bench its optical model and motion limits.",
    );
    let mut preset = s.settings.preset.clone();
    ui.horizontal(|ui| {
        ui.label("preset");
        egui::ComboBox::from_id_salt("connection preset").selected_text(&preset).show_ui(ui, |ui| {
            for (name, _) in photorobot_core::bench::preset::EMBEDDED {
                ui.selectable_value(&mut preset, name.to_string(), name);
            }
        });
        ui.label("seed");
        ui.add(egui::DragValue::new(&mut s.settings.seed));
    });
    let changed = preset != s.settings.preset;
    s.settings.preset = preset;
    let on_it = p.connected.is_none() && s.worker.bench_name.contains(&s.settings.preset) && !changed;
    let label = if p.connected.is_some() { "Disconnect and use this virtual bench" } else { "Use this virtual bench" };
    if ui.add_enabled(idle && !on_it, egui::Button::new(label)).clicked() {
        p.disconnect(s, ctx);
    }
    message(ui, p);
}

fn message(ui: &mut egui::Ui, p: &ConnectionPanel) {
    match &p.message {
        Some(Ok(m)) => {
            ui.label(RichText::new(m).color(GOOD));
        }
        Some(Err(m)) => {
            ui.label(RichText::new(m).color(BAD).strong());
        }
        None => {}
    }
}

/// The hardware bench: the controllers and their identification, the reply timeout and the local
/// emulators, the axis mapping, Connect/Disconnect/Reconnect and the axes' status.
fn hardware(ui: &mut egui::Ui, s: &mut AppState, p: &mut ConnectionPanel, ctx: &egui::Context, idle: bool) {
    let locked = p.connected.is_some() || p.connecting;
    ui.label(RichText::new("Controllers").strong());
    controllers(ui, s, p, ctx, locked);
    ui.add_space(4.0);
    ui.label(RichText::new("Tunable laser").strong());
    laser_row(ui, s, p, ctx, locked);
    timeout_and_emulators(ui, s, p, locked);
    ui.add_space(6.0);
    mapping(ui, s, p, locked);
    ui.add_space(6.0);
    connect_buttons(ui, s, p, ctx, idle);
    confirm_new_session(ui, s, p, ctx);
    message(ui, p);
    ui.add_space(6.0);
    status(ui, s, p);
}

/// One row per controller: name, protocol, address and port (locked while connected), Identify.
fn controllers(ui: &mut egui::Ui, s: &mut AppState, p: &mut ConnectionPanel, ctx: &egui::Context, locked: bool) {
    egui::Grid::new("controllers").num_columns(6).spacing([12.0, 6.0]).striped(true).show(ui, |ui| {
        for h in ["controller", "protocol", "address", "port", "", "identification"] {
            ui.label(RichText::new(h).strong());
        }
        ui.end_row();
        let c = &mut s.settings.connection;
        for i in 0..c.controllers.len() {
            let a = &mut c.controllers[i];
            ui.label(&a.name);
            let choices = kind_choices(a.kind);
            if choices.len() > 1 && !locked {
                let before = a.kind;
                egui::ComboBox::from_id_salt(("protocol", i)).selected_text(kind_name(a.kind)).width(150.0).show_ui(
                    ui,
                    |ui| {
                        for &k in choices {
                            ui.selectable_value(&mut a.kind, k, kind_name(k));
                        }
                    },
                );
                if a.kind != before && a.port == default_port(before) {
                    a.port = default_port(a.kind);
                }
            } else {
                ui.label(kind_name(a.kind));
            }
            // A grid cell offers a text field only last frame's column width: give it its size.
            ui.add_enabled_ui(!locked, |ui| ui.add_sized([140.0, 20.0], egui::TextEdit::singleline(&mut a.host)));
            ui.add_enabled(!locked, egui::DragValue::new(&mut a.port).range(1..=65535));
            let busy = p.identifying[i];
            if ui
                .add_enabled(!busy && !locked, egui::Button::new("Identify"))
                .on_disabled_hover_text("disconnect first: Identify opens a connection of its own")
                .on_hover_text(match a.kind {
                    ControllerKind::PiGcs => "*IDN? and SAI?: who answers and which axes it has (changes nothing)",
                    ControllerKind::SmarActMcs => ":GNC and each channel's sensor type, :GST (moves nothing)",
                    ControllerKind::SmarActMcs2 => {
                        ":DEV:SNUM?, :DEV:NOCH? and each channel's movement type (moves nothing)"
                    }
                })
                .clicked()
            {
                let snapshot = c.clone();
                p.identify(i, &snapshot, ctx);
            }
            identification(ui, p, i, busy, &c.controllers[i]);
            ui.end_row();
        }
    });
}

/// The identification cell of controller `i`: a spinner while it is asked (`busy`, as at the
/// start of the row), its reply, or the error.
fn identification(ui: &mut egui::Ui, p: &ConnectionPanel, i: usize, busy: bool, address: &ControllerAddress) {
    if busy {
        ui.horizontal(|ui| {
            ui.spinner();
            ui.label(format!("asking {}…", address.address()));
        });
    } else {
        match &p.identities[i] {
            Some(Ok(id)) => {
                let axes: Vec<String> = id.axes.iter().map(|x| format!("{} ({})", x.id, x.unit.symbol())).collect();
                ui.vertical(|ui| {
                    ui.label(RichText::new(&id.reply).color(GOOD));
                    ui.label(format!("axes: {}", axes.join(", ")));
                });
            }
            Some(Err(e)) => {
                ui.add(egui::Label::new(RichText::new(e).color(BAD)).wrap());
            }
            None => {
                ui.label("–");
            }
        }
    }
}

/// The reply timeout, and starting or stopping the local emulators.
fn timeout_and_emulators(ui: &mut egui::Ui, s: &mut AppState, p: &mut ConnectionPanel, locked: bool) {
    ui.horizontal(|ui| {
        ui.label("reply timeout");
        ui.add_enabled(
            !locked,
            egui::DragValue::new(&mut s.settings.connection.timeout_s).range(0.05..=30.0).speed(0.05).suffix(" s"),
        );
        ui.separator();
        if p.emulators.is_none() {
            if ui
                .add_enabled(!locked, egui::Button::new("Start local emulators"))
                .on_hover_text(
                    "Serve a PI E-712 and a SmarAct MCS emulator on 127.0.0.1 (real time, the preset's optics on \
                     the photodiode) and point the addresses at them: try everything without hardware.",
                )
                .clicked()
            {
                p.start_emulators(s);
            }
        } else if ui
            .add_enabled(
                !locked || p.connected.as_ref().is_some_and(|c| !c.emulated),
                egui::Button::new("Stop local emulators"),
            )
            .clicked()
        {
            p.emulators = None;
            p.laser_emulator = None;
            p.message = Some(Ok("local emulators stopped".into()));
        }
        if let Some(e) = &p.emulators {
            let mut list: Vec<String> = e.addresses().iter().map(|(n, a)| format!("{n} {a}")).collect();
            if let Some(l) = &p.laser_emulator {
                list.push(format!("laser {}", l.addr()));
            }
            ui.label(RichText::new(format!("emulators: {}", list.join(", "))).weak());
        }
    });
}

/// Connect (asking first when the session has unsaved measurements), or Disconnect and Reconnect.
fn connect_buttons(ui: &mut egui::Ui, s: &mut AppState, p: &mut ConnectionPanel, ctx: &egui::Context, idle: bool) {
    ui.horizontal(|ui| {
        if p.connected.is_none() {
            if ui.add_enabled(idle && !p.connecting, egui::Button::new(RichText::new("Connect").size(16.0))).clicked() {
                if s.session.dirty {
                    p.confirm = true;
                } else {
                    p.connect(s, ctx);
                }
            }
        } else {
            if ui.add_enabled(idle, egui::Button::new(RichText::new("Disconnect").size(16.0))).clicked() {
                p.disconnect(s, ctx);
            }
            if ui
                .add_enabled(idle, egui::Button::new(RichText::new("Reconnect").size(16.0)))
                .on_hover_text("after a fault: open the links again and restore closed loop; the session is kept")
                .clicked()
            {
                s.worker.send(Command::Reconnect);
            }
        }
        if p.connecting {
            ui.spinner();
            ui.label("connecting…");
        }
    });
}

/// The question asked before a new bench replaces a session with unsaved measurements.
fn confirm_new_session(ui: &mut egui::Ui, s: &mut AppState, p: &mut ConnectionPanel, ctx: &egui::Context) {
    if p.confirm {
        ui.horizontal(|ui| {
            ui.label(
                RichText::new("The session has unsaved measurements; a new bench starts a new session.").color(BAD),
            );
            if ui.button("Connect anyway").clicked() {
                p.confirm = false;
                p.connect(s, ctx);
            }
            if ui.button("Cancel").clicked() {
                p.confirm = false;
            }
        });
    }
}

fn mapping(ui: &mut egui::Ui, s: &mut AppState, p: &ConnectionPanel, locked: bool) {
    ui.horizontal(|ui| {
        ui.label(RichText::new("Axis mapping").strong());
        ui.label("controller position = zero + sign·q (assets/benches/femto-hardware.ron)");
        if locked {
            ui.label(RichText::new("(disconnect to edit)").weak());
        }
        if ui.add_enabled(!locked, egui::Button::new("Reset to the robot description")).clicked() {
            if let Ok(robot) = BenchPreset::resolve(&s.settings.preset).and_then(|p| p.robot_description()) {
                s.settings.connection.mapping = mapping_of(&robot);
            }
        }
    });
    let config = HardwareConfig::femto();
    let robot = s.chain.description().clone();
    let c = &mut s.settings.connection;
    let names: Vec<String> = c.controllers.iter().map(|a| a.name.clone()).collect();
    egui::Grid::new("axis mapping").num_columns(6).spacing([12.0, 4.0]).striped(true).show(ui, |ui| {
        for h in ["joint", "type", "controller", "axis / channel", "zero", "sign"] {
            ui.label(RichText::new(h).strong());
        }
        ui.end_row();
        for m in &mut c.mapping {
            ui.label(&m.joint);
            let link = robot.links.iter().find(|l| l.name == m.joint);
            let unit = link.map_or("", |l| l.joint.display_unit());
            ui.label(link.map_or("?".to_string(), |l| format!("{:?} ({unit})", l.joint)));
            ui.add_enabled_ui(!locked, |ui| {
                egui::ComboBox::from_id_salt(("mapping controller", m.joint.clone()))
                    .selected_text(&m.controller)
                    .width(130.0)
                    .show_ui(ui, |ui| {
                        for n in &names {
                            ui.selectable_value(&mut m.controller, n.clone(), n);
                        }
                    });
            });
            // Once identified, offer the controller's axes; before, any identifier.
            let known = names
                .iter()
                .position(|n| *n == m.controller)
                .and_then(|i| p.identities.get(i).cloned().flatten())
                .and_then(|r| r.ok());
            ui.add_enabled_ui(!locked, |ui| match known {
                Some(id) => {
                    egui::ComboBox::from_id_salt(("mapping channel", m.joint.clone()))
                        .selected_text(&m.channel)
                        .width(60.0)
                        .show_ui(ui, |ui| {
                            for a in &id.axes {
                                ui.selectable_value(
                                    &mut m.channel,
                                    a.id.clone(),
                                    format!("{} ({})", a.id, a.unit.symbol()),
                                );
                            }
                        });
                }
                None => {
                    ui.add(egui::TextEdit::singleline(&mut m.channel).desired_width(60.0));
                }
            });
            let jc = config.joints.iter().find(|j| j.joint == m.joint);
            ui.label(format!("{:.1} {unit}", jc.map_or(0.0, |j| j.zero)));
            ui.label(if jc.map_or(1.0, |j| j.sign) > 0.0 { "+1" } else { "-1" });
            ui.end_row();
        }
    });
}

fn status(ui: &mut egui::Ui, s: &mut AppState, p: &mut ConnectionPanel) {
    ui.label(RichText::new("Axis status").strong());
    if p.connected.is_none() {
        ui.label("not connected");
        return;
    }
    // Poll through the worker (it owns the connections); one request at a time.
    let idle = s.busy.is_none() && s.wizard.running.is_none();
    let answered = match (&s.hardware_status, p.status_asked) {
        (Some((at, _)), Some(asked)) => *at >= asked,
        (_, None) => true,
        (None, Some(_)) => false,
    };
    let due = p.status_asked.is_none_or(|t| t.elapsed().as_secs_f64() >= STATUS_PERIOD_S);
    let stale = p.status_asked.is_some_and(|t| t.elapsed() > Duration::from_secs(2));
    if idle && due && (answered || stale) {
        s.worker.send(Command::HardwareStatus);
        p.status_asked = Some(Instant::now());
    }
    ui.ctx().request_repaint_after(Duration::from_secs_f64(STATUS_PERIOD_S));
    let Some((at, axes)) = &s.hardware_status else {
        ui.horizontal(|ui| {
            ui.spinner();
            ui.label("reading the controllers…");
        });
        return;
    };
    let age_s = at.elapsed().as_secs_f64();
    ui.label(if idle {
        format!("read from the controllers every {STATUS_PERIOD_S} s (last {age_s:.1} s ago)")
    } else {
        format!("the bench is busy: the table resumes after the step (last read {age_s:.1} s ago)")
    });
    egui::Grid::new("axis status").num_columns(9).spacing([14.0, 4.0]).striped(true).show(ui, |ui| {
        for h in
            ["joint", "controller", "axis", "position", "joint value", "motion", "servo", "referenced", "last error"]
        {
            ui.label(RichText::new(h).strong());
        }
        ui.end_row();
        for a in axes {
            axis_row(ui, a);
            ui.end_row();
        }
    });
    if let Some((at, laser)) = &s.laser_status {
        laser_status(ui, laser, at.elapsed().as_secs_f64());
    }
}

/// The laser's line under the axis table: wavelength and sweep state as last read, or its error.
fn laser_status(ui: &mut egui::Ui, l: &photorobot_core::bench::LaserStatus, age_s: f64) {
    let wavelength = l.wavelength_nm.map_or("wavelength ?".into(), |w| format!("{w:.4} nm"));
    let sweep = match l.sweeping {
        Some(true) => "sweeping",
        Some(false) => "not sweeping",
        None => "sweep state ?",
    };
    ui.horizontal(|ui| {
        ui.label(RichText::new("laser").strong());
        ui.label(format!("{}: {wavelength}, {sweep}", l.name));
        ui.label(format!("(read {age_s:.1} s ago)"));
        if let Some(e) = &l.error {
            ui.add(egui::Label::new(RichText::new(e).color(BAD)).truncate()).on_hover_text(e);
        }
    });
}

fn axis_row(ui: &mut egui::Ui, a: &AxisStatus) {
    ui.label(&a.joint);
    ui.label(&a.controller);
    ui.label(&a.axis);
    ui.monospace(position(a.position, a.unit));
    ui.monospace(format!("{} = {}", a.joint, position(a.q_display, a.unit)));
    let flag = |ui: &mut egui::Ui, v: Option<bool>, yes: &str, no: &str, none: &str| match v {
        Some(true) => ui.label(RichText::new(yes).color(GOOD)),
        Some(false) => ui.label(RichText::new(no).color(BAD)),
        None => ui.label(none),
    };
    match a.on_target {
        Some(true) => ui.label(RichText::new("on target").color(GOOD)),
        Some(false) => ui.label(RichText::new("moving").color(Color32::from_rgb(230, 180, 60))),
        None => ui.label("–"),
    };
    flag(ui, a.servo_on, "on", "OFF", "not reported")
        .on_hover_text("closed-loop (servo) state: PI `SVO?`; the MCS has no such query (its moves are closed loop)");
    flag(ui, a.referenced, "yes", "NO", "–");
    match &a.error {
        Some(e) => {
            ui.add(egui::Label::new(RichText::new(e).color(BAD)).truncate()).on_hover_text(e);
        }
        None => {
            ui.label("none");
        }
    };
}
