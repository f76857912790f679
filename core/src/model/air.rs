//! Refractive index of ambient air (Ciddor 1996, as implemented by the NIST Engineering Metrology Toolbox).
//! Owns the ambient-conditions record, its validation, and the saturation vapour pressure it needs.
//!
//! The cavity between the fiber and the lamella is in air: one fringe is λ/(2·n_air), so
//! leaving n_air out is a 268 ppm scale error at 1560 nm (80 nm over 300 µm).
//!
//! References:
//! - P. E. Ciddor, "Refractive index of air: new equations for the visible and near
//!   infrared", Applied Optics 35(9), 1566-1573 (1996).
//! - J. A. Stone and J. H. Zimmerman, "Index of Refraction of Air", NIST Engineering
//!   Metrology Toolbox, <https://emtoolbox.nist.gov/Wavelength/Documentation.asp>,
//!   Appendix A (saturation vapour pressure A-I, humidity A-II, Ciddor A-III). This module
//!   follows that appendix step by step, including its constants (R = 8.314472 J/(mol·K),
//!   IAPWS-IF97 vapour pressure over water, over ice below 0 °C) and its range of validity.

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Accepted temperature range, °C (NIST calculator's range of validity for Ciddor).
pub const TEMPERATURE_RANGE_C: (f64, f64) = (-40.0, 100.0);
/// Accepted pressure range, hPa (10 kPa to 140 kPa).
pub const PRESSURE_RANGE_HPA: (f64, f64) = (100.0, 1400.0);
/// Accepted relative humidity range, %.
pub const RELATIVE_HUMIDITY_RANGE_PERCENT: (f64, f64) = (0.0, 100.0);
/// Accepted CO2 mole fraction range, ppm (µmol/mol).
pub const CO2_RANGE_PPM: (f64, f64) = (0.0, 2000.0);
/// Accepted vacuum wavelength range, nm (Ciddor's dispersion formulas are fitted on 300-1700 nm).
pub const WAVELENGTH_RANGE_NM: (f64, f64) = (300.0, 1700.0);

/// Ambient conditions of the air in the cavity.
///
/// `Default` is the metrology reference: 20 °C, 1013.25 hPa, 50 % RH, 450 ppm CO2.
/// Missing fields take their default when deserialised (`#[serde(default)]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct AmbientConditions {
    /// Air temperature, °C.
    pub temperature_c: f64,
    /// Total air pressure, hPa.
    pub pressure_hpa: f64,
    /// Relative humidity over liquid water (over ice below 0 °C), %.
    pub relative_humidity_percent: f64,
    /// CO2 mole fraction, ppm (µmol/mol).
    pub co2_ppm: f64,
}

impl Default for AmbientConditions {
    fn default() -> Self {
        Self { temperature_c: 20.0, pressure_hpa: 1013.25, relative_humidity_percent: 50.0, co2_ppm: 450.0 }
    }
}

/// Why an air index could not be computed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum AirIndexError {
    /// An input is outside the range where the Ciddor equation is valid (or is not finite).
    #[error("{quantity} = {value} {unit} is outside the accepted range {min}..{max} {unit}")]
    OutOfRange {
        /// Which input (`temperature`, `pressure`, `relative humidity`, `CO2`, `wavelength`).
        quantity: &'static str,
        /// The value given.
        value: f64,
        /// Lowest accepted value.
        min: f64,
        /// Highest accepted value.
        max: f64,
        /// Unit of `value`, `min` and `max`.
        unit: &'static str,
    },
    /// The humidity asks for more water vapour than the total pressure allows
    /// (e.g. 100 % RH at 100 °C and 500 hPa).
    #[error(
        "water vapour partial pressure {vapour_pa:.0} Pa exceeds the total pressure \
         {pressure_pa:.0} Pa (lower the relative humidity or the temperature)"
    )]
    VapourExceedsPressure {
        /// Partial pressure of water vapour asked for, Pa.
        vapour_pa: f64,
        /// Total pressure, Pa.
        pressure_pa: f64,
    },
}

fn check_range(
    quantity: &'static str,
    value: f64,
    (min, max): (f64, f64),
    unit: &'static str,
) -> Result<(), AirIndexError> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(AirIndexError::OutOfRange { quantity, value, min, max, unit })
    }
}

impl AmbientConditions {
    /// Checks every field against the accepted ranges (NaN is rejected).
    pub fn validate(&self) -> Result<(), AirIndexError> {
        check_range("temperature", self.temperature_c, TEMPERATURE_RANGE_C, "°C")?;
        check_range("pressure", self.pressure_hpa, PRESSURE_RANGE_HPA, "hPa")?;
        check_range("relative humidity", self.relative_humidity_percent, RELATIVE_HUMIDITY_RANGE_PERCENT, "%")?;
        check_range("CO2", self.co2_ppm, CO2_RANGE_PPM, "ppm")
    }
}

/// Saturation vapour pressure of water, Pa (NIST toolbox Appendix A-I).
///
/// Over liquid water (IAPWS-IF97 formulation) for `temperature_c` ≥ 0 °C, over ice
/// (IAPWS 1995 sublimation formula) below. No range check: the caller validates.
pub fn saturation_vapour_pressure_pa(temperature_c: f64) -> f64 {
    let t_k = temperature_c + 273.15;
    if temperature_c >= 0.0 {
        const K: [f64; 10] = [
            1.167_052_145_28e3,
            -7.242_131_670_32e5,
            -1.707_384_694_01e1,
            1.202_082_470_25e4,
            -3.232_555_032_23e6,
            1.491_510_861_35e1,
            -4.823_265_736_16e3,
            4.051_134_054_21e5,
            -2.385_555_756_78e-1,
            6.501_753_484_48e2,
        ];
        let omega = t_k + K[8] / (t_k - K[9]);
        let a = omega * omega + K[0] * omega + K[1];
        let b = K[2] * omega * omega + K[3] * omega + K[4];
        let c = K[5] * omega * omega + K[6] * omega + K[7];
        let x = -b + (b * b - 4.0 * a * c).sqrt();
        1e6 * (2.0 * c / x).powi(4)
    } else {
        const A1: f64 = -13.928_169;
        const A2: f64 = 34.707_823_8;
        let theta = t_k / 273.16;
        let y = A1 * (1.0 - theta.powf(-1.5)) + A2 * (1.0 - theta.powf(-1.25));
        611.657 * y.exp()
    }
}

/// Phase refractive index of moist air at a vacuum wavelength (Ciddor 1996, NIST version).
///
/// `wavelength_nm` is the vacuum wavelength (300-1700 nm). Returns `n` (not `n - 1`).
/// At 1560 nm and the default conditions, n - 1 = 268.14 ppm; sensitivities there are
/// -0.944 ppm/K, +0.265 ppm/hPa and -0.0087 ppm per % RH.
///
/// Errors if an input is outside the accepted ranges (see the `*_RANGE_*` constants) or
/// if the humidity implies a vapour pressure above the total pressure.
pub fn air_index_ciddor(wavelength_nm: f64, ambient: &AmbientConditions) -> Result<f64, AirIndexError> {
    check_range("wavelength", wavelength_nm, WAVELENGTH_RANGE_NM, "nm")?;
    ambient.validate()?;

    let t = ambient.temperature_c;
    let t_k = t + 273.15;
    let p = ambient.pressure_hpa * 100.0; // Pa
    let xc = ambient.co2_ppm;

    // A-II: mole fraction of water vapour, with the enhancement factor f.
    let f = 1.00062 + 3.14e-8 * p + 5.6e-7 * t * t;
    let vapour_pa = ambient.relative_humidity_percent / 100.0 * saturation_vapour_pressure_pa(t);
    let xv = f * vapour_pa / p;
    if xv >= 1.0 {
        return Err(AirIndexError::VapourExceedsPressure { vapour_pa: f * vapour_pa, pressure_pa: p });
    }

    // A-III: Ciddor.
    const R: f64 = 8.314_472; // J/(mol·K)
    const MV: f64 = 0.018_015; // kg/mol, water
    const ZA: f64 = 0.999_592_211_5; // compressibility of dry air at 15 °C, 101325 Pa
    const RHO_VS: f64 = 0.009_859_38; // kg/m³, pure water vapour at 20 °C, 1333 Pa
    let wavelength_um = wavelength_nm * 1e-3;
    let s = 1.0 / (wavelength_um * wavelength_um); // µm⁻²

    // Refractivities of standard dry air (15 °C, 101325 Pa, 450 ppm CO2) and of standard
    // water vapour.
    let r_as = 1e-8 * (5_792_105.0 / (238.0185 - s) + 167_917.0 / (57.362 - s));
    let r_vs = 1.022e-8 * (295.235 + 2.6422 * s - 0.032_380 * s * s + 0.004_028 * s * s * s);
    // CO2 correction: molar mass and refractivity.
    let ma = 0.028_963_5 + 1.2011e-8 * (xc - 400.0);
    let r_axs = r_as * (1.0 + 5.34e-7 * (xc - 450.0));

    // Compressibility of the moist air (BIPM 1981/91).
    let pt = p / t_k;
    let zm = 1.0
        - pt * (1.581_23e-6 - 2.9331e-8 * t
            + 1.1043e-10 * t * t
            + (5.707e-6 - 2.051e-8 * t) * xv
            + (1.9898e-4 - 2.376e-6 * t) * xv * xv)
        + pt * pt * (1.83e-11 - 0.765e-8 * xv * xv);

    let rho_axs = 101_325.0 * ma / (ZA * R * 288.15);
    let rho_v = xv * p * MV / (zm * R * t_k);
    let rho_a = (1.0 - xv) * p * ma / (zm * R * t_k);

    Ok(1.0 + (rho_a / rho_axs) * r_axs + (rho_v / RHO_VS) * r_vs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ambient(t: f64, p_hpa: f64, rh: f64) -> AmbientConditions {
        AmbientConditions { temperature_c: t, pressure_hpa: p_hpa, relative_humidity_percent: rh, co2_ppm: 450.0 }
    }

    fn refractivity_ppm(wavelength_nm: f64, a: &AmbientConditions) -> f64 {
        (air_index_ciddor(wavelength_nm, a).unwrap() - 1.0) * 1e6
    }

    #[test]
    fn refractivity_at_1560_nm_default_conditions_is_268_1_ppm() {
        let n1 = refractivity_ppm(1560.0, &AmbientConditions::default());
        assert!((n1 - 268.1).abs() < 0.2, "n - 1 = {n1} ppm");
    }

    #[test]
    fn sensitivities_at_1560_nm_match_spec_within_10_percent() {
        let base = AmbientConditions::default();
        let d = |f: &dyn Fn(&mut AmbientConditions, f64), h: f64| {
            let mut up = base;
            let mut down = base;
            f(&mut up, h);
            f(&mut down, -h);
            (refractivity_ppm(1560.0, &up) - refractivity_ppm(1560.0, &down)) / (2.0 * h)
        };
        let per_kelvin = d(&|a, h| a.temperature_c += h, 0.5);
        let per_hpa = d(&|a, h| a.pressure_hpa += h, 1.0);
        let per_percent_rh = d(&|a, h| a.relative_humidity_percent += h, 5.0);
        for (got, want, what) in
            [(per_kelvin, -0.94, "ppm/K"), (per_hpa, 0.265, "ppm/hPa"), (per_percent_rh, -0.0087, "ppm/%RH")]
        {
            assert!(((got - want) / want).abs() < 0.10, "sensitivity {got} {what}, expected {want}");
        }
    }

    /// Sample calculations published by NIST (Stone & Zimmerman, Engineering Metrology
    /// Toolbox, table of Ciddor results; 450 ppm CO2): (°C, % RH, kPa, nm, n).
    /// They are given to 1e-9; we allow 2e-9 for rounding.
    #[test]
    fn matches_nist_sample_calculations() {
        const NIST: [(f64, f64, f64, f64, f64); 14] = [
            (20.0, 0.0, 101.325, 633.0, 1.000_271_800),
            (20.0, 0.0, 60.0, 633.0, 1.000_160_924),
            (20.0, 0.0, 120.0, 633.0, 1.000_321_916),
            (50.0, 0.0, 100.0, 633.0, 1.000_243_285),
            (5.0, 0.0, 100.0, 633.0, 1.000_282_756),
            (-40.0, 0.0, 100.0, 633.0, 1.000_337_580),
            (50.0, 100.0, 120.0, 633.0, 1.000_287_924),
            (40.0, 75.0, 120.0, 633.0, 1.000_299_418),
            (20.0, 100.0, 100.0, 633.0, 1.000_267_394),
            (40.0, 100.0, 110.0, 1700.0, 1.000_270_247),
            (20.0, 0.0, 101.325, 1700.0, 1.000_268_479),
            (40.0, 100.0, 110.0, 300.0, 1.000_289_000),
            (20.0, 0.0, 101.325, 300.0, 1.000_286_581),
            (-40.0, 0.0, 120.0, 300.0, 1.000_427_233),
        ];
        for (t, rh, p_kpa, wl, want) in NIST {
            let n = air_index_ciddor(wl, &ambient(t, p_kpa * 10.0, rh)).unwrap();
            assert!((n - want).abs() < 2e-9, "{t} °C, {rh} %, {p_kpa} kPa, {wl} nm: n = {n:.10}, NIST {want:.9}");
        }
    }

    /// The NIST value 1.000271800 at 633 nm is for DRY air; 50 % RH lowers it by ~0.43 ppm.
    #[test]
    fn humidity_lowers_the_633_nm_reference_value() {
        let dry = air_index_ciddor(633.0, &ambient(20.0, 1013.25, 0.0)).unwrap();
        let humid = air_index_ciddor(633.0, &ambient(20.0, 1013.25, 50.0)).unwrap();
        let drop_ppm = (dry - humid) * 1e6;
        assert!((0.3..0.6).contains(&drop_ppm), "drop {drop_ppm} ppm");
    }

    #[test]
    fn co2_raises_the_index() {
        let mut a = AmbientConditions::default();
        let n450 = air_index_ciddor(1560.0, &a).unwrap();
        a.co2_ppm = 1450.0;
        let n1450 = air_index_ciddor(1560.0, &a).unwrap();
        // Ciddor: refractivity scales by 1 + 5.34e-7·Δx_c, i.e. +0.14 ppm for +1000 ppm.
        let rise_ppm = (n1450 - n450) * 1e6;
        assert!((0.10..0.20).contains(&rise_ppm), "rise {rise_ppm} ppm");
    }

    #[test]
    fn saturation_vapour_pressure_known_points() {
        // Triple point (over ice and over water agree), 20 °C and boiling point.
        let ice = saturation_vapour_pressure_pa(-1e-9);
        let water = saturation_vapour_pressure_pa(0.0);
        assert!((ice - 611.2).abs() < 0.5, "ice {ice}");
        assert!((water - 611.2).abs() < 0.5, "water {water}");
        let p20 = saturation_vapour_pressure_pa(20.0);
        assert!((p20 - 2339.2).abs() < 1.0, "20 °C {p20}");
        let p100 = saturation_vapour_pressure_pa(100.0);
        assert!((p100 - 101_418.0).abs() < 50.0, "100 °C {p100}");
    }

    #[test]
    fn out_of_range_inputs_are_errors_naming_the_field() {
        let ok = AmbientConditions::default();
        let cases: [(AmbientConditions, f64, &str); 7] = [
            (AmbientConditions { temperature_c: 101.0, ..ok }, 1560.0, "temperature"),
            (AmbientConditions { pressure_hpa: 50.0, ..ok }, 1560.0, "pressure"),
            (AmbientConditions { relative_humidity_percent: -1.0, ..ok }, 1560.0, "relative humidity"),
            (AmbientConditions { co2_ppm: 2500.0, ..ok }, 1560.0, "CO2"),
            (ok, 1800.0, "wavelength"),
            (ok, f64::NAN, "wavelength"),
            (AmbientConditions { temperature_c: f64::NAN, ..ok }, 1560.0, "temperature"),
        ];
        for (a, wl, field) in cases {
            match air_index_ciddor(wl, &a) {
                Err(AirIndexError::OutOfRange { quantity, .. }) => assert_eq!(quantity, field),
                other => panic!("{field}: expected OutOfRange, got {other:?}"),
            }
        }
        let msg = air_index_ciddor(1560.0, &AmbientConditions { temperature_c: 101.0, ..ok }).unwrap_err().to_string();
        assert!(msg.contains("-40..100"), "{msg}");
    }

    #[test]
    fn range_limits_are_inclusive() {
        let a = ambient(-40.0, 100.0, 0.0);
        assert!(air_index_ciddor(300.0, &a).is_ok());
        let b = ambient(100.0, 1400.0, 0.0);
        assert!(air_index_ciddor(1700.0, &b).is_ok());
    }

    #[test]
    fn impossible_humidity_is_an_error() {
        let a = ambient(100.0, 500.0, 100.0);
        assert!(matches!(air_index_ciddor(1560.0, &a), Err(AirIndexError::VapourExceedsPressure { .. })));
    }

    #[test]
    fn serde_fills_missing_fields_with_defaults() {
        let a: AmbientConditions = serde_json::from_str(r#"{"temperature_c": 22.5}"#).unwrap();
        assert_eq!(a.temperature_c, 22.5);
        assert_eq!(a.pressure_hpa, AmbientConditions::default().pressure_hpa);
        assert_eq!(a.co2_ppm, 450.0);
        let back: AmbientConditions = serde_json::from_str(&serde_json::to_string(&a).unwrap()).unwrap();
        assert_eq!(back, a);
    }
}
