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

/// The union of the lists of each run of `run` consecutive points (each in index order): what
/// the lists stage finds anyway ([`LIST_RUN`] points a run), or what a search gives for the
/// bake's clusters (the GPU's: [`RunUnions::whole`]); from these the clusters of any multiple
/// of `run` points merge their candidate lists without reading every point's list again. Kept
/// in blocks of `per_block` runs as their maker made them (CSR per block).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunUnions {
    pub(crate) run: usize,
    pub(crate) runs: usize,
    pub(crate) per_block: usize,
    pub(crate) blocks: Vec<(Vec<u32>, Vec<u32>)>,
}

impl RunUnions {
    /// The unions of every run of `run` consecutive points of `points`, as one CSR index
    /// (`start`: one offset per run and one after; `ids`: each union sorted, each id once);
    /// `None` where they do not fit together.
    pub fn whole(run: usize, points: usize, start: Vec<u32>, ids: Vec<u32>) -> Option<RunUnions> {
        let runs = points.div_ceil(run.max(1));
        let fits = run > 0
            && start.len() == runs + 1
            && start.first() == Some(&0)
            && start.windows(2).all(|w| w[0] <= w[1])
            && start.last().map(|&s| s as usize) == Some(ids.len());
        fits.then(|| RunUnions {
            run,
            runs,
            per_block: runs.max(1),
            blocks: vec![(start, ids)],
        })
    }

    /// Points per run.
    pub fn run(&self) -> usize {
        self.run
    }

    /// How many runs.
    pub fn len(&self) -> usize {
        self.runs
    }

    pub fn is_empty(&self) -> bool {
        self.runs == 0
    }

    /// Run r's union, in index order.
    pub fn union(&self, r: usize) -> &[u32] {
        let (start, ids) = &self.blocks[r / self.per_block];
        let k = r % self.per_block;
        &ids[start[k] as usize..start[k + 1] as usize]
    }

    /// Every run's union as one CSR index, where they are kept as one (no copy).
    pub(crate) fn as_one(&self) -> Option<(&[u32], &[u32])> {
        match self.blocks.as_slice() {
            [(start, ids)] if self.per_block >= self.runs => Some((start, ids)),
            _ => None,
        }
    }
}

/// Points per run of the lists stage (and per union in [`RunUnions`]).
pub const LIST_RUN: usize = RUN;

/// Points per block of the lists stage: one parallel task, one buffer of lists (a piece of
/// [`Neighbours`](crate::Neighbours) where the points came in spatial order) and one piece
/// of links. A search that gives its links in pieces of this many consecutive points lets the
/// spray's union-find join each piece's own links in parallel.
pub const LIST_BLOCK: usize = RUN * RUNS_PER_BLOCK;
