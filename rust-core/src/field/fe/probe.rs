//! The field at arbitrary world points: the cell holding each point (over a
//! [`CellIndex`]), T⁻¹ by Newton in that cell, and the Lagrange interpolant there. What a
//! host needs to grade another method's vertices or to resample a solution; the particle
//! system never needs it (its particles live in reference space).

use super::{CellIndex, FeMesh, Scratch};
use glam::DVec3;
use rayon::prelude::*;

/// Where a probed point lies and the field there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// The cell holding the point (the first in index order where faces are shared).
    pub cell: usize,
    /// The point's reference coordinates in that cell (T⁻¹(x)).
    pub reference: DVec3,
    /// F*(reference) of the probed point array.
    pub value: f64,
}

/// For every world point, the cell holding it, its reference point there and the point
/// array `values` (one value per mesh point) interpolated there; None where no cell holds
/// the point. Points are independent, so the result does not depend on the thread count.
pub fn probe(
    mesh: &FeMesh,
    index: &CellIndex,
    values: &[f64],
    points: &[DVec3],
) -> Vec<Option<Hit>> {
    assert_eq!(
        values.len(),
        mesh.points.len(),
        "probe: the array has a value per mesh point"
    );
    points
        .par_iter()
        .with_min_len(64)
        .map_init(Scratch::default, |scratch, &x| {
            let mut evaluations = 0;
            let (cell, reference) = index.locate_thorough(mesh, x, scratch, &mut evaluations)?;
            let value = mesh.value(values, cell, reference, scratch);
            Some(Hit {
                cell,
                reference,
                value,
            })
        })
        .collect()
}
