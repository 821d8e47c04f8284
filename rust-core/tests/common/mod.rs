//! Helpers shared by the integration tests: synthetic particle sets and an independent
//! brute-force SPH evaluator (all particles, no neighbour grid, no shared code path
//! beyond the kernel formulas).
#![allow(dead_code)]

use glam::DVec3;
use isobar::field::kernel::Kernel;
use isobar::field::particles::{Attribute, ParticleData};

/// A deterministic pseudo-random generator (tests must not depend on a seed source).
pub struct Lcg(pub u64);
impl Lcg {
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Particles on a jittered cubic lattice filling the box `lo..hi` with spacing `dx`,
/// with a scalar 'pressure' growing with depth and a 'velocity' vector.
pub fn block(lo: DVec3, hi: DVec3, dx: f64, seed: u64) -> ParticleData {
    let mut rng = Lcg(seed);
    let n = ((hi - lo) / dx).floor();
    let mut positions = Vec::new();
    for k in 0..=n.z as i64 {
        for j in 0..=n.y as i64 {
            for i in 0..=n.x as i64 {
                let jitter = DVec3::new(rng.next(), rng.next(), rng.next()) - 0.5;
                positions
                    .push(lo + DVec3::new(i as f64, j as f64, k as f64) * dx + jitter * 0.2 * dx);
            }
        }
    }
    with_fields(positions, hi.z)
}

/// Adds 'pressure' (hydrostatic below `top`) and 'velocity' arrays.
pub fn with_fields(positions: Vec<DVec3>, top: f64) -> ParticleData {
    let pressure = positions
        .iter()
        .map(|p| 1000.0 * 9.81 * (top - p.z))
        .collect();
    let velocity = positions.iter().map(|p| [p.y, -p.x, 0.1 * p.z]).collect();
    ParticleData {
        positions,
        attributes: vec![
            Attribute::scalar("pressure", pressure),
            Attribute::vector("velocity", velocity),
        ],
        ..Default::default()
    }
}

/// Brute-force SPH: volumes from densities computed over all pairs (constant mass), then
/// A(x) and S(x) summed over all particles.
pub struct Brute {
    pub kernel: Kernel,
    pub h: f64,
    pub positions: Vec<DVec3>,
    pub volumes: Vec<f64>,
    pub values: Vec<f64>,
}

impl Brute {
    pub fn new(kernel: Kernel, h: f64, positions: &[DVec3], values: Vec<f64>) -> Self {
        let volumes = positions
            .iter()
            .map(|&x| {
                1.0 / positions
                    .iter()
                    .map(|&y| kernel.value(x.distance(y), h))
                    .sum::<f64>()
            })
            .collect();
        Brute {
            kernel,
            h,
            positions: positions.to_vec(),
            volumes,
            values,
        }
    }

    /// (A(x), S(x)).
    pub fn eval(&self, x: DVec3) -> (f64, f64) {
        let mut a = 0.0;
        let mut s = 0.0;
        for ((p, v), val) in self.positions.iter().zip(&self.volumes).zip(&self.values) {
            let w = v * self.kernel.value(x.distance(*p), self.h);
            a += w * val;
            s += w;
        }
        (a, s)
    }
}
