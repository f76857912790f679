//! The workbench GUI (eframe/egui): the top bar (bench, busy state, theme, settings), one tab per
//! view, the status bar and the keyboard shortcuts. Owns only presentation state; the bench runs
//! in the worker thread, the science is `photorobot_core`, the views are in [`crate::views`].
//!
//! Shortcuts act on the open tab (the view with focus): F5 runs the next wizard step in the
//! Wizard, Esc stops the motion the open view started, Space pauses the live trace in Live. The
//! red Stop in the status bar stops whatever moves, from any tab.

use crate::dialogs::{Dialogs, NativeDialogs};
use crate::motion::Motion;
use crate::settings::Settings;
use crate::state::{AppState, StepState};
use crate::views::{self, inspector::Inspector};
use crate::worker::Worker;
use egui::RichText;

/// The views, one per tab.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tab {
    /// Live irradiance, fringe count, dL, gap, visibility.
    Live,
    /// Pre-alignment gauge.
    Align,
    /// 3D robot, joints, frame tree.
    Robot,
    /// Calibration wizard.
    Wizard,
    /// Trace inspector.
    Traces,
    /// Identified parameters.
    Results,
    /// Validation motions.
    Validation,
    /// Discrepancy workflow.
    Diagnosis,
    /// Moves of the lamella to a target with the calibration.
    Position,
    /// Bench choice, controllers, axis mapping and status.
    Connection,
}

impl Tab {
    /// Every tab in display order.
    pub const ALL: [Tab; 10] = [
        Tab::Live,
        Tab::Align,
        Tab::Robot,
        Tab::Wizard,
        Tab::Traces,
        Tab::Results,
        Tab::Validation,
        Tab::Diagnosis,
        Tab::Position,
        Tab::Connection,
    ];

    /// Its title.
    pub fn title(self) -> &'static str {
        match self {
            Tab::Live => "Live",
            Tab::Align => "Align",
            Tab::Robot => "Robot",
            Tab::Wizard => "Wizard",
            Tab::Traces => "Traces",
            Tab::Results => "Results",
            Tab::Validation => "Validation",
            Tab::Diagnosis => "Diagnosis",
            Tab::Position => "Position",
            Tab::Connection => "Connection",
        }
    }

    /// The motion this view starts, which Esc stops while it is open.
    pub fn motion(self) -> Option<Motion> {
        match self {
            Tab::Live | Tab::Align => Some(Motion::Live),
            Tab::Robot => Some(Motion::Jog),
            Tab::Wizard => Some(Motion::Step),
            Tab::Validation => Some(Motion::Validation),
            Tab::Diagnosis => Some(Motion::Diagnosis),
            Tab::Position => Some(Motion::Position),
            Tab::Traces | Tab::Results | Tab::Connection => None,
        }
    }
}

/// The application.
pub struct Workbench {
    /// Shared state.
    pub state: AppState,
    /// The open tab.
    pub tab: Tab,
    /// The inspector's selection and plot cache.
    pub inspector: Inspector,
    /// The connection panel (emulators, identify results, the hardware bench).
    pub connection: views::connection::ConnectionPanel,
    /// Settings being edited (applied on "Apply").
    editing: Option<Settings>,
    /// The theme the visuals were last set to.
    applied_dark: Option<bool>,
    /// An action waiting for the unsaved-changes answer.
    pub pending: Option<Pending>,
    /// An action waiting for the save the user chose in the unsaved-changes prompt.
    pub after_save: Option<Pending>,
    /// A session folder whose autosave may be recovered (and how many traces it holds).
    pub recovery: Option<(std::path::PathBuf, usize)>,
    /// The window may close (nothing unsaved, or the user said so).
    pub quit: bool,
    /// Why a session folder could not be opened (shown until acknowledged).
    pub open_error: Option<String>,
}

/// An action that would lose unsaved changes.
#[derive(Debug, Clone, PartialEq)]
pub enum Pending {
    /// Start a new session.
    New,
    /// Open a session folder.
    Open(std::path::PathBuf),
    /// Close the window.
    Quit,
}

impl Workbench {
    /// The workbench on the virtual bench the settings name. `notify` wakes the UI when the
    /// worker has news (the app passes `request_repaint`).
    pub fn new(settings: Settings, dialogs: Box<dyn Dialogs>, notify: Box<dyn Fn() + Send>) -> Result<Self, String> {
        let worker = Worker::virtual_bench(&settings.preset, Some(settings.seed), settings.pace(), notify)?;
        Ok(Self {
            state: AppState::new(settings, worker, dialogs),
            tab: Tab::Wizard,
            inspector: Inspector::default(),
            connection: Default::default(),
            editing: None,
            applied_dark: None,
            pending: None,
            after_save: None,
            recovery: None,
            quit: false,
            open_error: None,
        })
    }

    /// At start, with no session open: offer the newest untitled session a crash left unsaved.
    pub fn offer_untitled_recovery(&mut self) {
        if self.state.session.dir.is_none() && self.recovery.is_none() {
            self.recovery = crate::session_io::newest_untitled(&self.state.session.untitled_base);
        }
    }

    /// Draw one frame.
    pub fn show(&mut self, ui: &mut egui::Ui) {
        self.state.poll_worker();
        self.resume_after_save();
        let ctx = ui.ctx().clone();
        // Identify and Connect finish on other threads whichever tab is open.
        self.connection.poll(&mut self.state, &ctx);
        if self.applied_dark != Some(self.state.settings.dark) {
            let dark = self.state.settings.dark;
            ctx.set_visuals(if dark { egui::Visuals::dark() } else { egui::Visuals::light() });
            self.applied_dark = Some(dark);
            // This pass was laid out with the old style: draw the next one with the new.
            ctx.request_repaint();
        }
        self.shortcuts(&ctx);
        egui::Panel::top("top bar").show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.heading("photorobot");
                ui.menu_button("File", |ui| self.file_menu(ui));
                // A hardware bench's name lists every controller's address: the hover has it.
                let bench = &self.state.worker.bench_name;
                ui.label(format!("bench: {}", bench.split(" (").next().unwrap_or(bench))).on_hover_text(bench);
                let name = self
                    .state
                    .session
                    .dir
                    .as_ref()
                    .and_then(|d| d.file_name())
                    .map_or("untitled".to_string(), |n| n.to_string_lossy().into_owned());
                ui.label(format!("session: {name}{}", if self.state.session.dirty { " (unsaved)" } else { "" }));
                ui.separator();
                for t in Tab::ALL {
                    ui.selectable_value(&mut self.tab, t, RichText::new(t.title()).size(15.0));
                }
                ui.separator();
                // Settings… is in the File menu: with it here the bar overflowed 1400 px and
                // clipped the button.
                if ui.button(if self.state.settings.dark { "Light theme" } else { "Dark theme" }).clicked() {
                    self.state.settings.dark = !self.state.settings.dark;
                }
            });
        });
        egui::Panel::bottom("status bar").show(ui, |ui| {
            ui.horizontal(|ui| {
                self.stop_button(ui);
                if let Some(b) = &self.state.busy {
                    ui.spinner();
                    ui.label(b);
                } else if let Some(r) = &self.state.wizard.running {
                    ui.spinner();
                    ui.label(format!("{} {:.0} %", r.label, r.fraction * 100.0));
                } else {
                    ui.label("idle");
                }
                ui.separator();
                self.state.messages.sync(&self.state.status);
                crate::views::messages::toggle(ui, &mut self.state);
                ui.label(&self.state.status);
                ui.separator();
                let q = self.state.q_display;
                ui.monospace(format!(
                    "q = ({:.2}, {:.2}, {:.2}) µm ({:.3}, {:.3}, {:.3})°",
                    q[0], q[1], q[2], q[3], q[4], q[5]
                ));
            });
        });
        views::messages::panel(ui, &mut self.state);
        self.settings_window(&ctx);
        views::lab::window(&ctx, &mut self.state);
        self.prompts(&ctx);
        self.worker_failure(&ctx);
        let mut go_to_align = false;
        egui::CentralPanel::default().show(ui, |ui| match self.tab {
            Tab::Live => views::live::ui(ui, &mut self.state),
            Tab::Align => views::align::ui(ui, &mut self.state),
            Tab::Robot => views::robot::ui(ui, &mut self.state),
            Tab::Wizard => views::wizard::ui(ui, &mut self.state, &mut go_to_align),
            Tab::Traces => views::inspector::ui(ui, &mut self.state, &mut self.inspector),
            Tab::Results => views::results::ui(ui, &mut self.state),
            Tab::Validation => views::validation::ui(ui, &mut self.state),
            Tab::Diagnosis => views::diagnosis::ui(ui, &mut self.state),
            Tab::Position => views::position::ui(ui, &mut self.state),
            Tab::Connection => views::connection::ui(ui, &mut self.state, &mut self.connection),
        });
        if go_to_align {
            self.tab = Tab::Align;
        }
        // Live data keeps coming while the live signal streams or a plan runs.
        if self.state.busy.is_some()
            || self.state.wizard.running.is_some()
            || self.state.worker.live.load(std::sync::atomic::Ordering::Relaxed)
        {
            ctx.request_repaint_after(std::time::Duration::from_millis(30));
        }
    }

    fn file_menu(&mut self, ui: &mut egui::Ui) {
        if ui.button("New session").clicked() {
            self.request(Pending::New);
        }
        if ui.button("Open session… (Ctrl+O)").clicked() {
            self.open_dialog();
        }
        ui.menu_button("Open recent", |ui| {
            if self.state.settings.recent.is_empty() {
                ui.label("none yet");
            }
            for r in self.state.settings.recent.clone() {
                if ui.button(&r).clicked() {
                    self.request(Pending::Open(r.into()));
                }
            }
        });
        if ui.button("Save (Ctrl+S)").clicked() {
            self.save(false);
        }
        if ui.button("Save as…").clicked() {
            self.save(true);
        }
        if ui.button("Settings…").clicked() {
            self.editing = Some(self.state.settings.clone());
        }
        if ui.button("Lab record and notes…").clicked() {
            views::lab::open(ui.ctx());
        }
        if ui.button("Export report…").clicked() {
            if let Some(path) = self.state.dialogs.save_report() {
                self.state.status = match self.state.snapshot().export_report(&path) {
                    Ok(()) => format!("report written to {}", path.display()),
                    Err(e) => format!("report not written: {e}"),
                };
            }
        }
    }

    fn open_dialog(&mut self) {
        if let Some(dir) = self.state.dialogs.open_session() {
            self.request(Pending::Open(dir));
        }
    }

    /// Save in the session folder (asking for one the first time, or with `as_new`).
    pub fn save(&mut self, as_new: bool) -> bool {
        let untitled = self
            .state
            .session
            .dir
            .as_ref()
            .is_none_or(|d| d.file_name().is_some_and(|n| n.to_string_lossy().starts_with("untitled-")));
        let dir = if as_new || untitled { self.state.dialogs.save_session() } else { self.state.session.dir.clone() };
        match dir {
            Some(dir) => {
                self.state.save_in_background(dir, false);
                true
            }
            None => false,
        }
    }

    /// Once the save chosen in the unsaved-changes prompt has finished: go ahead if it
    /// succeeded, ask again (with its error) if it did not.
    fn resume_after_save(&mut self) {
        if self.state.session.saving > 0 {
            return;
        }
        if let Some(action) = self.after_save.take() {
            if self.state.session.dirty {
                self.pending = Some(action);
            } else {
                self.perform(action);
            }
        }
    }

    /// Do `action` now, or after the unsaved-changes prompt.
    pub fn request(&mut self, action: Pending) {
        if self.state.session.dirty {
            self.pending = Some(action);
        } else {
            self.perform(action);
        }
    }

    fn perform(&mut self, action: Pending) {
        match action {
            Pending::New => self.state.start_new_session(),
            // A folder open in another photorobot is refused before anything is read from it.
            Pending::Open(dir) if self.refuse_locked(&dir) => {}
            Pending::Open(dir) => match crate::session_io::recoverable(&dir) {
                Some(n) => self.recovery = Some((dir, n)),
                None => self.open(&dir, false),
            },
            Pending::Quit => {
                self.state.session.dirty = false;
                self.quit = true;
            }
        }
    }

    /// Whether `dir` is open in another photorobot (the error is then on show).
    fn refuse_locked(&mut self, dir: &std::path::Path) -> bool {
        match self.state.acquire_lock(dir) {
            Ok(_) => false,
            Err(e) => {
                self.state.status = format!("cannot open: {e}");
                self.open_error = Some(e);
                true
            }
        }
    }

    fn open(&mut self, dir: &std::path::Path, recover: bool) {
        // The folder stays locked while its session is open here.
        let lock = match self.state.acquire_lock(dir) {
            Ok(lock) => lock,
            Err(e) => {
                self.state.status = format!("cannot open: {e}");
                self.open_error = Some(e);
                return;
            }
        };
        match crate::session_io::load(dir, recover) {
            Ok(loaded) => {
                if lock.is_some() {
                    self.state.session.lock = lock;
                }
                self.state.apply_loaded(loaded, dir);
                // A recovered session is newer than what is saved: it needs a save.
                if recover {
                    self.state.session.mark_dirty();
                }
                self.state.status = format!("{} {}", if recover { "recovered" } else { "opened" }, dir.display());
                self.tab = if self.state.results.report.is_some() { Tab::Results } else { Tab::Wizard };
            }
            Err(e) => self.state.status = format!("cannot open: {e}"),
        }
    }

    fn prompts(&mut self, ctx: &egui::Context) {
        if let Some(action) = self.pending.clone() {
            let mut answer = None;
            egui::Window::new("Unsaved changes").collapsible(false).resizable(false).show(ctx, |ui| {
                ui.label("The session has measurements or results that are not saved.");
                if let Some(e) = &self.state.session.save_error {
                    ui.colored_label(egui::Color32::from_rgb(220, 80, 60), format!("The last save failed: {e}"));
                }
                ui.horizontal(|ui| {
                    if ui.button("Save").clicked() {
                        answer = Some(0);
                    }
                    if ui.button("Discard").clicked() {
                        answer = Some(1);
                    }
                    if ui.button("Cancel").clicked() {
                        answer = Some(2);
                    }
                });
            });
            match answer {
                Some(0) => {
                    self.pending = None;
                    // The action waits for the save: done once it succeeds, asked again if it fails.
                    if self.save(false) {
                        self.after_save = Some(action);
                    }
                }
                Some(1) => {
                    self.pending = None;
                    self.state.session.dirty = false;
                    self.perform(action);
                }
                Some(_) => self.pending = None,
                None => {}
            }
        }
        if let Some((dir, n)) = self.recovery.clone() {
            let mut answer = None;
            egui::Window::new("Recover the autosave?").collapsible(false).resizable(false).show(ctx, |ui| {
                ui.label(format!(
                    "{} holds an autosave with {n} traces: the last run there did not end with a save (a crash?).",
                    dir.display()
                ));
                ui.horizontal(|ui| {
                    if ui.button("Recover the autosave").clicked() {
                        answer = Some(true);
                    }
                    // An untitled session has no saved session to open instead.
                    if photorobot_core::session::session_path(&dir).is_file()
                        && ui.button("Open the saved session").clicked()
                    {
                        answer = Some(false);
                    }
                    if ui.button("Cancel").clicked() {
                        self.recovery = None;
                    }
                });
            });
            if let Some(recover) = answer {
                self.recovery = None;
                self.open(&dir, recover);
            }
        }
        if let Some(e) = self.open_error.clone() {
            egui::Window::new("Cannot open the session").collapsible(false).resizable(false).show(ctx, |ui| {
                ui.colored_label(egui::Color32::from_rgb(220, 80, 60), e);
                if ui.button("OK").clicked() {
                    self.open_error = None;
                }
            });
        }
    }

    fn shortcuts(&mut self, ctx: &egui::Context) {
        let (save, open) = ctx.input_mut(|i| {
            (
                i.consume_key(egui::Modifiers::COMMAND, egui::Key::S),
                i.consume_key(egui::Modifiers::COMMAND, egui::Key::O),
            )
        });
        if save {
            self.save(false);
        }
        if open {
            self.open_dialog();
        }
        let typing = ctx.egui_wants_keyboard_input();
        let (f5, esc, space) = ctx.input(|i| {
            (i.key_pressed(egui::Key::F5), i.key_pressed(egui::Key::Escape), i.key_pressed(egui::Key::Space))
        });
        // F5 and Esc act on the open tab only; a modal question takes the keys while it is up.
        let asking = self.state.wizard.confirm_redo.is_some() || self.state.worker_failure.is_some();
        if f5 && self.tab == Tab::Wizard && !asking {
            let steps = &self.state.wizard.steps;
            if let Some(i) = (0..steps.len()).find(|&i| steps[i].state != StepState::Done && self.state.step_used(i)) {
                self.state.request_step(i);
            }
        }
        if f5 && self.tab == Tab::Position && !asking && !typing {
            self.state.go_position();
        }
        if esc && !asking {
            if let Some(motion) = self.tab.motion() {
                self.state.stop(motion);
            }
        }
        if space && !typing && self.tab == Tab::Live {
            self.state.live.paused = !self.state.live.paused;
        }
    }

    /// The red Stop, shown while anything moves: it stops whatever runs, from any tab (Esc only
    /// when the open view started the motion, and then the label says so).
    fn stop_button(&mut self, ui: &mut egui::Ui) {
        let Some(moving) = self.state.moving() else { return };
        let label = if self.tab.motion() == Some(moving) { "Stop (Esc)" } else { "Stop" };
        let button = egui::Button::new(RichText::new(label).size(16.0).strong().color(egui::Color32::WHITE))
            .fill(egui::Color32::from_rgb(200, 40, 40));
        let hover = "stop every motion of the bench; the traces recorded so far are kept";
        if ui.add(button).on_hover_text(hover).clicked() {
            self.state.stop_all();
        }
    }

    /// The worker caught a panic: say so, with the message, and offer to save what was kept.
    fn worker_failure(&mut self, ctx: &egui::Context) {
        let Some(message) = self.state.worker_failure.clone() else { return };
        let mut close = false;
        // Below the top bar, centred, as the settings.
        let at = ctx.content_rect().center_top() + egui::vec2(0.0, 48.0);
        let window = egui::Window::new("The bench worker failed").collapsible(false).resizable(false);
        window.pivot(egui::Align2::CENTER_TOP).default_pos(at).show(ctx, |ui| {
            ui.colored_label(egui::Color32::from_rgb(220, 80, 60), format!("panic: {message}"));
            ui.label(
                "What ran was stopped. Every trace recorded before the failure is kept (a wizard step \
                 is marked stopped). The bench is ready for the next command.",
            );
            ui.horizontal(|ui| {
                if ui.button("Save the session").clicked() {
                    self.save(false);
                    close = true;
                }
                if ui.button("Close").clicked() {
                    close = true;
                }
            });
        });
        if close {
            self.state.worker_failure = None;
        }
    }

    fn settings_window(&mut self, ctx: &egui::Context) {
        let Some(mut s) = self.editing.take() else { return };
        let mut open = true;
        let mut apply = false;
        // Below the top bar, centred: not over the bar and its menus.
        let at = ctx.content_rect().center_top() + egui::vec2(0.0, 48.0);
        egui::Window::new("Settings").open(&mut open).pivot(egui::Align2::CENTER_TOP).default_pos(at).show(ctx, |ui| {
            egui::Grid::new("settings grid").num_columns(2).show(ui, |ui| {
                ui.label("bench preset");
                egui::ComboBox::from_id_salt("preset").selected_text(&s.preset).show_ui(ui, |ui| {
                    for (name, _) in photorobot_core::bench::preset::EMBEDDED {
                        ui.selectable_value(&mut s.preset, name.to_string(), name);
                    }
                });
                ui.end_row();
                ui.label("random seed");
                ui.add(egui::DragValue::new(&mut s.seed));
                ui.end_row();
                ui.label("bench speed (0 = as fast as possible)");
                ui.add(egui::DragValue::new(&mut s.speed).range(0.0..=1000.0).suffix("× real time"));
                ui.end_row();
                ui.label("live window");
                ui.add(egui::DragValue::new(&mut s.live_window_s).range(0.1..=600.0).suffix(" s"));
                ui.end_row();
                ui.label("theme");
                ui.checkbox(&mut s.dark, "dark");
                ui.end_row();
            });
            ui.label("Changing the bench or the seed restarts the bench and clears the recorded steps.");
            apply = ui.button("Apply").clicked();
        });
        if apply {
            let restart = s.preset != self.state.settings.preset || s.seed != self.state.settings.seed;
            if restart {
                let ctx2 = ctx.clone();
                match Worker::virtual_bench(&s.preset, Some(s.seed), s.pace(), Box::new(move || ctx2.request_repaint()))
                {
                    Ok(w) => {
                        let dialogs = std::mem::replace(&mut self.state.dialogs, Box::new(NativeDialogs));
                        self.state = AppState::new(s, w, dialogs);
                    }
                    Err(e) => self.state.status = format!("bench not changed: {e}"),
                }
            } else {
                self.state.settings = s;
            }
        } else if open {
            self.editing = Some(s);
        }
    }
}

/// The eframe application: the workbench plus settings persistence.
pub struct App {
    /// The workbench.
    pub workbench: Workbench,
}

impl eframe::App for App {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        if ctx.input(|i| i.viewport().close_requested()) && !self.workbench.quit && self.workbench.state.session.dirty {
            ctx.send_viewport_cmd(egui::ViewportCommand::CancelClose);
            self.workbench.pending = Some(Pending::Quit);
        }
        self.workbench.show(ui);
        // Close once every save has finished writing.
        if self.workbench.quit && self.workbench.state.session.saving == 0 {
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
        }
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        eframe::set_value(storage, eframe::APP_KEY, &self.workbench.state.settings);
    }
}

/// Open the native window on the virtual bench of the saved settings.
pub fn run_native() -> eframe::Result {
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default().with_inner_size([1400.0, 900.0]).with_title("photorobot"),
        ..Default::default()
    };
    eframe::run_native(
        "photorobot",
        options,
        Box::new(|cc| {
            let settings: Settings = cc.storage.and_then(|s| eframe::get_value(s, eframe::APP_KEY)).unwrap_or_default();
            let notify = |ctx: egui::Context| Box::new(move || ctx.request_repaint());
            let workbench = Workbench::new(settings, Box::new(NativeDialogs), notify(cc.egui_ctx.clone()))
                .or_else(|e| {
                    eprintln!("warning: saved settings refused ({e}); starting on the default bench");
                    Workbench::new(Settings::default(), Box::new(NativeDialogs), notify(cc.egui_ctx.clone()))
                })
                .map_err(|e| -> Box<dyn std::error::Error + Send + Sync> { e.into() })?;
            let mut workbench = workbench;
            workbench.offer_untitled_recovery();
            Ok(Box::new(App { workbench }))
        }),
    )
}
