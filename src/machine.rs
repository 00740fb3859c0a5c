//! What this machine offers: cores and memory available now.

/// Logical cores this process may use.
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Bytes of memory available now (`MemAvailable` in /proc/meminfo), where known.
pub fn available_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Keeps large freed blocks in the process for reuse instead of returning them to the system.
/// A bake allocates and frees gigabytes per step, and glibc unmaps blocks above its (adaptive)
/// mmap threshold when they are freed, so each step faulted its memory in and had the kernel
/// zero it again: a fifth of a 1M-point bake's samples were in `clear_page`, 13 % with these
/// settings.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets the allocator's thresholds; it is called first thing in main,
    // before any other thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
    }
}
