//! The photorobot application: a thin command-line interface and the eframe workbench over `photorobot_core`.
//! Owns argument parsing, printing and the GUI; every command's work is a core function.

pub mod bench_guard;
pub mod cli;
pub mod decimate;
pub mod dialogs;
pub mod gui;
pub mod hardware_bench;
pub mod log;
pub mod messages;
pub mod motion;
pub mod plan_design;
pub mod positioning;
pub mod session_io;
pub mod settings;
pub mod state;
pub mod step_recording;
pub mod sweep_forecast;
pub mod views;
pub mod worker;
