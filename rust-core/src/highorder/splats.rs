//! Splat radii. A host draws each sample as a disk; where the disks leave a gap, a render
//! shows a hole. The paper's radius, d/√3 for the local spacing d, is the covering radius
//! of an even hexagonal packing, but the relaxed packing is not even: 4–8 % of a sphere
//! lay outside every disk. Each sample's radius here is the reach of its Voronoi cell
//! among its neighbours, in its tangent plane: every surface point near the sample that
//! is closer to it than to any neighbour lies within it.

use super::neighbours::Neighbours;
use super::particle::Particle;
use rayon::prelude::*;

/// A radius is at most this many times the even-packing radius: a sample at the edge of
/// the surface (the mesh boundary) has no neighbours on one side, and its cell would
/// reach as far as the search does.
const MOST: f64 = 2.5;

/// The covering radius of each particle, at least its even-packing radius `even[i]`.
pub(super) fn covering_radii(particles: &[Particle], even: &[f64]) -> Vec<f64> {
    let largest = even.iter().copied().fold(0.0, f64::max);
    if particles.len() < 2 || largest <= 0.0 {
        return even.to_vec();
    }
    // A neighbour farther than twice the largest radius cannot cut a cell that small.
    let near = Neighbours::build(particles, 2.0 * MOST * largest);
    particles
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let most = MOST * even[i];
            let (t1, t2) = p.n.any_orthonormal_pair();
            // The square whose corners lie at `most`, cut by each neighbour's bisector.
            let h = most / std::f64::consts::SQRT_2;
            let mut cell = vec![[-h, -h], [h, -h], [h, h], [-h, h]];
            for &j in near.of(i) {
                let q = particles[j as usize].x - p.x;
                let v = [q.dot(t1), q.dot(t2)];
                let half = 0.5 * (v[0] * v[0] + v[1] * v[1]);
                if half > 0.0 {
                    cell = clip(&cell, v, half);
                }
            }
            let reach = cell.iter().map(|c| c[0].hypot(c[1])).fold(0.0, f64::max);
            reach.clamp(even[i], most)
        })
        .collect()
}

/// The part of convex polygon `poly` where y · v ≤ `half` (the side of the bisector
/// between the origin and v that holds the origin).
fn clip(poly: &[[f64; 2]], v: [f64; 2], half: f64) -> Vec<[f64; 2]> {
    let side = |a: &[f64; 2]| a[0] * v[0] + a[1] * v[1] - half;
    let mut out = Vec::with_capacity(poly.len() + 1);
    for (k, a) in poly.iter().enumerate() {
        let b = &poly[(k + 1) % poly.len()];
        let (sa, sb) = (side(a), side(b));
        if sa <= 0.0 {
            out.push(*a);
        }
        if (sa < 0.0 && sb > 0.0) || (sa > 0.0 && sb < 0.0) {
            let t = sa / (sa - sb);
            out.push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bisector_keeps_the_origins_side() {
        let square = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];
        // A neighbour at (1, 0): the bisector x = 0.5.
        let cut = clip(&square, [1.0, 0.0], 0.5);
        let reach = cut.iter().map(|c| c[0].hypot(c[1])).fold(0.0, f64::max);
        assert_eq!(cut.len(), 4, "{cut:?}");
        assert!(cut.iter().all(|c| c[0] <= 0.5 + 1e-15), "{cut:?}");
        assert!((reach - 2f64.sqrt()).abs() < 1e-12, "{reach}");
        // Six neighbours at distance 1 (a hexagonal ring): the cell is the hexagon of
        // circumradius 1/√3, the even packing's covering radius.
        let mut cell = square.to_vec();
        for k in 0..6 {
            let a = k as f64 * std::f64::consts::PI / 3.0;
            cell = clip(&cell, [a.cos(), a.sin()], 0.5);
        }
        let reach = cell.iter().map(|c| c[0].hypot(c[1])).fold(0.0, f64::max);
        assert!((reach - 1.0 / 3f64.sqrt()).abs() < 1e-12, "{reach}");
    }
}
