//! Software prefetch: loops over scattered memory (a sliding surface's cells in its
//! brick maps, their nodes' values in the store's bricks) name the addresses they will read a few
//! iterations ahead, so that the cache misses of several iterations overlap instead of
//! each stalling in turn.

/// Starts loading the cache line holding `value` into the caches. Only a hint: it reads
/// nothing the program can see and cannot fault; nothing happens on targets without it.
#[inline(always)]
pub(crate) fn prefetch<T>(value: &T) {
    prefetch_address(value as *const T);
}

/// [`prefetch`] by address, for memory no reference may be made to (another thread may
/// be writing it): the address need not be valid, nothing is read or faulted.
#[inline(always)]
pub(crate) fn prefetch_address<T>(address: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch neither reads into the program nor faults, whatever the address.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>(address.cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = address;
}
