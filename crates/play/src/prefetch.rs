//! Background threads that run the host half of an upload for the steps the frame loop asks
//! for. A new request replaces the queue (a jump cancels what is stale); an urgent one also
//! withdraws the loads in flight that it does not want, so the step asked for gets the
//! cores. The frame loop collects finished steps with [`Prefetcher::poll`], which never
//! waits.

use std::collections::{HashSet, VecDeque};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::Instant;

/// Where steps come from: a cache directory, or an instrumented stand-in in tests.
pub trait StepLoader: Send + Sync + 'static {
    type Step: Send + 'static;
    /// Loads step `index`; the error names the file and what is wrong with it. `waited` says
    /// that the frame loop waits for it (the step an urgent request asked for first), so it
    /// may take resources from the loads ahead. A load may ask `withdrawn` as it goes and give
    /// up (with any error) once it says `true`: nobody wants the step any more.
    fn load(
        &self,
        index: usize,
        waited: bool,
        withdrawn: &(dyn Fn() -> bool + Sync),
    ) -> Result<Self::Step, String>;
}

/// A finished load.
#[derive(Debug)]
pub struct Loaded<T> {
    pub index: usize,
    /// The request generation it was queued under ([`Prefetcher::generation`]).
    pub generation: u64,
    pub result: Result<T, String>,
    pub seconds: f64,
}

#[derive(Debug, Default)]
struct Queue {
    waiting: VecDeque<usize>,
    in_flight: HashSet<usize>,
    /// Loads in flight that an urgent request withdrew.
    withdrawn: HashSet<usize>,
    /// The step the last urgent request asked for first, until a plain request.
    waited: Option<usize>,
    generation: u64,
    shutdown: bool,
}

#[derive(Debug, Default)]
struct Shared {
    queue: Mutex<Queue>,
    wake: Condvar,
}

impl Shared {
    fn lock(&self) -> std::sync::MutexGuard<'_, Queue> {
        self.queue.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// Loader threads over a [`StepLoader`].
#[derive(Debug)]
pub struct Prefetcher<T> {
    shared: Arc<Shared>,
    results: Receiver<Loaded<T>>,
}

impl<T: Send + 'static> Prefetcher<T> {
    /// `threads` loader threads (at least one) over `source`.
    pub fn new<S: StepLoader<Step = T>>(source: Arc<S>, threads: usize) -> Prefetcher<T> {
        let shared = Arc::new(Shared::default());
        let (tx, results) = channel();
        for n in 0..threads.max(1) {
            let (shared, source, tx) = (shared.clone(), source.clone(), tx.clone());
            // A thread that cannot start leaves the others; with none, poll() stays empty and
            // the engine reports steps as not yet loaded.
            let _ = slosh_render::spawn_background(format!("slosh-prefetch-{n}"), move || {
                worker(&shared, &*source, &tx)
            });
        }
        Prefetcher { shared, results }
    }

    /// Replaces the queue with `wanted`, in order of priority, skipping steps being loaded
    /// now. Returns the new generation; loads queued before it are dropped unstarted.
    pub fn request(&self, wanted: impl IntoIterator<Item = usize>) -> u64 {
        self.replace(wanted, None)
    }

    fn replace(&self, wanted: impl IntoIterator<Item = usize>, waited: Option<usize>) -> u64 {
        let mut q = self.shared.lock();
        q.waited = waited;
        let mut seen = HashSet::new();
        let waiting: VecDeque<usize> = wanted
            .into_iter()
            .filter(|i| !q.in_flight.contains(i) && seen.insert(*i))
            .collect();
        if waiting != q.waiting {
            q.generation += 1;
            q.waiting = waiting;
            self.shared.wake.notify_all();
        }
        q.generation
    }

    /// [`Prefetcher::request`], and every load in flight that `wanted` does not hold is
    /// withdrawn: its result, if it gives up, is dropped unseen. The first of `wanted` loads
    /// as waited for.
    pub fn request_urgent(&self, wanted: &[usize]) -> u64 {
        let generation = self.replace(wanted.iter().copied(), wanted.first().copied());
        let mut q = self.shared.lock();
        let stale: Vec<usize> = q
            .in_flight
            .iter()
            .copied()
            .filter(|i| !wanted.contains(i))
            .collect();
        q.withdrawn.extend(stale);
        generation
    }

    /// The current request generation.
    pub fn generation(&self) -> u64 {
        self.shared.lock().generation
    }

    /// Whether step `index` is queued or being loaded.
    pub fn pending(&self, index: usize) -> bool {
        let q = self.shared.lock();
        q.in_flight.contains(&index) || q.waiting.contains(&index)
    }

    /// Steps being loaded now.
    pub fn in_flight(&self) -> Vec<usize> {
        self.shared.lock().in_flight.iter().copied().collect()
    }

    /// Steps queued, in order.
    pub fn queued(&self) -> Vec<usize> {
        self.shared.lock().waiting.iter().copied().collect()
    }

    /// The loads finished since the last call; never waits.
    pub fn poll(&self) -> Vec<Loaded<T>> {
        self.results.try_iter().collect()
    }

    /// Waits for the next finished load (benchmarks and tests; the frame loop uses `poll`).
    pub fn wait(&self) -> Option<Loaded<T>> {
        self.results.recv().ok()
    }
}

impl<T> Drop for Prefetcher<T> {
    fn drop(&mut self) {
        // Threads end after the load in hand, which is withdrawn so that it gives up where it
        // can; nobody here waits for a slow one (the binary does, before it exits).
        let mut q = self.shared.lock();
        q.shutdown = true;
        let in_flight: Vec<usize> = q.in_flight.iter().copied().collect();
        q.withdrawn.extend(in_flight);
        drop(q);
        self.shared.wake.notify_all();
    }
}

fn worker<S: StepLoader>(shared: &Shared, source: &S, tx: &Sender<Loaded<S::Step>>) {
    loop {
        let (index, generation, waited) = {
            let mut q = shared.lock();
            loop {
                if q.shutdown {
                    return;
                }
                if let Some(index) = q.waiting.pop_front() {
                    q.in_flight.insert(index);
                    break (index, q.generation, q.waited == Some(index));
                }
                q = shared.wake.wait(q).unwrap_or_else(PoisonError::into_inner);
            }
        };
        let start = Instant::now();
        let withdrawn = || shared.lock().withdrawn.contains(&index);
        let result = source.load(index, waited, &withdrawn);
        if result.is_err() && withdrawn() {
            let mut q = shared.lock();
            q.in_flight.remove(&index);
            q.withdrawn.remove(&index);
            continue;
        }
        let loaded = Loaded {
            index,
            generation,
            result,
            seconds: start.elapsed().as_secs_f64(),
        };
        // The result is sent before the step leaves `in_flight`, so a step is always either
        // pending or in the channel until polled.
        let gone = tx.send(loaded).is_err();
        {
            let mut q = shared.lock();
            q.in_flight.remove(&index);
            q.withdrawn.remove(&index);
        }
        if gone {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc::SyncSender;

    /// Records every load; each waits for a go from the test.
    struct Gated {
        loads: Mutex<Vec<usize>>,
        /// Loads that found themselves withdrawn when let go.
        gave_up: Mutex<Vec<usize>>,
        /// Loads told that the frame loop waits for them.
        waited: Mutex<Vec<usize>>,
        started: Mutex<SyncSender<usize>>,
        go: Mutex<Receiver<()>>,
    }

    impl StepLoader for Gated {
        type Step = usize;
        fn load(
            &self,
            index: usize,
            waited: bool,
            withdrawn: &(dyn Fn() -> bool + Sync),
        ) -> Result<usize, String> {
            self.loads
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .push(index);
            if waited {
                self.waited
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .push(index);
            }
            let _ = self
                .started
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .send(index);
            let _ = self
                .go
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .recv();
            if withdrawn() {
                self.gave_up
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .push(index);
                Err("withdrawn".into())
            } else if index == 13 {
                Err("step 13 is unlucky".into())
            } else {
                Ok(index * 10)
            }
        }
    }

    fn gated() -> (Arc<Gated>, Receiver<usize>, Sender<()>) {
        let (started_tx, started) = std::sync::mpsc::sync_channel(100);
        let (go, go_rx) = channel();
        let source = Arc::new(Gated {
            loads: Mutex::new(Vec::new()),
            gave_up: Mutex::new(Vec::new()),
            waited: Mutex::new(Vec::new()),
            started: Mutex::new(started_tx),
            go: Mutex::new(go_rx),
        });
        (source, started, go)
    }

    #[test]
    fn a_slow_source_never_blocks_poll_and_a_jump_cancels_stale_work() {
        let (source, started, go) = gated();
        let prefetch = Prefetcher::new(source.clone(), 1);
        prefetch.request(0..10);
        // The one thread is inside load(0), held there.
        assert_eq!(started.recv().ok(), Some(0));
        // The frame loop polls while the source is stuck: it gets nothing, at once.
        assert!(prefetch.poll().is_empty());
        assert!(prefetch.pending(0));
        // A jump to 50: the queued 1..10 are dropped unstarted.
        let generation = prefetch.request(50..53);
        assert_eq!(prefetch.queued(), vec![50, 51, 52]);
        for _ in 0..4 {
            go.send(()).ok();
        }
        let mut got = Vec::new();
        while got.len() < 4 {
            let loaded = prefetch.wait().expect("the loader answers");
            got.push((loaded.index, loaded.generation >= generation));
        }
        assert_eq!(got, vec![(0, false), (50, true), (51, true), (52, true)]);
        let loads = source
            .loads
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone();
        assert_eq!(loads, vec![0, 50, 51, 52], "stale requests never loaded");
    }

    /// A dropped prefetcher (the engine closed, or the process ending on an error) withdraws
    /// the load in hand, so that it gives up at its next piece rather than running on.
    #[test]
    fn dropping_the_prefetcher_withdraws_the_load_in_hand() {
        let (source, started, go) = gated();
        let prefetch = Prefetcher::new(source.clone(), 1);
        prefetch.request([7]);
        assert_eq!(started.recv().ok(), Some(7));
        drop(prefetch);
        go.send(()).ok();
        let deadline = Instant::now() + std::time::Duration::from_secs(10);
        let gave_up = loop {
            let gave_up = source
                .gave_up
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .clone();
            if !gave_up.is_empty() || Instant::now() > deadline {
                break gave_up;
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        };
        assert_eq!(gave_up, vec![7]);
    }

    #[test]
    fn an_urgent_request_withdraws_the_loads_it_does_not_want() {
        let (source, started, go) = gated();
        let prefetch = Prefetcher::new(source.clone(), 2);
        prefetch.request([0, 1]);
        let mut first = vec![started.recv().ok(), started.recv().ok()];
        first.sort();
        assert_eq!(first, vec![Some(0), Some(1)]);
        // A jump to 40 while 0 and 1 load: 1 is still wanted, 0 is withdrawn.
        prefetch.request_urgent(&[40, 1]);
        for _ in 0..3 {
            go.send(()).ok();
        }
        let mut got: Vec<(usize, Result<usize, String>)> = (0..2)
            .filter_map(|_| prefetch.wait())
            .map(|l| (l.index, l.result))
            .collect();
        got.sort_by_key(|g| g.0);
        assert_eq!(got, vec![(1, Ok(10)), (40, Ok(400))]);
        // The withdrawn load gave up and its result never came.
        let start = Instant::now();
        while prefetch.pending(0) {
            assert!(start.elapsed().as_secs() < 5, "step 0 stays pending");
            std::thread::yield_now();
        }
        assert!(prefetch.poll().is_empty());
        // Only the urgent request's first step loaded as waited for; 1, still wanted, keeps
        // the plain request's standing.
        let waited = source
            .waited
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone();
        assert_eq!(waited, vec![40]);
    }

    #[test]
    fn failures_come_back_as_results() {
        let (source, _started, go) = gated();
        let prefetch = Prefetcher::new(source, 2);
        prefetch.request([12, 13]);
        go.send(()).ok();
        go.send(()).ok();
        let mut results: Vec<(usize, Result<usize, String>)> = (0..2)
            .filter_map(|_| prefetch.wait())
            .map(|l| (l.index, l.result))
            .collect();
        results.sort_by_key(|r| r.0);
        assert_eq!(results[0], (12, Ok(120)));
        assert_eq!(results[1], (13, Err("step 13 is unlucky".into())));
        // Nothing is left queued; the loader lets go of each step right after sending it.
        assert!(prefetch.queued().is_empty());
        let start = Instant::now();
        while prefetch.pending(12) || prefetch.pending(13) {
            assert!(
                start.elapsed().as_secs() < 5,
                "loads stay pending after they finished"
            );
            std::thread::yield_now();
        }
    }
}
