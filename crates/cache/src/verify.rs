//! Full verification of a step file: the footer checksum over every byte, each section's
//! checksum and decoding, and the structural invariants the tracer relies on.

use rayon::prelude::*;

use crate::ball_state::{BALLS_PER_STATE_WORD, exact_half};
use crate::error::{Error, Result};
use crate::format::SectionEntry;
use crate::layout::{BallState, Element, GpuPoint, GpuSphere, MIN_NORMAL_HALF};
use crate::names;
use crate::reader::CacheFile;

/// Sections that `check_invariants` decodes.
const STRUCTURAL: [&str; 6] = [
    names::POINTS,
    names::BALLS,
    names::SPHERES,
    names::CLUSTER_START,
    names::CLUSTER_NEIGHBOURS,
    names::BVH_NODES,
];

/// What a successful verification covered.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VerifyReport {
    pub sections: usize,
    pub raw_bytes: u64,
}

impl CacheFile {
    pub fn verify(&self) -> Result<VerifyReport> {
        let invalid = |problem: String| Error::Invalid {
            path: self.path().to_path_buf(),
            problem,
        };
        if !self.body_intact() {
            self.unchanged()?;
            return Err(invalid(
                "the footer checksum does not match the file's bytes (corrupt or modified)".into(),
            ));
        }
        // The invariant checks decode (and so checksum) the structural sections; the rest are
        // decoded here, so that no section is decoded twice.
        if let Err(problem) = self.check_invariants() {
            // A file that changed under its map fails its checks; said as what happened.
            self.unchanged()?;
            return Err(invalid(problem));
        }
        for entry in &self.header().sections {
            // Chunked sections are decoded against their chunks' checksums; the section's
            // own checksum is checked too.
            if !entry.chunks.is_empty() {
                self.check_sum(entry, "section", 0, self.stored(entry), &entry.xxh3)?;
            }
            if let Some(field) = entry.name.strip_prefix(names::FIELD_PREFIX) {
                // Decoded whole, for the ranges its header records.
                self.check_field_ranges(entry, field)
                    .map_err(|problem| invalid(format!("field '{field}': {problem}")))?;
            } else if !STRUCTURAL.contains(&entry.name.as_str()) {
                self.check_decodes(entry)?;
            }
        }
        // A file that shrank under its map read zeros somewhere above.
        self.unchanged()?;
        Ok(VerifyReport {
            sections: self.header().sections.len(),
            raw_bytes: self.header().sections.iter().map(|s| s.raw).sum(),
        })
    }

    /// Field `field`'s section decodes, and each of its views' ranges is the header's (a step
    /// of format 9.0, whose header records none for any field, is not asked).
    fn check_field_ranges(&self, entry: &SectionEntry, field: &str) -> Result<(), String> {
        let mut bytes = vec![0u8; entry.raw as usize];
        self.decode_into(entry, &mut bytes, &mut Vec::new())
            .map_err(|e| e.to_string())?;
        let recorded = &self.header().field_ranges;
        if recorded.is_empty() {
            return Ok(());
        }
        let element = Element::from_name(&entry.element)
            .ok_or_else(|| format!("an element '{}' no field has", entry.element))?;
        let found = crate::field_view_ranges(field, element, &bytes);
        for view in crate::views_of(field, element) {
            let want = found.iter().find(|(v, _)| *v == view).map(|(_, r)| *r);
            let have = recorded.get(&view).copied();
            if want != have {
                return Err(format!(
                    "the header records the range of '{view}' as {have:?}, its values span {want:?}"
                ));
            }
        }
        Ok(())
    }

    fn check_invariants(&self) -> Result<(), String> {
        let header = self.header();
        let n = header.points as usize;
        // Reported under the file's path by the caller, as `Error::Section` would be.
        let decode_err = |e: Error| match e {
            Error::Section {
                section,
                offset,
                problem,
                ..
            } => format!("section '{section}' (at byte {offset}): {problem}"),
            // The file's path is said once, by the caller.
            Error::Invalid { problem, .. } => problem,
            other => other.to_string(),
        };
        let points: Vec<GpuPoint> = self.decode(names::POINTS).map_err(decode_err)?;
        let balls = self.balls().map_err(decode_err)?;
        let cubic = self.cubic_words().map_err(decode_err)?;
        let spheres: Vec<GpuSphere> = self.decode(names::SPHERES).map_err(decode_err)?;
        let start: Vec<u32> = self.decode(names::CLUSTER_START).map_err(decode_err)?;
        // The cluster lists are checked as the runs they are stored as: expanded, a 1M-point
        // step's were 44 MB made for the check alone.
        let (base, words) = self.cluster_words().map_err(decode_err)?;
        let lists = self.packed_lists(&start, &base, &words);
        lists
            .check()
            .map_err(|problem| decode_err(self.lists_error(problem)))?;
        let size = header.neighbour_cluster as usize;
        if size == 0 {
            return Err("the neighbour cluster size is 0".into());
        }
        let clusters = n.div_ceil(size);
        let bvh = self.bvh().map_err(decode_err)?;
        if points.len() != n || balls.len() != n || start.len() != clusters + 1 {
            return Err(format!(
                "the header says {n} points in {clusters} clusters; sections hold {} points, {} \
                 balls, {} cluster offsets",
                points.len(),
                balls.len(),
                start.len()
            ));
        }
        for entry in &header.sections {
            let per_point =
                entry.name == names::NORMALS || entry.name.starts_with(names::FIELD_PREFIX);
            if per_point && entry.count != n as u64 {
                return Err(format!(
                    "section '{}' has {} elements for {n} points",
                    entry.name, entry.count
                ));
            }
        }
        // The per-element checks run in parallel and report the first offender, as a serial
        // scan would: at 1M points they were a tenth of a second on one core after every bake.
        // Radius and reach are normal half floats (the shaders may flush subnormals), the
        // radius positive; `normal_half` holds for both.
        let normal_half = |x: f32| x.is_finite() && x >= MIN_NORMAL_HALF;
        if let Some(i) = first_where(points.len(), |i| {
            let p = &points[i];
            !(p.position.iter().all(|c| c.is_finite())
                && normal_half(p.radius())
                && normal_half(p.reach()))
        }) {
            let p = points[i];
            return Err(format!(
                "point {i} is not finite or has a radius ({}) or reach ({}) that is not a \
                 positive normal half float",
                p.radius(),
                p.reach()
            ));
        }
        // Monotone from 0, the offsets end at the candidates' count, which the runs hold.
        if start.first() != Some(&0) || start.windows(2).any(|w| w[0] > w[1]) {
            return Err("cluster offsets are not monotone from 0 to the list length".into());
        }
        if let Some(i) = lists.first_unsorted(n) {
            return Err(format!(
                "the candidate list of cluster {i} is not sorted, distinct and in range"
            ));
        }
        // A step without particles has no h.
        let global_h = !header.mls.per_point_h && n > 0;
        if global_h && exact_half(header.smoothing_length as f32).is_none() {
            return Err(format!(
                "the header's h ({}) is not a positive normal half float",
                header.smoothing_length
            ));
        }
        if let Some(i) = first_where(balls.len().min(cubic.len()), |i| {
            let (b, cubic) = (&balls[i], cubic[i]);
            // Finite, and no subnormal half float (a GPU may flush those); h a positive
            // normal half float; a droplet member's sphere in range, its other coefficient
            // words zero.
            let finite = b
                .coeffs(cubic)
                .iter()
                .all(|c| c.is_finite() && (*c == 0.0 || c.abs() >= MIN_NORMAL_HALF))
                && exact_half(b.h).is_some();
            let sphere_ok = match b.sphere() {
                Some(s) => (s as usize) < spheres.len() && b.ball.coeffs[1..] == [0, 0],
                None => true,
            };
            // A candidate, and only a candidate, has a normal (the trace walk tests the
            // ball alone); a full fit has the degree asked for.
            let candidate = matches!(b.kind(), BallState::Full | BallState::Degraded);
            let normal_ok = b.ball.is_candidate() == candidate;
            let degree_ok = b.kind() != BallState::Full || b.degree() == header.mls.degree;
            !finite || !sphere_ok || !normal_ok || !degree_ok
        }) {
            return Err(format!("ball {i} is invalid: {:?}", balls[i]));
        }
        // The renderers draw every ball at the header's degree where it counts none degraded.
        let degraded = balls
            .iter()
            .filter(|b| b.kind() == BallState::Degraded)
            .count() as u64;
        if degraded != header.stats.fit_degraded {
            return Err(format!(
                "{degraded} balls are degraded; the header counts {}",
                header.stats.fit_degraded
            ));
        }
        // The places of `ball_states` and `ball_h` past the last ball hold nothing.
        let unused = |name: &str, per_word: usize, bits: usize| -> Result<(), String> {
            let Some(entry) = self.section(name) else {
                return Ok(());
            };
            let used = n % per_word;
            let words: Vec<u32> = self.decode(&entry.name).map_err(decode_err)?;
            match words.last() {
                Some(&w) if used > 0 && w >> (bits * used) != 0 => Err(format!(
                    "section '{name}' sets bits past its last ball ({w:#010x})"
                )),
                _ => Ok(()),
            }
        };
        unused(names::BALL_STATES, BALLS_PER_STATE_WORD, 4)?;
        unused(names::BALL_H, 2, 16)?;
        if let Some(d) = spheres
            .iter()
            .position(|s| !(s.centre.iter().all(|c| c.is_finite()) && s.radius > 0.0))
        {
            return Err(format!(
                "droplet sphere {d} is not finite or has no positive radius"
            ));
        }
        // Every candidate (fitted ball or sphere) is in exactly one leaf's range; a range may
        // also cover balls that are not candidates, which the walk skips.
        let depth = bvh
            .depth()
            .ok_or("the BVH's child links leave the node array or are not a tree")?;
        if depth as u64 > crate::MAX_BVH_DEPTH {
            return Err(format!(
                "the BVH is {depth} levels deep; the tracer walks at most {}",
                crate::MAX_BVH_DEPTH
            ));
        }
        let grid = header.bvh_grid;
        if !grid.is_valid() {
            return Err(format!(
                "the BVH's grid {grid:?} is not finite with power-of-two steps"
            ));
        }
        let items = n + spheres.len();
        // A serial scan of the nodes would report the first node with a problem: its box, its
        // children's place or its range (first), an item another leaf holds (then), an item
        // outside its box (last). The items' leaves are marked in one pass, which notes the
        // first overlap; every node is checked in parallel, and the earliest problem by
        // (node, order) is reported: a scan with every check took 37 ms of a 1M verify.
        let leaf_range = |node: &crate::bvh::BvhNode| {
            node.first as usize..node.first as usize + node.count as usize
        };
        let mut seen = vec![false; items];
        let mut overlap: Option<(usize, String)> = None;
        for (k, node) in bvh.nodes.iter().enumerate() {
            if node.count == 0 {
                continue;
            }
            let range = leaf_range(node);
            let Some(leaf) = seen.get_mut(range.clone()) else {
                continue;
            };
            if let Some(j) = leaf.iter().position(|&s| s) {
                overlap = Some((k, format!("BVH item {} is in two leaves", range.start + j)));
                break;
            }
            leaf.fill(true);
        }
        let node_problem = |k: usize| -> Option<(usize, u8, String)> {
            let node = &bvh.nodes[k];
            if !(node.lo.iter().chain(&node.hi).all(|c| c.is_finite()))
                || (0..3).any(|a| node.lo[a] > node.hi[a])
            {
                return Some((k, 0, format!("a BVH node has an invalid box: {node:?}")));
            }
            if node.count == 0 {
                // The tracer walks down only (its descent has no loop guard).
                return (node.first as usize <= k).then(|| {
                    (
                        k,
                        0,
                        format!(
                            "BVH node {k} has children {} and {}: children must follow their \
                             parent",
                            node.first,
                            node.first + 1
                        ),
                    )
                });
            }
            // A leaf is a range of items (at most `MAX_LEAF_RANGE`, which its four bits of
            // count hold); the balls in it that are not candidates are skipped by the walk,
            // but no item belongs to two leaves.
            let range = leaf_range(node);
            if range.end > items {
                return Some((
                    k,
                    0,
                    format!(
                        "a BVH leaf holds items {}..{} of {items}",
                        range.start, range.end
                    ),
                ));
            }
            // The leaf's box holds the balls and spheres the walk tests in it (a box that
            // does not would hide them: a wrong picture, not an error), to within an f32
            // rounding of the stored centres.
            let held = |centre: [f32; 3], radius: f32| {
                (0..3).all(|a| {
                    let slack = 4.0 * f32::EPSILON * (centre[a].abs() + radius);
                    node.lo[a] <= centre[a] - radius + slack
                        && node.hi[a] >= centre[a] + radius - slack
                })
            };
            range
                .into_iter()
                .find(|&item| match item.checked_sub(n) {
                    Some(d) => !held(spheres[d].centre, spheres[d].radius),
                    None => {
                        matches!(balls[item].kind(), BallState::Full | BallState::Degraded)
                            && !held(points[item].position, points[item].radius())
                    }
                })
                .map(|item| {
                    (
                        k,
                        2,
                        format!(
                            "BVH item {item} lies outside its leaf's box {:?} .. {:?}",
                            node.lo, node.hi
                        ),
                    )
                })
        };
        let first_problem = first_map(bvh.nodes.len(), node_problem);
        let overlap = overlap.map(|(k, problem)| (k, 1, problem));
        if let Some((_, _, problem)) = first_problem
            .into_iter()
            .chain(overlap)
            .min_by_key(|p| (p.0, p.1))
        {
            return Err(problem);
        }
        if let Some(i) = first_where(balls.len().min(seen.len()), |i| {
            !seen[i] && matches!(balls[i].kind(), BallState::Full | BallState::Degraded)
        }) {
            return Err(format!(
                "ball {i} ({:?}) is missing from the BVH",
                balls[i].kind()
            ));
        }
        if let Some(d) = seen[n..].iter().position(|s| !s) {
            return Err(format!("droplet sphere {d} is missing from the BVH"));
        }
        Ok(())
    }
}

/// Elements a parallel check hands each task at once. rayon's first-match search reads its
/// shared "found" flag for every element it is given; by chunks it reads it once a chunk. Its
/// consumer and plumbing were 28 % of the samples of a one-core verify of a 1M-point step,
/// and by chunks `slosh inspect DIR --verify` of that step took 15 % less time.
const CHECK_CHUNK: usize = 4096;

/// `f` of the first index below `len` where it is `Some`, as a serial scan would find it,
/// checked in parallel by chunks of [`CHECK_CHUNK`].
fn first_map<T: Send>(len: usize, f: impl Fn(usize) -> Option<T> + Sync) -> Option<T> {
    (0..len.div_ceil(CHECK_CHUNK))
        .into_par_iter()
        .find_map_first(|c| (c * CHECK_CHUNK..len.min((c + 1) * CHECK_CHUNK)).find_map(&f))
}

/// The first index below `len` where `bad` holds, as a serial scan would find it.
fn first_where(len: usize, bad: impl Fn(usize) -> bool + Sync) -> Option<usize> {
    first_map(len, |i| bad(i).then_some(i))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first offender in index order, whichever chunk finishes first: offenders in
    /// several chunks, at a chunk's edges, at the very end, and none.
    #[test]
    fn chunked_checks_find_the_first_offender_as_a_scan_would() {
        let len = 10 * CHECK_CHUNK + 17;
        let scan = |bad: &dyn Fn(usize) -> bool| (0..len).find(|&i| bad(i));
        let cases: [&(dyn Fn(usize) -> bool + Sync); 5] = [
            &|i| i == 3 * CHECK_CHUNK + 5 || i == 7 * CHECK_CHUNK || i == 9 * CHECK_CHUNK + 1,
            &|i| i == CHECK_CHUNK - 1 || i == CHECK_CHUNK,
            &|i| i >= 2 * CHECK_CHUNK,
            &|i| i == len - 1,
            &|_| false,
        ];
        for (k, bad) in cases.iter().enumerate() {
            assert_eq!(first_where(len, bad), scan(bad), "case {k}");
        }
        assert_eq!(first_where(0, |_| true), None);
        assert_eq!(
            first_map(len, |i| (i % 5000 == 4999).then(|| format!("at {i}"))),
            Some("at 4999".to_string())
        );
    }
}
