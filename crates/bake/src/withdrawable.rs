//! A neighbour search that gives up once its caller withdraws the bake: a step baked for a
//! viewer that has moved on (a jump) stops at its next search instead of holding the cores
//! and the GPU that the step now asked for needs.

use std::num::NonZero;

use slosh_mls::{
    ListRequest, NearestIds, NeighbourLists, NeighbourSearch, PointIndex, SurfaceError,
};

use crate::device_turns::{DeviceTurns, TurnOrder, on_device};

/// Asked before each search: `true` ends the bake with [`SurfaceError::Withdrawn`].
pub type Withdrawn<'w> = &'w (dyn Fn() -> bool + Sync);

/// `inner`, asking `withdrawn` before it indexes and before each query, each run with the
/// step's work on the device in `turns` where the stages share one.
pub(crate) struct Withdrawable<'w> {
    pub(crate) inner: &'w dyn NeighbourSearch,
    pub(crate) withdrawn: Withdrawn<'w>,
    pub(crate) turns: Option<&'w std::sync::Arc<DeviceTurns>>,
    pub(crate) order: TurnOrder,
}

impl std::fmt::Debug for Withdrawable<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Withdrawable")
            .field("inner", &self.inner)
            .finish()
    }
}

impl Withdrawable<'_> {
    fn check(&self) -> Result<(), SurfaceError> {
        if (self.withdrawn)() {
            Err(SurfaceError::Withdrawn)
        } else {
            Ok(())
        }
    }

    /// `stage`, unless the bake was withdrawn, with the step's work on the device in turns.
    fn run<R>(&self, stage: impl FnOnce() -> Result<R, SurfaceError>) -> Result<R, SurfaceError> {
        self.check()?;
        on_device(self.turns, self.order, stage)
    }
}

struct WithdrawableIndex<'a> {
    inner: Box<dyn PointIndex + 'a>,
    search: &'a Withdrawable<'a>,
}

impl NeighbourSearch for Withdrawable<'_> {
    fn index<'a>(
        &'a self,
        points: &'a [[f64; 3]],
    ) -> Result<Box<dyn PointIndex + 'a>, SurfaceError> {
        let inner = self.run(|| self.inner.index(points))?;
        Ok(Box::new(WithdrawableIndex {
            inner,
            search: self,
        }))
    }

    fn describe(&self) -> String {
        self.inner.describe()
    }
}

impl PointIndex for WithdrawableIndex<'_> {
    fn nearest(&self, count: NonZero<usize>) -> Result<Vec<u32>, SurfaceError> {
        self.search.run(|| self.inner.nearest(count))
    }

    fn lists(&self, request: ListRequest<'_>) -> Result<NeighbourLists, SurfaceError> {
        self.search.run(|| self.inner.lists(request))
    }

    fn orientation_votes(
        &self,
        nearest: NearestIds<'_>,
        normals: &[Option<[f64; 3]>],
    ) -> Result<Option<Vec<u32>>, SurfaceError> {
        self.search
            .run(|| self.inner.orientation_votes(nearest, normals))
    }
}
