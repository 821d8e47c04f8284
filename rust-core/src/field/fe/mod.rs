//! High-order finite elements: Lagrange hexahedra, tetrahedra and wedges of any order in
//! VTK's node ordering, used both for the geometry (the mapping T from reference to world
//! space) and for the field, as VTK's Lagrange cells are.
//!
//! `shape` numbers the nodes, `classic` reads VTK's linear and quadratic cells as the
//! Lagrange cells of the same functions, `basis` evaluates basis functions with first and second
//! derivatives, `mesh` assembles T, J, ∂J, the world-space gradient and Hessian (the
//! paper's eqs. 19–20), checks elements and pairs faces, `locate` carries a reference
//! point across a face into the neighbouring cell, `bernstein` gives each cell a box that
//! provably holds it (its mapping's Bézier control points), `search` finds the cell and
//! reference point of a world point over those boxes (T⁻¹, for the marching-cubes baseline),
//! `probe` evaluates the field at world points
//! through it, `curvature` gives
//! principal curvatures.

mod basis;
mod bernstein;
pub(crate) mod classic;
pub mod curvature;
mod locate;
mod mesh;
mod probe;
mod search;
mod shape;
#[cfg(test)]
mod tests;

pub use basis::BasisValues;
pub use locate::Walk;
pub(crate) use locate::INSIDE_SLACK;
pub use mesh::{Evaluation, FeMesh, Scratch};
pub use probe::{probe, Hit};
pub use search::CellIndex;
pub use shape::{Kind, Shape};
