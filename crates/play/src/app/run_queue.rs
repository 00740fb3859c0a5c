//! How long the UI thread has waited, runnable, for a core: a pass that took long because
//! other processes held the cores is told apart from one that did too much itself.

use std::time::Duration;

/// The time the calling thread has spent runnable but not running since it began, where the
/// kernel keeps it (Linux: `/proc/thread-self/schedstat`, its second field, in nanoseconds).
pub fn waited_for_a_core() -> Option<Duration> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let nanos = text.split_whitespace().nth(1)?.parse().ok()?;
    Some(Duration::from_nanos(nanos))
}
