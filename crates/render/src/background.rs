//! Threads that use the GPU beside the caller's: the engine's loaders and the staging
//! warm-up. A process that exits while one of them still writes into mapped memory can crash
//! in the driver's exit-time teardown (on the H100 host, `bench scrub` ended by an upload
//! error exited with SIGSEGV while a render ended by the same error did not), so the binary
//! waits for them, a bounded time, before it exits.

use std::sync::{Condvar, Mutex, PoisonError};
use std::time::Duration;

/// Threads started and not yet ended.
struct Registry {
    live: Mutex<usize>,
    ended: Condvar,
}

static BACKGROUND: Registry = Registry::new();

/// Counts a thread from before it starts until it ends (or never starts).
struct Live(&'static Registry);

impl Drop for Live {
    fn drop(&mut self) {
        *self.0.lock() -= 1;
        self.0.ended.notify_all();
    }
}

impl Registry {
    const fn new() -> Registry {
        Registry {
            live: Mutex::new(0),
            ended: Condvar::new(),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, usize> {
        self.live.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn spawn<T: Send + 'static>(
        &'static self,
        name: String,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> std::io::Result<std::thread::JoinHandle<T>> {
        *self.lock() += 1;
        let live = Live(self);
        std::thread::Builder::new().name(name).spawn(move || {
            let _live = live;
            work()
        })
    }

    fn wait(&self, timeout: Duration) -> usize {
        let live = self.lock();
        *self
            .ended
            .wait_timeout_while(live, timeout, |live| *live > 0)
            .unwrap_or_else(PoisonError::into_inner)
            .0
    }
}

/// A named thread that [`wait_for_background`] waits for.
pub fn spawn<T: Send + 'static>(
    name: String,
    work: impl FnOnce() -> T + Send + 'static,
) -> std::io::Result<std::thread::JoinHandle<T>> {
    BACKGROUND.spawn(name, work)
}

/// Waits until every thread of [`spawn`] has ended, or `timeout` has passed; returns how
/// many are still running. Their owners must have asked them to stop (dropped the engine).
pub fn wait_for_background(timeout: Duration) -> usize {
    BACKGROUND.wait(timeout)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waits_for_threads_that_end_and_gives_up_on_those_that_do_not() {
        static OWN: Registry = Registry::new();
        let (tx, rx) = std::sync::mpsc::channel::<()>();
        let quick = OWN.spawn("quick".into(), || {
            std::thread::sleep(Duration::from_millis(50))
        });
        let held = OWN.spawn("held".into(), move || rx.recv().ok()).unwrap();
        quick.unwrap().join().unwrap();
        // The held thread keeps one live past a short wait, and no more.
        let start = std::time::Instant::now();
        assert_eq!(OWN.wait(Duration::from_millis(300)), 1);
        assert!(start.elapsed() >= Duration::from_millis(300));
        drop(tx);
        held.join().unwrap();
        assert_eq!(OWN.wait(Duration::from_secs(5)), 0);
    }
}
