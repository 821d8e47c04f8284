//! Software prefetch: loops over scattered memory (a sliding surface's cells in its
//! brick maps, their nodes in a mapped volume) name the addresses they will read a few
//! iterations ahead, so that the cache misses of several iterations overlap instead of
//! each stalling in turn.

/// Starts loading the cache line holding `value` into the caches. Only a hint: it reads
/// nothing the program can see and cannot fault; nothing happens on targets without it.
#[inline(always)]
pub(crate) fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch neither reads into the program nor faults; `value` is a live
    // reference in any case.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>((value as *const T).cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}
