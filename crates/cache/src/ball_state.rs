//! What a ball stores beside its 16 bytes (format 9): four bits of state, eight balls to a
//! word of the `ball_states` section, and h, the header's one value or, where h is per point,
//! a half float two to a word of the `ball_h` section. [`StoredBall`] gathers a ball's parts
//! as the CPU reads them; the shaders read the same words (`ball_state`, `ball_h` in
//! shaders/mls.wgsl).

use crate::error::{Error, Result};
use crate::layout::{BallState, CubicWords, GpuBall, unhalves};
use crate::names;
use crate::reader::CacheFile;

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

impl CacheFile {
    /// Checks that `ball_states` holds a place for every point, and `ball_h` too where h is
    /// per point (and is absent otherwise), from the section table alone.
    pub fn check_ball_words(&self) -> Result<()> {
        let header = self.header();
        let n = header.points;
        let check = |name: &str, per_word: u64, wanted: bool| -> std::result::Result<(), String> {
            match self.section(name) {
                None if wanted => Err(format!("section '{name}' is missing")),
                Some(_) if !wanted => Err(format!(
                    "section '{name}' is present where h is the step's one value"
                )),
                Some(e) if e.count != n.div_ceil(per_word) => Err(format!(
                    "section '{name}' holds {} words for {n} points ({per_word} to a word)",
                    e.count
                )),
                _ => Ok(()),
            }
        };
        check(names::BALL_STATES, BALLS_PER_STATE_WORD as u64, true)
            .and_then(|()| check(names::BALL_H, 2, header.mls.per_point_h))
            .map_err(|problem| Error::Invalid {
                path: self.path().to_path_buf(),
                problem,
            })
    }

    /// Every ball with its state bits and h, gathered from `balls`, `ball_states` and the
    /// header's h or `ball_h`; an error where a section is missing or of the wrong length.
    pub fn balls(&self) -> Result<Vec<StoredBall>> {
        self.check_ball_words()?;
        let header = self.header();
        let balls: Vec<GpuBall> = self.decode(names::BALLS)?;
        if balls.len() as u64 != header.points {
            return Err(Error::Invalid {
                path: self.path().to_path_buf(),
                problem: format!("{} balls for {} points", balls.len(), header.points),
            });
        }
        let states: Vec<u32> = self.decode(names::BALL_STATES)?;
        let per_point: Option<Vec<u32>> = header
            .mls
            .per_point_h
            .then(|| self.decode(names::BALL_H))
            .transpose()?;
        let global = header.smoothing_length as f32;
        Ok(balls
            .into_iter()
            .enumerate()
            .map(|(i, ball)| StoredBall {
                ball,
                bits: BallBits::of(&states, i),
                h: per_point.as_deref().map_or(global, |w| h_of(w, i)),
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
