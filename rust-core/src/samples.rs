//! Oriented point samples of a surface: the output of extractors that place points rather
//! than triangles (the high-order particle system), kept beside [`crate::mesh::Mesh`] so
//! writers and hosts treat both alike.

use crate::field::particles::Attribute;

/// Points on a surface with unit normals and splat radii, plus named per-point arrays.
/// Positions stay f64 for the same reason as mesh vertices (they are on the level set to
/// a tolerance that f32 would not keep); hosts convert at their boundary.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointSamples {
    pub positions: Vec<[f64; 3]>,
    /// Unit normals (along the field's gradient), one per point.
    pub normals: Vec<[f32; 3]>,
    /// Radius of the disk each point stands for: the reach of its Voronoi cell among its
    /// neighbours in its tangent plane, so that the disks cover the surface (at least
    /// d/√3 for the local spacing d, an even packing's, and at most 2.5 times that).
    pub radii: Vec<f64>,
    /// Per-point arrays (element id, reference coordinates, curvature, energy ...).
    pub attributes: Vec<Attribute>,
}

impl PointSamples {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when there are no points.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// The per-point array called `name`, if present.
    pub fn attribute(&self, name: &str) -> Option<&Attribute> {
        self.attributes.iter().find(|a| a.name == name)
    }

    /// Distance from each point to its nearest other point (brute force over a uniform
    /// binning); the statistic tests use to judge how evenly points are spread.
    pub fn nearest_neighbour_distances(&self) -> Vec<f64> {
        let n = self.positions.len();
        if n < 2 {
            return vec![f64::INFINITY; n];
        }
        let p: Vec<glam::DVec3> = self.positions.iter().map(|&q| q.into()).collect();
        let (lo, hi) = p
            .iter()
            .fold((p[0], p[0]), |(a, b), &q| (a.min(q), b.max(q)));
        // About two points per bin on a surface of n points.
        let cell = ((hi - lo).max_element() / (n as f64 / 2.0).sqrt()).max(1e-300);
        let key = |q: glam::DVec3| ((q - lo) / cell).floor().as_ivec3();
        let mut bins: std::collections::HashMap<glam::IVec3, Vec<usize>> = Default::default();
        for (i, &q) in p.iter().enumerate() {
            bins.entry(key(q)).or_default().push(i);
        }
        (0..n)
            .map(|i| {
                let k = key(p[i]);
                let mut best = f64::INFINITY;
                let mut ring = 1;
                loop {
                    for dz in -ring..=ring {
                        for dy in -ring..=ring {
                            for dx in -ring..=ring {
                                for &j in bins
                                    .get(&(k + glam::IVec3::new(dx, dy, dz)))
                                    .into_iter()
                                    .flatten()
                                {
                                    if j != i {
                                        best = best.min(p[i].distance(p[j]));
                                    }
                                }
                            }
                        }
                    }
                    // Anything in a ring further out is at least ring·cell away.
                    if best <= ring as f64 * cell || ring > 64 {
                        return best;
                    }
                    ring += 1;
                }
            })
            .collect()
    }
}
