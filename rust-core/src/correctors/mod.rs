//! Marching Correctors (Rosswog-style SPH isosurfaces after the paper in
//! `shared/papers/marching-correctors-sph-isosurfaces.txt`): a virtual grid that is never
//! stored, seed cells from particle pairs, surface tracking from cell to cell, vertices
//! corrected onto the SPH level set, free-surface trimming with the sum of weights.

pub mod cache;
mod estimate;
pub mod seeds;
pub mod surface;
pub mod tracking;
pub mod trimming;
pub mod vertices;

use crate::error::{Error, Result};
use crate::field::particles::ParticleData;
use crate::field::sph::SphField;
use crate::gpu::Backend;
use crate::mc::VirtualGrid;
use crate::mesh::Mesh;
use crate::progress::Progress;
use cache::NodeCache;
use glam::DVec3;
use std::time::Instant;
use vertices::Placement;

/// Free-surface trimming thresholds on the sum of weights.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trim {
    /// Cells with a corner below this are discarded (paper: 0.1).
    pub node: f64,
    /// Triangles are clipped where the sum of weights crosses this (paper: 0.5).
    pub vertex: f64,
}

impl Default for Trim {
    fn default() -> Self {
        Trim {
            node: 0.1,
            vertex: 0.5,
        }
    }
}

/// A fixed lattice for the virtual grid: node positions `origin + (i, j, k) · cell_size`
/// for integers i, j, k. Pieces of a data-parallel extraction share one so their grids
/// coincide where they overlap.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lattice {
    pub origin: DVec3,
    pub cell_size: f64,
}

/// Parameters of an extraction.
#[derive(Clone, Debug, PartialEq)]
pub struct Params {
    /// One surface per value, all in one mesh (with an `Isovalue` array when several).
    pub isovalues: Vec<f64>,
    /// Virtual cell size as a multiple of the smallest smoothing length (paper: c = 0.5).
    pub grid_factor: f64,
    /// Correct vertices onto the level set (quality mode); false = preview.
    pub correct: bool,
    /// Relative tolerance on |F − iso|: absolute = tolerance × |iso| (× the largest |raw
    /// value| when iso = 0).
    pub tolerance: f64,
    /// Trimming at free surfaces; None keeps the whole surface.
    pub trim: Option<Trim>,
    /// Vertex normals (from the SPH gradient in quality mode, from faces in preview).
    pub normals: bool,
    /// Particle arrays to interpolate onto the surface vertices.
    pub attributes: Vec<String>,
    /// Use this lattice instead of `grid_factor` × smallest h from the data's corner.
    pub lattice: Option<Lattice>,
    /// Keep only the surface in cells whose lowest corner lies in the half-open box
    /// `[min, max)`; the surface is still tracked through every particle given (the halo).
    pub clip: Option<(DVec3, DVec3)>,
    /// Bytes the extraction may use. The surface's size is unknown until it is tracked, so
    /// tracking stops with `OverBudget` as soon as what it found would need more (a grid
    /// factor far too fine, say), before building any vertex.
    pub memory_budget: u64,
    /// Where the seed cells' neighbour search runs (`gpu::seeds` on the GPU; the exact
    /// tests stay on the CPU, so every back end gives the same seeds and surface).
    pub backend: Backend,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            isovalues: vec![],
            grid_factor: 0.5,
            correct: true,
            tolerance: 1e-6,
            trim: Some(Trim::default()),
            normals: true,
            attributes: vec![],
            lattice: None,
            clip: None,
            memory_budget: crate::field::DEFAULT_MEMORY_BUDGET,
            backend: Backend::Cpu,
        }
    }
}

impl Params {
    /// Checks every parameter, naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        let bad = |name, message: String| Err(Error::InvalidParameter { name, message });
        if self.isovalues.is_empty() {
            return bad("isovalues", "at least one isovalue is needed".into());
        }
        if let Some(v) = self.isovalues.iter().find(|v| !v.is_finite()) {
            return bad("isovalues", format!("{v} is not a finite number"));
        }
        if !(self.grid_factor > 0.0 && self.grid_factor.is_finite()) {
            return bad(
                "grid_factor",
                format!("must be positive, got {}", self.grid_factor),
            );
        }
        if let Some(l) = self.lattice {
            if !(l.cell_size > 0.0 && l.cell_size.is_finite() && l.origin.is_finite()) {
                return bad(
                    "lattice",
                    format!(
                        "needs a finite origin and a positive cell size, got {:?} and {}",
                        l.origin.to_array(),
                        l.cell_size
                    ),
                );
            }
        }
        if let Some((lo, hi)) = self.clip {
            if !(lo.is_finite() && hi.is_finite() && lo.cmplt(hi).all()) {
                return bad(
                    "clip",
                    format!(
                        "needs min < max on every axis, got {:?} and {:?}",
                        lo.to_array(),
                        hi.to_array()
                    ),
                );
            }
        }
        if !(self.tolerance > 0.0 && self.tolerance < 1.0) {
            return bad(
                "tolerance",
                format!("must lie in (0, 1), got {}", self.tolerance),
            );
        }
        if let Some(t) = self.trim {
            if !(t.node >= 0.0 && t.vertex >= 0.0 && t.node.is_finite() && t.vertex.is_finite()) {
                return bad(
                    "trim",
                    format!(
                        "thresholds must be non-negative and finite, got node {} and vertex {}",
                        t.node, t.vertex
                    ),
                );
            }
        }
        Ok(())
    }
}

/// Time spent per phase, in seconds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Timings {
    pub seeds: f64,
    pub tracking: f64,
    pub vertices: f64,
    pub trimming: f64,
    pub attributes: f64,
    pub total: f64,
}

/// The figures of the paper's Tables I–V, summed over isovalues.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Stats {
    pub virtual_cells: u64,
    pub seed_cells: u64,
    pub non_intersected_seeds: u64,
    pub discarded_cells: u64,
    /// Cells the surface passes through (after discarding).
    pub cells_used: u64,
    pub vertices: u64,
    pub triangles: u64,
    /// Every SPH evaluation: grid nodes, corrections, cut points, attributes.
    pub field_evaluations: u64,
    pub node_lookups: u64,
    /// Nodes evaluated: the missing ones and the rest of their rows of four along x,
    /// which cost little more (`SphField::values_on_row`) and are read later or never.
    pub node_evaluations: u64,
    /// 1 − node evaluations / node lookups.
    pub cache_hit_ratio: f64,
    /// Largest number of nodes the cache held.
    pub cached_nodes: u64,
    pub corrected_vertices: u64,
    pub correction_mean: f64,
    pub correction_max: f64,
    pub correction_stdev: f64,
    /// Vertices whose correction did not reach the tolerance (kept at their best point).
    pub unconverged_vertices: u64,
    pub trim_cut_points: u64,
    /// The back end the seed search ran on: `Cpu` or `Gpu` (never `Auto`).
    pub backend: Backend,
    pub timings: Timings,
    /// What the caller should tell the user although nothing failed: the field's own
    /// warnings, and each isovalue the field never crosses.
    pub warnings: Vec<String>,
}

/// A surface and how it was made.
#[derive(Clone, Debug)]
pub struct Extraction {
    pub mesh: Mesh,
    pub stats: Stats,
}

/// The virtual grid for `field`: cells of `grid_factor` × the smallest smoothing length
/// (or the given lattice), covering every point where some particle's kernel is non-zero.
pub fn virtual_grid(field: &SphField, params: &Params) -> Result<VirtualGrid> {
    let (lo, hi) = field.bounds();
    match params.lattice {
        None => {
            let cell = params.grid_factor * field.min_h();
            let pad = field.max_support() + cell;
            VirtualGrid::covering(lo - pad, hi + pad, cell, "grid_factor")
        }
        Some(l) => {
            let pad = field.max_support() + l.cell_size;
            VirtualGrid::on_lattice(l.origin, l.cell_size, lo - pad, hi + pad)
        }
    }
}

/// Drops the cells outside `params.clip` (by their lowest corner).
pub(crate) fn clip_cells(
    grid: &VirtualGrid,
    cells: &mut Vec<crate::mc::ActiveCell>,
    params: &Params,
) {
    if let Some((lo, hi)) = params.clip {
        cells.retain(|c| {
            let p = grid.node_position(c.key);
            p.cmpge(lo).all() && p.cmplt(hi).all()
        });
    }
}

/// Absolute tolerance on |F − iso| for relative tolerance `rel`.
pub fn absolute_tolerance(field: &SphField, iso: f64, rel: f64) -> f64 {
    let scale = if iso != 0.0 {
        iso.abs()
    } else {
        (0..field.len())
            .map(|i| field.raw_value(i).abs())
            .fold(0.0, f64::max)
            .max(f64::MIN_POSITIVE)
    };
    rel * scale
}

/// Where the seed search finds each particle's neighbours: the CPU's neighbour grid, or
/// candidate lists found once per extraction on the GPU (`gpu::seeds`).
enum Neighbours {
    Cpu,
    #[cfg(feature = "gpu")]
    Gpu(crate::gpu::seeds::Candidates),
}

impl Neighbours {
    /// For a resolved back end (`Cpu` or `Gpu`).
    #[cfg_attr(not(feature = "gpu"), allow(unused_variables))]
    fn new(field: &SphField, backend: Backend) -> Result<Neighbours> {
        match backend {
            #[cfg(feature = "gpu")]
            Backend::Gpu => {
                let gpu = crate::gpu::device::get()?;
                let on_device = crate::gpu::sph::GpuField::new(gpu, field, field.bounds().0)?;
                Ok(Neighbours::Gpu(crate::gpu::seeds::Candidates::new(
                    gpu, &on_device, field,
                )?))
            }
            _ => Ok(Neighbours::Cpu),
        }
    }

    fn seed_cells(
        &self,
        field: &SphField,
        grid: &VirtualGrid,
        iso: f64,
        search: &seeds::SeedSearch,
    ) -> Result<Vec<u64>> {
        match self {
            Neighbours::Cpu => seeds::seed_cells(field, grid, iso, search),
            #[cfg(feature = "gpu")]
            Neighbours::Gpu(c) => crate::gpu::seeds::seed_cells(c, field, grid, iso, search),
        }
    }
}

/// A node cache at least this large is handed back to the system once freed (below it,
/// walking the allocator's free lists is not worth the megabytes).
const RETURN_FREED_BYTES: u64 = 8 << 20;

/// Extracts the isosurfaces of `field` by Marching Correctors. `data` supplies the arrays
/// named in `params.attributes`.
pub fn extract(
    field: &SphField,
    data: &ParticleData,
    params: &Params,
    progress: &mut Progress,
) -> Result<Extraction> {
    params.validate()?;
    let start = Instant::now();
    let grid = virtual_grid(field, params)?;
    let attributes = surface::Carried::new(field, data, &params.attributes)?;
    let mut stats = Stats {
        virtual_cells: grid.cell_count(),
        warnings: field.warnings().to_vec(),
        ..Stats::default()
    };
    let mut cache = NodeCache::for_grid(field, &grid, tracking::index_bytes(params.memory_budget));
    let mut mesh = Mesh::default();
    let n = params.isovalues.len() as f64;
    progress.phase("seed cells", 0.0, 0.0)?;
    let t = Instant::now();
    stats.backend = params.backend.resolve()?;
    let search = seeds::SeedSearch::new(field, params.memory_budget)?;
    let neighbours = Neighbours::new(field, stats.backend)?;
    stats.field_evaluations += field.len() as u64;
    estimate::check_surface_size(field, &grid, params, &neighbours, &search, progress)?;
    // Held only until the last isovalue's seeds: tracking's peak comes later (1M frame:
    // freeing the positions, pair grid and probes took 51-54 MiB off the peak RSS).
    let mut search = Some(search);
    stats.timings.seeds += t.elapsed().as_secs_f64();
    for (k, &iso) in params.isovalues.iter().enumerate() {
        let at = |f: f64| (k as f64 + f) / n;
        progress.phase("seed cells", at(0.0), at(0.1))?;
        let t = Instant::now();
        let searching = search
            .as_ref()
            .expect("kept until the last isovalue's seeds");
        let seeds = neighbours.seed_cells(field, &grid, iso, searching)?;
        if k + 1 == params.isovalues.len() {
            search = None;
        }
        let seeded = seeds.len();
        stats.seed_cells += seeded as u64;
        stats.timings.seeds += t.elapsed().as_secs_f64();

        progress.phase("surface tracking", at(0.1), at(0.5))?;
        let t = Instant::now();
        // Earlier isovalues' surfaces stay in memory: what tracking may hold is the rest.
        let earlier = mesh.heap_bytes();
        let room = Params {
            memory_budget: params.memory_budget.saturating_sub(earlier),
            ..params.clone()
        };
        let mut tracked = tracking::track(field, &grid, seeds, iso, &room, &mut cache, progress)
            .map_err(|e| {
                e.besides(
                    earlier,
                    "the surfaces of the earlier isovalues",
                    params.memory_budget,
                )
            })?;
        // Cells the surface crosses, before trimming (discarded) and clipping took some.
        let crossed = tracked.active.len() as u64 + tracked.discarded;
        clip_cells(&grid, &mut tracked.active, params);
        stats.non_intersected_seeds += tracked.non_intersected_seeds;
        stats.discarded_cells += tracked.discarded;
        stats.cells_used += tracked.active.len() as u64;
        stats.cached_nodes = stats.cached_nodes.max(cache.len() as u64);
        stats.node_lookups = cache.lookups;
        stats.node_evaluations = cache.evaluations;
        stats.cache_hit_ratio = cache.hit_ratio();
        stats.timings.tracking += t.elapsed().as_secs_f64();

        let placement = if params.correct {
            Placement::Corrected {
                field,
                tolerance: absolute_tolerance(field, iso, params.tolerance),
            }
        } else {
            Placement::Linear
        };
        let span = (at(0.5), at(1.0));
        // Tracking visits every cell around a cut edge of a cell it keeps (the faces that
        // edge lies on are crossed), so the list is complete unless cells were dropped.
        let complete = (tracked.discarded == 0 && params.clip.is_none()).then_some(grid.cells);
        let cut = surface::cut_edges(
            &cache,
            &tracked.active,
            complete,
            placement,
            progress,
            span,
            &mut stats,
        )?;
        if k + 1 == params.isovalues.len() {
            // No node is read again: the cache's bricks (more bytes than the finished mesh on
            // large frames) are freed before the mesh's arrays are allocated, and handed
            // back to the system, or the mesh's arrays come on top of them (1M frame: peak
            // RSS 2,246 -> 1,652-1,687 MiB; the hand-back takes 70 ms of 12 s).
            let freed = cache.bytes();
            cache = NodeCache::default();
            if freed >= RETURN_FREED_BYTES {
                crate::heap::return_freed_memory();
            }
        }
        let vertices = surface::place_vertices(&grid, cut, iso, placement, progress, &mut stats)?;
        let part = surface::finish(
            field,
            vertices,
            &tracked.active,
            iso,
            params,
            placement,
            &attributes,
            progress,
            span,
            &mut stats,
        )?;
        // Seed cells come from particle pairs on either side of the isovalue.
        let between = (seeded > 0).then_some(grid.cell_size);
        surface::append_surface(
            &mut mesh,
            part,
            iso,
            crossed,
            between,
            params,
            &mut stats.warnings,
        );
    }
    stats.field_evaluations += stats.node_evaluations;
    stats.vertices = mesh.vertex_count() as u64;
    stats.triangles = mesh.triangles.len() as u64;
    stats.timings.total = start.elapsed().as_secs_f64();
    progress.phase("done", 1.0, 1.0)?;
    Ok(Extraction { mesh, stats })
}
