//! The tunable laser in the Connection view: its family (or none), address, identification
//! (`*IDN?`, wavelength, sweep state) and the local laser emulator on the emulators' optical bench.

use super::{ConnectionPanel, Done, BAD, GOOD};
use crate::hardware_bench::open_laser;
use crate::settings::{laser_default_port, ConnectionSettings};
use crate::state::AppState;
use egui::RichText;
use photorobot_core::hardware::controller_bench::{HardwareConfig, LaserConfig, LaserFamily};
use photorobot_core::hardware::emulator::{LaserEmulator, LaserEmulatorConfig, LocalEmulators};

impl ConnectionPanel {
    /// Serve the emulators' laser over SCPI (the settings' family, Keysight when none is driven) at
    /// the laser's port or any free one, and point the laser's address at it.
    pub(super) fn start_laser_emulator(&mut self, s: &mut AppState, e: &LocalEmulators) -> Result<String, String> {
        let l = &mut s.settings.connection.laser;
        if l.family == LaserFamily::None {
            l.family = LaserFamily::Keysight;
            l.port = laser_default_port(l.family);
        }
        let config = LaserEmulatorConfig::new(l.family);
        let emu = LaserEmulator::start_on(l.port, e.emu_laser(), config.clone())
            .or_else(|_| LaserEmulator::start_on(0, e.emu_laser(), config))
            .map_err(|err| err.to_string())?;
        let addr = emu.addr();
        let moved = if addr.port() != l.port { format!(" ({} is taken)", l.port) } else { String::new() };
        l.host = addr.ip().to_string();
        l.port = addr.port();
        self.laser_emulator = Some(emu);
        self.laser_identity = None;
        Ok(format!("{:?} laser at {addr}{moved}", l.family))
    }

    pub(super) fn identify_laser(&mut self, c: &ConnectionSettings, ctx: &egui::Context) {
        let mut config = HardwareConfig::femto();
        config.laser = Some(LaserConfig { family: c.laser.family, address: c.laser.address(), timeout_s: c.timeout_s });
        let tx = self.jobs.0.clone();
        let ctx = ctx.clone();
        self.laser_identifying = true;
        self.laser_identity = None;
        std::thread::spawn(move || {
            let r = open_laser(&config, 0.0).map(|(_, id)| id).and_then(|id| id.ok_or("no laser to ask".to_string()));
            let _ = tx.send(Done::LaserIdentified(r));
            ctx.request_repaint();
        });
    }
}

/// The laser's row: family, address and port (locked while connected), Identify, and what it
/// answered; with family None, a note that sweeps are refused.
pub(super) fn laser_row(
    ui: &mut egui::Ui,
    s: &mut AppState,
    p: &mut ConnectionPanel,
    ctx: &egui::Context,
    locked: bool,
) {
    egui::Grid::new("laser").num_columns(6).spacing([12.0, 6.0]).striped(true).show(ui, |ui| {
        for h in ["laser", "command set", "address", "port", "", "identification"] {
            ui.label(RichText::new(h).strong());
        }
        ui.end_row();
        let l = &mut s.settings.connection.laser;
        ui.label("tunable laser");
        let before = l.family;
        ui.add_enabled_ui(!locked, |ui| {
            egui::ComboBox::from_id_salt("laser family").selected_text(family_name(l.family)).width(150.0).show_ui(
                ui,
                |ui| {
                    for f in [LaserFamily::Keysight, LaserFamily::Santec, LaserFamily::None] {
                        ui.selectable_value(&mut l.family, f, family_name(f));
                    }
                },
            );
        });
        if l.family != before {
            p.laser_identity = None;
            if l.family != LaserFamily::None && l.port == laser_default_port(before) {
                l.port = laser_default_port(l.family);
            }
        }
        let driven = l.family != LaserFamily::None;
        ui.add_enabled_ui(!locked && driven, |ui| ui.add_sized([140.0, 20.0], egui::TextEdit::singleline(&mut l.host)));
        ui.add_enabled(!locked && driven, egui::DragValue::new(&mut l.port).range(1..=65535));
        if ui
            .add_enabled(driven && !locked && !p.laser_identifying, egui::Button::new("Identify"))
            .on_disabled_hover_text(
                "disconnect first (Identify opens a connection of its own); no laser to ask with None",
            )
            .on_hover_text("*IDN?, the wavelength and the sweep state (changes nothing)")
            .clicked()
        {
            let snapshot = s.settings.connection.clone();
            p.identify_laser(&snapshot, ctx);
        }
        laser_identification(ui, p, &s.settings.connection);
        ui.end_row();
    });
}

fn family_name(f: LaserFamily) -> &'static str {
    match f {
        LaserFamily::Keysight => "Keysight 816x / N777x",
        LaserFamily::Santec => "Santec TSL-570",
        LaserFamily::None => "no tunable laser",
    }
}

fn laser_identification(ui: &mut egui::Ui, p: &ConnectionPanel, c: &ConnectionSettings) {
    if c.laser.family == LaserFamily::None {
        ui.add(
            egui::Label::new(RichText::new(
                "The laser stays at the preset's wavelength: the wizard and calibrate leave the plans' sweeps out.",
            ))
            .wrap(),
        );
    } else if p.laser_identifying {
        ui.horizontal(|ui| {
            ui.spinner();
            ui.label(format!("asking {}…", c.laser.address()));
        });
    } else {
        match &p.laser_identity {
            Some(Ok(id)) => {
                ui.vertical(|ui| {
                    ui.label(RichText::new(&id.idn).color(GOOD));
                    let state = if id.sweeping { "sweeping" } else { "not sweeping" };
                    ui.label(format!("wavelength {:.4} nm, {state}", id.wavelength_nm));
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
