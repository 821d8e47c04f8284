//! Neighbour lists over a spatial binning (the paper's §4.1): bins as large as the
//! kernel's largest world extent, lists refreshed every few iterations.

use super::particle::Particle;
use glam::{DVec3, I64Vec3};
use rayon::prelude::*;

/// Per-particle neighbour indices, flattened (CSR).
pub(crate) struct Neighbours {
    start: Vec<u32>,
    list: Vec<u32>,
}

impl Neighbours {
    /// Indices of particles within `radius` of each particle whose normals are within 90°
    /// of its own (the paper's rule against neighbours on adjacent sheets), in index order.
    pub fn build(particles: &[Particle], radius: f64) -> Neighbours {
        let key = |x: DVec3| (x / radius).floor().as_i64vec3();
        let mut sorted: Vec<(I64Vec3, u32)> = particles
            .iter()
            .enumerate()
            .map(|(i, p)| (key(p.x), i as u32))
            .collect();
        sorted.par_sort_unstable_by(|a, b| a.0.to_array().cmp(&b.0.to_array()).then(a.1.cmp(&b.1)));
        let r2 = radius * radius;
        let lists: Vec<Vec<u32>> = particles
            .par_iter()
            .enumerate()
            .map(|(i, p)| {
                let k = key(p.x);
                let mut out = Vec::new();
                for dz in -1..=1 {
                    for dy in -1..=1 {
                        for dx in -1..=1 {
                            let b = (k + I64Vec3::new(dx, dy, dz)).to_array();
                            let lo = sorted.partition_point(|e| e.0.to_array() < b);
                            for &(kb, j) in &sorted[lo..] {
                                if kb.to_array() != b {
                                    break;
                                }
                                let q = &particles[j as usize];
                                if j as usize != i
                                    && p.x.distance_squared(q.x) < r2
                                    && p.n.dot(q.n) > 0.0
                                {
                                    out.push(j);
                                }
                            }
                        }
                    }
                }
                out.sort_unstable();
                out
            })
            .collect();
        let mut start = Vec::with_capacity(particles.len() + 1);
        let mut list = Vec::new();
        start.push(0);
        for l in lists {
            list.extend(l);
            start.push(list.len() as u32);
        }
        Neighbours { start, list }
    }

    /// The neighbours of particle i.
    pub fn of(&self, i: usize) -> &[u32] {
        &self.list[self.start[i] as usize..self.start[i + 1] as usize]
    }
}
