//! Which bakes get the cores first: a step a viewer waits for (a jump) over the steps it bakes
//! ahead of need. A waited-for step runs on a rayon pool of every core; each step ahead on a
//! pool of its own share of them, at a lower scheduling priority, so the kernel gives the
//! waited-for step the cores while both have work, and the steps ahead every core that it
//! leaves idle.

use std::sync::{Condvar, Mutex, PoisonError};

use rayon::ThreadPool;

/// Why a step is baked now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Urgency {
    /// Someone waits for it.
    Waited,
    /// Baked ahead of need.
    Ahead,
}

/// How much lower the priority of the pool that bakes ahead is (nice, added to the
/// process's): at 10 the kernel weighs a thread 110 against 1024 at the process's own.
pub(crate) const AHEAD_NICENESS: i32 = 10;

/// The pools: one for a waited-for step, on every thread; and one for each step baked ahead
/// at once, each on its share of the threads at the lower priority, as the batch's jobs are
/// (`batch.rs`: steps sharing one pool spread every stage over all cores and pay for its
/// splitting and stealing, and a thread waiting inside one step could start another).
#[derive(Debug)]
pub(crate) struct Pools {
    waited: Option<ThreadPool>,
    /// The pools ahead that no bake holds now.
    ahead: Mutex<Vec<ThreadPool>>,
    ahead_given_back: Condvar,
    /// Whether any pool ahead was made (else bakes ahead run on the caller's pool).
    ahead_made: bool,
}

impl Pools {
    /// A waited-for pool of `threads` threads and `jobs` pools ahead sharing them.
    pub(crate) fn new(threads: usize, jobs: usize) -> Pools {
        // A pool that cannot be made leaves its bakes on the caller's pool.
        let pool = |name: String, threads: usize, lower: bool| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads.max(1))
                .thread_name(move |t| format!("bake-{name}-{t}"))
                .start_handler(move |_| {
                    if lower {
                        lower_priority();
                    }
                })
                .build()
                .ok()
        };
        let jobs = jobs.max(1);
        let ahead: Vec<ThreadPool> = (0..jobs)
            .filter_map(|job| {
                let share = crate::jobs::thread_share(threads, jobs, job);
                pool(format!("ahead-{job}"), share, true)
            })
            .collect();
        Pools {
            waited: pool("waited".into(), threads, false),
            ahead_made: !ahead.is_empty(),
            ahead: Mutex::new(ahead),
            ahead_given_back: Condvar::new(),
        }
    }

    /// Runs `work` on the pool for `urgency`: for a step ahead, the first pool ahead that no
    /// other bake holds (waiting for one where all are held).
    pub(crate) fn install<R: Send>(&self, urgency: Urgency, work: impl FnOnce() -> R + Send) -> R {
        match urgency {
            Urgency::Waited => match &self.waited {
                Some(pool) => pool.install(work),
                None => work(),
            },
            Urgency::Ahead if !self.ahead_made => work(),
            Urgency::Ahead => {
                let held = HeldPool::take(self);
                held.pool().install(work)
            }
        }
    }
}

/// A pool ahead held by one bake, given back when dropped (a bake that panics too).
struct HeldPool<'p> {
    pools: &'p Pools,
    pool: Option<ThreadPool>,
}

impl<'p> HeldPool<'p> {
    fn take(pools: &'p Pools) -> HeldPool<'p> {
        let mut free = pools.ahead.lock().unwrap_or_else(PoisonError::into_inner);
        let pool = loop {
            match free.pop() {
                Some(pool) => break pool,
                None => {
                    free = pools
                        .ahead_given_back
                        .wait(free)
                        .unwrap_or_else(PoisonError::into_inner);
                }
            }
        };
        HeldPool {
            pools,
            pool: Some(pool),
        }
    }

    fn pool(&self) -> &ThreadPool {
        self.pool.as_ref().expect("held until dropped")
    }
}

impl Drop for HeldPool<'_> {
    fn drop(&mut self) {
        if let Some(pool) = self.pool.take() {
            self.pools
                .ahead
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .push(pool);
            self.pools.ahead_given_back.notify_one();
        }
    }
}

/// Lowers the calling thread's priority by [`AHEAD_NICENESS`]. On Linux the nice value is
/// the thread's own, not the process's (setpriority(2), "NOTES"); where the call fails, the
/// thread keeps its priority, and bakes ahead only share the cores evenly.
fn lower_priority() {
    #[cfg(unix)]
    // SAFETY: nice only changes the calling thread's scheduling priority.
    unsafe {
        libc::nice(AHEAD_NICENESS);
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    fn niceness() -> i32 {
        // SAFETY: getpriority reads the calling thread's nice value (its tid, 0 here).
        unsafe { libc::getpriority(libc::PRIO_PROCESS, 0) }
    }

    /// Every thread of the pool that bakes ahead runs at a lower priority than the caller's,
    /// and the waited-for pool's at the caller's.
    #[test]
    fn steps_baked_ahead_run_at_a_lower_priority() {
        use rayon::prelude::*;
        let own = niceness();
        let pools = Pools::new(4, 2);
        let on = |urgency| -> Vec<i32> {
            pools.install(urgency, || {
                (0..64)
                    .into_par_iter()
                    .map(|_| {
                        std::thread::sleep(std::time::Duration::from_millis(1));
                        niceness()
                    })
                    .collect()
            })
        };
        let expected = (own + AHEAD_NICENESS).min(19);
        assert!(on(Urgency::Ahead).iter().all(|&n| n == expected), "ahead");
        assert!(on(Urgency::Waited).iter().all(|&n| n == own), "waited");
    }

    /// Each step baked ahead at once has a pool of its own, of its share of the threads
    /// (8 threads, 4 jobs: 2 each), and a step beyond them waits for a pool to be given back.
    #[test]
    fn each_step_ahead_has_a_pool_of_its_own() {
        use std::sync::Barrier;
        use std::sync::atomic::{AtomicUsize, Ordering};
        let pools = Pools::new(8, 4);
        let together = Barrier::new(4);
        let seen: Vec<(String, usize)> = std::thread::scope(|s| {
            let bakes: Vec<_> = (0..4)
                .map(|_| {
                    s.spawn(|| {
                        pools.install(Urgency::Ahead, || {
                            // All four hold their pools at once.
                            together.wait();
                            let name = std::thread::current().name().unwrap_or("").to_string();
                            (name, rayon::current_num_threads())
                        })
                    })
                })
                .collect();
            bakes
                .into_iter()
                .map(|b| b.join().expect("a bake"))
                .collect()
        });
        let mut pools_seen: Vec<String> = seen
            .iter()
            .map(|(name, _)| {
                name.rsplit_once('-')
                    .map_or(name.clone(), |(p, _)| p.to_string())
            })
            .collect();
        pools_seen.sort();
        pools_seen.dedup();
        assert_eq!(pools_seen.len(), 4, "{seen:?}");
        assert!(seen.iter().all(|(_, threads)| *threads == 2), "{seen:?}");
        // One pool: two bakes ahead take turns.
        let pools = Pools::new(2, 1);
        let (inside, most) = (AtomicUsize::new(0), AtomicUsize::new(0));
        std::thread::scope(|s| {
            for _ in 0..2 {
                s.spawn(|| {
                    pools.install(Urgency::Ahead, || {
                        let now = inside.fetch_add(1, Ordering::SeqCst) + 1;
                        most.fetch_max(now, Ordering::SeqCst);
                        std::thread::sleep(std::time::Duration::from_millis(100));
                        inside.fetch_sub(1, Ordering::SeqCst);
                    })
                });
            }
        });
        assert_eq!(most.load(Ordering::SeqCst), 1);
    }
}
