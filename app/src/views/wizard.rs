//! Calibration wizard: the measurement plan (the paper's strategies or the designed plan, what
//! each costs and determines, a plan designed for the bench at hand), pre-alignment check, the
//! steps of the plan, each explained (what the robot will do and why), with its planned motions,
//! a run button, progress, cancel, the recorded traces and redo; then identification.

use crate::motion::RedoAnswer;
use crate::state::{AppState, StepState};
use egui::RichText;
use egui_plot::{Line, Plot, PlotPoints};
use photorobot_core::measure::alignment::SignalQuality;

/// Draw the wizard.
pub fn ui(ui: &mut egui::Ui, s: &mut AppState, go_to_align: &mut bool) {
    confirm_redo(ui, s);
    egui::ScrollArea::vertical().id_salt("wizard").show(ui, |ui| {
        ui.heading("Calibration wizard");
        plan_choice(ui, s);
        ui.separator();
        ui.add_enabled_ui(!s.wizard.quick, |ui| {
            ui.horizontal(|ui| {
                ui.label("Identifier:");
                ui.radio_value(&mut s.settings.joint_mode, true, "joint (every parameter, with σ)");
                ui.radio_value(&mut s.settings.joint_mode, false, "paper (steps A, B, C)");
                if s.wizard.quick {
                    ui.label("(the designed plan is the joint identifier's)");
                }
            });
        });
        no_tunable_laser(ui, s);
        ui.separator();
        ui.label(RichText::new("0. Pre-alignment").size(18.0).strong());
        let q: Option<SignalQuality> = s.live.quality;
        match q {
            Some(q) => ui.label(q.advice()),
            None => ui.label("no live signal measured yet: check the signal in the Align view first"),
        };
        if ui.button("Open the alignment gauge").clicked() {
            *go_to_align = true;
        }
        for i in 0..s.wizard.steps.len() {
            ui.separator();
            step(ui, s, i);
        }
        ui.separator();
        ui.label(RichText::new(format!("{}. Identify", s.wizard.steps.len() + 1)).size(18.0).strong());
        let ready = s.ready_to_identify();
        let idle = s.busy.is_none() && s.wizard.running.is_none();
        if !ready {
            ui.label("run every step of the chosen plan above first");
        }
        if ui.add_enabled(ready && idle, egui::Button::new(RichText::new("Identify").size(18.0))).clicked() {
            s.identify();
        }
        if s.busy.as_deref() == Some("identifying") {
            ui.horizontal(|ui| {
                ui.spinner();
                ui.label("identifying: extracting dL and gaps from every trace, then the least-squares fit");
            });
        }
        if let Some(e) = &s.results.identify_error {
            ui.colored_label(ui.visuals().error_fg_color, format!("identification failed: {e}"));
        }
        if let Some(r) = &s.results.report {
            ui.label(format!(
                "identified from {} observations, residual {:.2} σ RMS: see Results",
                r.observations, r.residual_rms_sigma
            ));
        }
    });
}

/// Bench time of steps (min), from their plans' timing model from q = 0.
fn minutes(s: &AppState, steps: impl Iterator<Item = usize>) -> f64 {
    let limits = photorobot_core::plan::MotionLimits::default();
    steps.filter_map(|i| s.wizard.steps[i].plan.duration_s(s.chain.description(), [0.0; 6], &limits).ok()).sum::<f64>()
        / 60.0
}

/// The measurement plan: the paper's strategies or the designed plan, what each costs in bench
/// time and what it determines, and a plan designed for the bench at hand.
fn plan_choice(ui: &mut egui::Ui, s: &mut AppState) {
    ui.label(RichText::new("Measurement plan").size(18.0).strong());
    let n = s.wizard.steps.len();
    let joint = s.settings.joint_mode;
    let paper = minutes(s, (0..n).filter(|&i| !s.wizard.steps[i].designed && (joint || !s.wizard.steps[i].joint_only)));
    let designed = minutes(s, (0..n).filter(|&i| s.wizard.steps[i].designed));
    let running = s.wizard.running.is_some();
    ui.add_enabled_ui(!running, |ui| {
        let what = if joint { "strategies 1 and 2 and the extra measurements" } else { "strategies 1 and 2" };
        ui.radio_value(&mut s.wizard.quick, false, format!("The paper's {what}: {paper:.1} min of bench time"));
        ui.label(if joint {
            "    Determines every parameter the motions can see, far beyond the required σ (on table2-ideal: β_et, \
             θ_et 0.00006°; β_wf, θ_wf 0.0006°; x_wf, z_wf 0.005 µm; the gap y_wf − Z_et within 0.1 nm). The split \
             of the gap between y_wf and Z_et is seen only at second order."
        } else {
            "    Steps A, B, C: the lamella's tilt β_et, θ_et to about 0.0001° and the beam's line across the stage; \
             not where the fiber sits on it, nor its direction (held at the design value), nor the absolute gap."
        });
        let source = match &s.wizard.design.result {
            Some((preset, Ok(_))) => format!("designed here for {preset}"),
            _ => "shipped, designed for table2-ideal".into(),
        };
        ui.radio_value(
            &mut s.wizard.quick,
            true,
            format!("The designed plan ({source}): {designed:.2} min of bench time"),
        );
        ui.label(
            "    The joint identifier's required σ and no more: β_et, θ_et ≤ 0.005°, β_wf, θ_wf ≤ 0.01°, x_wf, z_wf ≤ \
             0.2 µm, the gap y_wf − Z_et ≤ 0.017 µm (on table2-ideal: 0.0017-0.0029°, 0.0023-0.0034°, 0.04-0.06 µm; \
             the gap within 0.1 nm). A move's forecast σ of the gap is then a few nm.",
        );
    });
    design_for_this_bench(ui, s);
}

/// "Design a plan for this bench": the experiment design for the preset at hand, and what it
/// predicts.
fn design_for_this_bench(ui: &mut egui::Ui, s: &mut AppState) {
    let preset = s.settings.preset.clone();
    let holds = s.wizard.steps.iter().any(|st| st.designed && !st.traces.is_empty());
    ui.horizontal(|ui| {
        let idle = !s.wizard.design.running() && s.wizard.running.is_none();
        let button = egui::Button::new(format!("Design a plan for this bench ({preset})"));
        if ui.add_enabled(idle && !holds, button).on_hover_text("as `photorobot design` does: a pilot run of 117 candidate motions at the design extrinsics, then the cheapest set that reaches every required σ").clicked() {
            s.wizard.design.start(&preset);
        }
        if s.wizard.design.running() {
            ui.spinner();
            ui.label("designing: a pilot run of the candidate motions, then the selection…");
            ui.ctx().request_repaint_after(std::time::Duration::from_millis(200));
        }
        if holds {
            ui.label("(the designed plan's step holds traces: redo it from scratch to measure another plan)");
        }
    });
    match &s.wizard.design.result {
        Some((preset, Ok(d))) => {
            ui.label(format!(
                "Designed for {preset}: {} motions, {:.2} min of bench time; predicted σ (required):",
                d.chosen.len(),
                d.total_s / 60.0
            ));
            for t in &d.targets {
                ui.monospace(format!(
                    "    {:<36} {:>10.5} {} ({:.4})",
                    t.name, t.predicted_sigma, t.unit, t.required_sigma
                ));
            }
        }
        Some((preset, Err(e))) => {
            ui.colored_label(ui.visuals().error_fg_color, format!("no plan designed for {preset}: {e}"));
        }
        None => {}
    }
}

/// Before step 1, on a bench without a tunable laser: the steps skip their sweeps, and what the
/// identifier loses by it (forecast on a pilot run of the plans).
fn no_tunable_laser(ui: &mut egui::Ui, s: &mut AppState) {
    if s.worker.tunable_laser {
        return;
    }
    let sweeps: usize = s.identifier_plans().iter().map(|p| p.sweeps()).sum();
    ui.separator();
    let warn = ui.visuals().warn_fg_color;
    ui.label(RichText::new("No tunable laser on this bench").size(18.0).strong().color(warn));
    ui.label(format!(
        "The laser cannot sweep its wavelength: the steps below run their motions and leave their {sweeps} \
         wavelength sweeps out. What that costs the identification:"
    ));
    match s.sweep_cost_forecast() {
        None => {
            ui.horizontal(|ui| {
                ui.spinner();
                ui.label("forecasting what the missing sweeps cost (a pilot run of the plans)…");
            });
            ui.ctx().request_repaint_after(std::time::Duration::from_millis(200));
        }
        Some(Ok(cost)) => {
            for sentence in cost.sentences() {
                ui.label(format!("• {sentence}"));
            }
        }
        Some(Err(e)) => {
            ui.colored_label(ui.visuals().error_fg_color, format!("the forecast failed: {e}"));
        }
    }
}

fn step(ui: &mut egui::Ui, s: &mut AppState, i: usize) {
    let idle = s.busy.is_none() && s.wizard.running.is_none();
    let used = s.step_used(i);
    let st = &s.wizard.steps[i];
    ui.label(RichText::new(format!("{}. {}", i + 1, st.title)).size(18.0).strong());
    if !used {
        ui.label(if s.wizard.quick || st.designed {
            "(not used by the measurement plan chosen above)"
        } else {
            "(not used by the paper identifier)"
        });
    }
    ui.label(st.explanation);
    let moves = st.plan.recorded_moves();
    let sweeps = st.plan.segments.iter().filter(|g| matches!(g, photorobot_core::plan::Segment::Sweep { .. })).count();
    let duration = st
        .plan
        .duration_s(s.chain.description(), [0.0; 6], &photorobot_core::plan::MotionLimits::default())
        .map_or("?".into(), |d| format!("{:.1} min", d / 60.0));
    let sweeps = if s.worker.tunable_laser { format!("{sweeps} sweeps") } else { format!("{sweeps} sweeps left out") };
    egui::CollapsingHeader::new(format!(
        "planned motions: {} segments, {moves} recorded moves, {sweeps}, about {duration} of bench time",
        st.plan.segments.len()
    ))
    .id_salt(("plan", i))
    .show(ui, |ui| {
        for (k, g) in st.plan.segments.iter().enumerate().take(200) {
            let what = match g {
                photorobot_core::plan::Segment::Move { to, record, .. } => format!(
                    "move to {:?}{}",
                    to.values().map(|v| v.map_or("·".to_string(), |v| format!("{v:.1}"))),
                    if *record { ", recorded" } else { "" }
                ),
                photorobot_core::plan::Segment::Sweep { from_nm, to_nm, .. } => {
                    format!("wavelength sweep {from_nm:.1} to {to_nm:.1} nm")
                }
                photorobot_core::plan::Segment::Dwell { duration_s, .. } => format!("dwell {duration_s:.2} s"),
            };
            ui.monospace(format!("{:>3} {:<40} {what}", k + 1, g.label()));
        }
    });
    let running_this = s.wizard.running.as_ref().is_some_and(|r| r.step == i);
    // F5 runs the first step not done: one never run or one stopped before its end.
    let label = match (&st.state, st.resume) {
        (StepState::Pending, _) => format!("Run step {} (F5)", i + 1),
        (StepState::Stopped(_), Some(_)) => format!("Resume or redo step {} (F5)", i + 1),
        (StepState::Stopped(_), None) => format!("Redo step {} (F5)", i + 1),
        _ => format!("Redo step {}", i + 1),
    };
    ui.horizontal(|ui| {
        if ui.add_enabled(idle && used, egui::Button::new(label)).clicked() {
            s.request_step(i);
        }
        if running_this && ui.button("Cancel (Esc)").clicked() {
            s.cancel();
        }
        match &s.wizard.steps[i].state {
            StepState::Pending => ui.label("not run"),
            StepState::Running => ui.label("running…"),
            StepState::Done => ui.label(format!("done: {} traces", s.wizard.steps[i].traces.len())),
            StepState::Stopped(e) => ui.colored_label(
                ui.visuals().warn_fg_color,
                format!("stopped: {e}; {} kept", plural(s.wizard.steps[i].traces.len(), "trace")),
            ),
        };
    });
    if let Some(r) = s.wizard.running.as_ref().filter(|r| r.step == i) {
        let (label, f) = (&r.label, r.fraction);
        ui.add(egui::ProgressBar::new(f as f32).show_percentage().text(format!("{label} — {:.0} %", f * 100.0)));
    }
    let st = &s.wizard.steps[i];
    if !st.traces.is_empty() {
        egui::CollapsingHeader::new(format!("recorded traces ({})", st.traces.len())).id_salt(("traces", i)).show(
            ui,
            |ui| {
                for t in st.traces.iter().take(100) {
                    ui.monospace(format!(
                        "{:<44} {:>8} samples {:>8.2} s",
                        t.meta.label,
                        t.len(),
                        t.t_s.last().unwrap_or(&0.0) - t.t_s[0]
                    ));
                }
                if let Some(t) = st.traces.last() {
                    let step = (t.len() / 2000).max(1);
                    let pts: Vec<[f64; 2]> =
                        (0..t.len()).step_by(step).map(|k| [t.t_s[k] - t.t_s[0], t.irradiance[k]]).collect();
                    ui.label(format!("last trace: {}", t.meta.label));
                    Plot::new(("last trace", i)).height(140.0).x_axis_label("s").y_axis_label("mW").show(ui, |p| {
                        p.line(Line::new("irradiance", PlotPoints::from(pts)));
                    });
                }
            },
        );
    }
}

/// The question before a step with traces runs again: "Resume" (a stopped step) keeps its whole
/// traces and measures the rest, "Redo" runs it again from the start, "Keep" (or Esc, or a click
/// beside the question) keeps its traces and runs nothing.
fn confirm_redo(ui: &mut egui::Ui, s: &mut AppState) {
    let Some(i) = s.wizard.confirm_redo else { return };
    let Some(step) = s.wizard.steps.get(i) else {
        s.wizard.confirm_redo = None;
        return;
    };
    let (count, state, resume) = (step.traces.len(), step.state.clone(), step.resume);
    let plan = s.plan_run(i);
    let interrupted = resume.and_then(|r| plan.segments.get(r.progress.next_segment)).map(|g| g.label().to_string());
    let mut answer = None;
    let modal = egui::Modal::new(egui::Id::unique("confirm redo")).show(ui.ctx(), |ui| {
        ui.heading(if resume.is_some() {
            format!("Resume or redo step {}?", i + 1)
        } else {
            format!("Redo step {}?", i + 1)
        });
        let how = match &state {
            StepState::Stopped(e) => format!("it was stopped ({e})"),
            StepState::Done => "it ran to the end".into(),
            _ => "it ran before".into(),
        };
        ui.label(format!("Redo step {} discards its {}: {how}.", i + 1, plural(count, "trace")));
        if let Some(r) = resume {
            ui.label(format!(
                "Resume keeps its {} and measures the rest, from the start of the segment it had reached ({}).",
                plural(r.whole_traces, "whole trace"),
                interrupted.as_deref().unwrap_or("?")
            ));
        }
        ui.horizontal(|ui| {
            if resume.is_some() && ui.button("Resume").clicked() {
                answer = Some(RedoAnswer::Resume);
            }
            if ui.button("Redo").clicked() {
                answer = Some(RedoAnswer::Redo);
            }
            if ui.button("Keep").clicked() {
                answer = Some(RedoAnswer::Keep);
            }
        });
    });
    if answer.is_none() && modal.should_close() {
        answer = Some(RedoAnswer::Keep);
    }
    if let Some(answer) = answer {
        s.answer_redo(answer);
    }
}

/// `n` and `what`, plural unless one ("1 trace", "3 traces").
fn plural(n: usize, what: &str) -> String {
    format!("{n} {what}{}", if n == 1 { "" } else { "s" })
}
