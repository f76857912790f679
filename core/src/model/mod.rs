//! The forward model of the bench: robot kinematics, extrinsics, optics.
//! Everything that simulates or fits uses this one model.

pub mod air;
pub mod optics;
