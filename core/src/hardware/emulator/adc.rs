//! An analog input as a controller's ADC delivers it: input noise, a finite range and resolution.
//! Owns the quantisation and the noise, drawn from a hash of the sample's key so that a recorded
//! sample reads the same every time it is read (a recorder stores its samples).

/// A bipolar ADC: ±`range_v`, `bits` of resolution, Gaussian input noise of `noise_lsb` LSB rms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Adc {
    /// Full scale (V): readings are clamped to ±this.
    pub range_v: f64,
    /// Resolution (bits over the whole ±range).
    pub bits: u32,
    /// Input noise (LSB rms).
    pub noise_lsb: f64,
    /// Seed of the noise.
    pub seed: u64,
}

impl Adc {
    /// The converter the emulated E-712 analog inputs are given: ±10 V, 16 bits, 0.5 LSB rms of
    /// noise (an assumption: the E-712's analog-input resolution is to be checked on the device).
    pub fn e712(seed: u64) -> Self {
        Adc { range_v: 10.0, bits: 16, noise_lsb: 0.5, seed }
    }

    /// One step of the converter (V).
    pub fn lsb_v(&self) -> f64 {
        2.0 * self.range_v / (1u64 << self.bits.min(62)) as f64
    }

    /// The reading of `volts` for the sample identified by `key`: noise added, clamped, quantised.
    pub fn read(&self, volts: f64, key: u64) -> f64 {
        let lsb = self.lsb_v();
        let noisy = volts + self.noise_lsb * lsb * gaussian(self.seed ^ key.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        (noisy.clamp(-self.range_v, self.range_v - lsb) / lsb).round() * lsb
    }
}

/// splitmix64: a well-mixed 64-bit hash.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A standard normal deviate from `key` (Box-Muller on two hashed uniforms).
fn gaussian(key: u64) -> f64 {
    let u = |k: u64| ((mix(k) >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let (u1, u2) = (u(key), u(key ^ 0xD1B5_4A32_D192_ED03));
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The readings' rms error against the truth is the quantisation and the noise together
    /// (LSB·√(1/12 + 0.25)); a sample reads the same twice; the range clamps.
    #[test]
    fn readings_are_quantised_noisy_and_repeatable() {
        let adc = Adc::e712(1);
        let lsb = adc.lsb_v();
        assert!((lsb - 20.0 / 65536.0).abs() < 1e-15);
        let n = 20_000;
        let ss: f64 = (0..n)
            .map(|k| {
                let v = 1.234_567 + k as f64 * 1.7e-6;
                let r = adc.read(v, k);
                assert!(((r / lsb) - (r / lsb).round()).abs() < 1e-9, "on the grid");
                (r - v).powi(2)
            })
            .sum();
        let rms = (ss / n as f64).sqrt() / lsb;
        let expected = (1.0 / 12.0f64 + 0.25).sqrt();
        assert!((rms / expected - 1.0).abs() < 0.05, "{rms} LSB vs {expected}");
        assert_eq!(adc.read(0.5, 7), adc.read(0.5, 7));
        assert!(adc.read(50.0, 1) < 10.0 && adc.read(-50.0, 1) >= -10.0);
    }
}
