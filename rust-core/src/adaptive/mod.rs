//! Adaptive crack-free SPH surfaces on 3-level grids, after
//! `shared/papers/gpu-adaptive-3level-sph-surfaces.txt`: coarse cells split to level 3
//! where they hold few particles (the paper's splashes; off by default, see
//! [`DEFAULT_SPLASH_THRESHOLD`]), cells at the surface raised to the lowest
//! level whose surface lies within `max_error` finest cells of the finest one ([`refine`]), cells
//! hiding a droplet between their sub-cell corners raised until a node sees it
//! ([`refine::hidden_surfaces`]), face neighbours raised so levels differ by at most one,
//! marching cubes per level with bisected edge points that coincide across levels, and
//! the cracks between levels filled from a table of every transition-face pattern.
//!
//! [`extract_sph`] is the whole pipeline on an SPH field; [`extract`] takes any field and
//! a level map, which the tests use to force every mix of levels.

pub mod cli;
pub mod crack_gen;
pub mod crack_table;
pub mod cracks;
pub mod grid;
pub mod lattice;
pub mod levels;
pub mod refine;

use crate::error::{three_digits, Error, Result};
use crate::field::sph::carried::Carried;
use crate::field::sph::SphField;
use crate::field::ScalarField;
use crate::gpu::Backend;
use crate::mesh::Mesh;
use crate::progress::Progress;
use grid::CoarseGrid;
use lattice::Lattice;
use levels::LevelArrays;
use std::time::Instant;

/// Default of [`Params::max_error`] in finest cells. The criterion bounds each cell's own
/// surface (a sample near a face against the face neighbour's surface too) and the crack
/// triangles in its faces against finer cells; the extractor's points, bisected in the
/// field rather than on the lattice, add a little (up to 0.1 on a saddle), so it sits
/// below the target of half a finest cell:
/// with no splash cells, at 0.4 the splashsurf frames and shapes in `shared/data` stay
/// within 0.5 finest cells of the uniform finest surface at grid factors 0.375 and 0.5
/// (`tests/adaptive_frames.rs`, `bench/results/adaptive_splash.md`, worst 0.497).
pub const DEFAULT_MAX_ERROR: f64 = 0.4;

/// Default of [`Params::splash_threshold`]: no splash cells. The paper's rule (1: a coarse
/// cell holding one particle is a splash) assumes coarse cells holding many particles; at
/// the cell sizes users pick for SPH surfaces (finest cells of 0.375–0.5 h, coarse cells
/// of 1.5–2 particle spacings) every ordinary surface cell holds one to three particles,
/// so the rule put most of the surface at level 3 (90 % of dam_break_23's triangles):
/// 1.03–1.7× fewer triangles than uniform on 20 of the 22 frame settings measured, where
/// the error criterion alone gives 1.4–13× (at the default max_error) and keeps droplets
/// fine where their surface needs it (`bench/results/adaptive_splash.md`, session 25).
pub const DEFAULT_SPLASH_THRESHOLD: u32 = 0;

/// Most layers [`Params::splash_dilation`] may ask for.
pub(crate) const MAX_SPLASH_DILATION: u32 = 8;

/// Parameters of an adaptive extraction. The field itself (kernel, h, h-scale, which
/// quantity) is chosen with `SphSettings`, as for Marching Correctors.
#[derive(Clone, Debug, PartialEq)]
pub struct Params {
    pub isovalue: f64,
    /// Finest (level-3) cell size as a multiple of the smallest smoothing length; coarse
    /// cells are four times larger.
    pub grid_factor: f64,
    /// Splash criterion: a coarse cell holding 1..=this many particles becomes level 3
    /// (paper: 1; default 0, none: see [`DEFAULT_SPLASH_THRESHOLD`]).
    pub splash_threshold: u32,
    /// Layers of neighbour cells (26-neighbourhood) raised to level 3 around each splash
    /// cell, so a droplet's whole kernel support is contoured finely (0 = the paper).
    pub splash_dilation: u32,
    /// Error criterion, added to the splash one: a cell at or next to the surface takes
    /// the lowest level whose marching-cubes surface lies within this many finest cells
    /// of the finest level's in that cell ([`refine`]). 0 = off (the splash criterion
    /// alone).
    pub max_error: f64,
    /// Hidden-surface rule ([`refine::hidden_surfaces`]): a cell rises to the level whose
    /// sub-cell corners see the side of the isovalue that the field at one of its
    /// particles lies on (a droplet or bubble between the corners would otherwise vanish).
    /// Independent of `max_error`: it guards topology, not distance. On by default.
    pub hidden_surfaces: bool,
    /// n: bisection halvings on level-3 edges (n+1 on level 2, n+2 on level 1; paper: 5),
    /// then linear interpolation. 0 places level-3 points linearly between the finest
    /// nodes, as uniform marching cubes does, and coarser edges halve only down to the
    /// finest lattice (values already stored): points still coincide across levels.
    pub bisection_iterations: u32,
    /// Vertex normals from the field gradient.
    pub normals: bool,
    /// Bytes the grid arrays may take; larger grids are refused before allocation.
    pub memory_budget: u64,
    /// Where the per-level work runs (`extract_sph` only; `extract` is CPU).
    pub backend: Backend,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            isovalue: 0.5,
            grid_factor: 0.5,
            splash_threshold: DEFAULT_SPLASH_THRESHOLD,
            splash_dilation: 1,
            max_error: DEFAULT_MAX_ERROR,
            hidden_surfaces: true,
            bisection_iterations: 5,
            normals: true,
            memory_budget: crate::field::DEFAULT_MEMORY_BUDGET,
            backend: Backend::Cpu,
        }
    }
}

impl Params {
    /// Checks every parameter, naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        let bad = |name, message: String| Err(Error::InvalidParameter { name, message });
        if !self.isovalue.is_finite() {
            return bad(
                "isovalue",
                format!("{} is not a finite number", self.isovalue),
            );
        }
        if !(self.grid_factor > 0.0 && self.grid_factor.is_finite()) {
            return bad(
                "grid_factor",
                format!("must be positive, got {}", self.grid_factor),
            );
        }
        if !(self.max_error >= 0.0 && self.max_error.is_finite()) {
            return bad(
                "max_error",
                format!(
                    "must be 0 (off) or a positive number of finest cells, got {}",
                    self.max_error
                ),
            );
        }
        // Each layer is a coarse cell (four finest cells) around a splash cell; the kernel
        // support a layer is meant to cover is one or two of them, and each layer costs a
        // pass over every cell of the grid.
        if self.splash_dilation > MAX_SPLASH_DILATION {
            return bad(
                "splash_dilation",
                format!(
                    "must lie in 0..={MAX_SPLASH_DILATION} layers of coarse cells, got {}",
                    self.splash_dilation
                ),
            );
        }
        if self.bisection_iterations > 16 {
            return bad(
                "bisection_iterations",
                format!("must lie in 0..=16, got {}", self.bisection_iterations),
            );
        }
        Ok(())
    }
}

/// Seconds per phase.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Timings {
    /// Registration, splitting and level adjustment.
    pub levels: f64,
    /// Marching cubes of the three levels (field values, edges, triangles).
    pub surfaces: f64,
    pub cracks: f64,
    /// Merging the levels' points into one mesh.
    pub assembly: f64,
    /// Particle arrays carried onto the vertices ([`carry`]).
    pub attributes: f64,
    pub total: f64,
}

/// What an extraction did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Stats {
    pub coarse_cells: u64,
    /// Coarse cells of level 1, 2, 3.
    pub cells_per_level: [u64; 3],
    /// Marching-cubes triangles from cells of level 1, 2, 3.
    pub triangles_per_level: [u64; 3],
    /// Raises by the error criterion, to level 2 and to level 3: its per-cell test, then
    /// cells balancing had raised to a level off by more than `max_error` (to 3) and
    /// cells whose crack triangles were off (one level up; a cell raised 1 → 2 this way
    /// and then 2 → 3 counts in both).
    pub error_raised: [u64; 2],
    /// Cells the hidden-surface rule raised (before balancing).
    pub hidden_raised: u64,
    pub transition_faces: u64,
    pub crack_triangles: u64,
    pub vertices: u64,
    pub triangles: u64,
    pub field_evaluations: u64,
    /// Points found on several levels whose positions differ (0 when bisection agrees).
    pub point_mismatches: u64,
    /// Bytes of the per-level arrays at their largest (values, cases, offsets, edges,
    /// points, triangles) on the host, with the finest-lattice values the CPU back end
    /// keeps near the surface: on the GPU back end values and cases stay on the device.
    pub array_bytes: u64,
    pub timings: Timings,
    /// The back end that ran (`Cpu` or `Gpu`, never `Auto`).
    pub backend: Backend,
    /// What the caller should tell the user although nothing failed (see
    /// [`crate::correctors::Stats::warnings`]).
    pub warnings: Vec<String>,
}

/// A surface and how it was made.
#[derive(Clone, Debug)]
pub struct Extraction {
    pub mesh: Mesh,
    pub stats: Stats,
}

/// The coarse grid for `field`: finest cells of `grid_factor` × the smallest smoothing
/// length, covering every point where some kernel is non-zero plus one coarse cell, so the
/// grid's border lies outside every surface.
pub fn grid_for(field: &SphField, params: &Params) -> Result<CoarseGrid> {
    let (lo, hi) = field.bounds();
    let fine = params.grid_factor * field.min_h();
    let pad = field.max_support() + fine * grid::FINE_PER_COARSE as f64;
    CoarseGrid::covering(lo - pad, hi + pad, fine)
}

/// Steps 1–3 on `field`'s particles: registration, splitting, level adjustment.
pub fn levels_for(field: &SphField, grid: &CoarseGrid, params: &Params) -> Result<Vec<u8>> {
    Ok(levels_and_refined(field, grid, params, &mut Progress::none())?.levels)
}

/// The cell levels and what came with them.
#[derive(Clone, Debug)]
pub struct Levels {
    /// Level of each coarse cell, balanced.
    pub levels: Vec<u8>,
    /// What the criteria did.
    pub refined: refine::Refined,
    /// The finest-lattice values the error criterion evaluated, for the level surfaces.
    pub lattice: Lattice,
}

/// [`levels_for`] and what came with them.
fn levels_and_refined(
    field: &SphField,
    grid: &CoarseGrid,
    params: &Params,
    progress: &mut Progress,
) -> Result<Levels> {
    check_grid_budget(field, grid, params)?;
    let positions: Vec<_> = (0..field.len()).map(|i| field.position(i)).collect();
    let counts = grid::register(grid, &positions)?;
    progress.report(0.1)?;
    levels_from_counts(field, grid, &positions, &counts, params, progress)
}

/// Bytes per coarse cell held while the levels are chosen: the particle count (4), the
/// level (1), and one byte more for a pass's copy (dilation) or the corner signs (the
/// error criterion).
const LEVEL_STEP_BYTES_PER_CELL: u64 = 6;

/// Bytes the per-cell arrays of the level step take for `grid`.
fn level_step_bytes(grid: &CoarseGrid) -> u64 {
    grid.cell_count() as u64 * LEVEL_STEP_BYTES_PER_CELL
}

/// Bytes the level step needs on `grid` before anything is allocated: the per-cell arrays
/// with the coarse-node values the error criterion evaluates, or the level arrays with
/// every cell at level 1 (levels only rise), whichever is more.
fn grid_bytes(grid: &CoarseGrid, params: &Params) -> u64 {
    let corners = if params.max_error > 0.0 {
        Lattice::corner_bytes(grid)
    } else {
        0
    };
    let all_level_1 = grid.cell_count() as u64 * (levels::bytes_per_cell(1) + 5);
    (level_step_bytes(grid) + corners).max(all_level_1)
}

/// Refuses a coarse grid whose arrays ([`grid_bytes`]) exceed the budget, before minutes
/// of work on a grid that cannot be contoured, naming the grid factor that fits.
fn check_grid_budget(field: &SphField, grid: &CoarseGrid, params: &Params) -> Result<()> {
    let needed = grid_bytes(grid, params);
    if needed <= params.memory_budget {
        return Ok(());
    }
    // Cells scale with 1 / grid factor³, but the padding does not shrink with them and
    // counts are whole: from the cube-root guess, coarser until the grid fits. The
    // coarsest grids keep a few cells a side, so a budget below theirs fits none.
    let fits = |factor: f64| {
        let coarser = Params {
            grid_factor: factor,
            ..params.clone()
        };
        grid_for(field, &coarser).is_ok_and(|g| grid_bytes(&g, &coarser) <= params.memory_budget)
    };
    let guess = params.grid_factor * (needed as f64 / params.memory_budget.max(1) as f64).cbrt();
    let remedy = (0..200)
        .map(|k| guess * 1.02f64.powi(k))
        .find(|&factor| fits(factor))
        .map_or_else(
            || "no grid factor fits this budget".to_string(),
            |factor| format!("a grid factor of at least {} fits", three_digits(factor)),
        );
    Err(Error::OverBudget {
        what: format!(
            "a coarse grid of {}×{}×{} cells ({remedy})",
            grid.cells[0], grid.cells[1], grid.cells[2]
        ),
        needed_bytes: needed,
        budget_bytes: params.memory_budget,
    })
}

/// Steps 2–3 from step 1's particle counts per coarse cell: the splash criterion and its
/// dilation, the hidden-surface rule at the `positions` of the particles
/// ([`refine::hidden_surfaces`]), the error criterion on `field` ([`refine`]), then
/// balancing. Both back ends take their levels from here (the GPU's field evaluations for
/// the levels run here on the CPU), so they contour the same cells.
pub fn levels_from_counts<F: ScalarField + ?Sized>(
    field: &F,
    grid: &CoarseGrid,
    positions: &[glam::DVec3],
    counts: &[u32],
    params: &Params,
    progress: &mut Progress,
) -> Result<Levels> {
    let mut levels = grid::split(counts, params.splash_threshold);
    progress.nested(0.1, 0.2, |p| {
        grid::dilate(grid, &mut levels, params.splash_dilation, p)
    })?;
    // The coarse nodes first: the hidden-surface rule and the error criterion read them
    // (and level 1 contours them, but with both off the extraction evaluates them then).
    let mut lattice = Lattice::new(grid);
    // What the per-cell arrays leave.
    let budget = params.memory_budget.saturating_sub(level_step_bytes(grid));
    let corners = if params.hidden_surfaces || params.max_error > 0.0 {
        progress.nested(0.2, 0.25, |p| lattice.cover_corners(field, grid, budget, p))?
    } else {
        0
    };
    // Before the error criterion, so that its balancing rounds test the neighbours these
    // cells pull up.
    let hidden = if params.hidden_surfaces {
        refine::hidden_surfaces(
            field,
            grid,
            &lattice,
            positions,
            &mut levels,
            params.isovalue,
        )
    } else {
        refine::Refined::default()
    };
    progress.report(0.3)?;
    let mut refined = progress.nested(0.3, 0.9, |p| {
        refine::refine(
            field,
            grid,
            counts,
            &mut levels,
            params.isovalue,
            params.max_error,
            &mut lattice,
            budget,
            p,
        )
    })?;
    refined.evaluations += corners;
    refined.hidden = hidden.hidden;
    refined.evaluations += hidden.evaluations;
    let balanced = progress.nested(0.9, 1.0, |p| {
        refine::balance_within(
            grid,
            &lattice,
            &mut levels,
            params.isovalue,
            params.max_error,
            p,
        )
    })?;
    refined.raised[0] += balanced[0];
    refined.raised[1] += balanced[1];
    Ok(Levels {
        levels,
        refined,
        lattice,
    })
}

/// Adds the error criterion's work to an extraction's stats.
fn add_refined(stats: &mut Stats, refined: refine::Refined) {
    stats.error_raised = refined.raised;
    stats.hidden_raised = refined.hidden;
    stats.field_evaluations += refined.evaluations;
}

/// The adaptive surface of an SPH field.
pub fn extract_sph(
    field: &SphField,
    params: &Params,
    progress: &mut Progress,
) -> Result<Extraction> {
    params.validate()?;
    let start = Instant::now();
    progress.phase("cell levels", 0.0, 0.05)?;
    let grid = grid_for(field, params)?;
    let mut out = match params.backend.resolve()? {
        Backend::Gpu => extract_sph_gpu(field, &grid, params, progress, start)?,
        _ => {
            let Levels {
                levels,
                refined,
                mut lattice,
            } = levels_and_refined(field, &grid, params, progress)?;
            let elapsed = start.elapsed().as_secs_f64();
            let mut out = extract_on(field, &grid, &levels, &mut lattice, params, progress)?;
            out.stats.timings.levels = elapsed;
            add_refined(&mut out.stats, refined);
            out
        }
    };
    out.stats.timings.total += out.stats.timings.levels;
    out.stats
        .warnings
        .splice(0..0, field.warnings().iter().cloned());
    Ok(out)
}

/// Carries the particle arrays in `carried` onto the surface's vertices, as Marching
/// Correctors does (Shepard-normalised SPH interpolation, one field evaluation a vertex),
/// on either back end's mesh.
pub fn carry(
    field: &SphField,
    carried: &Carried,
    out: &mut Extraction,
    progress: &mut Progress,
) -> Result<()> {
    if carried.is_empty() {
        return Ok(());
    }
    let t = Instant::now();
    progress.phase("attributes", 0.0, 1.0)?;
    let attributes = carried.onto(field, &out.mesh.positions, progress)?;
    out.mesh.attributes.extend(attributes);
    out.stats.field_evaluations += out.mesh.positions.len() as u64;
    let elapsed = t.elapsed().as_secs_f64();
    out.stats.timings.attributes += elapsed;
    out.stats.timings.total += elapsed;
    Ok(())
}

/// [`extract_sph`], then [`carry`]: the run's progress window `from..to` (a caller's share
/// after building the field), its last 5 % for the arrays when there are any.
pub fn extract_sph_carrying(
    field: &SphField,
    carried: &Carried,
    params: &Params,
    (from, to): (f64, f64),
    progress: &mut Progress,
) -> Result<Extraction> {
    let end = if carried.is_empty() {
        to
    } else {
        to - 0.05 * (to - from)
    };
    progress.window(from, end);
    let mut out = extract_sph(field, params, progress)?;
    progress.window(end, to);
    carry(field, carried, &mut out, progress)?;
    Ok(out)
}

/// [`extract_sph`] on the GPU: the field uploaded once, registration on the device
/// (`gpu::register`, counts equal to the CPU's), splitting and balancing on the CPU, then
/// [`extract_gpu`]'s per-level work on the same upload. `timings.levels` includes the
/// field upload, which the per-level work would otherwise pay.
#[cfg(feature = "gpu")]
fn extract_sph_gpu(
    field: &SphField,
    grid: &CoarseGrid,
    params: &Params,
    progress: &mut Progress,
    start: Instant,
) -> Result<Extraction> {
    check_grid_budget(field, grid, params)?;
    let gpu = crate::gpu::device::get()?;
    let on_device = crate::gpu::sph::GpuField::new(gpu, field, grid.origin)?;
    let registered = crate::gpu::register::register(gpu, &on_device, field, grid)?;
    // The error criterion's samples are evaluated on the CPU (`refine`), so the GPU
    // contours exactly the CPU's levels.
    let positions: Vec<_> = (0..field.len()).map(|i| field.position(i)).collect();
    // The lattice the criterion filled serves only the CPU's level surfaces.
    let Levels {
        levels, refined, ..
    } = levels_from_counts(
        field,
        grid,
        &positions,
        &registered.counts,
        params,
        progress,
    )?;
    let elapsed = start.elapsed().as_secs_f64();
    let mut out = extract_gpu_on(gpu, &on_device, field, grid, &levels, params, progress)?;
    out.stats.timings.levels = elapsed;
    add_refined(&mut out.stats, refined);
    Ok(out)
}

#[cfg(not(feature = "gpu"))]
fn extract_sph_gpu(
    _: &SphField,
    _: &CoarseGrid,
    _: &Params,
    _: &mut Progress,
    _: Instant,
) -> Result<Extraction> {
    Err(crate::gpu::adapter_name().expect_err("no GPU without the feature"))
}

/// The adaptive surface of any field on `grid` with the given cell levels (checked:
/// 1..=3, face neighbours at most one apart, see [`grid::check_levels`]). Every surface
/// must stay inside the grid: its border nodes should lie below the isovalue.
pub fn extract<F: ScalarField + ?Sized>(
    field: &F,
    grid: &CoarseGrid,
    levels: &[u8],
    params: &Params,
    progress: &mut Progress,
) -> Result<Extraction> {
    extract_on(
        field,
        grid,
        levels,
        &mut Lattice::new(grid),
        params,
        progress,
    )
}

/// [`extract`] reading and adding to the finest-lattice values in `lattice`.
fn extract_on<F: ScalarField + ?Sized>(
    field: &F,
    grid: &CoarseGrid,
    levels: &[u8],
    lattice: &mut Lattice,
    params: &Params,
    progress: &mut Progress,
) -> Result<Extraction> {
    let lattice = std::cell::RefCell::new(lattice);
    let mut out = extract_with(
        grid,
        levels,
        params,
        progress,
        |level, progress| {
            let mut lattice = lattice.borrow_mut();
            let budget = params.memory_budget;
            let covering = progress.nested(0.0, 0.3, |p| {
                lattice.cover_level(field, grid, levels, level, budget, p)
            })?;
            let mut built = progress.nested(0.3, 1.0, |p| {
                levels::build_level(
                    field,
                    grid,
                    levels,
                    level,
                    &lattice,
                    params.isovalue,
                    params.bisection_iterations,
                    params.normals,
                    p,
                )
            })?;
            built.evaluations += covering;
            Ok(built)
        },
        |arrays, faces, progress| {
            cracks::fill(grid, levels, arrays, faces, params.isovalue, progress)
        },
        || lattice.borrow().bytes(),
    )?;
    out.stats.array_bytes += lattice.borrow().bytes();
    Ok(out)
}

/// [`extract_sph`]'s per-level work (`gpu::level`) and crack filling (`gpu::cracks`) on
/// the GPU with given levels (the tests force levels this way); the assembly as on the
/// CPU. `extract_sph` itself goes through `extract_sph_gpu`, which registers on the device.
#[cfg(all(test, feature = "gpu"))]
pub(crate) fn extract_gpu(
    field: &SphField,
    grid: &CoarseGrid,
    levels: &[u8],
    params: &Params,
    progress: &mut Progress,
) -> Result<Extraction> {
    let gpu = crate::gpu::device::get()?;
    let on_device = crate::gpu::sph::GpuField::new(gpu, field, grid.origin)?;
    extract_gpu_on(gpu, &on_device, field, grid, levels, params, progress)
}

/// [`extract_gpu`] with `field` already on the device (relative to `grid.origin`).
#[cfg(feature = "gpu")]
fn extract_gpu_on(
    gpu: &crate::gpu::device::Gpu,
    on_device: &crate::gpu::sph::GpuField,
    field: &SphField,
    grid: &CoarseGrid,
    levels: &[u8],
    params: &Params,
    progress: &mut Progress,
) -> Result<Extraction> {
    // One table of settled nodes for all levels; cracks compare the levels' settled
    // values with the same f32 isovalue.
    let sides = std::cell::RefCell::new(crate::gpu::sides::Sides::new(
        gpu,
        field,
        grid,
        params.isovalue,
    ));
    let iso = sides.borrow().iso32;
    // Each level's device buffers, kept for crack filling to bind as they are.
    let on_level = std::cell::RefCell::new(Vec::with_capacity(3));
    let mut out = extract_with(
        grid,
        levels,
        params,
        progress,
        |level, progress| {
            let built = crate::gpu::level::build_level(
                gpu,
                on_device,
                grid,
                levels,
                level,
                &mut sides.borrow_mut(),
                params.bisection_iterations,
                params.normals,
                progress,
            )?;
            on_level.borrow_mut().push(built.buffers);
            Ok(built.arrays)
        },
        // One dispatch: nothing to report between.
        |_, faces, _| {
            let b = on_level.borrow();
            let fine = [b[1].as_ref(), b[2].as_ref()];
            crate::gpu::cracks::fill(gpu, grid, levels, fine, faces, iso)
        },
        // Values and cases stay on the device.
        || 0,
    )?;
    out.stats.backend = Backend::Gpu;
    Ok(out)
}

/// Fill triangles of the transition faces from the three levels' arrays, as
/// [`cracks::fill`] gives them.
type Fills = Vec<[(u8, u32); 3]>;

/// Levels checked, then `build` for levels 1, 2, 3, `fill` for the cracks of every
/// transition face, and the mesh assembled. `held` gives the bytes the back end holds
/// besides the level arrays (the CPU's finest-lattice values): with the arrays built so
/// far they must stay within the budget, checked after each level, before the next.
fn extract_with(
    grid: &CoarseGrid,
    levels: &[u8],
    params: &Params,
    progress: &mut Progress,
    mut build: impl FnMut(u8, &mut Progress) -> Result<LevelArrays>,
    fill: impl FnOnce(&[LevelArrays], &[cracks::TransitionFace], &mut Progress) -> Result<Fills>,
    held: impl Fn() -> u64,
) -> Result<Extraction> {
    params.validate()?;
    progress.phase("checking levels", 0.0, 0.05)?;
    grid::check_levels(grid, levels, progress)?;
    levels::check_budget(levels, held(), params.memory_budget)?;
    let start = Instant::now();
    let mut stats = Stats {
        coarse_cells: levels.len() as u64,
        ..Stats::default()
    };
    for &l in levels {
        stats.cells_per_level[l as usize - 1] += 1;
    }
    let t = Instant::now();
    let mut arrays: Vec<LevelArrays> = Vec::with_capacity(3);
    for level in 1..=3u8 {
        let from = 0.05 + 0.25 * (level - 1) as f64;
        progress.phase("level surfaces", from, from + 0.25)?;
        let a = build(level, progress)?;
        stats.field_evaluations += a.evaluations;
        stats.triangles_per_level[level as usize - 1] = a.triangles.len() as u64;
        arrays.push(a);
        let needed = arrays.iter().map(array_bytes).sum::<u64>() + held();
        if needed > params.memory_budget {
            return Err(Error::OverBudget {
                what: format!(
                    "the adaptive surface's arrays up to level {level} ({} / {} / {} cells of \
                     level 1 / 2 / 3; a larger grid factor or max_error needs fewer)",
                    stats.cells_per_level[0], stats.cells_per_level[1], stats.cells_per_level[2]
                ),
                needed_bytes: needed,
                budget_bytes: params.memory_budget,
            });
        }
    }
    stats.array_bytes = arrays.iter().map(array_bytes).sum();
    stats.timings.surfaces = t.elapsed().as_secs_f64();

    progress.phase("crack filling", 0.8, 0.9)?;
    let t = Instant::now();
    let faces = progress.nested(0.0, 0.3, |p| cracks::transition_faces(grid, levels, p))?;
    let fills = progress.nested(0.3, 1.0, |p| fill(&arrays, &faces, p))?;
    stats.transition_faces = faces.len() as u64;
    stats.crack_triangles = fills.len() as u64;
    stats.timings.cracks = t.elapsed().as_secs_f64();

    progress.phase("assembly", 0.9, 1.0)?;
    let t = Instant::now();
    let (mesh, mismatches) = assemble(&arrays, &fills, params.normals);
    stats.point_mismatches = mismatches;
    stats.timings.assembly = t.elapsed().as_secs_f64();
    stats.vertices = mesh.vertex_count() as u64;
    stats.triangles = mesh.triangles.len() as u64;
    if mesh.triangles.is_empty() {
        stats
            .warnings
            .push(crate::mesh::no_surface(params.isovalue));
    }
    stats.timings.total = start.elapsed().as_secs_f64();
    progress.phase("done", 1.0, 1.0)?;
    Ok(Extraction { mesh, stats })
}

fn array_bytes(a: &LevelArrays) -> u64 {
    (a.cells.len() * 4
        + a.values.len() * 8
        + a.cases.len()
        + a.triangle_offsets.len() * 4
        + a.edges.len() * 8
        + a.points.len() * std::mem::size_of::<levels::EdgePoint>()
        + a.triangles.len() * 12) as u64
}

/// One mesh from the levels: points merged by their finest-edge identity (bit-identical
/// wherever several levels found them), then each level's triangles and the fills.
/// Also returns how many repeated points disagreed with the first one found.
fn assemble(arrays: &[LevelArrays], fills: &[[(u8, u32); 3]], normals: bool) -> (Mesh, u64) {
    let mut ids: Vec<(u64, u8, u32)> = arrays
        .iter()
        .flat_map(|a| {
            a.points
                .iter()
                .enumerate()
                .map(move |(i, p)| (p.id, a.level, i as u32))
        })
        .collect();
    ids.sort_unstable();
    // Global vertex of each (level, E index).
    let mut global: Vec<Vec<u32>> = arrays.iter().map(|a| vec![0; a.points.len()]).collect();
    let mut mesh = Mesh::default();
    let mut last = None;
    let mut mismatches = 0;
    for &(id, level, i) in &ids {
        let p = &arrays[level as usize - 1].points[i as usize];
        if last == Some(id) {
            let first = mesh.positions.last().expect("a point was pushed");
            if *first != p.position.to_array() {
                mismatches += 1;
            }
        } else {
            mesh.positions.push(p.position.to_array());
            if normals {
                mesh.normals.push(p.normal.as_vec3().to_array());
            }
            last = Some(id);
        }
        global[level as usize - 1][i as usize] = mesh.positions.len() as u32 - 1;
    }
    for a in arrays {
        let g = &global[a.level as usize - 1];
        mesh.triangles
            .extend(a.triangles.iter().map(|t| t.map(|e| g[e as usize])));
    }
    mesh.triangles.extend(
        fills
            .iter()
            .map(|t| t.map(|(level, e)| global[level as usize - 1][e as usize])),
    );
    (mesh, mismatches)
}
#[cfg(test)]
mod tests;
