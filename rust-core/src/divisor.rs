//! Division by a number fixed at run time as a multiplication and a shift.
//!
//! Turning a lattice index into coordinates divides by the lattice's dimensions, which
//! are known only at run time, so the compiler emits `div`: tens of cycles each, and the
//! slider's update does it for every key it looks up. For 32-bit numerators a 64-bit
//! reciprocal rounded up gives the exact quotient (Lemire, Kaser and Kurz, "Faster
//! remainder by direct computation", 2019: with c = ⌈2⁶⁴ / d⌉, ⌊n / d⌋ = ⌊c·n / 2⁶⁴⌋
//! for every n < 2³²).

/// A divisor in 2 ..= u32::MAX with its reciprocal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Divisor {
    d: u64,
    /// ⌈2⁶⁴ / d⌉ (fits: d ≥ 2).
    c: u64,
}

impl Divisor {
    /// Panics unless 2 ≤ `d` (1 would need 2⁶⁴).
    pub(crate) fn new(d: u32) -> Divisor {
        assert!(d >= 2, "divisor {d} below 2");
        let d = d as u64;
        Divisor {
            d,
            c: u64::MAX / d + 1,
        }
    }

    /// (n / d, n % d).
    #[inline(always)]
    pub(crate) fn div_rem(self, n: u32) -> (u32, u32) {
        let q = ((self.c as u128 * n as u128) >> 64) as u64;
        (q as u32, (n as u64 - q * self.d) as u32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Quotient and remainder equal the hardware's for divisors small, odd, powers of two
    /// and near the top, at numerators around multiples of the divisor and at the ends.
    #[test]
    fn agrees_with_integer_division() {
        let mut next = crate::test_rng::lcg(3);
        let mut divisors = vec![
            2u32,
            3,
            5,
            7,
            8,
            255,
            256,
            257,
            641,
            65_536,
            1 << 31,
            u32::MAX,
        ];
        divisors.extend((0..200).map(|_| ((next() >> 21) as u32).max(2)));
        for d in divisors {
            let div = Divisor::new(d);
            let mut ns = vec![0u32, 1, d - 1, d, u32::MAX, u32::MAX - 1];
            for k in [1u64, 2, 3, 1000] {
                let m = k * d as u64;
                ns.extend(
                    [m - 1, m, m + 1]
                        .into_iter()
                        .filter(|&n| n <= u32::MAX as u64)
                        .map(|n| n as u32),
                );
            }
            ns.extend((0..200).map(|_| (next() >> 21) as u32));
            for n in ns {
                assert_eq!(div.div_rem(n), (n / d, n % d), "{n} / {d}");
            }
        }
    }
}
