//! Frame tree: the hierarchy world → links → end effector → tool → reflection point, and world →
//! fiber, each node with its transform in its parent (translation µm, rotation as roll-pitch-yaw
//! °); selecting a node highlights it in the robot view.

use crate::state::AppState;
use photorobot_core::model::frames::FrameTree;

/// Draw the tree of `tree`; a click selects a node.
pub fn ui(ui: &mut egui::Ui, s: &mut AppState, tree: &FrameTree) {
    ui.heading("Frame tree");
    egui::ScrollArea::vertical().id_salt("frame tree").show(ui, |ui| node(ui, s, tree, 0));
}

fn node(ui: &mut egui::Ui, s: &mut AppState, tree: &FrameTree, i: usize) {
    let n = &tree.nodes[i];
    let t = n.local.translation.vector;
    let (r, p, y) = n.local.rotation.euler_angles();
    let selected = s.robot_view.selected_frame == Some(i);
    let children: Vec<usize> = tree.children(i).collect();
    let id = ui.make_persistent_id(("frame", i));
    egui::collapsing_header::CollapsingState::load_with_default_open(ui.ctx(), id, true)
        .show_header(ui, |ui| {
            if ui.selectable_label(selected, &n.name).clicked() {
                s.robot_view.selected_frame = if selected { None } else { Some(i) };
            }
        })
        .body(|ui| {
            ui.label(
                egui::RichText::new(format!(
                    "t = ({:.3}, {:.3}, {:.3}) µm, rpy = ({:.4}, {:.4}, {:.4})°",
                    t.x,
                    t.y,
                    t.z,
                    r.to_degrees(),
                    p.to_degrees(),
                    y.to_degrees()
                ))
                .monospace()
                .size(10.5),
            );
            for c in children {
                node(ui, s, tree, c);
            }
        });
}
