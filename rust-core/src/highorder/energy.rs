//! The compact cotangent energy of Meyer et al. (SMI 2005) and the distance scaling of the
//! paper's eq. 6.

use std::f64::consts::{FRAC_PI_2, PI};

/// β = 0.5 / cos(π/6) = 1/√3: the hexagonal-packing constant of eq. 6.
pub(crate) const BETA: f64 = 0.577_350_269_189_625_8;

/// E(r) = cot(rπ/2) + rπ/2 − π/2 for r < 1, else 0: infinite at 0, zero with zero slope at 1.
pub fn energy(r: f64) -> f64 {
    if r >= 1.0 {
        return 0.0;
    }
    let a = r.max(1e-12) * FRAC_PI_2;
    1.0 / a.tan() + a - FRAC_PI_2
}

/// dE/dr (negative: the energy repels).
pub fn energy_derivative(r: f64) -> f64 {
    if r >= 1.0 {
        return 0.0;
    }
    let s = (r.max(1e-12) * FRAC_PI_2).sin();
    FRAC_PI_2 * (1.0 - 1.0 / (s * s))
}

/// Distance scale α between two particles with mean curvature magnitude `d` (eq. 6):
/// α = β (1 + ρ d s / 2π) / s, bounded by `alpha_max`.
///
/// Eq. 6 as printed divides by sβ, which ends the kernel at 0.58 s, inside the first ring
/// of a hexagonal packing of spacing s, where every energy would vanish; the text says the
/// kernel ends at the two-ring (√3 s = s/β), which is this α. The kernel's world extent on
/// a plane is therefore s/β, the size of the neighbour bins.
pub fn alpha(s: f64, rho: f64, d: f64, alpha_max: f64) -> f64 {
    (BETA * (1.0 + rho * d * s / (2.0 * PI)) / s).min(alpha_max)
}

/// Energy of a particle in an ideal hexagonal packing of spacing s on a plane: six
/// neighbours at r = β (the two-ring sits exactly at the kernel's end).
pub fn ideal_energy() -> f64 {
    6.0 * energy(BETA)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derivative_matches_differences_and_kernel_is_compact() {
        for r in [0.1, 0.3, 0.5, 0.7, 0.9, 0.99] {
            let h = 1e-6;
            let fd = (energy(r + h) - energy(r - h)) / (2.0 * h);
            assert!((fd - energy_derivative(r)).abs() < 1e-5 * (1.0 + fd.abs()));
        }
        assert!(energy(1.0) == 0.0 && energy(1.0 - 1e-9).abs() < 1e-12);
        assert!(energy(0.5) > 0.0 && energy_derivative(0.5) < 0.0);
        assert!((BETA - 0.5 / (PI / 6.0).cos()).abs() < 1e-15);
        assert!(ideal_energy() > 0.0);
    }
}
