//! Shared kittest helpers of the GUI test binaries (`gui.rs`, `connection.rs`): the headless
//! harness, waiting on the worker, tab switching, screenshots, in-memory eframe storage and a
//! save through the scripted folder dialog, the end of a resumed wizard step, a bench preset
//! without a tunable laser and the recovery of a crashed untitled session.
#![allow(dead_code)] // each test binary uses its own subset

use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use photorobot_app::dialogs::ScriptedDialogs;
use photorobot_app::gui::{Tab, Workbench};
use std::path::Path;
use std::time::{Duration, Instant};

/// Window size of every test and screenshot.
pub const SIZE: egui::Vec2 = egui::vec2(1400.0, 900.0);

/// The workbench in a headless harness rendered with wgpu (Mesa llvmpipe).
pub fn harness(app: Workbench) -> Harness<'static, Workbench> {
    Harness::builder().with_size(SIZE).wgpu().build_ui_state(|ui, app: &mut Workbench| app.show(ui), app)
}

/// Scroll the widget labelled `label` into view, as a user would, and click it once it has
/// stopped moving: a click lands where the widget is drawn, and the wizard's later buttons sit
/// below its steps.
pub fn click_in_view(h: &mut Harness<'_, Workbench>, label: &str) {
    h.get_by_label(label).scroll_to_me();
    h.run_steps(2);
    // The scroll is animated: step until the widget stops moving.
    for _ in 0..120 {
        let before = h.get_by_label(label).rect();
        h.run_steps(1);
        if h.get_by_label(label).rect() == before {
            break;
        }
    }
    h.get_by_label(label).click();
}

/// Step the UI (the worker and network I/O run on other threads) until `done` holds, or fail
/// after `timeout` with the status line and the connection panel's message.
pub fn wait_until(h: &mut Harness<'_, Workbench>, what: &str, timeout: Duration, done: impl Fn(&Workbench) -> bool) {
    let start = Instant::now();
    loop {
        h.run_steps(1);
        if done(h.state()) {
            h.run_steps(2);
            return;
        }
        assert!(
            start.elapsed() < timeout,
            "timed out after {timeout:?} waiting for {what}; status: {}; connection panel: {:?}",
            h.state().state.status,
            h.state().connection.message
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Wait for the resumed wizard step 1 to end (the first `kept` of its traces from before), and
/// check that it holds those first, unchanged, and one whole trace per recorded segment of its
/// plan, in order, with nothing left to resume.
pub fn resumed_step_1_ends_whole(h: &mut Harness<'_, Workbench>, kept: &[photorobot_core::trace::Trace]) {
    use photorobot_app::state::StepState;
    wait_until(h, "the rest of step 1", Duration::from_secs(600), |w| w.state.wizard.steps[0].state == StepState::Done);
    let step = &h.state().state.wizard.steps[0];
    assert_eq!(step.traces[..kept.len()], kept[..], "the traces from before come first, unchanged");
    let labels: Vec<&str> = step.traces.iter().map(|t| t.meta.label.as_str()).collect();
    let planned: Vec<&str> = step.plan.segments.iter().filter(|g| g.is_recorded()).map(|g| g.label()).collect();
    assert_eq!(labels, planned, "one whole trace per recorded segment, in order");
    assert!(step.resume.is_none(), "nothing left to resume");
}

/// A copy of the `table2-ideal` preset named `fixed-laser` whose laser is not tunable, written
/// into `dir`: its path.
pub fn fixed_laser_preset(dir: &Path) -> String {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/benches/table2-ideal.ron"))
        .unwrap()
        .replace("name: \"table2-ideal\"", "name: \"fixed-laser\"")
        .replace(
            "laser: (wavelength_nm: 1560.0, rin_rel: 0.0)",
            "laser: (wavelength_nm: 1560.0, rin_rel: 0.0, tunable: false)",
        );
    assert!(text.contains("tunable: false"));
    let preset = dir.join("fixed-laser.ron");
    std::fs::write(&preset, text).unwrap();
    preset.display().to_string()
}

/// Recover the newest untitled session a crash left in `base`, as offered at start.
pub fn recover_untitled(h: &mut Harness<'_, Workbench>, base: &Path) {
    h.state_mut().state.session.untitled_base = base.to_path_buf();
    h.state_mut().offer_untitled_recovery();
    h.run_steps(3);
    h.get_by_label("Recover the autosave").click();
    h.run_steps(3);
}

/// Click a tab and check it is shown.
pub fn open(h: &mut Harness<'_, Workbench>, tab: Tab) {
    h.get_by_label(tab.title()).click();
    h.run_steps(3);
    assert_eq!(h.state().tab, tab);
}

/// Render the window, check it is not blank, and with PHOTOROBOT_SCREENSHOTS set write it to
/// `screenshots/<name>.png`.
pub fn screenshot(h: &mut Harness<'_, Workbench>, name: &str) {
    let image = h.render().expect("the headless renderer (Mesa llvmpipe) renders the window");
    assert_eq!((image.width(), image.height()), (SIZE.x as u32, SIZE.y as u32));
    let distinct: std::collections::HashSet<[u8; 4]> = image.pixels().map(|p| p.0).collect();
    assert!(distinct.len() > 20, "the rendered frame of {name} looks blank");
    if std::env::var_os("PHOTOROBOT_SCREENSHOTS").is_some() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../screenshots");
        std::fs::create_dir_all(&dir).unwrap();
        image.save(dir.join(format!("{name}.png"))).unwrap();
    }
}

/// Save the session as `folder` through the scripted folder dialog, wait for the save and load
/// it back from disk.
pub fn save_as_and_load(h: &mut Harness<'_, Workbench>, folder: &Path) -> photorobot_core::session::Session {
    h.state_mut().state.dialogs =
        Box::new(ScriptedDialogs { folders: vec![Some(folder.to_path_buf())], ..Default::default() });
    h.state_mut().save(true);
    wait_until(h, "the save", Duration::from_secs(60), |w| w.state.session.saving == 0);
    photorobot_core::session::Session::load(folder).expect("the saved session loads")
}

/// eframe storage in memory.
#[derive(Default)]
pub struct MemoryStorage(pub std::collections::HashMap<String, String>);

impl eframe::Storage for MemoryStorage {
    fn get_string(&self, key: &str) -> Option<String> {
        self.0.get(key).cloned()
    }
    fn set_string(&mut self, key: &str, value: String) {
        self.0.insert(key.to_string(), value);
    }
    fn remove_string(&mut self, key: &str) {
        self.0.remove(key);
    }
    fn flush(&mut self) {}
}
