//! When freed memory goes back to the system.

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

/// Lets a batch extraction reuse the memory it frees instead of handing it back at once.
/// glibc maps each block past its mmap threshold (which rises to at most 32 MiB) on its
/// own and unmaps it when freed, and returns a heap's top past its trim threshold, so an
/// extraction that allocates and frees a wavefront's lists wave after wave faults the
/// same pages in anew every time: 0.84 M page faults and 2.0–2.5 s of kernel time on the
/// 1.26 M-particle benchmark frame, against 0.54 M with both thresholds raised.
/// `return_freed_memory` still hands back what the extraction frees in bulk, before the
/// mesh is allocated. The setting is process-wide, so only the command line makes it: a
/// host application keeps its own allocator policy.
pub fn reuse_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets the allocator's thresholds; no pointer is involved.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 1 << 30);
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
    }
}
