//! Unit vectors in one 32-bit word: the octahedral map (Meyer et al. 2010, "On floating-point
//! normal vectors"), two signed 16-bit coordinates. The `normals` section and the balls'
//! support normals are stored so (format 4).
//!
//! Decoding is exact arithmetic in the same order on every machine (an integer to f32, one
//! multiplication by a constant, subtractions, sign changes), so the CPU and the shaders
//! (`octahedral` in shaders/step.wgsl) get the same f32 vector bit for bit: the neighbour
//! rule tests signs of dot products on it. The decoded vector is not normalised (its L1
//! norm is 1); users normalise it where they need a unit vector.

/// The word of "no normal": a zero vector (the input's normal was unusable). Its first
/// coordinate, −32768, is one that encoding never writes.
pub const NO_NORMAL: u32 = 0x8000_8000;

/// One step of a coordinate, 1/32767 rounded to f32: the shaders take the same bits
/// (shared constants in crates/render's shaders.rs).
pub const OCTAHEDRAL_STEP: f32 = 1.0 / 32767.0;

fn sign(x: f32) -> f32 {
    if x >= 0.0 { 1.0 } else { -1.0 }
}

/// The low and high signed halves of a word.
fn halves(word: u32) -> (i16, i16) {
    (word as u16 as i16, (word >> 16) as u16 as i16)
}

/// The vector a word stands for: on the unit octahedron (|x| + |y| + |z| = 1), or zero for
/// [`NO_NORMAL`].
pub fn decode(word: u32) -> [f32; 3] {
    let (a, b) = halves(word);
    if a == i16::MIN {
        return [0.0; 3];
    }
    on_octahedron(a, b)
}

/// The point of the unit octahedron whose coordinates are `a` and `b` steps.
#[inline]
fn on_octahedron(a: i16, b: i16) -> [f32; 3] {
    let (x, y) = (
        f32::from(a) * OCTAHEDRAL_STEP,
        f32::from(b) * OCTAHEDRAL_STEP,
    );
    let z = 1.0 - x.abs() - y.abs();
    if z >= 0.0 {
        [x, y, z]
    } else {
        [(1.0 - y.abs()) * sign(x), (1.0 - x.abs()) * sign(y), z]
    }
}

/// The floor and ceiling of `v`, |v| at most 32767, by truncation (exact there): `floor`
/// and `ceil` are library calls on the baseline x86-64 target.
#[inline]
fn floor_and_ceiling(v: f64) -> (f64, f64) {
    let t = v as i32 as f64;
    (
        if t > v { t - 1.0 } else { t },
        if t < v { t + 1.0 } else { t },
    )
}

/// `decode(word)` normalised (zero stays zero).
pub fn decode_unit(word: u32) -> [f32; 3] {
    let v = decode(word);
    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if len > 0.0 { v.map(|c| c / len) } else { v }
}

fn word(a: i16, b: i16) -> u32 {
    u32::from(a as u16) | (u32::from(b as u16) << 16)
}

/// The word whose direction is nearest `n`'s (of the four codes around its projection);
/// [`NO_NORMAL`] where `n` is zero or not finite.
pub fn encode(n: [f64; 3]) -> u32 {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    if !(l1.is_finite() && l1 > 0.0) {
        return NO_NORMAL;
    }
    // On the unit octahedron: no product below can overflow, whatever `n`'s length.
    let m = n.map(|c| c / l1);
    let (mut x, mut y) = (m[0], m[1]);
    if m[2] < 0.0 {
        let sx = if x >= 0.0 { 1.0 } else { -1.0 };
        let sy = if y >= 0.0 { 1.0 } else { -1.0 };
        (x, y) = ((1.0 - y.abs()) * sx, (1.0 - x.abs()) * sy);
    }
    let step = |v: f64| v.clamp(-32767.0, 32767.0) as i16;
    let (fa, ca) = floor_and_ceiling(x * 32767.0);
    let (fb, cb) = floor_and_ceiling(y * 32767.0);
    // The four codes around the projection, each measured on its own, in f64 (the f32
    // normalisation's rounding would outweigh the codes' differences): the nearest has the
    // largest cosine to `m`, d·m / |d| (|m| is the same for all four), compared as
    // (d·m)|d·m| / |d|², which orders as the cosine does: no square roots (a million normals
    // and a million balls' normals every step).
    let a = [fa, fa, ca, ca].map(step);
    let b = [fb, cb, fb, cb].map(step);
    let closeness: [f64; 4] = std::array::from_fn(|k| {
        let d = on_octahedron(a[k], b[k]).map(f64::from);
        let dot = d[0] * m[0] + d[1] * m[1] + d[2] * m[2];
        dot * dot.abs() / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    });
    let mut best = (f64::NEG_INFINITY, NO_NORMAL);
    for k in 0..4 {
        if closeness[k] > best.0 {
            best = (closeness[k], word(a[k], b[k]));
        }
    }
    best.1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directions_come_back_within_a_few_hundred_thousandths_of_a_radian() {
        let mut worst = 0.0f64;
        let count = 20_000;
        for i in 0..count {
            // A Fibonacci sphere, and the axes and octant diagonals.
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / count as f64;
            let phi = i as f64 * 2.399_963_229_728_653;
            let r = (1.0 - z * z).sqrt();
            for n in [
                [r * phi.cos(), r * phi.sin(), z],
                [0.0, 0.0, -1.0],
                [1.0, 0.0, 0.0],
                [-1.0, -1.0, -1.0],
            ] {
                worst = worst.max(angle(encode(n), n));
            }
        }
        assert!(worst < 5e-5, "worst angle {worst}");
    }

    /// The angle between a word's direction and `n`, by atan2 of the cross and dot products:
    /// acos near 1 would measure f32 rounding, not the code.
    fn angle(word: u32, n: [f64; 3]) -> f64 {
        let d = decode(word).map(f64::from);
        let cross = [
            d[1] * n[2] - d[2] * n[1],
            d[2] * n[0] - d[0] * n[2],
            d[0] * n[1] - d[1] * n[0],
        ];
        let sin = (cross[0].powi(2) + cross[1].powi(2) + cross[2].powi(2)).sqrt();
        let cos: f64 = (0..3).map(|k| d[k] * n[k]).sum();
        sin.atan2(cos)
    }

    /// The word is the nearest of the four codes around the projection, found here by the
    /// library's floor and ceiling and measured by angle: none of the four is nearer by more
    /// than 1e-12 rad (two codes can lie equally near, within rounding), on 200,000 directions
    /// of a Fibonacci sphere, half of them flipped below the equator's fold.
    #[test]
    fn the_word_is_the_nearest_of_the_four_codes_around_the_projection() {
        let count = 200_000;
        let mut nearer = Vec::new();
        for i in 0..count {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / count as f64;
            let phi = i as f64 * 2.399_963_229_728_653;
            let r = (1.0 - z * z).sqrt();
            let n = [r * phi.cos(), r * phi.sin(), z];
            let l1 = n[0].abs() + n[1].abs() + n[2].abs();
            let (mut x, mut y) = (n[0] / l1, n[1] / l1);
            if n[2] < 0.0 {
                let sign = |v: f64| if v >= 0.0 { 1.0 } else { -1.0 };
                (x, y) = ((1.0 - y.abs()) * sign(x), (1.0 - x.abs()) * sign(y));
            }
            let chosen = angle(encode(n), n);
            for a in [(x * 32767.0).floor(), (x * 32767.0).ceil()] {
                for b in [(y * 32767.0).floor(), (y * 32767.0).ceil()] {
                    let other = angle(word(a as i16, b as i16), n);
                    if other < chosen - 1e-12 {
                        nearer.push((n, chosen, other));
                    }
                }
            }
        }
        assert!(
            nearer.is_empty(),
            "{} nearer codes, first {:?}",
            nearer.len(),
            nearer.first()
        );
    }

    /// The truncating floor and ceiling are `floor` and `ceil` over the coordinates' range:
    /// integers, halves, the neighbours of integers, signed zeros and the ends.
    #[test]
    fn floor_and_ceiling_by_truncation_are_exact() {
        let mut values = vec![0.0, -0.0, 32767.0, -32767.0];
        for i in -32767..=32767 {
            let v = f64::from(i);
            values.extend([v, v + 0.5, v.next_up(), v.next_down(), v + 0.999_999]);
        }
        for v in values.into_iter().filter(|v| v.abs() <= 32767.0) {
            let (f, c) = floor_and_ceiling(v);
            assert_eq!((f, c), (v.floor(), v.ceil()), "{v:e}");
        }
    }

    #[test]
    fn zero_and_non_finite_vectors_are_no_normal() {
        assert_eq!(encode([0.0; 3]), NO_NORMAL);
        assert_eq!(encode([f64::NAN, 0.0, 1.0]), NO_NORMAL);
        assert_eq!(decode(NO_NORMAL), [0.0; 3]);
        // Every other word decodes onto the octahedron.
        for w in [0u32, 0x7fff_7fff, 0x8001_8001, 0x1234_8765] {
            let v = decode(w);
            assert!(
                (v.iter().map(|c| c.abs()).sum::<f32>() - 1.0).abs() < 1e-6,
                "{w:x}"
            );
        }
    }
}
