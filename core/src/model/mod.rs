//! The forward model of the bench: robot description and kinematics, extrinsics, frame tree, optics.
//! Everything that simulates or fits uses this one model.

pub mod air;
pub mod effects;
pub mod extrinsics;
pub mod frames;
pub mod kinematics;
pub mod optics;
pub mod phase;
pub mod robot;
