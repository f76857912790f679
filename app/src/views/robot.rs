//! Robot view: a 3D wireframe of the robot (orthographic, Z up) with a triad for every frame of
//! the frame tree, the lamella plane and the beam from the fiber to the reflection point; orbit
//! (drag), zoom (scroll), reset. Beside it the joint readouts and jog controls, clamped to the
//! joint limits, and the frame tree.

use crate::state::{AppState, Camera};
use crate::views::frames;
use crate::worker::Command;
use egui::{Color32, Pos2, Stroke};
use nalgebra::{Point3, Rotation3, Vector3};
use photorobot_core::model::frames::{FrameKind, FrameTree};

/// Draw the robot view with its side panels.
pub fn ui(ui: &mut egui::Ui, s: &mut AppState) {
    let q = s.chain.description().q_from_display(&s.q_display);
    let tree = FrameTree::new(&s.chain, &s.extrinsics, &q);
    egui::Panel::left("jog").resizable(false).show(ui, |ui| jog(ui, s, &tree));
    egui::Panel::right("frame tree panel").default_size(470.0).show(ui, |ui| frames::ui(ui, s, &tree));
    egui::CentralPanel::default().show(ui, |ui| {
        ui.horizontal(|ui| {
            if ui.button("Reset view").clicked() {
                s.robot_view.camera = Camera::default();
            }
            ui.label("drag to orbit, scroll to zoom; Z up, beam along Y_w");
            if let Some(i) = s.robot_view.selected_frame {
                ui.strong(format!("selected: {}", tree.nodes[i].name));
            }
        });
        scene(ui, s, &tree);
    });
}

fn jog(ui: &mut egui::Ui, s: &mut AppState, tree: &FrameTree) {
    ui.heading("Joints");
    let desc = s.chain.description().clone();
    egui::Grid::new("joint grid").num_columns(2).show(ui, |ui| {
        for (j, l) in desc.links.iter().enumerate() {
            let unit = l.joint.display_unit();
            ui.label(format!("{} = {:.3} {unit}", l.name, s.q_display[j]));
            ui.add(
                egui::Slider::new(&mut s.robot_view.jog_target[j], l.limits.min..=l.limits.max)
                    .suffix(format!(" {unit}"))
                    .text("target"),
            );
            ui.end_row();
        }
    });
    let idle = s.busy.is_none() && s.wizard.running.is_none();
    ui.horizontal(|ui| {
        if ui.add_enabled(idle, egui::Button::new("Move to targets")).clicked() {
            s.worker.send(Command::Jog(s.robot_view.jog_target));
        }
        if ui.add_enabled(idle, egui::Button::new("Home (all joints 0)")).clicked() {
            s.robot_view.jog_target = [0.0; 6];
            s.worker.send(Command::Jog([0.0; 6]));
        }
    });
    ui.separator();
    match &tree.cavity {
        Ok(c) => {
            ui.label(egui::RichText::new(format!("L = {:.3} µm", c.length_um)).size(22.0))
                .on_hover_text("signed cavity length from the current extrinsics; the gap is |L|");
            let p = c.reflection_point_world_um;
            ui.label(format!("P_r (world) = ({:.3}, {:.3}, {:.3}) µm", p.x, p.y, p.z));
            ui.label(format!("angle between n_t and n_f = {:.3} mrad", c.tilt_rad * 1e3));
        }
        Err(e) => {
            ui.label(format!("no cavity: {e}"));
        }
    }
}

fn scene(ui: &mut egui::Ui, s: &mut AppState, tree: &FrameTree) {
    let size = ui.available_size();
    let (response, painter) = ui.allocate_painter(size, egui::Sense::drag());
    if response.dragged() {
        let d = response.drag_delta();
        s.robot_view.camera.yaw += d.x * 0.01;
        s.robot_view.camera.pitch = (s.robot_view.camera.pitch + d.y * 0.01).clamp(-1.55, 1.55);
    }
    if response.hovered() {
        let scroll = ui.input(|i| i.smooth_scroll_delta.y);
        if scroll != 0.0 {
            s.robot_view.camera.zoom = (s.robot_view.camera.zoom * (1.0 + scroll * 0.002)).clamp(0.05, 50.0);
        }
    }
    let rect = response.rect;
    painter.rect_filled(rect, 0.0, ui.visuals().extreme_bg_color);
    // The scene's extent: every origin, P_r and the beam.
    let mut pts: Vec<Point3<f64>> = tree.nodes.iter().map(|n| n.world.translation.vector.into()).collect();
    if let Ok(c) = &tree.cavity {
        pts.push(c.reflection_point_world_um);
    }
    let (mut lo, mut hi) = (pts[0], pts[0]);
    for p in &pts {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let centre = nalgebra::center(&lo, &hi);
    let extent = (hi - lo).norm().max(100.0);
    let rot = Rotation3::from_axis_angle(&Vector3::x_axis(), s.robot_view.camera.pitch as f64)
        * Rotation3::from_axis_angle(&Vector3::z_axis(), s.robot_view.camera.yaw as f64);
    let scale = rect.width().min(rect.height()) as f64 * 0.8 / extent * s.robot_view.camera.zoom as f64;
    let project = |p: &Point3<f64>| -> Pos2 {
        let v = rot * (p - centre);
        Pos2::new(rect.center().x + (v.x * scale) as f32, rect.center().y - (v.z * scale) as f32)
    };
    let text = ui.visuals().text_color();
    let grey = Stroke::new(2.0, ui.visuals().weak_text_color());
    // The kinematic chain: each frame to its parent.
    for n in &tree.nodes {
        if let Some(p) = n.parent {
            let a: Point3<f64> = tree.nodes[p].world.translation.vector.into();
            let b: Point3<f64> = n.world.translation.vector.into();
            painter.line_segment([project(&a), project(&b)], grey);
        }
    }
    // The lamella plane and the beam.
    if let Ok(c) = &tree.cavity {
        let n = c.n_t.into_inner();
        let u = n.cross(&Vector3::z()).try_normalize(1e-9).unwrap_or_else(|| n.cross(&Vector3::x()).normalize());
        let v = n.cross(&u);
        let h = 0.3 * extent;
        let corners: Vec<Pos2> = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .iter()
            .map(|(a, b)| project(&(c.reflection_point_world_um + (u * *a + v * *b) * h)))
            .collect();
        painter.add(egui::Shape::convex_polygon(
            corners,
            Color32::from_rgba_unmultiplied(120, 180, 255, 40),
            Stroke::new(1.5, Color32::from_rgb(120, 180, 255)),
        ));
        let fiber = tree.nodes.iter().find(|n| n.kind == FrameKind::Fiber).map(|n| n.world.translation.vector);
        if let Some(f) = fiber {
            painter.line_segment(
                [project(&f.into()), project(&c.reflection_point_world_um)],
                Stroke::new(3.0, Color32::from_rgb(255, 80, 60)),
            );
        }
    }
    // A triad per frame; the selected one thick, with its name.
    let axis_len = 0.12 * extent;
    for (i, n) in tree.nodes.iter().enumerate() {
        let o: Point3<f64> = n.world.translation.vector.into();
        let selected = s.robot_view.selected_frame == Some(i);
        let width = if selected { 4.0 } else { 1.5 };
        for (k, color) in [
            (0, Color32::from_rgb(230, 70, 70)),
            (1, Color32::from_rgb(70, 200, 90)),
            (2, Color32::from_rgb(80, 130, 255)),
        ] {
            let axis = n.world.rotation * Vector3::ith(k, 1.0);
            painter.line_segment([project(&o), project(&(o + axis * axis_len))], Stroke::new(width, color));
        }
        let named = selected || matches!(n.kind, FrameKind::World | FrameKind::Fiber | FrameKind::ReflectionPoint);
        if named {
            if selected {
                painter.circle_stroke(project(&o), 10.0, Stroke::new(2.0, Color32::YELLOW));
            }
            painter.text(
                project(&o) + egui::vec2(8.0, -14.0),
                egui::Align2::LEFT_BOTTOM,
                &n.name,
                egui::FontId::proportional(14.0),
                text,
            );
        }
    }
    painter.text(
        rect.left_bottom() + egui::vec2(8.0, -8.0),
        egui::Align2::LEFT_BOTTOM,
        format!("scene {:.0} µm across; axes x red, y green, z blue; beam red; lamella blue", extent),
        egui::FontId::proportional(13.0),
        text,
    );
}
