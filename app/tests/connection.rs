//! GUI test of the Connection view (egui_kittest, headless): local emulators started from the panel,
//! both controllers and the tunable laser identified, the hardware bench connected, a jog through the drivers seen in the
//! status table, a dropped link and Reconnect, a wrong device and a closed port explained, the settings persisted. With
//! PHOTOROBOT_SCREENSHOTS=1 the view is written to screenshots/connection.png (Mesa llvmpipe):
//! `PHOTOROBOT_SCREENSHOTS=1 cargo test -p photorobot --test connection`.

mod common;

use common::*;
use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use photorobot_app::dialogs::ScriptedDialogs;
use photorobot_app::gui::{App, Tab, Workbench};
use photorobot_app::settings::Settings;
use photorobot_core::hardware::controller_bench::LaserFamily;
use photorobot_core::hardware::emulator::{Fault, FaultSpec};
use std::time::Duration;

fn identified(w: &Workbench, i: usize) -> bool {
    w.connection.identities.get(i).is_some_and(|r| r.is_some())
}

/// Controller `i`'s Identify failed with a message containing `text`.
fn refused(w: &Workbench, i: usize, text: &str) -> bool {
    w.connection
        .identities
        .get(i)
        .is_some_and(|r| r.as_ref().is_some_and(|r| r.as_ref().is_err_and(|e| e.contains(text))))
}

/// One session through the Connection panel; the stages share the harness and the emulators, so
/// they run in order within one test rather than as separate tests.
#[test]
fn connection_panel_drives_the_emulated_controllers_and_explains_failures() {
    let wb = Workbench::new(Settings::default(), Box::new(ScriptedDialogs::default()), Box::new(|| {}))
        .expect("the embedded virtual bench starts");
    let mut h = harness(wb);
    choose_hardware_and_check_the_mapping(&mut h);
    start_emulators_and_identify_both(&mut h);
    connect_and_read_the_status(&mut h);
    jog_through_the_drivers(&mut h);
    screenshot(&mut h, "connection");
    drop_the_link_and_reconnect(&mut h);
    disconnect_to_the_virtual_bench(&mut h);
    identify_a_wrong_device(&mut h);
    let closed = identify_and_connect_to_a_closed_port(&mut h);
    check_the_settings_persist(h, closed);
}

type Kittest = Harness<'static, Workbench>;

/// Hardware mode: the mapping comes from the robot description: q1 on the E-712's axis 3, q6 on
/// MCS channel 2.
fn choose_hardware_and_check_the_mapping(h: &mut Kittest) {
    open(h, Tab::Connection);
    h.get_by_label("running on:");
    h.get_by_label("Hardware: stage controllers over TCP").click();
    h.run_steps(3);
    let mapping = h.state().state.settings.connection.mapping.clone();
    assert_eq!((mapping[0].controller.as_str(), mapping[0].channel.as_str()), ("PI E-712", "3"));
    assert_eq!((mapping[5].controller.as_str(), mapping[5].channel.as_str()), ("SmarAct MCS", "2"));
}

/// Local emulators, then Identify both controllers: the replies are shown.
fn start_emulators_and_identify_both(h: &mut Kittest) {
    h.get_by_label("Start local emulators").click();
    h.run_steps(3);
    h.get_by_label_contains("local emulators running");
    let emulators = h.state().connection.emulators.as_ref().expect("the emulators run").addresses();
    let controllers = h.state().state.settings.connection.controllers.clone();
    for (c, (name, address)) in controllers.iter().zip(&emulators) {
        assert_eq!((&c.name, c.address()), (name, address.clone()), "the addresses point at the emulators");
    }
    // One row at a time, each reply awaited before the next click: a reply changes its row's
    // height, which moves the rows below, and a click aimed at a button where the frame before
    // drew it would miss.
    let rows = h.get_all_by_label("Identify").count();
    assert_eq!(rows, 3, "two controllers and the laser");
    for k in 0..rows {
        h.get_all_by_label("Identify").nth(k).expect("the row's Identify").click();
        wait_until(h, &format!("identification {}", k + 1), Duration::from_secs(20), |w| match k {
            0 | 1 => identified(w, k),
            _ => w.connection.laser_identity.is_some(),
        });
    }
    let ids = h.state().connection.identities.clone();
    assert!(ids.iter().all(|r| r.as_ref().unwrap().is_ok()), "{ids:?}");
    h.get_by_label_contains("E-712 (emulated)");
    h.get_by_label("SmarAct MCS, system ID 3118000001, 3 channels: 0 rotary sensor 16 (°), 1 rotary sensor 17 (°), 2 rotary sensor 26 (°)");
    h.get_by_label("axes: 1 (µm), 2 (µm), 3 (µm)");
    // The laser row: the emulated Keysight on the emulators' optical bench, at the preset's wavelength.
    let laser = h.state().connection.laser_emulator.as_ref().expect("a laser emulator runs").addr();
    assert_eq!(h.state().state.settings.connection.laser.address(), laser.to_string());
    h.get_by_label("Keysight Technologies,8164B (emulated),MY00000000,V5.25(72637)");
    let preset = photorobot_core::bench::BenchPreset::resolve(&h.state().state.settings.preset).unwrap();
    let nominal_nm = preset.laser.wavelength_nm;
    let id = h.state().connection.laser_identity.clone().unwrap().unwrap();
    assert!((id.wavelength_nm - nominal_nm).abs() < 1e-6 && !id.sweeping, "{id:?} at {nominal_nm} nm");
    h.get_by_label(&format!("wavelength {nominal_nm:.4} nm, not sweeping"));
}

/// Connect: the worker now runs on the controllers; the status table reads them.
/// The connection completes whichever tab is open.
fn connect_and_read_the_status(h: &mut Kittest) {
    h.get_by_label("Connect").click();
    h.run_steps(1);
    open(h, Tab::Robot);
    wait_until(h, "the connection", Duration::from_secs(30), |w| w.connection.connected.is_some());
    open(h, Tab::Connection);
    assert!(h.state().connection.connected.as_ref().unwrap().emulated);
    assert!(h.state().state.worker.bench_name.starts_with("femto-hardware (PI E-712 at 127.0.0.1:"));
    wait_until(h, "the axis status", Duration::from_secs(20), |w| w.state.hardware_status.is_some());
    h.get_by_label("q1 = 0.0000 µm");
    assert_eq!(h.query_all_by_label("150.0000 µm").count(), 3, "the PI axes at their 150 µm joint zero");
    assert_eq!(h.query_all_by_label("on target").count(), 6);
    // Connect opened the laser through its driver and shows what it answered.
    let id = h.state().connection.laser_identity.clone();
    assert!(id.as_ref().is_some_and(|r| r.as_ref().is_ok_and(|id| id.idn.contains("8164B"))), "{id:?}");
    h.get_by_label("Keysight Technologies,8164B (emulated),MY00000000,V5.25(72637)");
    // While connected the laser is read with the axes: its wavelength and sweep state, read again
    // at every status poll.
    wait_until(h, "the laser status", Duration::from_secs(20), |w| w.state.laser_status.is_some());
    let (first, status) = h.state().state.laser_status.clone().unwrap();
    assert_eq!((status.sweeping, status.error.as_deref()), (Some(false), None), "{status:?}");
    let nominal_nm =
        photorobot_core::bench::BenchPreset::resolve(&h.state().state.settings.preset).unwrap().laser.wavelength_nm;
    assert!(status.wavelength_nm.is_some_and(|w| (w - nominal_nm).abs() < 1e-6), "{status:?}");
    h.get_by_label(&format!("{}: {nominal_nm:.4} nm, not sweeping", status.name));
    wait_until(h, "a second laser read", Duration::from_secs(20), |w| {
        w.state.laser_status.as_ref().is_some_and(|(at, _)| *at > first)
    });
}

/// A jog through the drivers (Robot tab); the status table follows on the Connection tab.
fn jog_through_the_drivers(h: &mut Kittest) {
    open(h, Tab::Robot);
    let target = [10.0, -5.0, 3.0, 0.2, -0.3, 0.5];
    h.state_mut().state.robot_view.jog_target = target;
    h.get_by_label("Move to targets").click();
    wait_until(h, "the jog on the controllers", Duration::from_secs(30), |w| {
        w.state.q_display.iter().zip(&target).all(|(q, t)| (q - t).abs() < 1e-6)
    });
    open(h, Tab::Connection);
    wait_until(h, "the status after the jog", Duration::from_secs(20), |w| {
        w.state.hardware_status.as_ref().is_some_and(|(_, axes)| {
            axes.iter().zip(&target).all(|(a, t)| a.q_display.is_some_and(|q| (q - t).abs() < 1e-6))
        })
    });
    h.get_by_label("160.0000 µm"); // q1 on axis 3: 150 + 10
    h.get_by_label("q1 = 10.0000 µm");
    h.get_by_label("q6 = 0.5000 °");
    assert_eq!(h.query_all_by_label("on target").count(), 6);
    assert!(h.query_all_by_label("none").count() >= 6, "no axis has an error");
}

/// A fault on the link: the status table names it on the PI axes; Reconnect clears it.
fn drop_the_link_and_reconnect(h: &mut Kittest) {
    h.state().connection.emulators.as_ref().unwrap().pi.inject(FaultSpec::on_command("POS?", 0, Fault::DropConnection));
    wait_until(h, "the fault in the status", Duration::from_secs(20), |w| {
        w.state.hardware_status.as_ref().is_some_and(|(_, axes)| axes[0].error.is_some())
    });
    let lost = "PI E-712: connection lost during `POS? 3`: closed by the peer";
    assert_eq!(h.query_all_by_label(lost).count(), 3, "the fault shows on the three PI axes");
    h.get_by_label("Reconnect").click();
    wait_until(h, "the reconnection", Duration::from_secs(20), |w| {
        w.state.busy.is_none()
            && w.state.status == "reconnected"
            && w.state.hardware_status.as_ref().is_some_and(|(_, axes)| axes.iter().all(|a| a.error.is_none()))
    });
    assert_eq!(h.query_all_by_label("none").count(), 6);
    h.get_by_label("q1 = 10.0000 µm");
}

/// Disconnect: back on the virtual bench.
fn disconnect_to_the_virtual_bench(h: &mut Kittest) {
    h.get_by_label("Disconnect").click();
    wait_until(h, "the disconnection", Duration::from_secs(20), |w| w.connection.connected.is_none());
    assert!(h.state().state.worker.bench_name.contains("virtual bench"), "{}", h.state().state.worker.bench_name);
    // No tunable laser: the row says sweeps are refused, and Identify has nothing to ask.
    let family = h.state().state.settings.connection.laser.family;
    h.state_mut().state.settings.connection.laser.family = LaserFamily::None;
    h.run_steps(2);
    h.get_by_label_contains("the wizard and calibrate leave the plans' sweeps out");
    assert_eq!(h.query_all_by_label("Identify").count(), 3);
    h.state_mut().state.settings.connection.laser.family = family;
    h.run_steps(2);
}

/// A wrong device: the PI driver at the MCS emulator's port.
fn identify_a_wrong_device(h: &mut Kittest) {
    let mcs_port = h.state().state.settings.connection.controllers[1].port;
    h.state_mut().state.settings.connection.controllers[0].port = mcs_port;
    h.run_steps(1);
    h.get_all_by_label("Identify").next().unwrap().click();
    let wrong = "is this a PI GCS controller?";
    wait_until(h, "the wrong-device identification", Duration::from_secs(20), |w| refused(w, 0, wrong));
    h.get_by_label_contains(wrong);
}

/// A closed port: refused, naming address and port, for Identify and for Connect. Returns the
/// port, which stays in the settings.
fn identify_and_connect_to_a_closed_port(h: &mut Kittest) -> u16 {
    let closed = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    h.state_mut().state.settings.connection.controllers[0].port = closed;
    h.run_steps(1);
    h.get_all_by_label("Identify").next().unwrap().click();
    let refusal = format!("PI E-712: cannot connect to 127.0.0.1:{closed}: ");
    wait_until(h, "the refused identification", Duration::from_secs(20), |w| refused(w, 0, &refusal));
    h.get_by_label_contains(&refusal);
    h.get_by_label("Connect").click();
    wait_until(h, "the refused connection", Duration::from_secs(20), |w| {
        !w.connection.connecting && w.connection.message.as_ref().is_some_and(|m| m.is_err())
    });
    h.get_by_label_contains(&format!("not connected: {refusal}"));
    assert!(h.state().connection.connected.is_none());
    assert!(h.state().state.worker.bench_name.contains("virtual bench"));
    closed
}

/// The connection settings persist with the other settings, the `closed` port included.
fn check_the_settings_persist(h: Kittest, closed: u16) {
    let mut app = App { workbench: h.into_state() };
    let mut storage = MemoryStorage::default();
    eframe::App::save(&mut app, &mut storage);
    let back: Settings = eframe::get_value(&storage, eframe::APP_KEY).expect("settings were saved");
    assert_eq!(back.connection, app.workbench.state.settings.connection);
    assert!(back.connection.hardware && back.connection.controllers[0].port == closed);
}
