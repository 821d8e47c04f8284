//! The unit tests' pseudo-random numbers: one 64-bit linear congruential generator
//! (Knuth's MMIX constants), deterministic from its seed, so no test depends on a seed
//! crate or on the run.

/// Successive 53-bit values from `seed`.
pub(crate) fn lcg(mut state: u64) -> impl FnMut() -> u64 {
    move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        state >> 11
    }
}

/// Successive values uniform in [0, 1) from `seed`.
pub(crate) fn unit(seed: u64) -> impl FnMut() -> f64 {
    let mut next = lcg(seed);
    move || next() as f64 / (1u64 << 53) as f64
}
