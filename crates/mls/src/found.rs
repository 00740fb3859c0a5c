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

/// Every point's neighbour list (CSR), the reach each list records, how many lists the cap
/// cut, the union of each run's lists where the runs were consecutive indices, and the links
/// asked for (per run).
#[derive(Debug)]
pub struct NeighbourLists {
    pub lists: Neighbours,
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
    /// bake's stage laps after its "neighbour lists"; empty where the search does not say.
    pub parts: Vec<(&'static str, f64)>,
}
