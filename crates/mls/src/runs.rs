//! The runs of consecutive points the lists stage queries at once, and the union of each
//! run's lists, which clusters merge.

/// Points per query. Larger runs query farther beyond each member's reach, smaller ones query
/// more often; 16 measured fastest of 8, 16 and 32 on a 100k-point sphere (2 cores).
pub(crate) const RUN: usize = 16;

/// Runs per parallel task. A task's lists go into one buffer: with one buffer per run, the
/// tens of thousands of small allocations that a 1M-point step keeps alive grew the
/// allocator's per-thread heaps piece by piece, and 16 threads spent more time in the kernel
/// than in the runs.
pub(crate) const RUNS_PER_BLOCK: usize = 32;

/// The union of the lists of each run of [`LIST_RUN`] consecutive points (each in index order):
/// what the lists stage finds anyway, and from which the clusters of any multiple of [`LIST_RUN`]
/// points merge their candidate lists without reading every point's list again. Kept as the
/// lists stage's blocks made them (CSR per block of runs).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunUnions {
    pub(crate) runs: usize,
    pub(crate) blocks: Vec<(Vec<u32>, Vec<u32>)>,
}

impl RunUnions {
    /// How many runs.
    pub fn len(&self) -> usize {
        self.runs
    }

    pub fn is_empty(&self) -> bool {
        self.runs == 0
    }

    /// Run r's union, in index order.
    pub fn union(&self, r: usize) -> &[u32] {
        let (start, ids) = &self.blocks[r / RUNS_PER_BLOCK];
        let k = r % RUNS_PER_BLOCK;
        &ids[start[k] as usize..start[k + 1] as usize]
    }
}

/// Points per run of the lists stage (and per union in [`RunUnions`]).
pub const LIST_RUN: usize = RUN;

/// Points per block of the lists stage: one parallel task, one buffer of lists (a piece of
/// [`Neighbours`](crate::Neighbours) where the points came in spatial order) and one piece
/// of links. A search that gives its links in pieces of this many consecutive points lets the
/// spray's union-find join each piece's own links in parallel.
pub const LIST_BLOCK: usize = RUN * RUNS_PER_BLOCK;
