//! Which way is up in a point set, from the data alone (the framing camera's default):
//! objects rest on a flat base, whose points face down; an open surface such as a fluid's free
//! surface faces up. Meshes from graphics (the bunny) are y-up, solver output often z-up or y-up,
//! and nothing in the files says which.

use rayon::prelude::*;

/// Points within this fraction of the extent from the low end belong to the base.
const BASE_BAND: f64 = 0.03;
/// A base point's normal points down by at least this cosine.
const BASE_COSINE: f64 = 0.8;
/// A base must hold this fraction of the points, and this many times the runner-up's.
const BASE_FRACTION: f64 = 0.03;
const BASE_MARGIN: f64 = 3.0;
/// The mean unit normal of an open, upward surface is at least this long.
const OPEN_MEAN: f64 = 0.3;

/// The unit axis (±x, ±y or ±z) that is up for `points` with unit `normals`, or `None` where
/// the data does not say (a closed shape without a base, no normals).
pub fn guess_up(points: &[[f64; 3]], normals: &[[f64; 3]]) -> Option<[f64; 3]> {
    if points.is_empty() || points.len() != normals.len() {
        return None;
    }
    let unit = |axis: usize, sign: f64| -> [f64; 3] {
        std::array::from_fn(|a| if a == axis { sign } else { 0.0 })
    };
    // An open surface facing one way (a free surface): the mean normal's dominant axis.
    let mut mean = [0.0f64; 3];
    for n in normals {
        for a in 0..3 {
            mean[a] += n[a];
        }
    }
    let mean = mean.map(|m| m / normals.len() as f64);
    let length = (mean[0] * mean[0] + mean[1] * mean[1] + mean[2] * mean[2]).sqrt();
    if length >= OPEN_MEAN {
        let axis = crate::geometry::dominant_axis(mean);
        return Some(unit(axis, mean[axis].signum()));
    } // A closed shape resting on a flat base: the base faces down.
    let (lo, hi) = crate::geometry::bounds_in_parallel(points);
    // A flat base: for each candidate up (axis, sign), the share of points in a thin band at
    // its low end whose normals point down; all six counted in one pass over the points.
    let band: [f64; 3] = std::array::from_fn(|a| BASE_BAND * (hi[a] - lo[a]));
    let counts = points
        .par_iter()
        .zip(normals)
        .fold(
            || [0usize; 6],
            |mut counts, (p, n)| {
                for axis in 0..3 {
                    if p[axis] - lo[axis] < band[axis] && -n[axis] > BASE_COSINE {
                        counts[2 * axis] += 1;
                    }
                    if hi[axis] - p[axis] < band[axis] && n[axis] > BASE_COSINE {
                        counts[2 * axis + 1] += 1;
                    }
                }
                counts
            },
        )
        .reduce(|| [0; 6], |a, b| std::array::from_fn(|k| a[k] + b[k]));
    let mut scores = Vec::with_capacity(6);
    for axis in 0..3 {
        if !(hi[axis] - lo[axis] > 0.0) {
            continue;
        }
        for (k, sign) in [(2 * axis, 1.0), (2 * axis + 1, -1.0)] {
            scores.push((counts[k] as f64 / points.len() as f64, axis, sign));
        }
    }
    scores.sort_by(|a, b| b.0.total_cmp(&a.0));
    match scores[..] {
        [best, second, ..] if best.0 >= BASE_FRACTION && best.0 >= BASE_MARGIN * second.0 => {
            Some(unit(best.1, best.2))
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A dome over a flat disc base, `up` being +y: the base's normals point −y.
    fn dome_on_base() -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
        let (mut p, mut n) = (Vec::new(), Vec::new());
        // The dome sampled evenly by area (heights uniform in [0, 1]).
        for i in 0..3200 {
            let h = (i as f64 + 0.5) / 3200.0;
            let r = (1.0 - h * h).sqrt();
            let phi = i as f64 * 2.399963;
            let d = [r * phi.cos(), h, r * phi.sin()];
            p.push(d);
            n.push(d);
        }
        for i in 0..20 {
            for j in 0..60 {
                let (r, phi) = (
                    i as f64 / 20.0,
                    2.0 * std::f64::consts::PI * j as f64 / 60.0,
                );
                p.push([r * phi.cos(), 0.0, r * phi.sin()]);
                n.push([0.0, -1.0, 0.0]);
            }
        }
        (p, n)
    }

    #[test]
    fn a_shape_resting_on_a_base_is_up_from_its_base() {
        let (p, n) = dome_on_base();
        assert_eq!(guess_up(&p, &n), Some([0.0, 1.0, 0.0]));
        // Turned upside down, up turns too.
        let flipped: Vec<[f64; 3]> = p.iter().map(|q| [q[0], -q[1], q[2]]).collect();
        let nf: Vec<[f64; 3]> = n.iter().map(|q| [q[0], -q[1], q[2]]).collect();
        assert_eq!(guess_up(&flipped, &nf), Some([0.0, -1.0, 0.0]));
    }

    #[test]
    fn an_open_surface_faces_up_and_a_closed_one_says_nothing() {
        // A wavy free surface over x, y with normals mostly +z.
        let (mut p, mut n) = (Vec::new(), Vec::new());
        for i in 0..50 {
            for j in 0..30 {
                let (x, y) = (i as f64 / 25.0, j as f64 / 30.0);
                p.push([x, y, 0.1 * (3.0 * x).sin()]);
                let slope = 0.3 * (3.0 * x).cos();
                let l = (1.0 + slope * slope).sqrt();
                n.push([-slope / l, 0.0, 1.0 / l]);
            }
        }
        assert_eq!(guess_up(&p, &n), Some([0.0, 0.0, 1.0]));
        // A sphere: no base, no mean normal.
        let mut s = Vec::new();
        for i in 0..2000 {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / 2000.0;
            let r = (1.0 - z * z).sqrt();
            let phi = i as f64 * 2.399963;
            s.push([r * phi.cos(), r * phi.sin(), z]);
        }
        assert_eq!(guess_up(&s, &s), None);
        assert_eq!(guess_up(&[], &[]), None);
    }
}
