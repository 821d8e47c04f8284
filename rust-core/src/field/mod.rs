//! Fields that extractors contour: anything that evaluates a value and a gradient at any
//! point, in f64. `sph` is the meshless one, `fe` the high-order finite elements.

pub mod fe;
pub mod grid;
pub mod kernel;
pub mod neighbours;
pub mod particles;
pub mod sph;

use glam::DVec3;

/// A scalar field defined everywhere in space.
pub trait ScalarField: Sync {
    /// F(x).
    fn value(&self, x: DVec3) -> f64;
    /// (F(x), ∇F(x)).
    fn value_and_gradient(&self, x: DVec3) -> (f64, DVec3);
    /// F at the lattice nodes `origin + spacing · (first + l)`, `l` in `0..n` per axis
    /// (x fastest, at most [`BLOCK`] per axis), into `out`: what [`ScalarField::value`]
    /// gives at each, to the bit. Node by node here; the SPH field evaluates the block at
    /// once, each particle visiting the nodes its support covers.
    fn values_on_block(
        &self,
        origin: DVec3,
        spacing: f64,
        first: [i64; 3],
        n: [usize; 3],
        out: &mut [f64],
    ) {
        assert!(n.iter().all(|&m| m <= BLOCK) && out.len() == n[0] * n[1] * n[2]);
        for (v, f) in out.iter_mut().enumerate() {
            let l = [v % n[0], v / n[0] % n[1], v / (n[0] * n[1])];
            let node = DVec3::new(
                (first[0] + l[0] as i64) as f64,
                (first[1] + l[1] as i64) as f64,
                (first[2] + l[2] as i64) as f64,
            );
            *f = self.value(origin + node * spacing);
        }
    }
}

/// Most nodes per axis of one [`ScalarField::values_on_block`] call.
pub const BLOCK: usize = sph::nodes::TILE;

/// Default memory budget for structures sized by the data's extent (4 GiB).
pub const DEFAULT_MEMORY_BUDGET: u64 = 4 << 30;
