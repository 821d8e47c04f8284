//! Sampled Hausdorff distance between two triangle meshes: how far one extraction's
//! surface strays from another's (the adaptive surface against the uniform finest one).

use crate::mesh::Mesh;
use glam::{DVec3, IVec3};
use rayon::prelude::*;
use std::collections::HashMap;

/// Point–triangle distance (closest point by regions, Ericson §5.1.5).
pub fn point_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return p.distance(a);
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return p.distance(b);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return p.distance(a + ab * (d1 / (d1 - d3)));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return p.distance(c);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return p.distance(a + ac * (d2 / (d2 - d6)));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return p.distance(b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))));
    }
    let denom = 1.0 / (va + vb + vc);
    p.distance(a + ab * (vb * denom) + ac * (vc * denom))
}

/// One-sided distance from samples of `from` (vertices, edge midpoints, centroids) to
/// `to`, searching triangles in buckets of size `bucket` (≥ the distances expected).
pub fn directed_hausdorff(from: &Mesh, to: &Mesh, bucket: f64) -> f64 {
    let pos = |m: &Mesh, i: u32| DVec3::from(m.positions[i as usize]);
    let key = |p: DVec3| (p / bucket).floor().as_ivec3();
    let mut buckets: HashMap<IVec3, Vec<usize>> = HashMap::new();
    for (t, tri) in to.triangles.iter().enumerate() {
        let [a, b, c] = tri.map(|i| pos(to, i));
        let (lo, hi) = (key(a.min(b).min(c)), key(a.max(b).max(c)));
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    buckets.entry(IVec3::new(x, y, z)).or_default().push(t);
                }
            }
        }
    }
    let distance = |p: DVec3| -> f64 {
        let k = key(p);
        let mut best = f64::INFINITY;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if let Some(ts) = buckets.get(&(k + IVec3::new(dx, dy, dz))) {
                        for &t in ts {
                            let [a, b, c] = to.triangles[t].map(|i| pos(to, i));
                            best = best.min(point_triangle(p, a, b, c));
                        }
                    }
                }
            }
        }
        best
    };
    from.triangles
        .par_iter()
        .map(|tri| {
            let [a, b, c] = tri.map(|i| pos(from, i));
            [a, (a + b) / 2.0, (a + b + c) / 3.0]
                .into_iter()
                .map(&distance)
                .fold(0.0, f64::max)
        })
        .reduce(|| 0.0, f64::max)
}

/// Symmetric Hausdorff distance (sampled).
pub fn hausdorff(a: &Mesh, b: &Mesh, bucket: f64) -> f64 {
    directed_hausdorff(a, b, bucket).max(directed_hausdorff(b, a, bucket))
}
