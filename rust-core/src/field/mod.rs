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
    /// F at the nodes of a [`TILE`]³ block of the lattice `origin + spacing · (first + l)`
    /// that `rows` marks (bit x of `rows[y + TILE · z]` for local node (x, y, z)), into
    /// `out[x + TILE · (y + TILE · z)]`; unmarked entries are left as they are. Each
    /// value is what [`ScalarField::value`] gives at the node, to the bit. Node by node
    /// here; the SPH field takes the tile at once, each particle visiting the marked nodes
    /// its support covers.
    fn values_on_tile(
        &self,
        origin: DVec3,
        spacing: f64,
        first: [i64; 3],
        rows: &[u8; TILE * TILE],
        out: &mut [f64; TILE * TILE * TILE],
    ) {
        for (r, &marked) in rows.iter().enumerate() {
            for x in (0..TILE).filter(|x| marked >> x & 1 == 1) {
                let l = [x, r % TILE, r / TILE];
                let node = DVec3::new(
                    (first[0] + l[0] as i64) as f64,
                    (first[1] + l[1] as i64) as f64,
                    (first[2] + l[2] as i64) as f64,
                );
                out[x + TILE * r] = self.value(origin + node * spacing);
            }
        }
    }
}

/// Nodes per axis of one [`ScalarField::values_on_tile`] tile (a row's nodes are one
/// byte's bits).
pub const TILE: usize = 8;

/// Default memory budget for structures sized by the data's extent (4 GiB).
pub const DEFAULT_MEMORY_BUDGET: u64 = 4 << 30;
