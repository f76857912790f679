//! Tests of the Fabry-Perot signal model, by concept; the shared bench and helpers live here.

use super::*;
use nalgebra::Complex;
use std::f64::consts::PI;

mod cleave_and_back_face;
mod fringe_expansion;
mod gaussian_coupling;
mod multi_beam;
mod validity;

const WL: f64 = 1560.0;
const N_AIR: f64 = 1.000_268;

fn bench(params: &OpticalParams) -> FabryPerot {
    FabryPerot::new(params, WL, N_AIR).unwrap()
}

fn glass() -> OpticalParams {
    OpticalParams { lamella_reflectance: 0.04, ..OpticalParams::default() }
}

/// Wraps an angle to (-π, π].
fn wrap(a: f64) -> f64 {
    let w = a.rem_euclid(2.0 * PI);
    if w > PI {
        w - 2.0 * PI
    } else {
        w
    }
}
