//! Where a bake's data-parallel stages run: the neighbour search (with the initial fits, where
//! it makes them) and the BVH's tree, each the CPU's reference or a GPU's
//! (`slosh-gpubake`), shared by every step in flight.

use std::sync::Arc;

use slosh_mls::{KdSearch, NeighbourSearch};

use crate::bvh::{PlocTree, TreeBuild};
use crate::device_turns::DeviceTurns;

#[derive(Debug, Clone)]
pub struct Stages {
    /// Finds each step's nearest points and neighbour lists.
    pub search: Arc<dyn NeighbourSearch>,
    /// Links each step's BVH leaves into a tree.
    pub tree: Arc<dyn TreeBuild>,
    /// Bytes of memory of the device the stages run on, where they run on one and it says:
    /// each step in flight holds its buffers there ([`crate::default_jobs`]).
    pub device_memory: Option<u64>,
    /// Told how many steps a batch bakes at once, before its first step, where the stages
    /// keep memory for the steps in flight together.
    pub in_flight: Option<Arc<dyn StepsInFlight>>,
    /// Where the steps in flight share a device: their turns on it ([`DeviceTurns`]).
    pub turns: Option<Arc<DeviceTurns>>,
}

/// Stages that keep memory for the steps in flight together (a device's transfer buffers),
/// sized by how many there are.
pub trait StepsInFlight: Send + Sync + std::fmt::Debug {
    /// Up to `steps` steps are baked at once. Told before the first step: what is sized by
    /// it (a staging pool's warm-up) is sized once, at the first step's first upload.
    fn steps_at_once(&self, steps: usize);

    /// No step is left to start, and `steps` are still being baked (0 once the last is
    /// done): what was kept for more steps may go, while the others finish.
    fn steps_left(&self, steps: usize) {
        let _ = steps;
    }
}

impl Stages {
    /// The reference stages, on the CPU: a k-d tree and obvhs's PLOC.
    pub fn cpu() -> Stages {
        Stages {
            search: Arc::new(KdSearch),
            tree: Arc::new(PlocTree),
            device_memory: None,
            in_flight: None,
            turns: None,
        }
    }

    /// Tells the stages that up to `steps` steps are baked at once ([`StepsInFlight`]).
    pub fn plan_steps_at_once(&self, steps: usize) {
        if let Some(in_flight) = &self.in_flight {
            in_flight.steps_at_once(steps);
        }
    }

    /// Tells the stages that no step is left to start and `steps` are still being baked
    /// ([`StepsInFlight::steps_left`]).
    pub fn plan_steps_left(&self, steps: usize) {
        if let Some(in_flight) = &self.in_flight {
            in_flight.steps_left(steps);
        }
    }

    /// Where they run, for reports: "neighbours on …, tree on …".
    pub fn describe(&self) -> String {
        format!(
            "neighbours on {}, tree on {}",
            self.search.describe(),
            self.tree.describe()
        )
    }
}

impl Default for Stages {
    fn default() -> Stages {
        Stages::cpu()
    }
}
