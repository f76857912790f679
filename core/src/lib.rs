//! photorobot core: the science of photo-robotic calibration, without any GUI.
//! Data flows one way: plan -> bench -> trace -> measurements -> estimates -> validation, diagnosis, reports.

pub mod bench;
pub mod calibration;
pub mod diagnose;
pub mod files;
pub mod hardware;
pub mod identify;
pub mod measure;
pub mod model;
pub mod plan;
pub mod position;
pub mod report;
pub mod session;
pub mod solver;
pub mod trace;
pub mod validate;
