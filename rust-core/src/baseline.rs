//! The route ParaView users take today, as a baseline: resample the SPH field onto the
//! full uniform grid, then plain marching cubes with linear interpolation. It shares the
//! virtual grid, the case table and the mesh assembly with Marching Correctors, so on the
//! same parameters the two differ only in how cells are found and vertices placed.

use crate::correctors::cache::{NodeSample, NodeValues};
use crate::correctors::vertices::Placement;
use crate::correctors::{clip_cells, surface, virtual_grid, Extraction, Params, Stats};
use crate::error::{Error, Result};
use crate::field::particles::ParticleData;
use crate::field::sph::{SphField, NODE_TILE};
use crate::mc::{case_index, ActiveCell, VirtualGrid};
use crate::mesh::Mesh;
use crate::progress::Progress;
use rayon::prelude::*;
use std::time::Instant;

/// Every node of the grid, evaluated.
struct DenseNodes {
    nodes: [usize; 3],
    samples: Vec<NodeSample>,
}

impl NodeValues for DenseNodes {
    fn node(&self, node: u64) -> NodeSample {
        let [x, y, z] = VirtualGrid::coords(node).map(|c| c as usize);
        self.samples[x + self.nodes[0] * (y + self.nodes[1] * z)]
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
    let needed = count * std::mem::size_of::<NodeSample>() as u128;
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
    let slice = nodes[0] * nodes[1];
    let mut samples = vec![(0.0, 0.0); count as usize];
    progress.phase("resampling", 0.0, 0.5)?;
    // Slabs of whole node tiles, listed tile by tile: the field evaluates a tile's
    // nodes together and needs no sorting.
    let tiles = nodes.map(|n| n.div_ceil(NODE_TILE));
    for (b, slab) in samples.chunks_mut(slice * NODE_TILE).enumerate() {
        let depth = slab.len() / slice;
        let keys: Vec<u64> = (0..tiles[0] * tiles[1])
            .into_par_iter()
            .flat_map_iter(|t| {
                let corner = [t % tiles[0], t / tiles[0]].map(|c| c * NODE_TILE);
                (0..depth).flat_map(move |z| {
                    (0..NODE_TILE).flat_map(move |y| {
                        (0..NODE_TILE).filter_map(move |x| {
                            let (x, y) = (corner[0] + x, corner[1] + y);
                            let z = b * NODE_TILE + z;
                            (x < nodes[0] && y < nodes[1])
                                .then(|| VirtualGrid::key(x as u32, y as u32, z as u32))
                        })
                    })
                })
            })
            .collect();
        let values = field.values_and_weights_at_nodes(&grid, &keys);
        let z0 = b * NODE_TILE;
        for (&k, v) in keys.iter().zip(values) {
            let [x, y, z] = VirtualGrid::coords(k).map(|c| c as usize);
            slab[x + nodes[0] * (y + nodes[1] * (z - z0))] = v;
        }
        progress.report((z0 + depth) as f64 / nodes[2] as f64)?;
    }
    let dense = DenseNodes { nodes, samples };
    let mut stats = Stats {
        virtual_cells: grid.cell_count(),
        node_evaluations: count as u64,
        field_evaluations: count as u64,
        ..Stats::default()
    };
    let attributes = surface::AttributeSource::new(field, data, &params.attributes)?;
    let mut mesh = Mesh::default();
    let n = params.isovalues.len() as f64;
    for (k, &iso) in params.isovalues.iter().enumerate() {
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
        clip_cells(&grid, &mut active, params);
        stats.cells_used += active.len() as u64;
        let part = surface::build(
            field,
            &grid,
            &dense,
            &active,
            iso,
            params,
            Placement::Linear,
            &attributes,
            progress,
            (0.5 + 0.5 * k as f64 / n, 0.5 + 0.5 * (k as f64 + 1.0) / n),
            &mut stats,
        )?;
        surface::append_surface(&mut mesh, part, iso, params);
    }
    stats.vertices = mesh.vertex_count() as u64;
    stats.triangles = mesh.triangles.len() as u64;
    stats.timings.total = start.elapsed().as_secs_f64();
    Ok(Extraction { mesh, stats })
}
