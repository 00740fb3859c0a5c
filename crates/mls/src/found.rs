//! What a neighbour search returns: the lists, and the initial fits where it made them.

use crate::neighbours::Neighbours;
use crate::poly::Poly;
use crate::runs::RunUnions;

/// One point's initial fit as a search computed it: `None` where there is no support plane or
/// the fit failed (the ball is never a candidate).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InitialFit {
    pub normal: [f32; 3],
    pub poly: Poly<f32>,
    pub degraded: bool,
}

/// What a search or a build kept of each point's neighbour list.
#[derive(Debug, Clone, PartialEq)]
pub enum KeptLists {
    /// Every list.
    Whole(Neighbours),
    /// Only each list's members within `band` of the reach it records (of its cut's distance,
    /// where the cap cut it), and those the cut's reach is measured on: what the reach a
    /// cache stores is measured on, where the lists themselves are in the cluster unions
    /// (`ListRequest::near_reach_band`). Each point's in index order.
    NearReach { band: f64, members: Neighbours },
}

impl KeptLists {
    /// Every list, where they were kept.
    pub fn whole(&self) -> Option<&Neighbours> {
        match self {
            KeptLists::Whole(lists) => Some(lists),
            KeptLists::NearReach { .. } => None,
        }
    }

    /// The members of point i's list that may lie farthest from it: every member, or those
    /// within the band of its reach. Whatever lies farther, in any precision within the
    /// band, is among them.
    pub fn farthest_of(&self, i: usize) -> &[u32] {
        match self {
            KeptLists::Whole(lists) => lists.of(i),
            KeptLists::NearReach { members, .. } => members.of(i),
        }
    }

    /// How many points have a list.
    pub fn len(&self) -> usize {
        match self {
            KeptLists::Whole(lists) => lists.len(),
            KeptLists::NearReach { members, .. } => members.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Every point's neighbour list (CSR), the reach each list records, how many lists the cap
/// cut, the union of each run's lists where the runs were consecutive indices, and the links
/// asked for (per run).
#[derive(Debug)]
pub struct NeighbourLists {
    pub lists: KeptLists,
    pub reach: Vec<f64>,
    pub capped: usize,
    pub run_unions: Option<RunUnions>,
    /// (i, j) for every j ≠ i in i's list within the link distance of i, in no useful order
    /// (a pair may come both ways), in pieces.
    pub links: Vec<Vec<(u32, u32)>>,
    /// Each point's spray component (points joined by the links), named by its smallest
    /// index, where the search joined the links itself; `links` may then be empty.
    pub components: Option<Vec<u32>>,
    /// Every point's initial fit, where the search made them (`ListRequest::fits`), and the
    /// seconds they took (within the call).
    pub fits: Option<Vec<Option<InitialFit>>>,
    pub fit_seconds: f64,
    /// Where the search's own time went, by part ("neighbour lists: …", seconds), for the
    /// bake's stage laps after its "neighbour lists", and the fits' parts ("initial fits: …")
    /// where it made them, which go after the fits' lap; empty where the search does not say.
    pub parts: Vec<(&'static str, f64)>,
}
