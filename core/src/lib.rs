//! photorobot core: the science of photo-robotic calibration, without any GUI.
//! Data flows one way: plan -> bench -> trace -> measurements -> estimates -> validation, diagnosis, reports.

pub mod alignment;
pub mod bench;
pub mod diagnose;
pub mod files;
pub mod fringes;
pub mod hardware;
pub mod identify;
pub mod import;
pub mod live_count;
pub mod measure;
pub mod model;
pub mod plan;
pub mod report;
pub mod session;
pub mod solver;
pub mod sweep;
pub mod trace;
pub mod validate;
