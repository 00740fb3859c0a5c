//! Where a field value falls on the colour map: t = (v − min) / (max − min) over the shown
//! range, which the shade pass forms for every neighbour value it averages. In plain f32 a
//! range such as ±3e38 overflows (its span, and the weighted sum of values near it) into
//! inf and NaN, and the hit is drawn in the missing colour or not at all. So the range is
//! first brought within [−1, 1] by a power of two, which changes no digit of any value, and
//! values more than [`FIELD_T_LIMIT`] spans outside it are clamped there first, so that no
//! step of the shader's sum can overflow. `shade.wgsl`'s `field_t` computes [`FieldMap::t`].

/// How many spans beyond the shown range a value may lie before it counts as lying there
/// (2^20): far past where the colour map saturates, and small enough that 128 weighted
/// values sum within f32.
pub const FIELD_T_LIMIT: f64 = 1_048_576.0;

/// The uniforms of the shade pass's map from a field value to t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldMap {
    /// Values are clamped to [low, high]: [`FIELD_T_LIMIT`] spans either side of the range.
    pub clamp: (f32, f32),
    /// The power of two that brings the range within [−1, 1].
    pub exponent: i32,
    /// The range's minimum scaled by 2^exponent.
    pub low: f32,
    /// 1 / (the range's span scaled by 2^exponent); 0 for an empty range, which maps every
    /// value to 0.5.
    pub inverse_span: f32,
}

impl FieldMap {
    /// The map of the range (`min`, `max`): finite, `min` ≤ `max`, or empty.
    pub fn new(min: f32, max: f32) -> FieldMap {
        let (lo, hi) = (f64::from(min), f64::from(max));
        // f64 holds every f32 span and its inverse exactly enough.
        let span = hi - lo;
        if !(span > 0.0 && span.is_finite()) {
            return FieldMap {
                clamp: (0.0, 0.0),
                exponent: 0,
                low: 0.0,
                inverse_span: 0.0,
            };
        }
        let largest = lo.abs().max(hi.abs());
        // 2^exponent · largest lies in [0.5, 1].
        let exponent = -(largest.log2().floor() as i32 + 1);
        let scaled = |v: f64| v * 2f64.powi(exponent);
        let limit = |v: f64| v.clamp(f64::from(f32::MIN), f64::from(f32::MAX)) as f32;
        FieldMap {
            clamp: (
                limit(lo - FIELD_T_LIMIT * span),
                limit(hi + FIELD_T_LIMIT * span),
            ),
            exponent,
            low: scaled(lo) as f32,
            inverse_span: (1.0 / scaled(span)) as f32,
        }
    }

    /// Where `v` (finite) falls on the map, as the shade pass computes it in f32; 0.5 for
    /// an empty range.
    pub fn t(&self, v: f32) -> f32 {
        if self.inverse_span == 0.0 {
            return 0.5;
        }
        let c = v.clamp(self.clamp.0, self.clamp.1);
        (ldexp(c, self.exponent) - self.low) * self.inverse_span
    }
}

/// c · 2^e in f32, as WGSL's `ldexp`: scaled in f64, where no f32 value and exponent of a
/// [`FieldMap`] overflows, and rounded once.
fn ldexp(c: f32, e: i32) -> f32 {
    (f64::from(c) * 2f64.powi(e)) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The map's t against (v − min) / (max − min) in f64, within f32 rounding of each step.
    #[test]
    fn the_map_places_values_as_the_plain_formula_does() {
        let ranges = [
            (0.0f32, 1.0f32),
            (-3e38, 3e38),
            (101_315.0, 101_335.0),
            (-1e-30, 2e-30),
            (1.0, 1.0 + f32::EPSILON),
            (f32::MIN, f32::MAX),
        ];
        for (lo, hi) in ranges {
            let map = FieldMap::new(lo, hi);
            let span = f64::from(hi) - f64::from(lo);
            for k in 0..=20 {
                let v = (f64::from(lo) + span * (f64::from(k) / 20.0)) as f32;
                let want = (f64::from(v) - f64::from(lo)) / span;
                let got = f64::from(map.t(v));
                assert!(
                    (got - want).abs() <= 4e-7 * want.abs().max(1.0),
                    "range ({lo:e}, {hi:e}), v {v:e}: t {got} where {want} is exact"
                );
            }
            // Beyond the range, clamped far out, never infinite.
            for v in [f32::MAX, f32::MIN, 0.0] {
                let t = map.t(v);
                assert!(t.is_finite(), "range ({lo:e}, {hi:e}): t({v:e}) = {t}");
                assert!(f64::from(t).abs() <= FIELD_T_LIMIT + 2.0);
            }
        }
        assert_eq!(FieldMap::new(2.0, 2.0).t(5.0), 0.5);
        assert_eq!(FieldMap::new(0.0, 0.0).t(-1.0), 0.5);
    }
}
