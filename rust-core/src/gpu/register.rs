//! Particle registration on the GPU (`shaders/register.wgsl`, Algorithm 1 step 1): the
//! coarse cell of every particle and the atomic count per cell, equal to
//! `adaptive::grid::register` for every input.
//!
//! Design. WGSL has no f64 and the CPU registration floors an f64 quotient, so an f32
//! division on the device would put particles within its rounding of a face in the
//! neighbouring cell. Instead the CPU turns its own cell function into per-axis
//! thresholds (`CoarseGrid::registration_thresholds`, bisection over f64 values: exact
//! by construction) and the kernel only *compares* the f32 positions the field upload
//! already holds with the thresholds rounded to f32. Rounding is monotone, so a strict
//! comparison is a proof about the f64 values; only an equal pair (a particle within half
//! an f32 ulp of a face) is undecided, and the kernel lists it for the CPU, which places
//! it with `CoarseGrid::cell_of`. The device does the per-particle work (locating and
//! counting, with atomics); the CPU's part is O(cells) thresholds and the deferred ones.
//! Those are few on moving fluid (0–5 of 24–47 thousand particles on the real frames the
//! tests use) but can be most of a frame whose particles still sit on their initial
//! lattice, when that lattice is commensurate with the coarse cells: its particles then
//! lie within f32 rounding of faces. Still exact; only the split of the work changes.
//!
//! Why not the other designs. Cell coordinates computed on the CPU and uploaded would
//! leave the device only the counting, after the CPU did the work the step is about, and
//! add 4 bytes a particle to the upload. Fixed-point positions would add 12 bytes a
//! particle (the f32 positions stay for the field) and their quantisation on the CPU is
//! the same per-particle work again. An f32 quotient with a correction step needs the
//! f64 residual on the device for the particles near a face: the thresholds give the same
//! decision without it.
//!
//! The result is only the counts: the next steps (splitting, dilation, balancing) read
//! nothing else, and the field's particle order on the device is the neighbour grid's.

use super::device::{gpu_error, Gpu};
use super::sph::GpuField;
use crate::adaptive::grid::{self, CoarseGrid};
use crate::error::Result;
use crate::field::sph::SphField;

/// `Register` of register.wgsl.
#[repr(C)]
#[derive(Clone, Copy)]
struct RegisterUniform {
    count: u32,
    cells: [u32; 3],
    base: [u32; 3],
    total: u32,
}

fn source() -> (&'static str, &'static str) {
    kernel_source!("register.wgsl", "register.wgsl")
}

/// Counts per coarse cell and how they were found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Registration {
    /// Particles per coarse cell (`CoarseGrid::index` order), equal to
    /// `grid::register`'s.
    pub counts: Vec<u32>,
    /// Particles the comparisons could not place (within half an f32 ulp of a coarse
    /// face), placed on the CPU.
    pub deferred: usize,
}

/// Registers `field`'s particles (uploaded as `on_device`, relative to `grid.origin`) on
/// `grid`. A particle outside the grid gives `grid::register`'s error.
pub fn register(
    gpu: &Gpu,
    on_device: &GpuField,
    field: &SphField,
    grid: &CoarseGrid,
) -> Result<Registration> {
    // The thresholds are offsets from the grid's origin: the device positions must be
    // the same offsets (rounded to f32), not offsets from another point.
    if on_device.origin != grid.origin {
        return Err(gpu_error(format!(
            "registration needs the particles relative to the grid origin {}, they are relative to {}",
            grid.origin, on_device.origin
        )));
    }
    let n = field.len();
    let total = grid.cell_count();
    let thresholds = grid.registration_thresholds();
    let mut base = [0u32; 3];
    let mut words: Vec<f32> = Vec::new();
    for (a, t) in thresholds.iter().enumerate() {
        base[a] = u32::try_from(words.len()).map_err(gpu_error)?;
        // `as f32` rounds to nearest, the same monotone rounding as the positions'.
        words.extend(t.iter().map(|&d| d as f32));
    }
    let uniform = RegisterUniform {
        count: u32::try_from(n).map_err(gpu_error)?,
        cells: grid.cells,
        base,
        total: u32::try_from(total).map_err(gpu_error)?,
    };
    let thresholds = gpu.upload("registration thresholds", &words);
    let uniform = gpu.uniform("register", &uniform);
    // One more count than cells: the last is the number of deferred particles.
    let counts = gpu.zeroed::<u32>("cell counts", total + 1)?;
    let deferred = gpu.zeroed::<u32>("deferred particles", n)?;
    gpu.dispatch(
        source(),
        "register_particles",
        &[
            (0, &on_device.particles),
            (3, &uniform),
            (4, &thresholds),
            (5, &counts),
            (6, &deferred),
        ],
        n as u64,
    )?;
    let mut counts: Vec<u32> = gpu.read(&counts, total + 1)?;
    let undecided = counts.pop().expect("the deferred counter") as usize;
    let slots: Vec<u32> = gpu.read(&deferred, undecided)?;
    for &slot in &slots {
        match grid.cell_of(field.position(slot as usize)) {
            Some(c) => counts[c] += 1,
            // Outside the grid: the CPU registration names the first such particle.
            None => {
                let positions: Vec<_> = (0..n).map(|i| field.position(i)).collect();
                grid::register(grid, &positions)?;
                return Err(gpu_error(format!(
                    "particle slot {slot} was deferred as outside the grid, but the CPU places every particle"
                )));
            }
        }
    }
    Ok(Registration {
        counts,
        deferred: undecided,
    })
}

// SAFETY: a plain `repr(C)` struct of 4-byte scalars without padding; any bits are valid.
unsafe impl bytemuck::Zeroable for RegisterUniform {}
unsafe impl bytemuck::Pod for RegisterUniform {}
