//! Which bakes get the cores first: a step a viewer waits for (a jump) over the steps it bakes
//! ahead of need. Both run on rayon pools of their own; the pool of steps baked ahead runs at
//! a lower scheduling priority, so the kernel gives the waited-for step the cores while
//! both have work, and the steps ahead every core that it leaves idle.

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

/// A pool for each urgency, of `threads` threads each.
#[derive(Debug)]
pub(crate) struct Pools {
    waited: Option<ThreadPool>,
    ahead: Option<ThreadPool>,
}

impl Pools {
    pub(crate) fn new(threads: usize) -> Pools {
        // A pool that cannot be made leaves its bakes on the caller's pool.
        let pool = |name: &'static str, lower: bool| {
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
        Pools {
            waited: pool("waited", false),
            ahead: pool("ahead", true),
        }
    }

    /// Runs `work` on the pool for `urgency`.
    pub(crate) fn install<R: Send>(&self, urgency: Urgency, work: impl FnOnce() -> R + Send) -> R {
        let pool = match urgency {
            Urgency::Waited => &self.waited,
            Urgency::Ahead => &self.ahead,
        };
        match pool {
            Some(pool) => pool.install(work),
            None => work(),
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
        let pools = Pools::new(4);
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
}
