//! Normal orientation repaired before anything uses the normals (`docs/algorithm.md`,
//! "Orientation"). A reversed normal drops every neighbour as "the other face" and leaves its
//! point alone, which draws a pit or a stray sphere; so each normal is checked against the
//! neighbours that lie in its tangent plane, and reversed where they contradict it. The two
//! faces of a thin sheet stay apart: a neighbour across the sheet lies off the tangent plane,
//! and its vote weighs little. Then small patches whose whole border contradicts
//! them are reversed together, which single votes cannot do from inside a patch.

use rayon::prelude::*;

/// Neighbours each normal is checked against: enough for a clear majority at 30 % reversed.
pub const ORIENT_NEIGHBOURS: usize = 16;
/// A normal is reversed when the weighted vote of its neighbours is below −this (votes run
/// from −1, all contradict, to 1, all agree): a margin that keeps a thin sheet's points,
/// whose vote is near 0, as they are.
const REVERSE_BELOW: f64 = 0.2;
/// A neighbour's vote weighs its tangent weight squared this many times (the 4th power), so
/// that a neighbour off the tangent plane counts less: across a thin sheet half a spacing
/// thick, a neighbour one spacing aside lies 27° off the plane, tangent weight 0.8 but vote
/// weight 0.41. With the tangent weight itself, such neighbours outvoted a point's own face:
/// of a sheet's 20000 normals with 1980 reversed, 3754 ended wrong (2291 correct ones
/// reversed); with its 4th power, 449. The 8th power left 28, but a droplet of 7 particles
/// was then drawn 1.09 spacings behind the truth (`sparse_droplets_give_finite_answers`,
/// which allows 1); leaving out neighbours beyond 1.5 to 3 times the sixth one's distance
/// did not bring it back, and why is not known.
pub const VOTE_SQUARINGS: u32 = 2;
/// The edges of a point reach no farther than [`EDGE_REACH`] times its distance to its
/// `EDGE_RANK`-th nearest place (other points at its own place, or at one nearer, not
/// counted): the neighbours of its own stretch of surface. Past
/// that, its [`ORIENT_NEIGHBOURS`] nearest may lie on another body across a gap (a droplet of
/// a few particles has no 16 of its own), whose normals face it and contradict its own.
pub const EDGE_RANK: usize = 6;
/// See [`EDGE_RANK`]. On a surface sampled evenly the 16th nearest lies about 1.6 times as
/// far as the 6th (√5/√2 on a square grid; on a hexagonal one twice, where 1.75 keeps the
/// first 12 rather than deciding a tie). In a clean `droplets` scene (20000 points, 200
/// droplets) the repair reversed 164 of 1663 correct normals with every edge kept, 47 with
/// a reach of 1.5, 35 with 1.75, 34 with 2 and 142 with 2.25: droplets that lie a little
/// past twice a point's 6th nearest. 1.75 stands clear of both ends.
pub const EDGE_REACH: f64 = 1.75;
/// Voting passes: each sees the repairs of the pass before (a reversed point among reversed
/// neighbours is outvoted once they are repaired).
const PASSES: usize = 3;
/// Tangent weight an edge needs to join two points into a patch or count at its border:
/// within 60° of the tangent plane.
const PATCH_WEIGHT: f64 = 0.75;
/// The largest patch reversed as a whole, as a fraction of the points, and at most this
/// fraction of the largest patch it borders: a wrong patch is a minority inside a surface;
/// the two faces of a sheet, which contradict each other across their whole border, are
/// alike in size and stay as they are.
const PATCH_FRACTION: f64 = 0.25;
const PATCH_MINORITY: f64 = 0.5;

/// A point's first-pass votes as a word, where another implementation cast them (a GPU's,
/// `PointIndex::orientation_votes`): its patch edges in the low [`ORIENT_NEIGHBOURS`] bits
/// (bit k: its k-th neighbour), and the bits below. One source for the shader that writes
/// them (`shaders/orient_votes.wgsl`).
pub mod vote_word {
    /// Its neighbours reverse its normal.
    pub const REVERSE: u32 = 1 << 16;
    /// One of its patch edges joins contradicting normals.
    pub const CONTRADICTED: u32 = 1 << 17;
    /// Rounding could have decided something: the caller casts this point's votes itself.
    pub const RECAST: u32 = 1 << 18;
    /// How near a tangent weight may lie to 0 or to the patch weight, and a dot product of
    /// two unit normals to 0, before rounding could decide it: the f32 offsets (split
    /// positions) and normals lie within about 1e-6 of f64's, relatively, and the weight is
    /// a few operations on them; a hundred times that.
    pub const WEIGHT_MARGIN: f32 = 1e-4;
    /// How near the reversal threshold a vote may lie (its ORIENT_NEIGHBOURS vote weights,
    /// each the 4th power of a weight within [`WEIGHT_MARGIN`]'s error, so within 4 times
    /// it, summed in f32) before rounding could decide it.
    pub const VOTE_MARGIN: f32 = 1e-2;
}

/// The constants the shader of first-pass votes takes from here, as WGSL.
pub fn vote_word_wgsl() -> String {
    format!(
        "const ORIENT_NEIGHBOURS: u32 = {ORIENT_NEIGHBOURS}u;\nconst NO_POINT: u32 = {NO_POINT}u;\n\
         const PATCH_WEIGHT: f32 = {PATCH_WEIGHT:?};\nconst REVERSE_BELOW: f32 = {REVERSE_BELOW:?};\n\
         const VOTE_REVERSE: u32 = {}u;\nconst VOTE_CONTRADICTED: u32 = {}u;\n\
         const VOTE_RECAST: u32 = {}u;\nconst WEIGHT_MARGIN: f32 = {:e};\n\
         const VOTE_MARGIN: f32 = {:e};\nconst VOTE_SQUARINGS: u32 = {VOTE_SQUARINGS}u;\n\
         const EDGE_RANK: u32 = {EDGE_RANK}u;\nconst EDGE_REACH: f32 = {EDGE_REACH:?};\n",
        vote_word::REVERSE,
        vote_word::CONTRADICTED,
        vote_word::RECAST,
        vote_word::WEIGHT_MARGIN,
        vote_word::VOTE_MARGIN,
    )
}

/// What the repair changed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OrientationRepair {
    /// Points whose normal ends reversed against the input, in all.
    pub flipped_points: usize,
    /// Patches reversed as a whole, and their points.
    pub flipped_patches: usize,
    pub patch_points: usize,
}

/// How much a neighbour at offset `d` counts for a normal `n`: 1 in the tangent plane, 0
/// along the normal (sin² of the angle to it), whichever way the normal points.
fn tangent_weight(n: [f64; 3], d: [f64; 3]) -> f64 {
    let dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    if dd <= 0.0 {
        return 0.0;
    }
    let along = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
    1.0 - along * along / dd
}

/// How much a neighbour of tangent weight `w` counts in a vote ([`VOTE_SQUARINGS`]).
fn vote_weight(w: f64) -> f64 {
    (0..VOTE_SQUARINGS).fold(w, |v, _| v * v)
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn neg(a: [f64; 3]) -> [f64; 3] {
    [-a[0], -a[1], -a[2]]
}

/// A point's nearest neighbours for the check, itself excluded, nearest first; `NO_POINT`
/// fills the slots a small set leaves empty.
pub type Around = [u32; ORIENT_NEIGHBOURS];
pub const NO_POINT: u32 = u32::MAX;

/// Every point's neighbours for the check, read where a nearest query left them (`stride`
/// ids a point, nearest first, the point itself among them or not): its first `take` others.
/// Read in place, point by point: an array of every point's [`Around`] was 64 bytes a point
/// of fresh memory, 256 MB at 4M points, that most steps never read again.
#[derive(Debug, Clone, Copy)]
pub struct NearestIds<'a> {
    ids: &'a [u32],
    stride: usize,
    take: usize,
}

impl<'a> NearestIds<'a> {
    /// `ids` holds `stride` ids a point (`stride` > 0); `take` is at most
    /// [`ORIENT_NEIGHBOURS`].
    pub fn new(ids: &'a [u32], stride: usize, take: usize) -> NearestIds<'a> {
        NearestIds {
            ids,
            stride: stride.max(1),
            take: take.min(ORIENT_NEIGHBOURS),
        }
    }

    /// Points.
    pub fn len(&self) -> usize {
        self.ids.len() / self.stride
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Ids a point, as the query left them.
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// The most others of a point the check takes.
    pub fn take(&self) -> usize {
        self.take
    }

    /// Point `i`'s neighbours for the check, `NO_POINT` past the last.
    pub fn around(&self, i: usize) -> Around {
        let mut around = [NO_POINT; ORIENT_NEIGHBOURS];
        let others = self.ids[i * self.stride..][..self.stride]
            .iter()
            .copied()
            .filter(|&j| j as usize != i);
        for (slot, j) in around.iter_mut().zip(others.take(self.take)) {
            *slot = j;
        }
        around
    }
}

/// The weighted edges from each point to its neighbours that have normals, computed where
/// they are walked rather than stored: the weight comes from the point's input normal's
/// direction (which a reversal does not change) and the offset. A neighbour at the place of
/// one before it (a particle written twice) is that one again: it makes no edge, where it
/// would vote twice and crowd the point's other neighbours out of the vote.
struct Edges<'a> {
    points: &'a [[f64; 3]],
    original: &'a [Option<[f64; 3]>],
    nearest: NearestIds<'a>,
}

impl Edges<'_> {
    /// The edges with the slot of point `i`'s neighbours each comes from.
    fn slots(&self, i: usize) -> impl Iterator<Item = (usize, u32, f64)> + '_ {
        let own = self.original[i];
        let around = self.nearest.around(i);
        let p = self.points[i];
        // Each slot's offset, squared distance, and whether it lies at the place of one before
        // it (a twin). Points at one place are at one distance, and the nearest come nearest
        // first, so a twin lies among the slots just before it at its distance (where the
        // order came from f32 distances, an f32 tie between two places could stand between
        // them, and then both count).
        let mut offset = [[0.0; 3]; ORIENT_NEIGHBOURS];
        let mut distance2 = [f64::NAN; ORIENT_NEIGHBOURS];
        let mut twin = [false; ORIENT_NEIGHBOURS];
        if own.is_some() {
            for (k, &j) in around.iter().enumerate() {
                if j == NO_POINT {
                    continue;
                }
                let q = self.points[j as usize];
                let d = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
                let dd = dot(d, d);
                (offset[k], distance2[k]) = (d, dd);
                twin[k] = (0..k)
                    .rev()
                    .take_while(|&m| distance2[m] == dd)
                    .any(|m| self.points[around[m] as usize] == q);
            }
        }
        // The reach of its edges, from the EDGE_RANK-th slot at a place of its own, not the
        // point's; fewer such (a step of a few points): no stretch of surface, no edges.
        let reach2 = (0..ORIENT_NEIGHBOURS)
            .filter(|&k| distance2[k] > 0.0 && !twin[k])
            .nth(EDGE_RANK - 1)
            .map_or(f64::NEG_INFINITY, |k| {
                EDGE_REACH * EDGE_REACH * distance2[k]
            });
        (0..ORIENT_NEIGHBOURS).filter_map(move |k| {
            let own = own?;
            let j = around[k];
            if j == NO_POINT
                || twin[k]
                || distance2[k] > reach2
                || self.original[j as usize].is_none()
            {
                return None;
            }
            let w = tangent_weight(own, offset[k]);
            (w > 0.0).then_some((k, j, w))
        })
    }
}

/// Repairs `normals` (unit or `None`) of `points`, given each point's nearest neighbours and,
/// where another implementation cast them, the first pass's votes ([`vote_word`]): those not
/// marked [`vote_word::RECAST`] are taken as they are, the others cast here. The result is
/// the same either way.
pub fn repair_orientation(
    points: &[[f64; 3]],
    normals: &mut [Option<[f64; 3]>],
    nearest: NearestIds<'_>,
    first_votes: Option<&[u32]>,
) -> OrientationRepair {
    let n = points.len();
    let given = first_votes.filter(|v| v.len() == n);
    // The first pass, over the normals as given. Where it reverses none and no patch edge
    // contradicts (clean data: most steps), nothing changes, and the input's copy that the
    // later passes weigh their edges by is never made: at 4M points its 128 MB of fresh
    // memory took longer than the rest of the repair. The first pass's patch edges serve the
    // patch step (their weights come from the input's normals, which no pass changes), and
    // where the votes were given, whether one of them contradicts.
    let (mut reverse, strong, mut known_contradicted) = {
        let edges = Edges {
            points,
            original: normals,
            nearest,
        };
        let (reverse, strong, known) = cast_pass(&edges, normals, given);
        if reverse.par_iter().any(|&r| r) {
            (reverse, strong, known)
        } else {
            let contradicted = known.unwrap_or_else(|| any_contradicted(normals, &edges, &strong));
            if !contradicted {
                return OrientationRepair::default();
            }
            (reverse, strong, Some(true))
        }
    };
    let original: Vec<Option<[f64; 3]>> = normals.par_iter().copied().collect();
    let edges = Edges {
        points,
        original: &original,
        nearest,
    };
    let mut reversed_any = false;
    for pass in 1..=PASSES {
        if !reverse.par_iter().any(|&r| r) {
            break;
        }
        reversed_any = true;
        for (normal, &r) in normals.iter_mut().zip(&reverse) {
            if r {
                *normal = normal.map(neg);
            }
        }
        if pass == PASSES {
            break;
        }
        reverse = cast_pass(&edges, normals, None).0;
    }
    if reversed_any {
        known_contradicted = None;
    }
    let (patches, points_in) =
        reverse_contradicted_patches(normals, &edges, &strong, known_contradicted);
    // Nothing reversed leaves every normal as it came.
    let flipped_points = if reversed_any || patches > 0 {
        normals
            .par_iter()
            .zip(&original)
            .filter(|(now, was)| matches!((now, was), (Some(a), Some(b)) if dot(*a, *b) < 0.0))
            .count()
    } else {
        0
    };
    OrientationRepair {
        flipped_points,
        flipped_patches: patches,
        patch_points: points_in,
    }
}

/// One voting pass over `current`: which normals their neighbours reverse, each point's
/// patch edges (tangent weight ≥ `PATCH_WEIGHT`; bit k: its k-th neighbour), and, where the
/// votes are `given` (another implementation's first pass) and cast here for none, whether a
/// patch edge joins contradicting normals.
fn cast_pass(
    edges: &Edges,
    current: &[Option<[f64; 3]>],
    given: Option<&[u32]>,
) -> (Vec<bool>, Vec<u32>, Option<bool>) {
    let cast = |i: usize| -> (bool, u32) {
        let Some(ni) = current[i] else {
            return (false, 0);
        };
        let (mut vote, mut total, mut mask) = (0.0, 0.0, 0u32);
        for (k, j, w) in edges.slots(i) {
            if w >= PATCH_WEIGHT {
                mask |= 1 << k;
            }
            if let Some(nj) = current[j as usize] {
                let weight = vote_weight(w);
                vote += weight * dot(ni, nj).signum();
                total += weight;
            }
        }
        (total > 0.0 && vote < -REVERSE_BELOW * total, mask)
    };
    match given {
        Some(words) => {
            // A point cast here may have a contradicted patch edge the word does not say.
            let recast_any = words.par_iter().any(|w| w & vote_word::RECAST != 0);
            let known =
                (!recast_any).then(|| words.par_iter().any(|w| w & vote_word::CONTRADICTED != 0));
            let (reverse, masks) = words
                .par_iter()
                .enumerate()
                .map(|(i, &w)| {
                    if w & vote_word::RECAST != 0 {
                        cast(i)
                    } else {
                        (
                            w & vote_word::REVERSE != 0,
                            w & ((1 << ORIENT_NEIGHBOURS) - 1),
                        )
                    }
                })
                .unzip();
            (reverse, masks, known)
        }
        None => {
            let (reverse, masks) = (0..current.len()).into_par_iter().map(cast).unzip();
            (reverse, masks, None)
        }
    }
}

/// Point `i`'s patch edges: the neighbours its `strong` bits name.
fn strong_of<'a>(edges: &'a Edges, strong: &'a [u32], i: usize) -> impl Iterator<Item = u32> + 'a {
    let (mask, around) = (strong[i], edges.nearest.around(i));
    (0..ORIENT_NEIGHBOURS)
        .filter(move |k| mask >> k & 1 == 1)
        .map(move |k| around[k])
}

/// Whether the normals at the two ends of an edge agree (a point without one agrees).
fn agree(normals: &[Option<[f64; 3]>], i: usize, j: usize) -> bool {
    match (normals[i], normals[j]) {
        (Some(a), Some(b)) => dot(a, b) >= 0.0,
        _ => true,
    }
}

/// Whether some patch edge joins contradicting normals. Agreeing patch edges join patches, so
/// a patch's border is made of contradicting ones: where none contradicts, no patch has a
/// border and none is reversed.
fn any_contradicted(normals: &[Option<[f64; 3]>], edges: &Edges, strong: &[u32]) -> bool {
    (0..normals.len())
        .into_par_iter()
        .any(|i| strong_of(edges, strong, i).any(|j| !agree(normals, i, j as usize)))
}

/// Patches: points joined by tangent edges whose normals agree. A patch of at most
/// `PATCH_FRACTION` of the points whose border edges all contradict it is reversed. `strong`:
/// each point's patch edges (bit k: its k-th neighbour's); `contradicted`, whether one of
/// them joins contradicting normals, where that is known already.
fn reverse_contradicted_patches(
    normals: &mut [Option<[f64; 3]>],
    edges: &Edges,
    strong: &[u32],
    contradicted: Option<bool>,
) -> (usize, usize) {
    let contradicted = contradicted.unwrap_or_else(|| any_contradicted(normals, edges, strong));
    if !contradicted {
        return (0, 0);
    }
    let n = normals.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn root(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            parent[i as usize] = parent[parent[i as usize] as usize];
            i = parent[i as usize];
        }
        i
    }
    for i in 0..n {
        for j in strong_of(edges, strong, i) {
            if agree(normals, i, j as usize) {
                let (a, b) = (root(&mut parent, i as u32), root(&mut parent, j));
                if a != b {
                    parent[a.max(b) as usize] = a.min(b);
                }
            }
        }
    }
    let roots: Vec<u32> = (0..n as u32).map(|i| root(&mut parent, i)).collect();
    let mut size = vec![0usize; n];
    for (i, &r) in roots.iter().enumerate() {
        size[r as usize] += usize::from(normals[i].is_some());
    }
    // Border edges of each patch: how many, how many agree across it, and the largest patch
    // across it.
    let mut border = vec![(0usize, 0usize, 0usize); n];
    for i in 0..n {
        if normals[i].is_none() {
            continue;
        }
        for j in strong_of(edges, strong, i) {
            let (ri, rj) = (roots[i] as usize, roots[j as usize] as usize);
            if rj != ri {
                let b = &mut border[ri];
                b.0 += 1;
                b.1 += usize::from(agree(normals, i, j as usize));
                b.2 = b.2.max(size[rj]);
            }
        }
    }
    let largest = ((n as f64 * PATCH_FRACTION) as usize).max(1);
    let reversed: Vec<bool> = (0..n)
        .map(|r| {
            let (edges, agreeing, beside) = border[r];
            size[r] > 0
                && size[r] <= largest
                && (size[r] as f64) <= PATCH_MINORITY * beside as f64
                && edges > 0
                && agreeing == 0
        })
        .collect();
    let (mut patches, mut points_in) = (0, 0);
    for r in 0..n {
        if reversed[r] {
            patches += 1;
            points_in += size[r];
        }
    }
    for (i, normal) in normals.iter_mut().enumerate() {
        if reversed[roots[i] as usize] {
            *normal = normal.map(neg);
        }
    }
    (patches, points_in)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ids a point the grids' nearest queries find: the point and its check's neighbours.
    const STRIDE: usize = ORIENT_NEIGHBOURS + 1;

    /// A `side`×`side` plane grid and each point's nearest ([`STRIDE`] a point, itself
    /// among them).
    fn grid(side: usize) -> (Vec<[f64; 3]>, Vec<u32>) {
        let points: Vec<[f64; 3]> = (0..side * side)
            .map(|k| [(k % side) as f64, (k / side) as f64, 0.0])
            .collect();
        let tree: kiddo::ImmutableKdTree<f64, 3> =
            kiddo::ImmutableKdTree::new_from_slice(&points).unwrap();
        let nearest: Vec<u32> = points
            .iter()
            .flat_map(|p| {
                tree.query(p)
                    .nearest_n::<kiddo::SquaredEuclidean<f64>>(
                        std::num::NonZero::new(STRIDE).unwrap(),
                    )
                    .execute()
                    .into_iter()
                    .map(|r| r.item)
            })
            .collect();
        (points, nearest)
    }

    fn view(nearest: &[u32]) -> NearestIds<'_> {
        NearestIds::new(nearest, STRIDE, ORIENT_NEIGHBOURS)
    }

    /// A point's neighbours leave the point out wherever the query put it, keep the order,
    /// stop at `take`, and end in `NO_POINT` where too few are left.
    #[test]
    fn a_points_neighbours_leave_it_out_wherever_it_lies() {
        let ids = [7, 0, 3, 1, 5, 1, 9, 4];
        let nearest = NearestIds::new(&ids, 4, 2);
        assert_eq!(nearest.len(), 2);
        assert_eq!(nearest.around(0)[..3], [7, 3, NO_POINT]);
        assert_eq!(nearest.around(1)[..3], [5, 9, NO_POINT]);
        let all = NearestIds::new(&ids, 4, ORIENT_NEIGHBOURS);
        assert_eq!(all.around(1)[..4], [5, 9, 4, NO_POINT]);
    }

    /// Every point's nearest by brute force, `STRIDE` a point, itself among them; `NO_POINT`
    /// past the last.
    fn brute_nearest(points: &[[f64; 3]]) -> Vec<u32> {
        crate::search::brute_force_nearest(points, STRIDE)
            .into_iter()
            .flat_map(|mut ids| {
                ids.resize(STRIDE, NO_POINT);
                ids
            })
            .collect()
    }

    /// A point with five neighbours that agree with its normal and one, nearer, that
    /// contradicts it but was written eight times: the eight are one neighbour and vote
    /// once, so the point keeps its normal (counted eight times, they reversed it: 5 for,
    /// 8 against). The eight, whose other neighbours all contradict them, are reversed.
    #[test]
    fn a_neighbour_written_twice_votes_once() {
        let mut points = vec![[0.0, 0.0, 0.0]];
        let mut normals = vec![Some([0.0, 0.0, 1.0])];
        for a in 0..5 {
            let t = f64::from(a) * std::f64::consts::TAU / 5.0;
            points.push([t.cos(), t.sin(), 0.0]);
            normals.push(Some([0.0, 0.0, 1.0]));
        }
        for _ in 0..8 {
            points.push([0.6, 0.3, 0.0]);
            normals.push(Some([0.0, 0.0, -1.0]));
        }
        let ids = brute_nearest(&points);
        let edges = Edges {
            points: &points,
            original: &normals,
            nearest: view(&ids),
        };
        assert_eq!(edges.slots(0).count(), 6, "the eight make one edge");
        // A copy's twins lie at its own place: no edge either.
        assert_eq!(edges.slots(6).count(), 6);
        let (reverse, _, _) = cast_pass(&edges, &normals, None);
        assert!(!reverse[0], "the point's vote: 5 for, 1 against");
        assert!(reverse[6..].iter().all(|&r| r), "{reverse:?}");
        assert!(!reverse[1..6].iter().any(|&r| r), "{reverse:?}");
    }

    /// A plane grid with normals +z, some reversed singly and one 5×5 patch reversed.
    #[test]
    fn single_reversals_and_a_patch_are_repaired() {
        let side = 40usize;
        let (points, nearest) = grid(side);
        let mut normals: Vec<Option<[f64; 3]>> = vec![Some([0.0, 0.0, 1.0]); points.len()];
        let singles = [5 * side + 5, 20 * side + 31, 33 * side + 2];
        for &i in &singles {
            normals[i] = Some([0.0, 0.0, -1.0]);
        }
        let patch: Vec<usize> = (0..25).map(|k| (10 + k / 5) * side + 20 + k % 5).collect();
        for &i in &patch {
            normals[i] = Some([0.0, 0.0, -1.0]);
        }
        let repair = repair_orientation(&points, &mut normals, view(&nearest), None);
        assert!(normals.iter().all(|n| *n == Some([0.0, 0.0, 1.0])));
        assert_eq!(repair.flipped_points, singles.len() + patch.len());
        // Votes wear the patch down from its corners; what is left goes back whole.
        assert_eq!(repair.flipped_patches, 1, "{repair:?}");
    }

    /// A reversed band across the grid that no vote reverses (its border points' neighbours
    /// lie half inside): the first pass changes nothing, yet the patch step must run and
    /// reverse the band whole; and a clean grid comes back as it was.
    #[test]
    fn a_patch_no_vote_reverses_is_repaired() {
        let side = 40usize;
        let (points, nearest) = grid(side);
        let up = Some([0.0, 0.0, 1.0]);
        let mut normals: Vec<Option<[f64; 3]>> = vec![up; points.len()];
        let band: Vec<usize> = (17 * side..23 * side).collect();
        for &i in &band {
            normals[i] = Some([0.0, 0.0, -1.0]);
        }
        let edges = Edges {
            points: &points,
            original: &normals,
            nearest: view(&nearest),
        };
        let (reverse, _, _) = cast_pass(&edges, &normals, None);
        assert!(
            !reverse.iter().any(|&r| r),
            "the first pass reverses {} points",
            reverse.iter().filter(|&&r| r).count()
        );
        let repair = repair_orientation(&points, &mut normals, view(&nearest), None);
        assert!(normals.iter().all(|n| *n == up), "{repair:?}");
        assert_eq!(
            repair,
            OrientationRepair {
                flipped_points: band.len(),
                flipped_patches: 1,
                patch_points: band.len(),
            }
        );
        let clean = repair_orientation(&points, &mut normals, view(&nearest), None);
        assert_eq!(clean, OrientationRepair::default());
        assert!(normals.iter().all(|n| *n == up));
    }
}
