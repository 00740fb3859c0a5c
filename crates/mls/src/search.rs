//! Where a build finds each point's nearest points and its neighbour lists: a kiddo k-d tree
//! on the CPU (the reference), or any other implementation that returns the same sets where
//! no two distances tie (`docs/algorithm.md`, "Neighbour search"), such as the GPU's
//! (`slosh-gpubake`).

use std::num::NonZero;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

use crate::error::SurfaceError;
use crate::found::NeighbourLists;
use crate::lists::neighbour_lists;
use crate::orient::NearestIds;
use crate::support::NormalsMode;

/// The initial fits a search may compute with the lists, where the lists already sit where it
/// computes (the GPU's): at each point, over its list, as `intersect::initial_fit_with`.
#[derive(Clone, Copy)]
pub struct FitRequest<'a> {
    /// Each point's smoothing length.
    pub h: &'a (dyn Fn(usize) -> f64 + Sync),
    pub degree: u8,
    pub normals: NormalsMode,
}

impl std::fmt::Debug for FitRequest<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FitRequest")
            .field("degree", &self.degree)
            .field("normals", &self.normals)
            .finish()
    }
}

/// What a neighbour list keeps beyond the reach and the cap: its links and the normals that
/// oppose; and the initial fits, where the search can make them.
#[derive(Clone, Copy)]
pub struct ListRequest<'a> {
    /// How far each point's list reaches (ρ_i + support·h_i).
    pub reach: &'a [f64],
    /// At most this many neighbours per point, the nearest by (d², index).
    pub cap: usize,
    /// Unit data normals: a neighbour whose normal opposes the point's is left out.
    pub normals: Option<&'a [Option<[f64; 3]>]>,
    /// The squared link distance of each point, where links (pairs within it) are wanted.
    pub link_distance2: Option<&'a (dyn Fn(usize) -> f64 + Sync)>,
    /// The initial fits, which a search makes only where it can make them beside the lists
    /// (then `NeighbourLists::fits`); the build fits the rest itself.
    pub fits: Option<FitRequest<'a>>,
    /// Where set, a search that makes the run unions, the fits and the links' components
    /// itself may keep of each list only the members within this distance of its reach
    /// ([`KeptLists::NearReach`](crate::KeptLists)), rather than every list: a bake's, which
    /// stores the unions and measures each list's reach on those members alone.
    pub near_reach_band: Option<f64>,
}

impl std::fmt::Debug for ListRequest<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ListRequest")
            .field("points", &self.reach.len())
            .field("cap", &self.cap)
            .field("normals", &self.normals.is_some())
            .field("links", &self.link_distance2.is_some())
            .field("fits", &self.fits.map(|f| f.degree))
            .field("near_reach_band", &self.near_reach_band)
            .finish()
    }
}

/// A neighbour search over one point set, made by [`NeighbourSearch::index`].
pub trait PointIndex {
    /// For every point, its `count` nearest points (itself among them), nearest first and
    /// equal distances by index, a tie at the cut going to the lower indices: point i's are
    /// `[i·count, (i + 1)·count)`. `count` is at most the number of points.
    fn nearest(&self, count: NonZero<usize>) -> Result<Vec<u32>, SurfaceError>;

    /// Every point's neighbour list (`lists.rs`: the nearest ≤ cap within reach, ties at the
    /// cut by index, minus opposing normals, in index order), the reach each records, and the
    /// links asked for.
    fn lists(&self, request: ListRequest<'_>) -> Result<NeighbourLists, SurfaceError>;

    /// The orientation check's first-pass votes (`orient.rs`, [`crate::vote_word`]) of every
    /// point, given its nearest (`nearest`: the ids of this index's last [`Self::nearest`]
    /// query) and the unit normals, where this index casts them itself (a GPU's, from the
    /// ids where its query left them); `None` where it leaves them to `repair_orientation`.
    /// No default: an index that wraps another passes them on.
    fn orientation_votes(
        &self,
        nearest: NearestIds<'_>,
        normals: &[Option<[f64; 3]>],
    ) -> Result<Option<Vec<u32>>, SurfaceError>;
}

/// A way to search point sets for neighbours, shared by the steps a bake has in flight.
pub trait NeighbourSearch: Send + Sync + std::fmt::Debug {
    /// An index over `points` (local coordinates, all finite, at least two).
    fn index<'a>(
        &'a self,
        points: &'a [[f64; 3]],
    ) -> Result<Box<dyn PointIndex + 'a>, SurfaceError>;

    /// What it runs on, for reports.
    fn describe(&self) -> String;
}

/// The reference search: a kiddo k-d tree, queried on the calling thread's rayon pool.
#[derive(Debug, Clone, Copy, Default)]
pub struct KdSearch;

struct KdIndex<'a> {
    tree: ImmutableKdTree<f64, 3>,
    points: &'a [[f64; 3]],
}

impl NeighbourSearch for KdSearch {
    fn index<'a>(
        &'a self,
        points: &'a [[f64; 3]],
    ) -> Result<Box<dyn PointIndex + 'a>, SurfaceError> {
        let tree = ImmutableKdTree::new_from_slice(points)
            .map_err(|e| SurfaceError::Index(format!("{e:?}")))?;
        Ok(Box::new(KdIndex { tree, points }))
    }

    fn describe(&self) -> String {
        "cpu (k-d tree)".into()
    }
}

impl PointIndex for KdIndex<'_> {
    /// Each point's `count` nearest in (d², index) order, a tie at the cut going to the lower
    /// indices, as the GPU's pass orders them (`shaders/nearest.wgsl`): kiddo orders equal
    /// distances, and cuts among them, as its tree happens to hold them, so that duplicates
    /// gave the orientation check other neighbours than the GPU's.
    fn nearest(&self, count: NonZero<usize>) -> Result<Vec<u32>, SurfaceError> {
        // One more than asked: whether the count-th distance ties with the next.
        let ask = count.saturating_add(1);
        let count = count.get();
        let by_distance_then_index =
            |a: &(f64, u32), b: &(f64, u32)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
        let lists: Vec<Vec<u32>> = self
            .points
            .par_iter()
            .map(|p| {
                let query = self.tree.query(p);
                let mut nn: Vec<(f64, u32)> = query
                    .nearest_n::<SquaredEuclidean<f64>>(ask)
                    .execute()
                    .iter()
                    .map(|r| (r.distance, r.item))
                    .collect();
                nn.sort_unstable_by(by_distance_then_index);
                if nn.len() > count && nn[count].0 == nn[count - 1].0 {
                    // Points tie across the cut: all of them at that distance (`within` is
                    // inclusive), the lower indices kept.
                    nn = self
                        .tree
                        .query(p)
                        .within::<SquaredEuclidean<f64>>(nn[count - 1].0)
                        .execute()
                        .iter()
                        .map(|r| (r.distance, r.item))
                        .collect();
                    nn.sort_unstable_by(by_distance_then_index);
                }
                nn.truncate(count);
                nn.into_iter().map(|(_, i)| i).collect()
            })
            .collect();
        if let Some(i) = lists.iter().position(|l| l.len() != count) {
            return Err(SurfaceError::Index(format!(
                "point {i}: {} nearest points found where {count} were asked for",
                lists[i].len()
            )));
        }
        Ok(lists.concat())
    }

    fn lists(&self, request: ListRequest<'_>) -> Result<NeighbourLists, SurfaceError> {
        Ok(neighbour_lists(
            &self.tree,
            self.points,
            request.reach,
            request.cap,
            request.normals,
            request.link_distance2,
        ))
    }

    /// The k-d tree leaves them to `repair_orientation`, which casts them in f64 itself.
    fn orientation_votes(
        &self,
        _nearest: NearestIds<'_>,
        _normals: &[Option<[f64; 3]>],
    ) -> Result<Option<Vec<u32>>, SurfaceError> {
        Ok(None)
    }
}

/// Each point's nearest by brute force, for tests: (d², index) order, itself among them,
/// the first `count` (all where there are fewer).
#[cfg(test)]
pub(crate) fn brute_force_nearest(points: &[[f64; 3]], count: usize) -> Vec<Vec<u32>> {
    points
        .iter()
        .map(|p| {
            let mut all: Vec<(f64, u32)> = points
                .iter()
                .enumerate()
                .map(|(j, q)| (crate::lists::distance2(*p, *q), j as u32))
                .collect();
            all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            all.into_iter().take(count).map(|(_, j)| j).collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distances that tie, within a point's nearest and across the cut (every point written
    /// three times, on a lattice whose spacing binary holds exactly), come in index order,
    /// the lower indices kept: kiddo alone gave 4914 of these 6000 points another set.
    #[test]
    fn ties_go_by_index_within_and_across_the_cut() {
        let mut points = Vec::new();
        for _copy in 0..3 {
            for i in 0..2000 {
                points.push([(i % 50) as f64 * 0.25, (i / 50) as f64 * 0.5, 0.0]);
            }
        }
        let index = KdSearch.index(&points).unwrap();
        for count in [1, 7, 17] {
            let found = index.nearest(NonZero::new(count).unwrap()).unwrap();
            assert!(
                found == brute_force_nearest(&points, count).concat(),
                "{count} nearest"
            );
        }
    }
}
