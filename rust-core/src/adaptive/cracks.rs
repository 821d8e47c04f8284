//! Crack detection and filling (the paper's Algorithm 3), one transition face at a time
//! in parallel. A face between a level-L and a level-(L+1) cell is cut into the
//! 2^(L-1) × 2^(L-1) quads of the coarse side; each quad's nine fine-side vertex signs
//! select a row of the committed pattern table, whose face points map to the fine level's
//! compacted edges. `gpu::cracks` (shaders/cracks.wgsl) walks faces the same way on the
//! GPU with the same table; its tests compare the two fill lists exactly.
//!
//! Crack triangles lie in their transition face's plane, between the coarse side's chord
//! and the fine side's polyline. Where the polyline crosses the chord (the surface runs
//! nearly parallel to the face) the part beyond the crossing is wound against the
//! surface: the mesh stays closed and consistently oriented, but such slivers face
//! inwards (double_dam_break_frame_01 at grid factor 0.375: 70 of 5,252 triangles with
//! the face normal at cos < −0.5 to the vertex normals, all of them crack triangles;
//! vertex-normal shading hides them, flat shading does not).

use super::crack_gen::{point_edge, ROW};
use super::crack_table::CRACK_PATTERNS;
use super::grid::{subdivisions, CoarseGrid, FINE_PER_COARSE};
use super::levels::LevelArrays;
use crate::error::Result;
use crate::progress::{chunked, collect_ranges, Progress};
use rayon::prelude::*;

/// A face between two cells whose levels differ: (lower cell along `axis`, axis).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct TransitionFace {
    pub cell: usize,
    pub axis: usize,
}

/// Every transition face, in (cell, axis) order.
pub fn transition_faces(
    grid: &CoarseGrid,
    levels: &[u8],
    progress: &mut Progress,
) -> Result<Vec<TransitionFace>> {
    collect_ranges(levels.len(), progress, |cells| {
        cells
            .into_par_iter()
            .flat_map_iter(|cell| {
                let n = grid.face_neighbours(cell);
                (0..3).filter_map(move |axis| {
                    let other = n[2 * axis + 1]?;
                    (levels[other] != levels[cell]).then_some(TransitionFace { cell, axis })
                })
            })
            .collect()
    })
}

/// Fill triangles of every transition face, as (level, index into that level's E)
/// triples, counter-clockwise seen from outside the region above the isovalue.
pub fn fill(
    grid: &CoarseGrid,
    levels: &[u8],
    arrays: &[LevelArrays],
    faces: &[TransitionFace],
    iso: f64,
    progress: &mut Progress,
) -> Result<Vec<[(u8, u32); 3]>> {
    chunked(faces, progress, |part| {
        part.par_iter()
            .flat_map_iter(|&face| face_triangles(grid, levels, arrays, face, iso))
            .collect()
    })
}

fn face_triangles(
    grid: &CoarseGrid,
    levels: &[u8],
    arrays: &[LevelArrays],
    face: TransitionFace,
    iso: f64,
) -> Vec<[(u8, u32); 3]> {
    let a = face.axis;
    let lower = face.cell;
    let mut upper_c = grid.coords(lower);
    upper_c[a] += 1;
    let upper = grid.index(upper_c);
    let (lo_level, hi_level) = (levels[lower], levels[upper]);
    // The table is counter-clockwise in (u, v), i.e. wound for a normal along +a, which
    // is right when the coarse cell is the lower one.
    let (coarse_level, fine_cell, flip) = if lo_level < hi_level {
        (lo_level, upper, false)
    } else {
        (hi_level, lower, true)
    };
    let fine_level = coarse_level + 1;
    let fine = &arrays[fine_level as usize - 1];
    let slot = fine
        .slot(fine_cell)
        .expect("the fine cell has the fine level");
    let mut origin = grid.coords(lower).map(|c| c * FINE_PER_COARSE);
    origin[a] += FINE_PER_COARSE;
    let mut out = Vec::new();
    face_fill(
        origin,
        a,
        coarse_level,
        |node| fine.value_at(grid, slot, node) > iso,
        |node, axis| {
            let e = fine
                .edge_index(node, axis)
                .expect("a crack point lies on a cut edge of the fine cell");
            (fine_level, e as u32)
        },
        &mut out,
    );
    if flip {
        for tri in &mut out {
            tri.swap(1, 2);
        }
    }
    out
}

/// The fill triangles of one transition face, appended to `out`: the face of a coarse
/// cell at `coarse_level` whose first node is `origin` (finest-lattice coordinates),
/// normal to `axis`. The face is cut into the coarse side's quads; each quad's nine
/// fine-side vertices (`above`: whether a node lies above the isovalue) select a row of
/// the pattern table, and each face point of the row is `point(first node of its fine
/// edge, the edge's axis)`. Counter-clockwise in (u, v) = (axis + 1, axis + 2), i.e.
/// wound for a normal along +axis. The extractor and the error criterion
/// (`refine::cracks_within`) fill faces through this one function.
pub(crate) fn face_fill<P>(
    origin: [u32; 3],
    axis: usize,
    coarse_level: u8,
    above: impl Fn([u32; 3]) -> bool,
    mut point: impl FnMut([u32; 3], usize) -> P,
    out: &mut Vec<[P; 3]>,
) {
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let quads = subdivisions(coarse_level);
    let quad = FINE_PER_COARSE / quads; // quad side in finest cells
    let half = quad / 2;
    for qv in 0..quads {
        for qu in 0..quads {
            let node = |i: u32, j: u32| -> [u32; 3] {
                let mut n = origin;
                n[u] += qu * quad + i * half;
                n[v] += qv * quad + j * half;
                n
            };
            let mut config = 0usize;
            for j in 0..3 {
                for i in 0..3 {
                    if above(node(i, j)) {
                        config |= 1 << (i + 3 * j);
                    }
                }
            }
            let row: &[u8; ROW] = &CRACK_PATTERNS[config];
            for t in 0..row[0] as usize {
                out.push(std::array::from_fn(|k| {
                    let ((i, j), dir) = point_edge(row[1 + 3 * t + k] as usize);
                    point(node(i as u32, j as u32), [u, v][dir])
                }));
            }
        }
    }
}
