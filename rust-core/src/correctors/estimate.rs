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
use crate::error::{Error, Result};
use crate::field::sph::SphField;
use crate::mc::VirtualGrid;
use crate::progress::Progress;

/// The coarse grid's cell size as a multiple of the largest smoothing length: the default
/// grid factor, where the surface's shape is resolved.
const COARSE_FACTOR: f64 = 0.5;

/// Grids less than this many times finer than the coarse one are not estimated: their
/// tracking refuses soon enough, and the estimate would cost over a sixteenth of it.
const MIN_RATIO: f64 = 4.0;

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
    let mut cache = NodeCache::for_grid(&coarse, tracking::index_bytes(params.memory_budget));
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
    let needed = cells * tracking::BYTES_PER_ACTIVE_CELL as f64;
    let budget = params.memory_budget;
    if needed <= budget as f64 {
        return Ok(());
    }
    // Bytes scale with 1 / cell size²: the cell size at which the estimate takes half the
    // budget, leaving the other half for the node cache and the visited set, which it
    // does not count (about 100 bytes a cell more on the double dam break).
    let fitting_cell = grid.cell_size * (2.0 * needed / budget as f64).sqrt();
    let remedy = match params.lattice {
        None => format!(
            "a grid factor of at least {}",
            three_digits(fitting_cell / field.min_h())
        ),
        Some(_) => format!("a cell size of at least {fitting_cell:.3e}"),
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

/// `x` (positive, finite) to three significant digits in plain notation: a factor such
/// as 0.000412 must not print as 0.000.
fn three_digits(x: f64) -> String {
    let decimals = (2 - x.log10().floor() as i64).max(0) as usize;
    format!("{x:.decimals$}")
}

#[cfg(test)]
mod tests {
    use super::three_digits;

    #[test]
    fn factors_keep_three_significant_digits() {
        assert_eq!(three_digits(0.0349), "0.0349");
        assert_eq!(three_digits(0.000412), "0.000412");
        assert_eq!(three_digits(0.5), "0.500");
        assert_eq!(three_digits(12.34), "12.3");
        assert_eq!(three_digits(1234.0), "1234");
    }
}
