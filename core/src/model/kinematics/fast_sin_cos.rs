//! sin x and cos x together without a library call, to about an ulp: Cody-Waite reduction by
//! π/2 and the fdlibm kernels, used by the DGM and the fringe phases.

// fdlibm's constants (e_rem_pio2.c, k_sin.c, k_cos.c), by their bits.
/// π/2 in three parts: the first 33 bits, the next 33 bits, the rest.
const PIO2_1: f64 = f64::from_bits(0x3FF9_21FB_5440_0000);
const PIO2_2: f64 = f64::from_bits(0x3DD0_B461_1A60_0000);
const PIO2_2T: f64 = f64::from_bits(0x3BA3_198A_2E03_7073);
/// sin r = r + r³·(S1 + r²·(S2 + …)) on [-π/4, π/4].
const SIN_POLY: [f64; 6] = [
    f64::from_bits(0xBFC5_5555_5555_5549),
    f64::from_bits(0x3F81_1111_1110_F8A6),
    f64::from_bits(0xBF2A_01A0_19C1_61D5),
    f64::from_bits(0x3EC7_1DE3_57B1_FE7D),
    f64::from_bits(0xBE5A_E5E6_8A2B_9CEB),
    f64::from_bits(0x3DE5_D93A_5ACF_D57C),
];
/// cos r = 1 - r²/2 + r⁴·(C1 + r²·(C2 + …)) on [-π/4, π/4].
const COS_POLY: [f64; 6] = [
    f64::from_bits(0x3FA5_5555_5555_554C),
    f64::from_bits(0xBF56_C16C_16C1_5177),
    f64::from_bits(0x3EFA_01A0_19CB_1590),
    f64::from_bits(0xBE92_7E4F_809C_52AD),
    f64::from_bits(0x3E21_EE9E_BDB4_B1C4),
    f64::from_bits(0xBDA8_FAE9_BE88_38D4),
];
/// Arguments beyond this go to the standard library: n·PIO2_1 and n·PIO2_2 stay exact.
const SIN_COS_LIMIT: f64 = 8.0e5;
/// Adding 1.5·2^52 rounds a number below 2^51 to an integer (and leaves it in the low bits).
const ROUNDING_SHIFT: f64 = 6_755_399_441_055_744.0;

/// The argument reduced to [-π/4, π/4] and the multiple of π/2 taken off, as the shifted float
/// whose low bits hold it: x = n·π/2 + r.
#[inline(always)]
fn reduce(x: f64) -> (f64, f64) {
    let shifted = x * std::f64::consts::FRAC_2_PI + ROUNDING_SHIFT;
    let n = shifted - ROUNDING_SHIFT;
    (((x - n * PIO2_1) - n * PIO2_2) - n * PIO2_2T, shifted)
}

/// fdlibm's __kernel_sin and __kernel_cos (no tail) on [-π/4, π/4].
#[inline(always)]
fn sin_cos_kernel(r: f64) -> (f64, f64) {
    let (s, c) = (&SIN_POLY, &COS_POLY);
    let z = r * r;
    let sin_tail = s[1] + z * (s[2] + z * (s[3] + z * (s[4] + z * s[5])));
    let sin = r + z * r * (s[0] + z * sin_tail);
    let cos_tail = z * (c[0] + z * (c[1] + z * (c[2] + z * (c[3] + z * (c[4] + z * c[5])))));
    let hz = 0.5 * z;
    let w = 1.0 - hz;
    (sin, w + (((1.0 - w) - hz) + z * cos_tail))
}

/// (sin x, cos x) from the kernel's values at r and the quadrant n mod 4 in the low bits of
/// `shifted`: odd quadrants swap sin and cos, quadrants 2, 3 negate sin and 1, 2 cos; chosen
/// with bit masks, without branches (fringe phases make the quadrant unpredictable).
#[inline(always)]
fn place_in_quadrant(sin_r: f64, cos_r: f64, shifted: f64) -> (f64, f64) {
    let bits = shifted.to_bits();
    let swap = (bits & 1).wrapping_neg(); // all ones in odd quadrants
    let pick = |a: f64, b: f64| (a.to_bits() & !swap) | (b.to_bits() & swap);
    let sin_sign = (bits >> 1) << 63;
    let cos_sign = ((bits >> 1) ^ bits) << 63;
    (f64::from_bits(pick(sin_r, cos_r) ^ sin_sign), f64::from_bits(pick(cos_r, sin_r) ^ cos_sign))
}

/// sin x and cos x together, to about 1 ulp, without a library call: the argument is reduced
/// by multiples of π/2 (Cody-Waite, π/2 in three parts, exact for |x| < 8e5, which covers
/// joint angles and fringe phases of gaps up to 100 mm) and the fdlibm kernels evaluate
/// sin and cos on [-π/4, π/4]; larger or non-finite arguments go to the standard library.
#[inline]
pub fn sin_cos(x: f64) -> (f64, f64) {
    if x.is_nan() || x.abs() > SIN_COS_LIMIT {
        return x.sin_cos();
    }
    let (r, shifted) = reduce(x);
    let (s, c) = sin_cos_kernel(r);
    place_in_quadrant(s, c, shifted)
}

/// [`sin_cos`] of two arguments at once: lane by lane the same operations and results,
/// written so that the compiler can evaluate both lanes with vector instructions.
#[inline(always)]
pub(crate) fn sin_cos_2(x: [f64; 2]) -> ([f64; 2], [f64; 2]) {
    if x.iter().any(|v| v.is_nan() || v.abs() > SIN_COS_LIMIT) {
        let (a, b) = (sin_cos(x[0]), sin_cos(x[1]));
        return ([a.0, b.0], [a.1, b.1]);
    }
    let ((r0, shifted0), (r1, shifted1)) = (reduce(x[0]), reduce(x[1]));
    let ((s0, c0), (s1, c1)) = (sin_cos_kernel(r0), sin_cos_kernel(r1));
    let ((s0, c0), (s1, c1)) = (place_in_quadrant(s0, c0, shifted0), place_in_quadrant(s1, c1, shifted1));
    ([s0, s1], [c0, c1])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sin_cos_agrees_with_the_standard_library_to_an_ulp() {
        let check = |x: f64| {
            let ((s, c), (s0, c0)) = (sin_cos(x), x.sin_cos());
            // An ulp of a value in [0.5, 1] is 1.1e-16; near zero, sin is relative.
            assert!((c - c0).abs() <= 2.3e-16, "cos {x}: {c} vs {c0}");
            assert!((s - s0).abs() <= 2.3e-16 * s0.abs().max(x.abs().min(1.0)), "sin {x}: {s} vs {s0}");
        };
        let mut x: f64 = 0.0;
        for i in 0..200_000 {
            // A low-discrepancy walk over 0..2e4 rad (fringe phases), scaled to joint angles and below.
            x = (x + 0.618_033_988_749_894_9 * 7.3).rem_euclid(2.0e4);
            for v in [x, -x, x * 1e-3, x * 1e-9] {
                check(v);
            }
            check(f64::from(i % 64) * std::f64::consts::FRAC_PI_4);
        }
        for x in [0.0, -0.0, 7.9e5, -7.9e5, 8.1e5, 1e10, f64::MIN_POSITIVE] {
            check(x);
        }
        // The two-lane version gives the same bits.
        let mut x: f64 = 0.1;
        for _ in 0..100_000 {
            x = (x + 0.618_033_988_749_894_9 * 7.3).rem_euclid(2.0e4);
            for pair in [[x, -x * 1e-3], [-x, x * 1e-9], [x, 9e5], [0.0, -0.0]] {
                let (s, c) = sin_cos_2(pair);
                for i in 0..2 {
                    let (s1, c1) = sin_cos(pair[i]);
                    assert_eq!((s[i].to_bits(), c[i].to_bits()), (s1.to_bits(), c1.to_bits()), "{}", pair[i]);
                }
            }
        }
        assert!(sin_cos(f64::NAN).0.is_nan() && sin_cos(f64::INFINITY).1.is_nan());
    }
}
