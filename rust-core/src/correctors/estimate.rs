//! Refuses a surface too large for the memory budget before tracking it.
//!
//! Tracking checks the budget as it walks, but a grid far finer than the particles (a
//! grid factor of 0.001 where 0.5 is usual) makes it walk for many seconds and gigabytes
//! before the walk itself is over budget. The surface's cell count scales with its area
//! over the cell size squared, so it is counted first on a grid as coarse as the default
//! one and scaled. Where the coarse grid misses small features the count comes out low,
//! and tracking's own check still applies: the estimate can refuse late, never wrongly.

use super::cache::NodeCache;
use super::seeds::SeedSearch;
use super::{clip_cells, tracking, Neighbours, Params};
use crate::error::{three_digits, Error, Result};
use crate::field::sph::SphField;
use crate::mc::VirtualGrid;
use crate::progress::Progress;

/// The coarse grid's cell size as a multiple of the largest smoothing length: the default
/// grid factor, where the surface's shape is resolved.
const COARSE_FACTOR: f64 = 0.5;

/// Grids less than this many times finer than the coarse one are not estimated: their
/// tracking refuses soon enough, and the estimate would cost over a sixteenth of it.
const MIN_RATIO: f64 = 4.0;

/// What tracking holds for each active cell besides the cell's own share
/// (`tracking::BYTES_PER_ACTIVE_CELL`): the node cache's and the visited set's bricks,
/// which tracking counts too. About 103 bytes a cell on dam_break_23 at grid factor 0.05
/// (3.16 million cells in 1.08 GB); without them an estimate of 240 bytes a cell let
/// that surface start and tracking refused it four seconds later. Where the cache keeps
/// one number a node (`SphField::value_is_weight`), 59.8 bytes a cell on the same frame
/// (`isobar sph FRAME --iso 0.6 --h 0.05 --field SumOfWeights --kernel cubic --grid-factor
/// 0.05`: 4.57 million cells, cache 254.5 MB, visited set 18.9 MB). Each a little under what
/// was measured: the estimate may refuse late, never wrongly.
const INDEX_BYTES_PER_ACTIVE_CELL: u64 = 100;
/// [`INDEX_BYTES_PER_ACTIVE_CELL`] where the cache keeps one number a node.
const INDEX_BYTES_PER_ACTIVE_CELL_ONE_NUMBER: u64 = 58;

/// Errs with `OverBudget` when the surfaces of `params.isovalues` on `grid` would need
/// more than `params.memory_budget`, counted on a coarser grid.
pub(super) fn check_surface_size(
    field: &SphField,
    grid: &VirtualGrid,
    params: &Params,
    neighbours: &Neighbours,
    search: &SeedSearch,
    progress: &mut Progress,
) -> Result<()> {
    let coarse_cell = COARSE_FACTOR * field.max_h();
    let ratio = coarse_cell / grid.cell_size;
    if ratio < MIN_RATIO {
        return Ok(());
    }
    progress.phase("estimating the surface", 0.0, 0.0)?;
    let (lo, hi) = field.bounds();
    let pad = field.max_support() + coarse_cell;
    let coarse = VirtualGrid::covering(lo - pad, hi + pad, coarse_cell, "grid_factor")?;
    let mut cache =
        NodeCache::for_grid(field, &coarse, tracking::index_bytes(params.memory_budget));
    let mut coarse_cells = 0u64;
    for &iso in &params.isovalues {
        let seeds = neighbours.seed_cells(field, &coarse, iso, search)?;
        let mut tracked =
            tracking::track(field, &coarse, seeds, iso, params, &mut cache, progress)?;
        // Scaled by the clipped part only: a clip box may keep a sliver of a large surface.
        clip_cells(&coarse, &mut tracked.active, params);
        coarse_cells += tracked.active.len() as u64;
    }
    let cells = coarse_cells as f64 * ratio * ratio;
    let index_bytes = if field.value_is_weight() {
        INDEX_BYTES_PER_ACTIVE_CELL_ONE_NUMBER
    } else {
        INDEX_BYTES_PER_ACTIVE_CELL
    };
    let needed = cells * (tracking::BYTES_PER_ACTIVE_CELL + index_bytes) as f64;
    let budget = params.memory_budget;
    if needed <= budget as f64 {
        return Ok(());
    }
    // Bytes scale with 1 / cell size²: the cell size at which the estimate takes half the
    // budget. It counts a smooth sheet on cells far coarser; a rough surface's cells,
    // and their bricks, take more (on a block of particles at a factor of 0.001, 1.6
    // times the estimate at four fifths of the budget).
    let fitting_cell = grid.cell_size * (2.0 * needed / budget as f64).sqrt();
    let remedy = match params.lattice {
        None => format!(
            "a grid factor of at least {}",
            three_digits(fitting_cell / field.min_h())
        ),
        // Four significant digits, rounded up ("at least").
        Some(_) => format!(
            "a cell size of at least {:.3e}",
            fitting_cell * (1.0 + 5e-4)
        ),
    };
    Err(Error::OverBudget {
        what: format!(
            "the surface on cells of size {:.3e} (about {cells:.2e} cells, counted on cells \
             {ratio:.0} times larger; {remedy} fits)",
            grid.cell_size
        ),
        needed_bytes: if needed >= u64::MAX as f64 {
            u64::MAX
        } else {
            needed as u64
        },
        budget_bytes: budget,
    })
}
