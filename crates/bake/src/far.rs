//! Part of step 1 of the bake: particles far beyond the rest are dropped. A solver may park
//! the particles it no longer moves at a sentinel (1e30, −9999): kept, one of them would set
//! the step's frame, and the rest, in local coordinates of that frame, would round to one
//! point. The surface would be lost without a word (`docs/bake.md`, "Select").

use rayon::prelude::*;

/// How far beyond the bulk's box a particle may lie, in multiples of the box's largest side.
/// At this bound the frame is at most about 2000 times the bulk's size, so f32 local
/// coordinates still resolve the bulk to about 1e-4 of it.
pub const FAR_BEYOND: f64 = 1000.0;

/// Particles sampled, evenly through the input's order, for the bulk's box.
const BULK_SAMPLE: usize = 4096;

/// Fraction of the sample left out at each end of each axis: the bulk's box holds the central
/// half of each coordinate, so that far particles, up to a quarter of a step's, do not set
/// it (a run whose outflow parks many).
const BULK_TAIL: f64 = 0.25;

/// A position that this fraction of the sample holds exactly, or more, is a pile: a solver
/// may park any number of particles at one sentinel. Piles are left out of the bulk's box,
/// so that the rest set it however many are parked; a pile near the rest is still kept.
const PILE: f64 = 0.01;

/// `candidates` (indices into `positions`, ascending, every position finite) without the
/// particles that lie more than [`FAR_BEYOND`] times the bulk's largest side beyond the bulk's
/// box, in the same order. The bulk's box is the central half of each axis's coordinates over
/// a sample of at most [`BULK_SAMPLE`] candidates, piles left out.
pub fn without_far(positions: &[[f64; 3]], candidates: Vec<u32>) -> Vec<u32> {
    let n = candidates.len();
    if n < 2 {
        return candidates;
    }
    let stride = n.div_ceil(BULK_SAMPLE);
    let sample = without_piles(
        candidates
            .iter()
            .step_by(stride)
            .map(|&i| positions[i as usize])
            .collect(),
    );
    let m = sample.len();
    let cut = (BULK_TAIL * (m - 1) as f64) as usize;
    let mut lo = [0.0; 3];
    let mut hi = [0.0; 3];
    for a in 0..3 {
        let mut values: Vec<f64> = sample.iter().map(|p| p[a]).collect();
        values.sort_unstable_by(f64::total_cmp);
        (lo[a], hi[a]) = (values[cut], values[m - 1 - cut]);
    }
    let side = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
    let reach = FAR_BEYOND * side;
    let near = |i: u32| {
        let p = positions[i as usize];
        (0..3).all(|a| p[a] >= lo[a] - reach && p[a] <= hi[a] + reach)
    };
    // Nearly always none is far: one pass that allocates nothing says so.
    if candidates.par_iter().all(|&i| near(i)) {
        return candidates;
    }
    candidates.into_par_iter().filter(|&i| near(i)).collect()
}

/// The sample without its piles ([`PILE`]); all of it where fewer than two points would be
/// left.
fn without_piles(mut sample: Vec<[f64; 3]>) -> Vec<[f64; 3]> {
    let least = ((PILE * sample.len() as f64).ceil() as usize).max(2);
    sample.sort_unstable_by(|p, q| {
        (p[0].total_cmp(&q[0]))
            .then(p[1].total_cmp(&q[1]))
            .then(p[2].total_cmp(&q[2]))
    });
    let rest: Vec<[f64; 3]> = sample
        .chunk_by(|p, q| p == q)
        .filter(|run| run.len() < least)
        .flatten()
        .copied()
        .collect();
    if rest.len() < 2 { sample } else { rest }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize, spacing: f64) -> Vec<[f64; 3]> {
        (0..n * n)
            .map(|k| [(k % n) as f64 * spacing, (k / n) as f64 * spacing, 0.0])
            .collect()
    }

    fn kept(positions: &[[f64; 3]]) -> Vec<u32> {
        without_far(positions, (0..positions.len() as u32).collect())
    }

    /// A 100 × 100 grid 0.99 wide: sentinels beyond 1000 sides of the bulk go, in any corner;
    /// spray within that bound stays, however sparse.
    #[test]
    fn sentinels_go_and_spray_stays() {
        let mut p = grid(100, 0.01);
        let bulk = p.len() as u32;
        p.push([1e30, 1e30, 1e30]);
        p.push([-9999.0, 0.5, 0.5]);
        // The bulk's box is about 0.5 wide (the central half), so the bound lies about 500
        // above its top (0 in z).
        p.push([0.5, 0.5, 600.0]);
        p.push([0.5, 0.5, 400.0]);
        p.push([50.0, -20.0, 3.0]); // a droplet flung a hundred sides away
        let k = kept(&p);
        let mut expected: Vec<u32> = (0..bulk).collect();
        expected.extend([bulk + 3, bulk + 4]);
        assert_eq!(k, expected);
    }

    /// Without far particles, every candidate is kept, as given (a subset, in order).
    #[test]
    fn nothing_far_keeps_everything() {
        let p = grid(70, 1e-3);
        let candidates: Vec<u32> = (0..p.len() as u32).step_by(3).collect();
        assert_eq!(without_far(&p, candidates.clone()), candidates);
        // Two points have no bulk apart from them: both are kept, 1e30 apart.
        assert_eq!(kept(&[[0.0; 3], [1e30, 0.0, 0.0]]), vec![0, 1]);
    }

    /// The bulk's box is set by the central half: far particles, a fifth of a step's here and
    /// each at its own place, cannot widen it enough to keep themselves.
    #[test]
    fn many_sentinels_are_all_dropped() {
        let mut p = grid(100, 0.01);
        let bulk = p.len();
        for k in 0..2500 {
            p.push([1e6 + k as f64, -1e30, 0.0]);
        }
        assert_eq!(kept(&p).len(), bulk);
    }

    /// Parked at one sentinel, any number go: twice the bulk's count here. A pile within the
    /// bound (coincident particles in the bulk) stays.
    #[test]
    fn a_pile_of_any_size_goes_where_far_and_stays_where_near() {
        let mut p = grid(100, 0.01);
        let bulk = p.len();
        p.extend(std::iter::repeat_n([1e30, 1e30, 1e30], 2 * bulk));
        assert_eq!(kept(&p).len(), bulk);
        let mut p = grid(100, 0.01);
        p.extend(std::iter::repeat_n([0.5, 0.5, 0.0], 3000));
        assert_eq!(kept(&p).len(), p.len());
        // Only a pile: nothing else sets a box, and nothing is dropped.
        assert_eq!(kept(&[[1.0, 2.0, 3.0]; 50]).len(), 50);
    }
}
