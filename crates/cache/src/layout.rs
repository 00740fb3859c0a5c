//! Element types of the GPU sections: `#[repr(C)]` Pod structs laid out exactly as the WGSL
//! storage-buffer structs of the same names (vec3 + scalar packs into 16 bytes there).

use bytemuck::{Pod, Zeroable};

/// A field value the GPU's field buffer holds for a point whose value is missing: one that is
/// not finite (NaN or infinite) in the cache, or this value itself. WGSL may assume that no
/// value is NaN or infinite, so the shade pass tests for this finite one instead: it leaves
/// such values out of its weighted mean, and draws a hit with none in `MISSING_FIELD_COLOUR`
/// (`slosh_render`). The host's readings leave them out alike.
pub const FIELD_MISSING: f32 = f32::MAX;

/// Whether a field value is missing ([`FIELD_MISSING`]).
pub fn field_missing(v: f32) -> bool {
    !v.is_finite() || v >= FIELD_MISSING
}

/// `struct Point { position: vec3<f32>, radii: u32 }` (format 7): a point, and its radius of
/// trust (low half) and its neighbour list's reach (high half) as half floats, each the
/// smallest normal half float at or above the value the bake computed. Both are bounds (a
/// ball's extent, a distance filter), so rounding them up keeps what they bound; the bake
/// builds the BVH over the stored radii.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuPoint {
    pub position: [f32; 3],
    pub radii: u32,
}

impl GpuPoint {
    /// A point from its position, radius of trust and reach (local units); `None` where a
    /// radius is not finite, negative, or beyond a half float's range.
    pub fn new(position: [f32; 3], radius: f64, reach: f64) -> Option<GpuPoint> {
        let word = u32::from(half_at_or_above(radius)?.to_bits())
            | (u32::from(half_at_or_above(reach)?.to_bits()) << 16);
        Some(GpuPoint {
            position,
            radii: word,
        })
    }

    /// The radius of trust, as stored.
    pub fn radius(&self) -> f32 {
        unhalves(self.radii)[0]
    }

    /// How far the point's neighbour list reaches, as stored.
    pub fn reach(&self) -> f32 {
        unhalves(self.radii)[1]
    }
}

/// The smallest normal half float at or above `x` (≥ 0), as f32: the radius of trust a point
/// stores for `x` (`GpuPoint::new`); `None` where there is none.
pub fn stored_radius(x: f64) -> Option<f32> {
    half_at_or_above(x).map(half::f16::to_f32)
}

/// The smallest normal half float ≥ `x`, for `x` in `[0, 65504]`; `None` otherwise.
fn half_at_or_above(x: f64) -> Option<half::f16> {
    if !(x >= 0.0 && x <= f64::from(half::f16::MAX.to_f32())) {
        return None;
    }
    if x <= f64::from(half::f16::MIN_POSITIVE.to_f32()) {
        return Some(half::f16::MIN_POSITIVE);
    }
    // `x` has a normal half's exponent: the half's bits are that exponent rebiased and the
    // top 10 bits of the fraction, one up where a bit below them is set (a carry into the
    // exponent is the next half up). Integer work, where rounding to nearest and stepping up
    // took 7 times as long.
    let bits = x.to_bits();
    // At least 1: `x` is above the smallest normal half, 2^-14.
    let exponent = (bits >> 52) + 15 - 1023;
    let fraction = bits & ((1 << 52) - 1);
    let below = u64::from(fraction & ((1 << 42) - 1) != 0);
    let half_bits = (exponent << 10 | fraction >> 42) + below;
    Some(half::f16::from_bits(half_bits as u16))
}

/// `struct Ball { normal: u32, coeffs: array<u32, 3> }` (16 bytes, format 9): the initial
/// support normal (octahedral, [`crate::octahedral`]) and the initial polynomial's first six
/// coefficients in coordinates scaled by 1/h as IEEE half floats two to a word (coefficient
/// 2k in the low half of word k). A ball that is no candidate (unfitted, or a droplet
/// member) has no normal ([`crate::octahedral::NO_NORMAL`]) and every candidate has one, so
/// the trace walk tells them apart by the ball alone; a droplet member's first coefficient
/// word holds its sphere's index (it has no polynomial to draw). What the ball is and the degree
/// fitted are four bits of the `ball_states` section ([`crate::BallBits`]), h the header's (or the
/// `ball_h` section's, where h is per point), and a cubic's other four coefficients are in
/// the `ball_cubic` section ([`CubicWords`]); [`crate::StoredBall`] gathers them.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuBall {
    pub normal: u32,
    pub coeffs: [u32; 3],
}

/// A cubic's coefficients 6–9 as half floats, two to a word (coefficient 6 + 2k in the low
/// half of word k): two words per point of the `ball_cubic` section, zero where the ball is
/// not cubic.
pub type CubicWords = [u32; 2];

/// `struct Sphere { centre: vec3<f32>, radius: f32 }`: a droplet.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuSphere {
    pub centre: [f32; 3],
    pub radius: f32,
}

/// What a ball is, in the low two bits of its [`crate::BallBits`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BallState {
    /// Fitted at the requested degree.
    Full = 0,
    /// Fitted at a lower degree ([`crate::BallBits::degree`]).
    Degraded = 1,
    /// No support plane or fit: never a candidate.
    Unfitted = 2,
    /// Member of a droplet drawn as a sphere.
    Droplet = 3,
}

/// Coefficients a ball holds itself: a polynomial of degree ≤ 2.
pub(crate) const BALL_COEFFS: usize = 6;

/// The smallest normal half float, 2^-14: no stored coefficient lies closer to zero, but zero.
pub const MIN_NORMAL_HALF: f32 = 1.0 / 16384.0;

/// Two coefficients as half floats in one word (the first in the low half); `None` where one
/// is not finite or beyond a half float's range. A value below the smallest normal half float
/// (6.1e-5) is stored as a zero of its sign: the shaders' `unpack2x16float` may flush
/// subnormals, and then decodes what the CPU does, bit for bit.
pub(crate) fn halves(a: f32, b: f32) -> Option<u32> {
    let half = |x: f32| {
        let h = half::f16::from_f32(x);
        h.is_finite().then(|| {
            if h.is_normal() {
                h.to_bits()
            } else {
                h.to_bits() & 0x8000
            }
        })
    };
    Some(u32::from(half(a)?) | (u32::from(half(b)?) << 16))
}

/// A word's two half floats as f32, exactly.
pub(crate) fn unhalves(w: u32) -> [f32; 2] {
    [w as u16, (w >> 16) as u16].map(|h| half::f16::from_bits(h).to_f32())
}

/// Droplet spheres a cache can hold (the BVH's item ids and the trace's links take 28 bits).
pub const MAX_SPHERES: u32 = 1 << 28;

/// Element types a section can hold, by the name the header records.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Element {
    Point,
    /// A unit vector in one word ([`crate::octahedral`]).
    Octahedral,
    Ball,
    Sphere,
    BvhNode,
    U32,
    F32,
    Vec4,
}

impl Element {
    pub const ALL: [Element; 8] = [
        Element::Point,
        Element::Octahedral,
        Element::Ball,
        Element::Sphere,
        Element::BvhNode,
        Element::U32,
        Element::F32,
        Element::Vec4,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Element::Point => "point",
            Element::Octahedral => "octahedral",
            Element::Ball => "ball",
            Element::Sphere => "sphere",
            Element::BvhNode => "bvh_node",
            Element::U32 => "u32",
            Element::F32 => "f32",
            Element::Vec4 => "vec4<f32>",
        }
    }

    pub fn size(self) -> usize {
        match self {
            Element::Point | Element::Sphere | Element::Vec4 => 16,
            Element::Ball => size_of::<GpuBall>(),
            Element::BvhNode => size_of::<crate::GpuBvhNode>(),
            Element::Octahedral | Element::U32 | Element::F32 => 4,
        }
    }

    pub fn from_name(name: &str) -> Option<Element> {
        Element::ALL.into_iter().find(|e| e.name() == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_store_radius_and_reach_rounded_up_to_normal_half_floats() {
        assert_eq!(size_of::<GpuPoint>(), 16);
        // Values across the range a local frame gives (its half-extent is 1), those a half
        // float holds exactly, and one below the smallest normal half float.
        for x in [3.7e-3, 4.5e-3, 0.0123456, 0.25, 1.0, 3.4641, 1e-7, 0.0] {
            let p = GpuPoint::new([0.1, -0.2, 0.3], x, 2.0 * x).unwrap();
            for (stored, want) in [(p.radius(), x), (p.reach(), 2.0 * x)] {
                let stored = f64::from(stored);
                assert!(stored >= want, "{stored} < {want}");
                assert!(stored >= f64::from(MIN_NORMAL_HALF), "{stored}");
                // The smallest one at or above: one step of 11 bits below it is too small.
                let below = half::f16::from_f64(stored).to_bits() - 1;
                let below = f64::from(half::f16::from_bits(below).to_f32());
                assert!(
                    below < want || stored == f64::from(MIN_NORMAL_HALF),
                    "{below} >= {want}"
                );
                assert!(
                    stored <= want.max(6.2e-5) * (1.0 + 2f64.powi(-10)),
                    "{stored}"
                );
            }
            assert_eq!(f64::from(stored_radius(x).unwrap()), f64::from(p.radius()));
        }
        // What a half float cannot hold is refused (the bake reports the step).
        for bad in [f64::NAN, -1e-3, 7e4, f64::INFINITY] {
            assert!(GpuPoint::new([0.0; 3], bad, 0.1).is_none(), "{bad}");
            assert!(GpuPoint::new([0.0; 3], 0.1, bad).is_none(), "{bad}");
        }
    }

    /// The smallest normal half float at or above `x`, checked by its definition for every
    /// normal half, the f64 values next to it and halfway to the next, and the ends: at or
    /// above `x`, normal, and the half below it (where one is normal) below `x`.
    #[test]
    fn the_half_at_or_above_is_the_smallest_normal_one_not_below() {
        let value = |bits: u16| f64::from(half::f16::from_bits(bits).to_f32());
        let mut xs = vec![0.0, 1e-300, 5e-324, value(0x0001), value(0x03ff), 65504.0];
        for bits in 0x0400u16..=0x7bff {
            let v = value(bits);
            xs.extend([v, v.next_up(), v.next_down(), (v + value(bits + 1)) / 2.0]);
        }
        for x in xs.into_iter().filter(|&x| x <= 65504.0) {
            let h = half_at_or_above(x).expect("in range").to_bits();
            assert!((0x0400..=0x7bff).contains(&h), "{x:e}: {h:#x}");
            assert!(value(h) >= x, "{x:e}: {h:#x}");
            assert!(h == 0x0400 || value(h - 1) < x, "{x:e}: {h:#x}");
        }
        assert!(half_at_or_above(65504f64.next_up()).is_none());
    }
}
