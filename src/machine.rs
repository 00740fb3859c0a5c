//! How this process uses the machine's memory.

/// Keeps freed memory in the process for reuse instead of returning it to the system. A bake
/// allocates and frees gigabytes per step, and glibc maps every block above its mmap
/// threshold (32 MB at most) afresh and unmaps it when freed, so each step faulted its large
/// arrays in and had the kernel zero them again (a fifth of a 1M-point bake's samples were in
/// `clear_page`). With no mmap at all, large blocks come from the heap, which is never trimmed,
/// and later steps reuse it.
///
/// Threads other than the first allocate from heaps of their own (64 MB each), and glibc
/// unmaps a thread's extra heap once it is wholly free, whatever the trim threshold, unless
/// the top pad asks to keep that much: so the pad is one such heap. What each saved, in page
/// faults and wall time, is in `docs/results-bake.md`.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets the allocator's thresholds; it is called first thing in main,
    // before any other thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_MAX, 0);
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
        libc::mallopt(libc::M_TOP_PAD, THREAD_HEAP_BYTES);
    }
}

/// The most a glibc thread heap holds (`HEAP_MAX_SIZE` on 64-bit systems).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const THREAD_HEAP_BYTES: i32 = 64 << 20;
