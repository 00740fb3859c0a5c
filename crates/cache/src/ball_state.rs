//! What a ball stores beside its 16 bytes (format 9): four bits of state, eight balls to a
//! word of the `ball_states` section, and h, the header's one value or, where h is per point,
//! a half float two to a word of the `ball_h` section; and the ball's 16 bytes made from a
//! fit ([`GpuBall::new`]). [`StoredBall`] gathers a ball's parts as the CPU reads them
//! (`CacheFile::balls`, step.rs); the shaders read the same words (`ball_state`, `ball_h` in
//! shaders/mls.wgsl).

use crate::layout::{BALL_COEFFS, BallState, CubicWords, GpuBall, MAX_SPHERES, halves, unhalves};

/// Balls per word of `ball_states`.
pub const BALLS_PER_STATE_WORD: usize = 8;

/// A ball's state: its kind (bits 0–1, [`BallState`]) and the degree fitted (bits 2–3), in
/// bits 4 (i mod 8) .. 4 (i mod 8) + 4 of word i / 8 of `ball_states` for ball i.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BallBits(pub u8);

impl BallBits {
    pub fn new(kind: BallState, degree: u8) -> BallBits {
        BallBits(kind as u8 | (degree & 3) << 2)
    }

    pub fn kind(self) -> BallState {
        match self.0 & 3 {
            0 => BallState::Full,
            1 => BallState::Degraded,
            2 => BallState::Unfitted,
            _ => BallState::Droplet,
        }
    }

    /// Degree of the stored polynomial (lower than requested where the data could not
    /// carry it).
    pub fn degree(self) -> u8 {
        (self.0 >> 2) & 3
    }

    /// The `ball_states` words of `bits`, ball i's in its place (unused places zero).
    pub fn pack(bits: &[BallBits]) -> Vec<u32> {
        bits.chunks(BALLS_PER_STATE_WORD)
            .map(|chunk| {
                chunk
                    .iter()
                    .enumerate()
                    .fold(0u32, |w, (k, b)| w | u32::from(b.0 & 15) << (4 * k))
            })
            .collect()
    }

    /// Ball i's bits in `words` (zero past their end).
    pub fn of(words: &[u32], i: usize) -> BallBits {
        let word = words.get(i / BALLS_PER_STATE_WORD).copied().unwrap_or(0);
        BallBits(((word >> (4 * (i % BALLS_PER_STATE_WORD))) & 15) as u8)
    }
}

/// `h` as the half float's bits a ball stores: `None` unless a positive normal half float
/// holds it exactly (the bake fits with h at half precision, `slosh_mls::half_precision`, so
/// it always does there).
pub fn exact_half(h: f32) -> Option<u16> {
    let stored = half::f16::from_f32(h);
    (stored.is_normal() && stored.to_f32() == h && h > 0.0).then_some(stored.to_bits())
}

/// The `ball_h` words of per-point `h`, two to a word (ball 2k in the low half); `None` where
/// one is not an exact positive normal half float.
pub fn pack_h(h: &[f32]) -> Option<Vec<u32>> {
    h.chunks(2)
        .map(|pair| {
            let low = u32::from(exact_half(pair[0])?);
            let high = pair
                .get(1)
                .map_or(Some(0), |&x| exact_half(x).map(u32::from))?;
            Some(low | high << 16)
        })
        .collect()
}

/// Ball i's h in `ball_h` words.
pub fn h_of(words: &[u32], i: usize) -> f32 {
    words.get(i / 2).map_or(0.0, |&w| unhalves(w)[i % 2])
}

/// A ball as the CPU reads it: its 16 bytes, its state bits and its h.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StoredBall {
    pub ball: GpuBall,
    pub bits: BallBits,
    /// The smoothing length, as stored.
    pub h: f32,
}

impl StoredBall {
    pub fn kind(&self) -> BallState {
        self.bits.kind()
    }

    pub fn degree(&self) -> u8 {
        self.bits.degree()
    }

    /// The droplet sphere this ball belongs to.
    pub fn sphere(&self) -> Option<u32> {
        (self.kind() == BallState::Droplet).then_some(self.ball.coeffs[0])
    }

    /// The support normal, normalised (zero where none was stored).
    pub fn normal(&self) -> [f32; 3] {
        crate::octahedral::decode_unit(self.ball.normal)
    }

    /// The ten coefficients as f32, exactly the stored values: the ball's six and, for a
    /// cubic, the four of its `ball_cubic` words (unused ones zero; all zero for a droplet
    /// member, whose first word names its sphere).
    pub fn coeffs(&self, cubic: CubicWords) -> [f32; 10] {
        let mut c = [0.0f32; 10];
        if self.kind() == BallState::Droplet {
            return c;
        }
        let words = if self.degree() == 3 { 5 } else { 3 };
        for (k, w) in self
            .ball
            .coeffs
            .iter()
            .chain(&cubic)
            .take(words)
            .enumerate()
        {
            c[2 * k..2 * k + 2].copy_from_slice(&unhalves(*w));
        }
        c
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::MIN_NORMAL_HALF;

    #[test]
    fn states_and_h_round_trip_through_their_words() {
        let kinds = [
            BallState::Full,
            BallState::Degraded,
            BallState::Unfitted,
            BallState::Droplet,
        ];
        let bits: Vec<BallBits> = (0..19)
            .map(|i| BallBits::new(kinds[i % 4], (i % 3) as u8 + 1))
            .collect();
        let words = BallBits::pack(&bits);
        assert_eq!(words.len(), 3);
        for (i, b) in bits.iter().enumerate() {
            assert_eq!(BallBits::of(&words, i), *b);
            assert_eq!((b.kind(), b.degree()), (kinds[i % 4], (i % 3) as u8 + 1));
        }
        assert_eq!(words[2] >> 12, 0, "places past the last ball stay zero");
        let h = [0.25f32, 0.015625, 3.0];
        let words = pack_h(&h).unwrap();
        assert_eq!(words.len(), 2);
        assert!((0..3).all(|i| h_of(&words, i) == h[i]));
        assert_eq!(words[1] >> 16, 0);
        assert_eq!(pack_h(&[0.1]), None, "0.1 is no half float");
        assert_eq!(pack_h(&[1e-6]), None, "subnormal");
        assert_eq!(pack_h(&[0.0]), None);
    }

    #[test]
    fn balls_keep_their_state_and_the_nearest_stored_coefficients() {
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
