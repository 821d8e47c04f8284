//! The route ParaView users take today, as a baseline: resample the SPH field onto the
//! full uniform grid, then plain marching cubes with linear interpolation. It shares the
//! virtual grid, the case table and the mesh assembly with Marching Correctors, so on the
//! same parameters the two differ only in how cells are found and vertices placed.

use crate::correctors::cache::{NodeSample, NodeValues};
use crate::correctors::vertices::Placement;
use crate::correctors::{clip_cells, surface, virtual_grid, Extraction, Params, Stats};
use crate::error::{Error, Result};
use crate::field::particles::ParticleData;
use crate::field::sph::{NodeTiles, SphField};
use crate::mc::{case_index, ActiveCell, VirtualGrid};
use crate::mesh::Mesh;
use crate::progress::Progress;
use rayon::prelude::*;
use std::time::Instant;

/// Every node of the grid, evaluated, stored tile by tile.
struct DenseNodes {
    tiles: NodeTiles,
    samples: Vec<NodeSample>,
}

impl NodeValues for DenseNodes {
    fn node(&self, node: u64) -> NodeSample {
        self.samples[self.tiles.index(node)]
    }
}

/// Extracts the isosurfaces by full-grid resampling and marching cubes. Refuses, before
/// allocating, a grid over `params.memory_budget` bytes. It runs on the CPU only: an
/// explicit GPU request is refused rather than quietly served by the CPU.
pub fn extract(
    field: &SphField,
    data: &ParticleData,
    params: &Params,
    progress: &mut Progress,
) -> Result<Extraction> {
    let memory_budget = params.memory_budget;
    params.validate()?;
    if params.backend == crate::gpu::Backend::Gpu {
        return Err(Error::InvalidParameter {
            name: "backend",
            message: "the full-grid baseline runs on the CPU only; ask for cpu or auto".into(),
        });
    }
    let start = Instant::now();
    let grid = virtual_grid(field, params)?;
    let nodes = grid.cells.map(|c| c as usize + 1);
    let count = nodes.iter().map(|&n| n as u128).product::<u128>();
    let tiles = NodeTiles::new(nodes);
    let needed = tiles.slots() * std::mem::size_of::<NodeSample>() as u128;
    if needed > memory_budget as u128 {
        return Err(Error::OverBudget {
            what: format!(
                "a full grid of {}×{}×{} nodes",
                nodes[0], nodes[1], nodes[2]
            ),
            needed_bytes: needed.min(u64::MAX as u128) as u64,
            budget_bytes: memory_budget,
        });
    }
    let mut samples = vec![(0.0, 0.0); tiles.slots() as usize];
    progress.phase("resampling", 0.0, 0.5)?;
    for (layer, chunk) in samples.chunks_mut(tiles.layer_len()).enumerate() {
        field.values_and_weights_on_tile_layer(&grid, &tiles, layer, chunk);
        progress.report((layer + 1) as f64 / tiles.layers() as f64)?;
    }
    let mut dense = DenseNodes { tiles, samples };
    let mut stats = Stats {
        virtual_cells: grid.cell_count(),
        node_evaluations: count as u64,
        field_evaluations: count as u64,
        warnings: field.warnings().to_vec(),
        ..Stats::default()
    };
    let attributes = surface::Carried::new(field, data, &params.attributes)?;
    let mut mesh = Mesh::default();
    let n = params.isovalues.len() as f64;
    for (k, &iso) in params.isovalues.iter().enumerate() {
        // The grid and the earlier isovalues' surfaces stay in memory.
        let held = needed as u64 + mesh.heap_bytes();
        if held > memory_budget {
            return Err(Error::OverBudget {
                what: format!(
                    "a full grid of {}×{}×{} nodes with the surfaces of {k} isovalues",
                    nodes[0], nodes[1], nodes[2]
                ),
                needed_bytes: held,
                budget_bytes: memory_budget,
            });
        }
        let node_threshold = params.trim.map(|t| t.node);
        let mut active: Vec<ActiveCell> = (0..grid.cells[2])
            .into_par_iter()
            .flat_map_iter(|z| {
                let dense = &dense;
                (0..grid.cells[1]).flat_map(move |y| {
                    (0..grid.cells[0]).filter_map(move |x| {
                        let key = VirtualGrid::key(x, y, z);
                        let corners: [NodeSample; 8] =
                            std::array::from_fn(|c| dense.node(VirtualGrid::corner(key, c)));
                        if let Some(t) = node_threshold {
                            if corners.iter().any(|&(_, w)| w < t) {
                                return None;
                            }
                        }
                        let case = case_index(&corners.map(|(v, _)| v), iso);
                        (case != 0 && case != 255).then_some(ActiveCell { key, case })
                    })
                })
            })
            .collect();
        let crossed = active.len() as u64;
        clip_cells(&grid, &mut active, params);
        stats.cells_used += active.len() as u64;
        let span = (0.5 + 0.5 * k as f64 / n, 0.5 + 0.5 * (k as f64 + 1.0) / n);
        let placement = Placement::Linear;
        let cut = surface::cut_edges(&dense, &active, None, placement, progress, span, &mut stats)?;
        if k + 1 == params.isovalues.len() {
            // The full grid is read no more: freed before the mesh's arrays are allocated.
            dense.samples = Vec::new();
        }
        let vertices = surface::place_vertices(&grid, cut, iso, placement, progress, &mut stats)?;
        let part = surface::finish(
            field,
            vertices,
            &active,
            iso,
            params,
            Placement::Linear,
            &attributes,
            progress,
            span,
            &mut stats,
        )?;
        surface::append_surface(
            &mut mesh,
            part,
            iso,
            crossed,
            None,
            params,
            &mut stats.warnings,
        );
    }
    stats.vertices = mesh.vertex_count() as u64;
    stats.triangles = mesh.triangles.len() as u64;
    stats.timings.total = start.elapsed().as_secs_f64();
    Ok(Extraction { mesh, stats })
}
