//! Stored precision: f32 values rounded to fewer mantissa bits before they are stored, so that
//! their low bits, which the MLS fit cannot resolve anyway, become zeros the compressor
//! removes. What the bake rounds, and what it costs in accuracy, is in `docs/cache-format.md`
//! ("Stored precision").

/// Mantissa bits of an f32: keeping all of them stores values exactly.
pub const F32_MANTISSA_BITS: u32 = 23;

/// `x` rounded to the nearest f32 with only the top `bits` mantissa bits (ties away from
/// zero in magnitude). Rounding up may carry into the exponent, which is the correct result;
/// a value that would round to infinity, and NaN or infinity, are returned unchanged.
pub fn round_mantissa(x: f32, bits: u32) -> f32 {
    if bits >= F32_MANTISSA_BITS || !x.is_finite() {
        return x;
    }
    let drop = F32_MANTISSA_BITS - bits;
    let half = 1u32 << (drop - 1);
    let sign = x.to_bits() & (1 << 31);
    // A finite magnitude is below 0x7f80_0000, so adding half a unit cannot overflow.
    let magnitude = ((x.to_bits() & !(1 << 31)) + half) >> drop << drop;
    let rounded = f32::from_bits(sign | magnitude);
    if rounded.is_finite() { rounded } else { x }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_keeps_the_top_bits_to_nearest() {
        // 1 + 2^-23 (the last bit) rounds to 1 with 10 bits; 1 + 2^-11 is the halfway point
        // between 1 and 1 + 2^-10 and rounds up.
        assert_eq!(round_mantissa(1.0 + f32::EPSILON, 10), 1.0);
        assert_eq!(
            round_mantissa(1.0 + 2f32.powi(-11), 10),
            1.0 + 2f32.powi(-10)
        );
        assert_eq!(
            round_mantissa(-(1.0 + 2f32.powi(-11)), 10),
            -(1.0 + 2f32.powi(-10))
        );
        // A carry into the exponent: just below 2 rounds to 2.
        assert_eq!(round_mantissa(2.0f32.next_down(), 10), 2.0);
        assert_eq!(round_mantissa(0.0, 10), 0.0);
        assert_eq!(round_mantissa(f32::MAX, 10), f32::MAX);
        assert!(round_mantissa(f32::NAN, 10).is_nan());
        assert_eq!(round_mantissa(0.1, 23), 0.1);
        // The relative error is at most half a unit of the last kept bit.
        let mut x = 1e-3f32;
        while x < 1e3 {
            for bits in [8, 12, 14, 16] {
                let r = round_mantissa(x, bits);
                assert!(
                    ((r - x) / x).abs() <= 2f32.powi(-(bits as i32) - 1),
                    "{x} {bits}"
                );
                assert_eq!(r.to_bits() & ((1 << (23 - bits)) - 1), 0);
            }
            x *= 1.37;
        }
    }
}
