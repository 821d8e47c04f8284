//! From-scratch marching cubes of a whole volume on the shared case table and assembly
//! (`mc::cut_edges`, `mc::triangulate`): the reference the slider must equal, and the
//! baseline it is measured against.

use super::runtime::edge_data_from;
use crate::error::Result;
use crate::field::grid::Volume;
use crate::mc::{
    case_index, cut_edges_complete, edge_node_axis, triangulate, ActiveCell, VirtualGrid,
};
use crate::mesh::Mesh;
use crate::progress::Progress;
use rayon::prelude::*;

/// The isosurface `iso` of `volume` by marching cubes over every cell: one vertex per cut
/// lattice edge (linear interpolation), normals from interpolated node gradients.
pub fn extract(volume: &Volume, iso: f64, progress: &mut Progress) -> Result<Mesh> {
    Ok(extract_keyed(volume, iso, progress)?.0)
}

/// [`extract`], also returning each vertex's grid edge key (`mc::edge_key`), sorted.
pub fn extract_keyed(
    volume: &Volume,
    iso: f64,
    progress: &mut Progress,
) -> Result<(Mesh, Vec<u64>)> {
    let lattice = &volume.lattice;
    let [nx, ny, nz] = lattice.dims;
    progress.phase("classifying cells", 0.0, 0.5)?;
    let value = |n: [usize; 3]| volume.at(n[0], n[1], n[2]);
    let cells: Vec<ActiveCell> = (0..nz - 1)
        .into_par_iter()
        .flat_map_iter(|z| {
            (0..ny - 1).flat_map(move |y| {
                (0..nx - 1).filter_map(move |x| {
                    let corners: [f64; 8] = std::array::from_fn(|c| {
                        volume.at(x + (c & 1), y + (c >> 1 & 1), z + (c >> 2 & 1)) as f64
                    });
                    let case = case_index(&corners, iso);
                    (case != 0 && case != 255).then(|| ActiveCell {
                        key: VirtualGrid::key(x as u32, y as u32, z as u32),
                        case,
                    })
                })
            })
        })
        .collect();
    progress.phase("triangles", 0.5, 1.0)?;
    // Every cell with a cut edge is listed: each edge comes from one cell.
    let edges = cut_edges_complete(&cells, [nx, ny, nz].map(|n| n as u32 - 1));
    let triangles = triangulate(&cells, &edges);
    let (positions, normals): (Vec<[f64; 3]>, Vec<[f32; 3]>) = edges
        .par_iter()
        .map(|&key| {
            let (node, axis) = edge_node_axis(key);
            let c = VirtualGrid::coords(node).map(|v| v as usize);
            let mut up = c;
            up[axis] += 1;
            let (p, n) = edge_data_from(lattice, value, c, up).vertex(lattice, c, axis, iso);
            (p.to_array(), n)
        })
        .unzip();
    progress.report(1.0)?;
    let mesh = Mesh {
        positions,
        normals,
        triangles,
        attributes: Vec::new(),
    };
    Ok((mesh, edges))
}
