//! GUI tests (egui_kittest, headless): drive the workbench and check what it shows by accessible labels.
//! With PHOTOROBOT_SCREENSHOTS=1 the rendered views are also written to screenshots/.

use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use photorobot_app::gui::Workbench;

fn harness() -> Harness<'static, Workbench> {
    Harness::builder()
        .with_size(egui::vec2(1100.0, 700.0))
        .wgpu()
        .build_ui_state(|ui, app: &mut Workbench| app.show(ui), Workbench::default())
}

fn save_screenshot(h: &mut Harness<'_, Workbench>, name: &str) {
    let image = h.render().expect("the headless renderer (Mesa llvmpipe) renders the window");
    assert_eq!((image.width(), image.height()), (1100, 700));
    // Not a blank frame: the window has many distinct colours (text, panels, sliders).
    let distinct: std::collections::HashSet<[u8; 4]> = image.pixels().map(|p| p.0).collect();
    assert!(distinct.len() > 20, "the rendered frame looks blank");
    if std::env::var_os("PHOTOROBOT_SCREENSHOTS").is_some() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../screenshots");
        std::fs::create_dir_all(&dir).unwrap();
        image.save(dir.join(format!("{name}.png"))).unwrap();
    }
}

#[test]
fn the_window_opens_on_the_virtual_bench_and_shows_the_cavity() {
    let mut h = harness();
    h.run();
    h.get_by_label_contains("L = -898.830 µm");
    h.get_by_label_contains("P_r (world) = (104.243, 1.280, 101.818) µm");
    for frame in ["world", "link 6 (q6)", "end effector", "fiber", "tool (lamella)", "reflection point P_r"] {
        assert!(h.query_all_by_label_contains(frame).next().is_some(), "frame {frame} is not shown");
    }
    save_screenshot(&mut h, "foundation-frames");
}

#[test]
fn home_button_returns_the_joints_to_zero() {
    let mut app = Workbench::default();
    app.set_joints_display(&[10.0, -20.0, 30.0, 1.0, -2.0, 3.0]);
    let mut h = Harness::builder()
        .with_size(egui::vec2(1100.0, 700.0))
        .build_ui_state(|ui, app: &mut Workbench| app.show(ui), app);
    h.run();
    h.get_by_label_contains("L = -923.295 µm");
    h.get_by_label("Home (all joints 0)").click();
    h.run();
    h.get_by_label_contains("L = -898.830 µm");
}
