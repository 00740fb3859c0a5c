//! The spray's components on the GPU (`shaders/spray_components.wgsl`): the links the lists
//! pass marks joined by a union-find over each batch of lists while it is there, and every
//! point's root read back once, 4 bytes a point, where the links (some dozen a point) were
//! read back, gathered and joined on the host.

use slosh_mls::SurfaceError;

use crate::dispatch::{Pooled, bind, groups, storage, uniform};
use crate::index::GpuIndex;
use crate::layout::ComponentParams;

/// Every point's parent on the GPU, joined batch by batch.
pub(crate) struct Components {
    parent: Pooled,
    points: usize,
}

impl Components {
    /// Every point its own component.
    pub(crate) fn new(index: &GpuIndex<'_>) -> Result<Components, SurfaceError> {
        let points = index.sorted.len();
        let own: Vec<u32> = (0..points as u32).collect();
        Ok(Components {
            parent: storage(&index.search.memory, "spray components", &own)?,
            points,
        })
    }

    /// Joins the links of the points `first..last`, whose lists `lists` holds from slot
    /// `list_base` (submitted after the batch's writes, so run after them).
    pub(crate) fn join(
        &self,
        index: &GpuIndex<'_>,
        list_start: &wgpu::Buffer,
        lists: &wgpu::Buffer,
        list_base: u32,
        (first, last): (usize, usize),
    ) -> Result<(), SurfaceError> {
        self.dispatch(
            index,
            ("spray components: join", &index.search.join_links),
            (list_start, lists),
            (first, last - first),
            list_base,
        )
    }

    /// Each point's component, named by its smallest index (waits for the GPU). The flatten
    /// pass reads no lists; `list_start` and `lists` fill the layout's bindings.
    pub(crate) fn finish(
        self,
        index: &GpuIndex<'_>,
        list_start: &wgpu::Buffer,
        lists: &wgpu::Buffer,
    ) -> Result<Vec<u32>, SurfaceError> {
        self.dispatch(
            index,
            ("spray components: flatten", &index.search.flatten),
            (list_start, lists),
            (0, self.points),
            0,
        )?;
        index.search.read_back(&self.parent, self.points as u64 * 4)
    }

    fn dispatch(
        &self,
        index: &GpuIndex<'_>,
        (pass, pipeline): (&'static str, &wgpu::ComputePipeline),
        (list_start, lists): (&wgpu::Buffer, &wgpu::Buffer),
        (first, count): (usize, usize),
        list_base: u32,
    ) -> Result<(), SurfaceError> {
        if count == 0 {
            return Ok(());
        }
        let search = index.search;
        let gpu = search.gpu();
        let (x, y, row_threads) = groups(gpu, count as u32);
        let params = uniform(
            gpu,
            &ComponentParams {
                first: first as u32,
                count: count as u32,
                list_base,
                row_threads,
            },
        );
        let group = bind(
            gpu,
            &search.components_layout,
            &[(0, &params), (1, list_start), (2, lists), (3, &self.parent)],
        );
        search.run(pass, &[(pipeline, (x, y))], &group);
        Ok(())
    }
}
