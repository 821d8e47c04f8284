//! ISOSLIDER: isovalue sliding on large regular volumes
//! (`../shared/papers/isoslider-interactive-isovalue-sliding.txt`).
//!
//! [`build::build_store`] sorts the node values and writes, into one store file, the
//! level-0 blocks (per node, which lattice edges turn on and off as the isovalue passes
//! it), the skip-list levels consolidating them with redundant edges removed, and the
//! values vertices are interpolated from. [`runtime::Slider`] maps the store and keeps one
//! isosurface in memory, updated coherently by [`runtime::Slider::set_isovalue`]: work is
//! proportional to the change in the surface, not to the volume. [`full::extract`] is the
//! from-scratch marching cubes of the same volume it must equal. [`lod`] merges cells of
//! the current surface into coarser ones within an error bound, crack-free. `cli` holds the
//! `slide-build` and `slide` commands.

pub mod build;
pub mod cli;
pub mod full;
pub mod lod;
pub mod runtime;
mod sort;
pub mod store;
mod value_bricks;
mod window;

pub use build::{build_store, BuildParams, BuildStats};
pub use lod::{LodMesh, LodParams};
pub use runtime::{Change, Slider, SliderStats};
pub use store::Store;
