//! Steps baked one at a time as a viewer asks for them: the batch driver's single-step bake
//! (read, bake, verify, write atomically) over a held cache directory, so that a raw case
//! plays at once and its steps stay baked for the next run.

use std::path::{Path, PathBuf};
use std::sync::{Condvar, Mutex, OnceLock, PoisonError};

use slosh_cache::{SeriesKey, step_file_name};

use crate::batch::{
    BatchOptions, StepOutcome, StepSource, bake_one, plan, prepare_dir, series_key,
};
use crate::claim::Claim;
use crate::device_turns::TurnOrder;
use crate::urgency::{Pools, Urgency};
use crate::withdrawable::Withdrawn;

/// A cache directory held for one series, whose steps are baked on request.
pub struct OnDemand {
    source: Box<dyn StepSource + Send>,
    opts: BatchOptions,
    key: SeriesKey,
    steps: Vec<(usize, f64)>,
    /// Where [`OnDemand::bake_as`] bakes: a waited-for step on `opts.threads` threads, and
    /// `opts.jobs` steps ahead at once, at a lower priority, on a share of them each; made at
    /// its first call (`render` and the batch never make them).
    pools: OnceLock<Pools>,
    /// Waited-for bakes running now (their step's lock held): bakes ahead pause at their next
    /// stage while any runs, so that the step someone waits for has the device and the
    /// cores to itself.
    waited_running: Mutex<usize>,
    waited_ended: Condvar,
    _claim: Claim,
}

impl std::fmt::Debug for OnDemand {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OnDemand")
            .field("source", &self.source.source_path())
            .field("out", &self.opts.out)
            .field("steps", &self.steps.len())
            .finish()
    }
}

impl OnDemand {
    /// Holds `opts.out` for the series of `source` that `opts` selects (refused, before
    /// anything is written, where another bake holds it or its step files are of another
    /// series), to bake its steps when asked.
    pub fn open(
        source: Box<dyn StepSource + Send>,
        opts: BatchOptions,
    ) -> Result<OnDemand, slosh_cache::Error> {
        let key = series_key(source.as_ref(), &opts);
        let steps = plan(source.as_ref(), &opts);
        let claim = prepare_dir(&opts.out, &steps, &key)?;
        // The steps baked ahead, and the one a viewer waits for.
        opts.stages.plan_steps_at_once(opts.jobs.max(1) + 1);
        Ok(OnDemand {
            source,
            opts,
            key,
            steps,
            pools: OnceLock::new(),
            waited_running: Mutex::new(0),
            waited_ended: Condvar::new(),
            _claim: claim,
        })
    }

    /// [`OnDemand::open`] over an EnSight case (`case`, opened from `path`), its points as
    /// the case's variables say ([`slosh_ensight::PointSource::Auto`]), baked by `stages` with
    /// `params`: a waited-for step on `threads` threads, and `jobs` steps ahead at once
    /// ([`OnDemand::jobs`]).
    pub fn of_case(
        case: slosh_ensight::Case,
        path: &Path,
        out: PathBuf,
        params: crate::BakeParams,
        (threads, jobs): (usize, usize),
        stages: crate::Stages,
    ) -> Result<OnDemand, slosh_cache::Error> {
        let source =
            crate::EnsightSource::new(case, path, slosh_ensight::PointSource::Auto, &params);
        let opts = BatchOptions {
            out,
            steps: None,
            jobs,
            threads,
            shard: crate::Shard::WHOLE,
            params,
            stages,
        };
        OnDemand::open(Box::new(source), opts)
    }

    /// (step index, time) of every step of the series, in order.
    pub fn steps(&self) -> &[(usize, f64)] {
        &self.steps
    }

    /// Steps baked ahead at once, on a share of the threads each (the bake's `--jobs`): as
    /// many as a viewer's loaders may ask for together.
    pub fn jobs(&self) -> usize {
        self.opts.jobs
    }

    /// What every step file of the series records.
    pub fn key(&self) -> &SeriesKey {
        &self.key
    }

    pub fn dir(&self) -> &Path {
        &self.opts.out
    }

    /// Where step `index` is (or will be) cached.
    pub fn path(&self, index: usize) -> PathBuf {
        self.opts.out.join(step_file_name(index))
    }

    /// Bakes step `index` into its file unless a current one is there (`Kept`); on the
    /// calling thread's rayon pool. A step the verifier would reject is never written. The
    /// bake that completes the series writes its manifest, as `slosh bake` does. Another
    /// holder baking the same step (in this process or another) is waited for.
    pub fn bake(&self, index: usize) -> StepOutcome {
        self.bake_unless_withdrawn(index, &|| false)
    }

    /// [`OnDemand::bake_unless_withdrawn`] on the pool for `urgency` instead of the calling
    /// thread's: a step someone waits for takes the cores from the steps baked ahead.
    /// A step baked ahead pauses between its stages while a waited-for step bakes.
    pub fn bake_as(&self, index: usize, urgency: Urgency, withdrawn: Withdrawn<'_>) -> StepOutcome {
        let pools = self
            .pools
            .get_or_init(|| Pools::new(self.opts.threads, self.opts.jobs));
        match urgency {
            Urgency::Waited => pools.install(urgency, || {
                self.bake_locked(index, TurnOrder::waited(index), withdrawn, || {
                    WaitedRunning::start(self)
                })
            }),
            Urgency::Ahead => {
                let paused = || {
                    self.wait_while_a_waited_step_bakes();
                    withdrawn()
                };
                pools.install(urgency, || {
                    self.bake_locked(index, TurnOrder::ahead(index), &paused, || ())
                })
            }
        }
    }

    fn wait_while_a_waited_step_bakes(&self) {
        let mut running = self
            .waited_running
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        while *running > 0 {
            running = self
                .waited_ended
                .wait(running)
                .unwrap_or_else(PoisonError::into_inner);
        }
    }

    /// [`OnDemand::bake`], given up (a failed outcome, nothing written) once `withdrawn`
    /// says so: it is asked before the read, between the bake's stages and before each
    /// neighbour search, and before the step is encoded and written.
    pub fn bake_unless_withdrawn(&self, index: usize, withdrawn: Withdrawn<'_>) -> StepOutcome {
        self.bake_locked(index, TurnOrder::waited(index), withdrawn, || ())
    }

    /// [`OnDemand::bake_unless_withdrawn`], with `locked` called once the step's lock is held
    /// and what it returns kept until the bake ends.
    fn bake_locked<G>(
        &self,
        index: usize,
        order: TurnOrder,
        withdrawn: Withdrawn<'_>,
        locked: impl FnOnce() -> G,
    ) -> StepOutcome {
        if !self.steps.iter().any(|(i, _)| *i == index) {
            return StepOutcome::Failed(format!("step {index} is not in the series"));
        }
        // Players, renders and bakes of one case share its directory (the claim lets bakes of
        // one series in together) and may want one step at once: the step's lock makes the
        // second wait, then find the first's file current, instead of baking it again and
        // replacing a file another may already have read or listed in the manifest. Opened
        // per call, so that this process's loaders exclude each other too.
        let path = self.opts.out.join(crate::claim::STEP_LOCKS_NAME);
        let locks = match slosh_fileio::RangeLocks::open(&path) {
            Ok(locks) => locks,
            Err(e) => return StepOutcome::Failed(e.to_string()),
        };
        let lock = match locks.lock(index as u64) {
            Ok(lock) => lock,
            Err(e) => return StepOutcome::Failed(e.to_string()),
        };
        // Counted only with its lock held: a waited-for bake of a step a bake ahead holds
        // waits for it, and that bake must not pause for the waiter.
        let held = locked();
        let outcome = bake_one(
            self.source.as_ref(),
            index,
            &self.opts,
            &self.key,
            withdrawn,
            order,
        );
        drop(held);
        drop(lock);
        if matches!(outcome, StepOutcome::Baked { .. })
            && self.steps.iter().all(|(i, _)| self.path(*i).exists())
        {
            // A manifest that cannot be written leaves the steps as they are: every one is
            // whole and checked on its own, and `slosh bake --manifest-only` writes it.
            let _ = slosh_cache::Manifest::refresh(&self.opts.out);
        }
        outcome
    }
}

/// One waited-for bake counted in [`OnDemand`]'s `waited_running` while it lives.
struct WaitedRunning<'a> {
    bake: &'a OnDemand,
}

impl<'a> WaitedRunning<'a> {
    fn start(bake: &'a OnDemand) -> WaitedRunning<'a> {
        *bake
            .waited_running
            .lock()
            .unwrap_or_else(PoisonError::into_inner) += 1;
        WaitedRunning { bake }
    }
}

impl Drop for WaitedRunning<'_> {
    fn drop(&mut self) {
        let mut running = self
            .bake
            .waited_running
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        *running = running.saturating_sub(1);
        if *running == 0 {
            self.bake.waited_ended.notify_all();
        }
    }
}
