//! The GPU's neighbour search as the build asks for it: the points uploaded once per step,
//! in Morton order, then the nearest-points and lists passes over grids of Morton cells.

use std::num::NonZero;

use slosh_mls::{
    ListRequest, NearestIds, NeighbourLists, NeighbourSearch, PointIndex, SurfaceError,
};

use crate::cells::SortedPoints;
use crate::dispatch::{gpu_error, guarded, storage};
use crate::index::GpuIndex;
use crate::passes::GpuStages;

impl NeighbourSearch for GpuStages {
    fn index<'a>(
        &'a self,
        points: &'a [[f64; 3]],
    ) -> Result<Box<dyn PointIndex + 'a>, SurfaceError> {
        let n = points.len();
        let bytes = n as u64 * 16;
        if bytes > self.gpu.max_binding() || n >= (1 << 31) {
            return Err(gpu_error(format!(
                "{n} points take {bytes} bytes, more than one binding of this adapter holds \
                 ({} bytes); bake with --device cpu",
                self.gpu.max_binding()
            )));
        }
        let sorted = SortedPoints::new(points);
        let gpu = &self.gpu;
        guarded(
            gpu,
            || {
                let positions = storage(&self.memory, "search positions", &sorted.high)?;
                let residuals = storage(&self.memory, "search residuals", &sorted.low)?;
                let original = storage(&self.memory, "search order", &sorted.order)?;
                Ok((positions, residuals, original))
            },
            gpu_error,
        )
        .map(
            |(positions, residuals, original)| -> Box<dyn PointIndex + 'a> {
                let margin = 1e-5 * sorted.extent();
                Box::new(GpuIndex {
                    search: self,
                    points,
                    sorted,
                    positions,
                    residuals,
                    original,
                    margin,
                    kept_nearest: Default::default(),
                })
            },
        )
    }

    fn describe(&self) -> String {
        format!("gpu ({})", self.gpu.describe())
    }
}

impl PointIndex for GpuIndex<'_> {
    fn nearest(&self, count: NonZero<usize>) -> Result<Vec<u32>, SurfaceError> {
        guarded(
            self.search.gpu(),
            || crate::nearest::nearest(self, count.get()),
            gpu_error,
        )
    }

    fn lists(&self, request: ListRequest<'_>) -> Result<NeighbourLists, SurfaceError> {
        // The lists' buffers need the room.
        drop(self.take_kept_nearest());
        guarded(
            self.search.gpu(),
            || crate::lists::lists(self, request),
            gpu_error,
        )
    }

    fn orientation_votes(
        &self,
        nearest: NearestIds<'_>,
        normals: &[Option<[f64; 3]>],
    ) -> Result<Option<Vec<u32>>, SurfaceError> {
        guarded(
            self.search.gpu(),
            || crate::orient::orientation_votes(self, nearest, normals),
            gpu_error,
        )
    }
}
