//! The workbench GUI (eframe/egui). For now: the virtual bench placeholder with joint jog sliders,
//! the frame tree and the cavity it defines. Owns only presentation state; the model is `photorobot_core`.

use photorobot_core::model::extrinsics::Extrinsics;
use photorobot_core::model::frames::FrameTree;
use photorobot_core::model::kinematics::Chain;

/// The application state.
pub struct Workbench {
    chain: Chain,
    extrinsics: Extrinsics,
    /// Joint values in display units (µm, °).
    q_display: Vec<f64>,
}

impl Default for Workbench {
    fn default() -> Self {
        let chain = Chain::femto_6dof();
        let q_display = vec![0.0; chain.dof()];
        Self { chain, extrinsics: Extrinsics::table2(), q_display }
    }
}

impl Workbench {
    /// Set the joints (µm, °), clamped to their limits.
    pub fn set_joints_display(&mut self, q_display: &[f64]) {
        for ((v, l), new) in self.q_display.iter_mut().zip(&self.chain.description().links).zip(q_display) {
            *v = new.clamp(l.limits.min, l.limits.max);
        }
    }

    /// Draw the whole window.
    pub fn show(&mut self, ui: &mut egui::Ui) {
        egui::Panel::top("title").show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.heading("photorobot");
                ui.label("bench: virtual (table2-ideal) — the measurement views come with the next issues");
            });
        });
        egui::Panel::left("joints").resizable(false).show(ui, |ui| {
            ui.heading("Joints");
            let desc = self.chain.description().clone();
            for (l, v) in desc.links.iter().zip(self.q_display.iter_mut()) {
                ui.add(egui::Slider::new(v, l.limits.min..=l.limits.max).text(format!(
                    "{} ({})",
                    l.name,
                    l.joint.display_unit()
                )));
            }
            if ui.button("Home (all joints 0)").clicked() {
                self.q_display.iter_mut().for_each(|v| *v = 0.0);
            }
        });
        let q = self.chain.description().q_from_display(&self.q_display);
        let tree = FrameTree::new(&self.chain, &self.extrinsics, &q);
        egui::CentralPanel::default().show(ui, |ui| {
            match &tree.cavity {
                Ok(c) => {
                    ui.label(egui::RichText::new(format!("L = {:.3} µm", c.length_um)).size(28.0))
                        .on_hover_text("signed cavity length; the gap is |L|");
                    let p = c.reflection_point_world_um;
                    ui.label(format!("P_r (world) = ({:.3}, {:.3}, {:.3}) µm", p.x, p.y, p.z));
                    ui.label(format!("angle between n_t and n_f = {:.3} mrad", c.tilt_rad * 1e3));
                }
                Err(e) => {
                    ui.label(format!("no cavity: {e}"));
                }
            }
            ui.separator();
            ui.heading("Frame tree");
            egui::Grid::new("frames").striped(true).show(ui, |ui| {
                ui.strong("frame");
                ui.strong("origin in world (µm)");
                ui.end_row();
                for (i, n) in tree.nodes.iter().enumerate() {
                    ui.label(format!("{}{}", "    ".repeat(tree.depth(i)), n.name));
                    let p = n.world.translation.vector;
                    ui.monospace(format!("{:>10.3} {:>10.3} {:>10.3}", p.x, p.y, p.z));
                    ui.end_row();
                }
            });
        });
    }
}

impl eframe::App for Workbench {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.show(ui);
    }
}

/// Open the native window.
pub fn run_native() -> eframe::Result {
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default().with_inner_size([1100.0, 700.0]).with_title("photorobot"),
        ..Default::default()
    };
    eframe::run_native("photorobot", options, Box::new(|_cc| Ok(Box::new(Workbench::default()))))
}
