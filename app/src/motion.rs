//! What moves the bench and stopping it: the kinds of motion the views start, which one runs,
//! stopping it (all of them share the worker's one stop flag, raised only while something
//! moves), and starting a wizard step without losing the traces of an earlier run.

use crate::state::AppState;
use crate::worker::{BUSY_DIAGNOSING, BUSY_EFFECT_VALIDATION, BUSY_JOGGING, BUSY_MOVING, BUSY_VALIDATING};
use std::sync::atomic::Ordering;

/// A motion of the bench, by the view that starts it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    /// A wizard step's plan (the Wizard view).
    Step,
    /// The validation motions before and after calibration (the Validation view).
    Validation,
    /// The diagnosis's discriminating motions and its validation with the effects (the Diagnosis view).
    Diagnosis,
    /// A jog to the joint targets or home (the Robot view).
    Jog,
    /// The live dither (the Live and Align views).
    Live,
    /// A move of the lamella to a target (the Position view).
    Position,
}

impl AppState {
    /// The motion running, as far as the UI knows (`None` when the bench stands still).
    pub fn moving(&self) -> Option<Motion> {
        if self.wizard.running.is_some() {
            return Some(Motion::Step);
        }
        match self.busy.as_deref() {
            Some(BUSY_VALIDATING) => return Some(Motion::Validation),
            Some(BUSY_DIAGNOSING | BUSY_EFFECT_VALIDATION) => return Some(Motion::Diagnosis),
            Some(BUSY_JOGGING) => return Some(Motion::Jog),
            Some(BUSY_MOVING) => return Some(Motion::Position),
            _ => {}
        }
        self.worker.live.load(Ordering::Relaxed).then_some(Motion::Live)
    }

    /// Stop whatever moves (the global Stop); nothing happens while the bench stands still, so
    /// the flag is never left up for the next motion.
    pub fn stop_all(&mut self) {
        if self.moving().is_some() {
            self.worker.cancel.store(true, Ordering::Relaxed);
            self.worker.live.store(false, Ordering::Relaxed);
            self.status = "stopping…".into();
        }
    }

    /// Stop `motion` if it is the one running (Esc in the view that starts it).
    pub fn stop(&mut self, motion: Motion) {
        if self.moving() == Some(motion) {
            self.stop_all();
        }
    }

    /// Run wizard step `i`, or, when it holds traces of an earlier run, ask first (the wizard
    /// shows the question; [`AppState::answer_redo`] takes the answer).
    pub fn request_step(&mut self, i: usize) {
        if self.wizard.running.is_some() || self.busy.is_some() {
            return;
        }
        if self.wizard.steps.get(i).is_some_and(|s| !s.traces.is_empty()) {
            self.wizard.confirm_redo = Some(i);
        } else {
            self.run_step(i);
        }
    }

    /// The answer to "redo step N?" ([`RedoAnswer`]).
    pub fn answer_redo(&mut self, answer: RedoAnswer) {
        if let Some(i) = self.wizard.confirm_redo.take() {
            match answer {
                RedoAnswer::Resume => self.resume_step(i),
                RedoAnswer::Redo => self.run_step(i),
                RedoAnswer::Keep => {}
            }
        }
    }
}

/// The technician's answer to the question before a wizard step with traces runs again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RedoAnswer {
    /// Keep the whole traces of a stopped step and measure the rest.
    Resume,
    /// Discard the step's traces and run it from the start.
    Redo,
    /// Keep everything and run nothing.
    Keep,
}
