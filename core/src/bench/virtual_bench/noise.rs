//! The noise of the virtual bench: standard normal deviates of a 128-layer ziggurat on
//! xoshiro256++ seeded (through SplitMix64) by the preset's seed or the run's, so a run is
//! reproducible from its seed on any platform.
//!
//! The generator is written out here rather than taken from `rand_xoshiro`: the simulated data
//! must stay bit-identical for a seed, independently of any crate's version.

/// xoshiro256++ (Blackman and Vigna, 2019), its state filled by SplitMix64 from a 64-bit seed:
/// fast, statistically sound for simulation, and fixed here so a seed gives the same noise on
/// every platform and with every version of `rand`.
#[derive(Debug, Clone)]
struct Xoshiro256PlusPlus {
    s: [u64; 4],
}

impl Xoshiro256PlusPlus {
    fn seed_from_u64(mut x: u64) -> Self {
        let mut split_mix = || {
            x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = x;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        };
        Self { s: [split_mix(), split_mix(), split_mix(), split_mix()] }
    }

    #[inline(always)]
    fn next_u64(&mut self) -> u64 {
        let s = &mut self.s;
        let result = s[0].wrapping_add(s[3]).rotate_left(23).wrapping_add(s[0]);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        result
    }

    /// Uniform in (0, 1]: 53 random bits.
    #[inline]
    fn uniform_open0(&mut self) -> f64 {
        ((self.next_u64() >> 11) + 1) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

/// Standard normal deviates by the ziggurat method (Marsaglia and Tsang, J. Stat. Softw. 5(8),
/// 2000) with 128 layers, on xoshiro256++. Each deviate takes 32 random bits, two per 64-bit
/// draw: 7 bits choose the layer and the other 25, independent of them (Doornik 2005), give a
/// signed value; 98.8 % of the deviates are accepted on that alone (a compare and a
/// product), the rest go through the exact wedge and tail tests with fresh uniforms. A
/// deviate is a multiple of 2^-24 of its layer's width (at most 3.7·2^-24 ≈ 2e-7): finer than
/// anything the simulated noise is compared with.
#[derive(Debug, Clone)]
pub(super) struct Gaussian {
    rng: Xoshiro256PlusPlus,
    /// Unused 32-bit half of the last draw, if any.
    spare: Option<u32>,
}

/// The ziggurat's tables, per layer i (1 the top, 127 the lowest rectangle, 0 the base strip
/// with the tail): the accept bound k_i = 2^24·x_(i-1)/x_i, the width w_i = x_i/2^24 (for the
/// base, its equivalent width V/f(R)) and f_i = exp(-x_i²/2), x_i the layer's right edge.
pub(super) struct ZigguratTables {
    k: [u32; 128],
    w: [f64; 128],
    f: [f64; 128],
}

/// Right edge of the bottom layer (128 layers, Marsaglia and Tsang).
const ZIGGURAT_R: f64 = 3.442_619_855_899;
/// Area of every layer.
const ZIGGURAT_V: f64 = 9.912_563_035_262_17e-3;
const ZIGGURAT_SCALE: f64 = (1u64 << 24) as f64;

pub(super) fn ziggurat_tables() -> &'static ZigguratTables {
    static TABLES: std::sync::OnceLock<ZigguratTables> = std::sync::OnceLock::new();
    TABLES.get_or_init(|| {
        // Marsaglia and Tsang's zigset, with 2^24 in place of 2^31.
        let (mut k, mut w, mut f) = ([0u32; 128], [0.0; 128], [0.0; 128]);
        let mut dn = ZIGGURAT_R;
        let mut tn = dn;
        let q = ZIGGURAT_V / (-0.5 * dn * dn).exp();
        k[0] = (dn / q * ZIGGURAT_SCALE) as u32;
        k[1] = 0;
        w[0] = q / ZIGGURAT_SCALE;
        w[127] = dn / ZIGGURAT_SCALE;
        f[0] = 1.0;
        f[127] = (-0.5 * dn * dn).exp();
        for i in (1..=126).rev() {
            dn = (-2.0 * (ZIGGURAT_V / dn + (-0.5 * dn * dn).exp()).ln()).sqrt();
            k[i + 1] = (dn / tn * ZIGGURAT_SCALE) as u32;
            tn = dn;
            f[i] = (-0.5 * dn * dn).exp();
            w[i] = dn / ZIGGURAT_SCALE;
        }
        ZigguratTables { k, w, f }
    })
}

impl Gaussian {
    pub(super) fn seed_from_u64(seed: u64) -> Self {
        ziggurat_tables();
        Self { rng: Xoshiro256PlusPlus::seed_from_u64(seed), spare: None }
    }

    #[inline(always)]
    fn bits32(&mut self) -> u32 {
        match self.spare.take() {
            Some(b) => b,
            None => {
                let b = self.rng.next_u64();
                self.spare = Some((b >> 32) as u32);
                b as u32
            }
        }
    }

    /// Fills `out` with standard normal deviates: the same sequence as calling
    /// [`Gaussian::sample`] for each, with the 64-bit draws split in place.
    pub(super) fn fill(&mut self, tables: &ZigguratTables, out: &mut [f64]) {
        let mut rest = out;
        if !rest.is_empty() && self.spare.is_some() {
            rest[0] = self.sample(tables);
            rest = &mut rest[1..];
        }
        let mut pairs = rest.chunks_exact_mut(2);
        for pair in &mut pairs {
            let b = self.rng.next_u64();
            pair[0] = self.deviate(tables, b as u32);
            pair[1] = self.deviate(tables, (b >> 32) as u32);
        }
        for x in pairs.into_remainder() {
            *x = self.sample(tables);
        }
    }

    /// The deviate of 32 random bits (fresh draws only if they fall outside the fast region).
    #[inline(always)]
    fn deviate(&mut self, tables: &ZigguratTables, bits: u32) -> f64 {
        let i = (bits & 127) as usize;
        let h = (bits as i32) >> 7; // signed, 25 bits, independent of i
        if h.unsigned_abs() < tables.k[i] {
            return f64::from(h) * tables.w[i];
        }
        self.sample_slow(tables, i, h)
    }

    /// One standard normal deviate.
    #[inline(always)]
    pub(super) fn sample(&mut self, tables: &ZigguratTables) -> f64 {
        let bits = self.bits32();
        self.deviate(tables, bits)
    }

    #[cold]
    fn sample_slow(&mut self, tables: &ZigguratTables, mut i: usize, mut h: i32) -> f64 {
        loop {
            let x = f64::from(h) * tables.w[i];
            if i == 0 {
                // The tail beyond R (Marsaglia's method).
                loop {
                    let x = -self.rng.uniform_open0().ln() / ZIGGURAT_R;
                    let y = -self.rng.uniform_open0().ln();
                    if y + y >= x * x {
                        return if h > 0 { ZIGGURAT_R + x } else { -ZIGGURAT_R - x };
                    }
                }
            }
            let u = 1.0 - self.rng.uniform_open0(); // [0, 1)
            if tables.f[i] + u * (tables.f[i - 1] - tables.f[i]) < (-0.5 * x * x).exp() {
                return x;
            }
            // A fresh draw (its other half unused), so that the sequence does not depend on
            // how deviates are grouped (`fill`).
            let bits = self.rng.next_u64() as u32;
            i = (bits & 127) as usize;
            h = (bits as i32) >> 7;
            if h.unsigned_abs() < tables.k[i] {
                return f64::from(h) * tables.w[i];
            }
        }
    }
}
