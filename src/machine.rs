//! How this process uses the machine's memory.
//!
//! A bake allocates and frees gigabytes per step. With glibc's allocator every step faulted
//! its large arrays in again and had the kernel zero them, in 4 KiB pages: on a 16-core
//! H100 host, 64 steps of 1M points through `slosh bake --device gpu` made 8.3 million page
//! faults and spent 24-27 s in the kernel beside 130-139 s in the bake. So Rust's
//! allocations come from jemalloc, which keeps what is freed for reuse for a while and backs
//! it with transparent huge pages ([`MALLOC_CONF`]). What each choice saved is in
//! `docs/results-bake.md`.

/// The allocator of every Rust allocation in the binary.
#[cfg(unix)]
#[global_allocator]
static ALLOCATOR: tikv_jemallocator::Jemalloc = tikv_jemallocator::Jemalloc;

/// jemalloc's options, read at its first allocation, before `main`: `thp:always` and
/// `metadata_thp:always` advise its memory for transparent huge pages (the kernels here give
/// them only where asked), 512 times fewer faults and TLB entries.
///
/// Freed pages go back to the system after jemalloc's own 10 s: steps in flight reuse them
/// long before. Never handing them back (`dirty_decay_ms:-1`) saved a few more faults but
/// let each arena keep its own: three 4M-point CPU steps on 2 cores peaked at 12.9 GB against
/// 5.7 GB with the decay (glibc: 6.9 GB), beyond what the jobs' memory estimate allows.
///
/// The crate prefixes jemalloc's symbols (it does not replace `malloc`), hence the name.
#[cfg(unix)]
#[unsafe(export_name = "_rjem_malloc_conf")]
pub static MALLOC_CONF: Option<&'static u8> = Some(&b"thp:always,metadata_thp:always\0"[0]);

/// Keeps memory that the C libraries free (zstd's contexts, a software Vulkan driver's
/// buffers), which glibc's `malloc` serves, in the process for reuse too. glibc maps every
/// block above its mmap threshold (32 MB at most) afresh and unmaps it when freed; with no
/// mmap at all, large blocks come from the heap, which is never trimmed.
///
/// Threads other than the first allocate from heaps of their own (64 MB each), and glibc
/// unmaps a thread's extra heap once it is wholly free, whatever the trim threshold, unless
/// the top pad asks to keep that much: so the pad is one such heap.
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

#[cfg(all(test, unix))]
mod tests {
    use std::ffi::{CStr, c_char, c_void};

    /// Reads jemalloc's option `name` into `value`, of the option's own type.
    fn read<T>(name: &CStr, value: &mut T) {
        let mut len = size_of::<T>();
        // SAFETY: `value` is a `T` of `len` bytes, the size mallctl is told; nothing is written.
        let status = unsafe {
            tikv_jemalloc_sys::mallctl(
                name.as_ptr(),
                (value as *mut T).cast::<c_void>(),
                &mut len,
                std::ptr::null_mut(),
                0,
            )
        };
        assert_eq!(status, 0, "mallctl({name:?}) failed: {status}");
    }

    fn text(name: &CStr) -> String {
        let mut value: *const c_char = std::ptr::null();
        read(name, &mut value);
        assert!(!value.is_null(), "{name:?} has no value");
        // SAFETY: jemalloc returns a pointer to one of its static, NUL-terminated option names.
        unsafe { CStr::from_ptr(value) }
            .to_string_lossy()
            .into_owned()
    }

    /// The options are [`super::MALLOC_CONF`]'s, not jemalloc's defaults (huge pages left
    /// to the kernel, none for its metadata): a wrong symbol name would leave them unread,
    /// silently. Freed pages go back after jemalloc's own 10 s (and no lazily freed ones
    /// linger after that), as [`super::MALLOC_CONF`] says.
    #[test]
    fn jemalloc_reads_the_options() {
        for (name, want) in [(c"opt.dirty_decay_ms", 10_000), (c"opt.muzzy_decay_ms", 0)] {
            let mut ms: isize = -2;
            read(name, &mut ms);
            assert_eq!(ms, want, "{name:?}");
        }
        assert_eq!(text(c"opt.thp"), "always");
        assert_eq!(text(c"opt.metadata_thp"), "always");
    }
}
