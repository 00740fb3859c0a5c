//! The union of the lists of each of the bake's clusters, made on the GPU from each batch of
//! lists while it is there (`shaders/cluster_unions.wgsl`): the sections store those unions,
//! which the host otherwise merged from every point's list (at 1M points, most of the
//! sections stage). A cluster with an id outside the shader's bitset (its span, or its halves
//! where the ids span more) is merged here, from its members' lists alone, read back.

use rayon::prelude::*;
use slosh_mls::{Neighbours, RunUnions, SurfaceError, cluster_union, csr_pieces};

use crate::dispatch::{bind, gpu_error, output, storage, uniform, workgroup_grid};
use crate::index::GpuIndex;
use crate::layout::{ID_MASK, SPAN_WIDE, UnionParams};

/// Points per cluster: the bake's.
pub(crate) const CLUSTER: usize = slosh_mls::NEIGHBOUR_CLUSTER as usize;

/// Clusters per parallel copy of the unions into place.
const UNIONS_PER_COPY: usize = 1024;

/// The unions made so far, batch by batch.
pub(crate) struct Unions {
    /// Each cluster's union's length (0 for a wide one, whose ids are not among `ids`).
    counts: Vec<u32>,
    /// The clusters with an id outside the bitset, in order, and their unions.
    wide: Vec<usize>,
    wide_unions: Vec<Vec<u32>>,
    ids: Vec<u32>,
}

/// One batch of lists on the GPU: its points (whole clusters, but for the set's last).
pub(crate) struct UnionBatch<'b> {
    /// Where each point's list begins among all lists, on the host and on the GPU.
    pub start: &'b [u32],
    pub list_start: &'b wgpu::Buffer,
    pub lists: &'b wgpu::Buffer,
    pub list_base: u32,
    pub first: usize,
    pub last: usize,
}

impl Unions {
    pub(crate) fn new(points: usize) -> Unions {
        Unions {
            counts: Vec::with_capacity(points.div_ceil(CLUSTER)),
            wide: Vec::new(),
            wide_unions: Vec::new(),
            ids: Vec::new(),
        }
    }

    /// The unions of `batch`'s clusters, appended (waits for the GPU).
    pub(crate) fn add(
        &mut self,
        index: &GpuIndex<'_>,
        batch: UnionBatch<'_>,
    ) -> Result<(), SurfaceError> {
        let search = index.search;
        let gpu = search.gpu();
        let first_cluster = batch.first / CLUSTER;
        debug_assert_eq!(first_cluster, self.counts.len());
        let clusters = batch.last.div_ceil(CLUSTER) - first_cluster;
        if clusters == 0 {
            return Ok(());
        }
        // One workgroup per cluster.
        let (x, y) = workgroup_grid(gpu, clusters as u32);
        let row_groups = x;
        let params = |write: u32| {
            uniform(
                gpu,
                &UnionParams {
                    first_cluster: first_cluster as u32,
                    clusters: clusters as u32,
                    points: index.sorted.len() as u32,
                    size: CLUSTER as u32,
                    list_base: batch.list_base,
                    row_groups,
                    write,
                    _pad0: 0,
                },
            )
        };
        let count_bytes = clusters as u64 * 4;
        let counts = output(&search.memory, "union counts", count_bytes);
        let no_starts = output(&search.memory, "no union starts", 16);
        let no_unions = output(&search.memory, "no unions", 16);
        let pass = |write, union_start: &wgpu::Buffer, unions: &wgpu::Buffer| {
            let params = params(write);
            let group = bind(
                gpu,
                &search.unions_layout,
                &[
                    (0, &params),
                    (1, batch.list_start),
                    (2, batch.lists),
                    (3, &counts),
                    (4, union_start),
                    (5, unions),
                ],
            );
            search.run(
                "cluster unions",
                &[(&search.cluster_unions, (x, y))],
                &group,
            );
        };
        pass(0, &no_starts, &no_unions);
        let mut batch_counts: Vec<u32> = search.read_back(&counts, count_bytes)?;
        let mut starts = Vec::with_capacity(clusters);
        let mut total = 0u64;
        let mut wide = Vec::new();
        for (k, c) in batch_counts.iter_mut().enumerate() {
            if *c == SPAN_WIDE {
                wide.push(first_cluster + k);
                *c = 0;
            }
            starts.push(u32::try_from(total).map_err(|_| gpu_error("cluster unions too long"))?);
            total += u64::from(*c);
        }
        if total > 0 {
            let union_start = storage(&search.memory, "union starts", &starts)?;
            let unions = output(&search.memory, "unions", total * 4);
            pass(1, &union_start, &unions);
            search.read_into(&unions, total * 4, &mut self.ids)?;
        }
        self.merge_wide(index, &batch, &wide)?;
        self.counts.extend_from_slice(&batch_counts);
        Ok(())
    }

    /// The unions of `batch`'s `wide` clusters, merged here from their members' lists (read
    /// back together, their marks cleared), in parallel: under 1 % of a Morton-ordered step's
    /// clusters.
    fn merge_wide(
        &mut self,
        index: &GpuIndex<'_>,
        batch: &UnionBatch<'_>,
        wide: &[usize],
    ) -> Result<(), SurfaceError> {
        if wide.is_empty() {
            return Ok(());
        }
        let n = index.sorted.len();
        let points = |c: usize| c * CLUSTER..((c + 1) * CLUSTER).min(n);
        let start = batch.start;
        let ranges: Vec<(u64, u64)> = wide
            .iter()
            .map(|&c| {
                let p = points(c);
                let from = u64::from(start[p.start] - batch.list_base);
                (from * 4, u64::from(start[p.end] - start[p.start]) * 4)
            })
            .collect();
        let words: Vec<u32> = index
            .search
            .readback
            .read_ranges(index.search.gpu(), batch.lists, &ranges)
            .map_err(gpu_error)?;
        // Where each cluster's words begin among those read.
        let mut at = Vec::with_capacity(wide.len() + 1);
        at.push(0usize);
        for r in &ranges {
            at.push(at[at.len() - 1] + (r.1 / 4) as usize);
        }
        let merged: Vec<Option<Vec<u32>>> = wide
            .par_iter()
            .enumerate()
            .map(|(w, &c)| {
                let p = points(c);
                let base = start[p.start];
                let local: Vec<u32> = start[p.start..=p.end].iter().map(|&s| s - base).collect();
                let ids: Vec<u32> = words[at[w]..at[w + 1]]
                    .iter()
                    .map(|&x| x & ID_MASK)
                    .collect();
                let lists = Neighbours::from_csr(local, ids)?;
                let mut out = Vec::new();
                cluster_union(&lists, 0..p.len(), &mut out);
                Some(out)
            })
            .collect();
        for (&c, m) in wide.iter().zip(merged) {
            let m =
                m.ok_or_else(|| gpu_error("a wide cluster's lists do not match their counts"))?;
            self.wide.push(c);
            self.wide_unions.push(m);
        }
        Ok(())
    }

    /// The unions of the `n` points' clusters of [`CLUSTER`] points.
    pub(crate) fn finish(self, n: usize) -> Option<RunUnions> {
        let Unions {
            mut counts,
            wide,
            wide_unions: merged,
            ids,
        } = self;
        if counts.len() != n.div_ceil(CLUSTER) {
            return None;
        }
        // CSR offsets of per-cluster counts.
        let offsets = |counts: &[u32]| -> Option<Vec<u32>> {
            let mut start = Vec::with_capacity(counts.len() + 1);
            start.push(0u32);
            for &c in counts {
                start.push(start[start.len() - 1].checked_add(c)?);
            }
            Some(start)
        };
        if wide.is_empty() {
            return RunUnions::whole(CLUSTER, n, offsets(&counts)?, ids);
        }
        // Where each cluster's ids lie among the GPU's (a wide one's: none).
        let from = offsets(&counts)?;
        if from[from.len() - 1] as usize != ids.len() {
            return None;
        }
        // The wide clusters' unions, each copied into its place.
        for (&c, m) in wide.iter().zip(&merged) {
            counts[c] = u32::try_from(m.len()).ok()?;
        }
        let start = offsets(&counts)?;
        // Copied into place by blocks of clusters in parallel.
        let mut all = vec![0u32; start[start.len() - 1] as usize];
        csr_pieces(&start, &mut all, UNIONS_PER_COPY)
            .into_par_iter()
            .for_each(|(clusters, piece)| {
                let base = start[clusters.start] as usize;
                for c in clusters {
                    let out = &mut piece[start[c] as usize - base..start[c + 1] as usize - base];
                    match wide.binary_search(&c) {
                        Ok(w) => out.copy_from_slice(&merged[w]),
                        Err(_) => out.copy_from_slice(&ids[from[c] as usize..from[c + 1] as usize]),
                    }
                }
            });
        RunUnions::whole(CLUSTER, n, start, all)
    }
}
