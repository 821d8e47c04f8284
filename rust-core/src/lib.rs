//! isobar: exact isosurfaces of SPH (meshless) data.
//!
//! Data flows one way: file or host arrays -> [`field`] -> extractor ([`correctors`],
//! [`baseline`]) -> [`mesh::Mesh`] -> writer or host. See ARCHITECTURE.md.

pub mod adaptive;
pub mod baseline;
pub mod capi;
pub mod correctors;
mod divisor;
pub mod error;
mod exact;
pub mod field;
pub mod gpu;
pub mod heap;
pub mod highorder;
pub mod io;
pub mod mc;
pub mod mesh;
mod prefetch;
pub mod progress;
pub mod samples;
pub mod slider;
pub mod terminal;
#[cfg(test)]
mod test_rng;

pub use error::{Error, Result};
