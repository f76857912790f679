//! The workbench GUI (eframe/egui): the top bar (bench, busy state, theme, settings), one tab per
//! view, the status bar and the keyboard shortcuts. Owns only presentation state; the bench runs
//! in the worker thread, the science is `photorobot_core`, the views are in [`crate::views`].
//!
//! Shortcuts: F5 runs the next wizard step, Esc cancels what runs, Space pauses the live trace.

use crate::dialogs::{Dialogs, NativeDialogs};
use crate::state::{AppState, Settings, StepState};
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
}

impl Tab {
    /// Every tab in display order.
    pub const ALL: [Tab; 8] =
        [Tab::Live, Tab::Align, Tab::Robot, Tab::Wizard, Tab::Traces, Tab::Results, Tab::Validation, Tab::Diagnosis];

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
    /// Settings being edited (applied on "Apply").
    editing: Option<Settings>,
    /// The theme the visuals were last set to.
    applied_dark: Option<bool>,
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
            editing: None,
            applied_dark: None,
        })
    }

    /// Draw one frame.
    pub fn show(&mut self, ui: &mut egui::Ui) {
        self.state.poll_worker();
        let ctx = ui.ctx().clone();
        if self.applied_dark != Some(self.state.settings.dark) {
            let dark = self.state.settings.dark;
            ctx.set_visuals(if dark { egui::Visuals::dark() } else { egui::Visuals::light() });
            self.applied_dark = Some(dark);
        }
        self.shortcuts(&ctx);
        egui::Panel::top("top bar").show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.heading("photorobot");
                ui.label(format!("bench: {}", self.state.worker.bench_name));
                ui.separator();
                for t in Tab::ALL {
                    ui.selectable_value(&mut self.tab, t, RichText::new(t.title()).size(16.0));
                }
                ui.separator();
                if ui.button(if self.state.settings.dark { "Light theme" } else { "Dark theme" }).clicked() {
                    self.state.settings.dark = !self.state.settings.dark;
                }
                if ui.button("Settings…").clicked() {
                    self.editing = Some(self.state.settings.clone());
                }
            });
        });
        egui::Panel::bottom("status bar").show(ui, |ui| {
            ui.horizontal(|ui| {
                if let Some(b) = &self.state.busy {
                    ui.spinner();
                    ui.label(b);
                } else if let Some((_, label, f)) = &self.state.running {
                    ui.spinner();
                    ui.label(format!("{label} {:.0} %", f * 100.0));
                } else {
                    ui.label("idle");
                }
                ui.separator();
                ui.label(&self.state.status);
                ui.separator();
                let q = self.state.q_display;
                ui.monospace(format!(
                    "q = ({:.2}, {:.2}, {:.2}) µm ({:.3}, {:.3}, {:.3})°",
                    q[0], q[1], q[2], q[3], q[4], q[5]
                ));
            });
        });
        self.settings_window(&ctx);
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
        });
        if go_to_align {
            self.tab = Tab::Align;
        }
        // Live data keeps coming while the live signal streams or a plan runs.
        if self.state.busy.is_some()
            || self.state.running.is_some()
            || self.state.worker.live.load(std::sync::atomic::Ordering::Relaxed)
        {
            ctx.request_repaint_after(std::time::Duration::from_millis(30));
        }
    }

    fn shortcuts(&mut self, ctx: &egui::Context) {
        let typing = ctx.egui_wants_keyboard_input();
        let (f5, esc, space) = ctx.input(|i| {
            (i.key_pressed(egui::Key::F5), i.key_pressed(egui::Key::Escape), i.key_pressed(egui::Key::Space))
        });
        if f5 {
            let joint = self.state.settings.joint_mode;
            if let Some(i) =
                self.state.steps.iter().position(|s| s.state != StepState::Done && (joint || !s.joint_only))
            {
                self.state.run_step(i);
            }
        }
        if esc {
            self.state.cancel();
        }
        if space && !typing && self.tab == Tab::Live {
            self.state.live.paused = !self.state.live.paused;
        }
    }

    fn settings_window(&mut self, ctx: &egui::Context) {
        let Some(mut s) = self.editing.take() else { return };
        let mut open = true;
        let mut apply = false;
        egui::Window::new("Settings").open(&mut open).show(ctx, |ui| {
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
        self.workbench.show(ui);
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
            Ok(Box::new(App { workbench }))
        }),
    )
}
