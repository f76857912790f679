//! Building one frame of the workbench with a 10-million-sample trace loaded (plot data
//! preparation included: the decimation runs every frame over the visible range).
//! `cargo bench -p photorobot --bench frame`; target ≤ 8 ms median in release.

use criterion::{criterion_group, criterion_main, Criterion};
use egui_kittest::Harness;
use photorobot_app::dialogs::ScriptedDialogs;
use photorobot_app::gui::{Tab, Workbench};
use photorobot_app::settings::Settings;
use photorobot_app::worker::Event;

const SAMPLES: usize = 10_000_000;

fn loaded(tab: Tab) -> Harness<'static, Workbench> {
    let mut w = Workbench::new(Settings::default(), Box::new(ScriptedDialogs::default()), Box::new(|| {})).unwrap();
    // Ten million samples of a fringe signal at 10 kHz, in batches as the bench sends them.
    let batch = 500;
    for b in 0..SAMPLES / batch {
        let t_s: Vec<f64> = (0..batch).map(|k| (b * batch + k) as f64 * 1e-4).collect();
        let irradiance: Vec<f64> = t_s.iter().map(|t| 0.5 + 0.3 * (t * 40.0).sin() + 0.01 * (t * 3e3).cos()).collect();
        w.state.apply(Event::Samples {
            t_s,
            irradiance,
            q_display: [0.0; 6],
            wavelength_nm: 1550.0,
            gap_um: Some(900.0),
            model_step_nm: 1.0,
        });
    }
    // The whole trace in view: the worst case for the decimation.
    w.state.settings.live_window_s = SAMPLES as f64 * 1e-4;
    w.tab = tab;
    let mut h = Harness::builder()
        .with_size(egui::vec2(1400.0, 900.0))
        .build_ui_state(|ui, app: &mut Workbench| app.show(ui), w);
    h.run_steps(3);
    h
}

fn frame(c: &mut Criterion) {
    let mut h = loaded(Tab::Live);
    assert_eq!(h.state().state.live.trace.len(), SAMPLES);
    c.bench_function("live view frame, 10 M samples in view", |b| b.iter(|| h.step()));
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = frame
}
criterion_main!(benches);
