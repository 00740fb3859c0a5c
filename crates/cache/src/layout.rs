//! Element types of the GPU sections: `#[repr(C)]` Pod structs laid out exactly as the WGSL
//! storage-buffer structs of the same names (vec3 + scalar packs into 16 bytes there).

use bytemuck::{Pod, Zeroable};

use crate::ball_state::BallBits;

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
    let mut h = half::f16::from_f64(x).max(half::f16::MIN_POSITIVE);
    while f64::from(h.to_f32()) < x {
        h = half::f16::from_bits(h.to_bits() + 1);
    }
    Some(h)
}

/// `struct Ball { normal: u32, coeffs: array<u32, 3> }` (16 bytes, format 9): the initial
/// support normal (octahedral, [`crate::octahedral`]) and the initial polynomial's first six
/// coefficients in coordinates scaled by 1/h as IEEE half floats two to a word (coefficient
/// 2k in the low half of word k). A ball that is no candidate (unfitted, or a droplet
/// member) has no normal ([`crate::octahedral::NO_NORMAL`]) and every candidate has one, so
/// the trace walk tells them apart by the ball alone; a droplet member's first coefficient
/// word holds its sphere's index (it has no polynomial to draw). What the ball is and the degree
/// fitted are four bits of the `ball_states` section ([`BallBits`]), h the header's (or the
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

/// What a ball is, in the low two bits of its [`BallBits`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BallState {
    /// Fitted at the requested degree.
    Full = 0,
    /// Fitted at a lower degree ([`BallBits::degree`]).
    Degraded = 1,
    /// No support plane or fit: never a candidate.
    Unfitted = 2,
    /// Member of a droplet drawn as a sphere.
    Droplet = 3,
}

/// Coefficients a ball holds itself: a polynomial of degree ≤ 2.
const BALL_COEFFS: usize = 6;

/// The smallest normal half float, 2^-14: no stored coefficient lies closer to zero, but zero.
pub const MIN_NORMAL_HALF: f32 = 1.0 / 16384.0;

/// Two coefficients as half floats in one word (the first in the low half); `None` where one
/// is not finite or beyond a half float's range. A value below the smallest normal half float
/// (6.1e-5) is stored as a zero of its sign: the shaders' `unpack2x16float` may flush
/// subnormals, and then decodes what the CPU does, bit for bit.
fn halves(a: f32, b: f32) -> Option<u32> {
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

impl GpuBall {
    /// Whether the ball is a candidate (fitted, full or degraded): it has a normal.
    pub fn is_candidate(&self) -> bool {
        self.normal & 0xffff != crate::octahedral::NO_NORMAL & 0xffff
    }

    /// A ball from its parts, its state bits, and a cubic's other coefficients: the normal
    /// encoded (none for a droplet member), the coefficients rounded to half floats; `None`
    /// where a coefficient is not finite or beyond a half float's range, a fitted ball's
    /// normal is not a direction (the caller stores the ball unfitted), or the sphere index
    /// or degree does not fit.
    pub fn new(
        normal: [f64; 3],
        coeffs: [f32; 10],
        degree: u8,
        kind: BallState,
        sphere: u32,
    ) -> Option<(GpuBall, BallBits, CubicWords)> {
        if sphere >= MAX_SPHERES || degree > 3 {
            return None;
        }
        let used = if degree == 3 { 10 } else { BALL_COEFFS };
        let mut c = [0.0f32; 10];
        c[..used].copy_from_slice(&coeffs[..used]);
        let word = |k: usize| halves(c[2 * k], c[2 * k + 1]);
        let (normal, coeffs, cubic) = match kind {
            BallState::Droplet => (crate::octahedral::NO_NORMAL, [sphere, 0, 0], [0, 0]),
            BallState::Unfitted => return None,
            BallState::Full | BallState::Degraded => {
                let normal = crate::octahedral::encode(normal);
                if normal == crate::octahedral::NO_NORMAL {
                    return None;
                }
                let coeffs = [word(0)?, word(1)?, word(2)?];
                (normal, coeffs, [word(3)?, word(4)?])
            }
        };
        let ball = GpuBall { normal, coeffs };
        Some((ball, BallBits::new(kind, degree), cubic))
    }

    /// A ball that is never a candidate: no support plane or fit, or one that could not be
    /// stored. It has no normal.
    pub fn unfitted() -> (GpuBall, BallBits) {
        let ball = GpuBall {
            normal: crate::octahedral::NO_NORMAL,
            coeffs: [0; 3],
        };
        (ball, BallBits::new(BallState::Unfitted, 0))
    }
}

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

    #[test]
    fn balls_keep_their_state_and_the_nearest_stored_coefficients() {
        use crate::ball_state::StoredBall;
        let c: [f32; 10] = [0.1, -2.5e-3, 3.0, -7.25, 1e-6, 40.0, 0.5, -0.25, 1e3, 2e-5];
        let half = |x: f32| half::f16::from_f32(x).to_f32();
        let h = half(0.02);
        let stored =
            |(ball, bits, _): (GpuBall, BallBits, CubicWords)| StoredBall { ball, bits, h };
        let made = GpuBall::new([0.0, 0.6, 0.8], c, 2, BallState::Degraded, 0).unwrap();
        let extra = made.2;
        let quadratic = stored(made);
        assert_eq!(size_of::<GpuBall>(), 16);
        assert_eq!(
            (quadratic.kind(), quadratic.degree()),
            (BallState::Degraded, 2)
        );
        assert_eq!(quadratic.sphere(), None);
        assert_eq!(extra, [0, 0], "a quadratic has no cubic words");
        let got = quadratic.coeffs(extra);
        for k in 0..6 {
            // The nearest half float: within half a unit of its 11 bits; below the smallest
            // normal one, zero.
            let want = if c[k].abs() < 6.1e-5 { 0.0 } else { half(c[k]) };
            assert_eq!(got[k], want, "{k}");
            assert!(
                want == 0.0 || (got[k] - c[k]).abs() <= c[k].abs() * 2f32.powi(-11),
                "{k}"
            );
        }
        assert_eq!(&got[6..], &[0.0; 4], "a quadratic stores six");
        // What the verifier requires: no subnormal half float (c[4] = 1e-6 became zero).
        assert!(got.iter().all(|g| *g == 0.0 || g.abs() >= MIN_NORMAL_HALF));
        assert_eq!(got[4], 0.0);
        let made = GpuBall::new([0.0, 0.0, -1.0], c, 3, BallState::Full, 0).unwrap();
        let extra = made.2;
        let cubic = stored(made);
        assert_eq!((cubic.kind(), cubic.degree()), (BallState::Full, 3));
        for (k, (&g, &x)) in cubic.coeffs(extra).iter().zip(&c).enumerate() {
            let want = if x.abs() < 6.1e-5 { 0.0 } else { half(x) };
            assert_eq!(g, want, "{k}");
        }
        let n = cubic.normal();
        assert!(n[2] < -0.999_999 && n[0].abs() < 1e-6, "{n:?}");
        // A droplet member names its sphere where its polynomial would be.
        let made =
            GpuBall::new([0.0, 0.0, 1.0], c, 2, BallState::Droplet, MAX_SPHERES - 1).unwrap();
        let extra = made.2;
        let member = stored(made);
        assert_eq!(
            (member.kind(), member.sphere(), extra),
            (BallState::Droplet, Some(MAX_SPHERES - 1), [0, 0])
        );
        assert_eq!(member.coeffs(extra), [0.0; 10]);
        let (ball, bits) = GpuBall::unfitted();
        assert_eq!(stored((ball, bits, [0; 2])).kind(), BallState::Unfitted);
        // Candidates, and only they, have a normal; a fit without one is not stored.
        assert!(quadratic.ball.is_candidate() && cubic.ball.is_candidate());
        assert!(!member.ball.is_candidate() && !ball.is_candidate());
        assert!(GpuBall::new([0.0; 3], c, 2, BallState::Full, 0).is_none());
        assert!(GpuBall::new([0.0, 0.0, 1.0], c, 2, BallState::Unfitted, 0).is_none());
        // What a half float cannot hold is refused (the bake stores the ball unfitted), in
        // the ball's six or a cubic's other four; so is a NaN.
        let mut big = c;
        big[3] = 1e6;
        assert!(GpuBall::new([0.0, 0.0, 1.0], big, 2, BallState::Full, 0).is_none());
        let mut big = c;
        big[8] = 1e6;
        assert!(GpuBall::new([0.0, 0.0, 1.0], big, 3, BallState::Full, 0).is_none());
        assert!(GpuBall::new([0.0, 0.0, 1.0], big, 2, BallState::Full, 0).is_some());
        big[0] = f32::NAN;
        assert!(GpuBall::new([0.0, 0.0, 1.0], big, 2, BallState::Full, 0).is_none());
        assert!(GpuBall::new([0.0, 0.0, 1.0], c, 2, BallState::Droplet, MAX_SPHERES).is_none());
    }
}
