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
/// Freed pages go back to the system after jemalloc's own 10 s, purged a little at a time
/// from the moment they are freed. Never handing them back (`dirty_decay_ms:-1`) let each
/// arena keep its own in the CPU bake, whose steps allocate on every thread: three 4M-point
/// CPU steps on 2 cores peaked at 12.9 GB against 5.7 GB with the decay (glibc: 6.9 GB),
/// beyond what the jobs' memory estimate allows. A bake whose stages run on a GPU keeps them
/// ([`keep_freed_pages`]).
///
/// The crate prefixes jemalloc's symbols (it does not replace `malloc`), hence the name.
#[cfg(unix)]
#[unsafe(export_name = "_rjem_malloc_conf")]
pub static MALLOC_CONF: Option<&'static u8> = Some(&b"thp:always,metadata_thp:always\0"[0]);

/// Stops jemalloc handing freed pages back to the system from now on, in every arena, those
/// made later too: for a bake whose stages run on a GPU, and a raw case played so. There the
/// decay had the kernel fault and zero the pages again: a series of 64 steps of 1M points on
/// a 16-core H100 host made 1.6 million page faults and spent 26-33 s in the kernel against
/// 8-11 s without it, and a raw case of 1M points played 18-34 % slower in order (58-68 s
/// against 12-13 s in the kernel; its peak memory 5.2-5.3 GB against 6.9). Its peak memory grows by a fifth or less (the
/// series 15.6-15.8 GB against 18.6-19.1, within the jobs' estimate of 2.1 GB a step in
/// flight; the 4M step 3.8 GB against 4.2): most of a step's time is on one thread, whose
/// arena reuses what it freed (`docs/results-bake.md`, stop 57).
pub fn keep_freed_pages() -> Result<(), String> {
    #[cfg(unix)]
    {
        for name in ["arenas.dirty_decay_ms", "arenas.muzzy_decay_ms"] {
            jemalloc::write(name, -1isize)?;
        }
        let narenas: u32 = jemalloc::read("arenas.narenas")?;
        // Arenas not made yet take the defaults just set. One that another thread was making
        // meanwhile may have taken the old ones and be found made only after the pass looked
        // at it: so passes go on until one finds no more arenas made than the one before.
        let mut made_before = None;
        loop {
            let mut made = 0;
            for i in 0..narenas {
                if !jemalloc::read::<bool>(&format!("arena.{i}.initialized"))? {
                    continue;
                }
                made += 1;
                for decay in ["dirty_decay_ms", "muzzy_decay_ms"] {
                    jemalloc::write(&format!("arena.{i}.{decay}"), -1isize)?;
                }
            }
            if made_before == Some(made) {
                break;
            }
            made_before = Some(made);
        }
    }
    Ok(())
}

/// [`keep_freed_pages`] where `stages` run on a device (as `slosh_bake::default_jobs` tells
/// them: the bake's, or a raw case's as it plays), or a line on stderr where jemalloc refuses.
pub fn keep_freed_pages_on_a_device(stages: &slosh_bake::Stages) {
    if stages.device_memory.is_some()
        && let Err(e) = keep_freed_pages()
    {
        eprintln!("freed memory goes back to the system as before: {e}");
    }
}

/// jemalloc's control interface (`mallctl`), by name.
#[cfg(unix)]
mod jemalloc {
    use std::ffi::{CString, c_void};

    fn call<T>(name: &str, old: Option<&mut T>, new: Option<&mut T>) -> Result<(), String> {
        let c_name = CString::new(name).map_err(|e| format!("mallctl name {name:?}: {e}"))?;
        let mut len = size_of::<T>();
        let (old_ptr, old_len) = match old {
            Some(v) => ((v as *mut T).cast::<c_void>(), &mut len as *mut usize),
            None => (std::ptr::null_mut(), std::ptr::null_mut()),
        };
        let (new_ptr, new_len) = match new {
            Some(v) => ((v as *mut T).cast::<c_void>(), size_of::<T>()),
            None => (std::ptr::null_mut(), 0),
        };
        // SAFETY: both values are `T`s of the sizes mallctl is told, the type `name` has.
        let status = unsafe {
            tikv_jemalloc_sys::mallctl(c_name.as_ptr(), old_ptr, old_len, new_ptr, new_len)
        };
        if status == 0 {
            Ok(())
        } else {
            Err(format!("jemalloc's {name}: error {status}"))
        }
    }

    /// The value of `name`, which has type `T`.
    pub(super) fn read<T: Default>(name: &str) -> Result<T, String> {
        let mut value = T::default();
        call(name, Some(&mut value), None)?;
        Ok(value)
    }

    /// Sets `name`, which has type `T`.
    pub(super) fn write<T>(name: &str, mut value: T) -> Result<(), String> {
        call(name, None, Some(&mut value))
    }
}

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
    use std::ffi::{CStr, c_char};

    use super::jemalloc::read;

    fn text(name: &str) -> String {
        let value: Option<&'static c_char> = read(name).expect("a readable option");
        let value = value.unwrap_or_else(|| panic!("{name:?} has no value"));
        // SAFETY: jemalloc returns a pointer to one of its static, NUL-terminated option names.
        unsafe { CStr::from_ptr(value) }
            .to_string_lossy()
            .into_owned()
    }

    /// After [`super::keep_freed_pages`], the arenas made before and after it keep freed
    /// pages; the options read at start-up are unchanged.
    #[test]
    fn a_gpu_bake_keeps_freed_pages() {
        super::keep_freed_pages().expect("the decays set");
        let made_after = std::thread::spawn(|| {
            let held = vec![1u8; 1 << 20];
            let arena: u32 = read("thread.arena").expect("the thread's arena");
            drop(held);
            arena
        })
        .join()
        .expect("the thread ran");
        for arena in [0, made_after] {
            for decay in ["dirty_decay_ms", "muzzy_decay_ms"] {
                let ms: isize = read(&format!("arena.{arena}.{decay}")).expect("the arena's decay");
                assert_eq!(ms, -1, "arena {arena}'s {decay}");
            }
        }
        let ms: isize = read("opt.dirty_decay_ms").expect("the option");
        assert_eq!(ms, 10_000);
    }

    /// The options are [`super::MALLOC_CONF`]'s, not jemalloc's defaults (huge pages left
    /// to the kernel, none for its metadata): a wrong symbol name would leave them unread,
    /// silently. Freed pages go back after jemalloc's own 10 s (and no lazily freed ones
    /// linger after that), as [`super::MALLOC_CONF`] says.
    #[test]
    fn jemalloc_reads_the_options() {
        for (name, want) in [("opt.dirty_decay_ms", 10_000), ("opt.muzzy_decay_ms", 0)] {
            let ms: isize = read(name).expect("the option");
            assert_eq!(ms, want, "{name:?}");
        }
        assert_eq!(text("opt.thp"), "always");
        assert_eq!(text("opt.metadata_thp"), "always");
    }
}
