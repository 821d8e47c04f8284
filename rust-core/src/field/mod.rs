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
}

/// Default memory budget for structures sized by the data's extent (4 GiB).
pub const DEFAULT_MEMORY_BUDGET: u64 = 4 << 30;
