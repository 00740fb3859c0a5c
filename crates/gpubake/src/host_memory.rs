//! Host arrays as large as a step's neighbour lists (hundreds of megabytes at 1M points),
//! filled once from a read-back: each 4 KB page of a fresh allocation costs a fault and a
//! clear when first written, and on the H100 host copying a 1M step's lists to the host took
//! 266.7 of the lists stage's 435.9 ms. Transparent huge pages take one fault per 2 MB.

/// Asks the kernel to back the whole 2 MB pages of `words`' capacity with transparent huge
/// pages, before they are first written (where transparent huge pages are `madvise`d, the
/// usual default). Advice only: where the kernel or the allocator cannot, nothing changes.
pub(crate) fn advise_huge_pages<T>(words: &mut Vec<T>) {
    #[cfg(target_os = "linux")]
    {
        // A transparent huge page on x86-64 and aarch64 Linux.
        const HUGE_PAGE: usize = 2 << 20;
        let start = words.as_mut_ptr() as usize;
        let end = start + words.capacity() * size_of::<T>();
        let (first, last) = (
            start.next_multiple_of(HUGE_PAGE),
            end / HUGE_PAGE * HUGE_PAGE,
        );
        if last > first {
            // SAFETY: the range lies within the vector's own allocation, and MADV_HUGEPAGE
            // changes how its pages are backed, never their contents; its result is advice
            // taken or not.
            unsafe {
                libc::madvise(
                    first as *mut libc::c_void,
                    last - first,
                    libc::MADV_HUGEPAGE,
                );
            }
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = words;
}
