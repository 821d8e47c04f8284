//! Handing freed memory back to the system.

/// Asks the allocator to return freed memory to the system. glibc keeps freed blocks
/// below its (self-raising) mmap threshold in its heaps, each thread's arena included, so
/// memory freed as many small blocks (a brick map's bricks, a kilobyte each) still counts
/// as resident, and whatever is allocated next comes on top of it. `malloc_trim` hands
/// those pages back. It walks the allocator's free lists (70 ms after the node cache of
/// the 1.26 M-particle benchmark frame), so it is called only after freeing megabytes;
/// elsewhere the allocator's own policy stands.
pub(crate) fn return_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only releases free memory; no pointer is involved.
    unsafe {
        libc::malloc_trim(0);
    }
}
