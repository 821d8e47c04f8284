//! Marching Correctors' seed-cell selection with the neighbour search on the GPU
//! (`shaders/seeds.wgsl`): the kernels list, for every particle, the particles within its
//! side radius enlarged by [`MARGIN`] (an f32 search cannot decide the boundary exactly);
//! `correctors::seeds::seed_cells_with` then applies the CPU's exact f64 tests (side
//! coverage, pair radius, straddling classes) and walks the segments. A superset of
//! candidates gives exactly the CPU's seeds, which the tests check.

use super::device::{gpu_error, Gpu};
use super::level::scan;
use super::sph::GpuField;
use crate::correctors::seeds::{seed_cells_with, side_radius, SeedSearch};
use crate::error::Result;
use crate::field::sph::SphField;
use crate::mc::VirtualGrid;

/// Relative enlargement of the squared search radius: f32 distances of particles at
/// 1e3 smoothing lengths from the origin err by ~1e-4 of h².
pub(crate) const MARGIN: f64 = 0.02;

#[repr(C)]
#[derive(Clone, Copy)]
struct SeedsUniform {
    count: u32,
    pad: [u32; 3],
}

fn source() -> (&'static str, &'static str) {
    kernel_source!("seeds.wgsl", "seeds.wgsl")
}

/// Every particle's neighbour candidates (grid slots), found on the GPU once per field.
pub struct Candidates {
    /// `list[offsets[i]..offsets[i + 1]]` are particle i's candidates.
    pub offsets: Vec<u32>,
    pub list: Vec<u32>,
}

impl Candidates {
    /// Runs the search for `field` (uploaded as `on_device`).
    pub fn new(gpu: &Gpu, on_device: &GpuField, field: &SphField) -> Result<Candidates> {
        let n = field.len();
        let radius2: Vec<f32> = (0..n)
            .map(|i| (side_radius(field, i).powi(2) * (1.0 + MARGIN)) as f32)
            .collect();
        let radius2 = gpu.upload("side radius²", &radius2);
        let uniform = gpu.uniform(
            "seeds",
            &SeedsUniform {
                count: u32::try_from(n).map_err(gpu_error)?,
                pad: [0; 3],
            },
        );
        let offsets = gpu.zeroed::<u32>("candidate offsets", n + 1)?;
        let [f0, f1, f2] = on_device.bindings();
        // The counting pass names `found` too (it shares the search function).
        let unused = gpu.zeroed::<u32>("no candidates yet", 1)?;
        gpu.dispatch(
            source(),
            "count_candidates",
            &[
                f0,
                f1,
                f2,
                (3, &uniform),
                (4, &radius2),
                (5, &offsets),
                (6, &unused),
            ],
            n as u64,
        )?;
        scan(gpu, &offsets, n as u64 + 1)?;
        let offsets_host: Vec<u32> = gpu.read(&offsets, n + 1)?;
        let total = offsets_host[n] as usize;
        let found = gpu.zeroed::<u32>("candidates", total)?;
        gpu.dispatch(
            source(),
            "write_candidates",
            &[
                f0,
                f1,
                f2,
                (3, &uniform),
                (4, &radius2),
                (5, &offsets),
                (6, &found),
            ],
            n as u64,
        )?;
        Ok(Candidates {
            list: gpu.read(&found, total)?,
            offsets: offsets_host,
        })
    }
}

/// Sorted, unique seed-cell keys for `iso`, equal to `correctors::seeds::seed_cells`.
pub fn seed_cells(
    candidates: &Candidates,
    field: &SphField,
    grid: &VirtualGrid,
    iso: f64,
    search: &SeedSearch,
) -> Result<Vec<u64>> {
    seed_cells_with(field, grid, iso, search, |i, visit| {
        let range = candidates.offsets[i] as usize..candidates.offsets[i + 1] as usize;
        visit(&candidates.list[range])
    })
}

// SAFETY: plain `repr(C)` structs of 4-byte scalars without padding; any bits are valid.
unsafe impl bytemuck::Zeroable for SeedsUniform {}
unsafe impl bytemuck::Pod for SeedsUniform {}
