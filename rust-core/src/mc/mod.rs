//! What every grid-based extractor shares: the case table, the (virtual) grid's node,
//! cell and edge keys, and the assembly of triangles from active cells. An extractor only
//! decides which cells are active and where on each cut edge its vertex goes.

pub mod bricks;
pub mod radix;
pub mod table;

pub(crate) use table::MOST_TRIANGLES;
pub use table::{case_table, corner_offset, edge_corner_axis, face_segments, CaseTable};

use crate::error::{Error, Result};
use crate::exact;
use bricks::BrickMap;
use glam::DVec3;

const AXIS_BITS: u32 = 20;
const AXIS_MASK: u64 = (1 << AXIS_BITS) - 1;
/// Most nodes a grid may have along one axis (keys pack three 20-bit coordinates).
pub const MAX_NODES_PER_AXIS: u64 = 1 << AXIS_BITS;

/// A uniform grid of cubic cells described by origin, cell size and cell counts; never
/// stored. Nodes and cells are named by keys packing (x, y, z) with x in the low bits, so
/// sorting keys orders them z-slice by z-slice, the order the paper's cache relies on.
///
/// The grid is a window onto a lattice: node (x, y, z) sits at
/// `origin + (offset + (x, y, z)) · cell_size`. Extractions that share a lattice (the
/// pieces of a data-parallel run) therefore compute bit-identical node positions even
/// when their windows differ.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VirtualGrid {
    /// Origin of the lattice.
    pub origin: DVec3,
    /// Lattice index of the window's first node.
    pub offset: [i64; 3],
    pub cell_size: f64,
    /// Cells per axis (nodes per axis = cells + 1).
    pub cells: [u32; 3],
}

impl VirtualGrid {
    /// The grid of cell size `cell_size` whose cells cover the box `lo..hi`, with its
    /// first node at `lo`. `knob` names the user's setting that chose the cell size
    /// (`grid_factor`, `spacing`): an error for cells too small for the data tells the
    /// user to raise it.
    pub fn covering(lo: DVec3, hi: DVec3, cell_size: f64, knob: &'static str) -> Result<Self> {
        Self::window(lo, cell_size, lo, hi, knob)
    }

    /// The window of the lattice (`origin`, `cell_size`) whose cells cover `lo..hi`.
    pub fn on_lattice(origin: DVec3, cell_size: f64, lo: DVec3, hi: DVec3) -> Result<Self> {
        Self::window(origin, cell_size, lo, hi, "lattice cell size")
    }

    /// The window of a lattice; `knob` names the setting that chose the cell size, for
    /// the error when the cells are too small for the data.
    fn window(
        origin: DVec3,
        cell_size: f64,
        lo: DVec3,
        hi: DVec3,
        knob: &'static str,
    ) -> Result<Self> {
        if !(cell_size > 0.0 && cell_size.is_finite()) {
            return Err(Error::InvalidParameter {
                name: "grid cell size",
                message: format!("must be positive and finite, got {cell_size}"),
            });
        }
        if !origin.is_finite() {
            return Err(Error::InvalidParameter {
                name: "lattice origin",
                message: format!("must be finite, got {:?}", origin.to_array()),
            });
        }
        let mut cells = [0u32; 3];
        let mut offset = [0i64; 3];
        let too_many = |a: usize, n: f64| Error::InvalidParameter {
            name: knob,
            message: format!(
                "the virtual grid would need {} cells along axis {a} (the data spans {:.6} \
                 with cells of {cell_size:.3e}); at most {} are supported — raise the {}",
                if n < 1e9 {
                    format!("{n:.0}")
                } else {
                    format!("{n:.3e}")
                },
                hi[a] - lo[a],
                MAX_NODES_PER_AXIS - 1,
                knob.replace('_', " "),
            ),
        };
        for a in 0..3 {
            // The span first: cells far too small for the data are the grid factor's fault,
            // whatever the origin.
            let span = ((hi[a] - lo[a]) / cell_size).ceil();
            if span + 1.0 > MAX_NODES_PER_AXIS as f64 {
                return Err(too_many(a, span));
            }
            let first = ((lo[a] - origin[a]) / cell_size).floor();
            let last = ((hi[a] - origin[a]) / cell_size).ceil();
            if !(first.abs() < 1e15 && last.abs() < 1e15) {
                return Err(Error::InvalidParameter {
                    name: "lattice origin",
                    message: format!(
                        "the data lies too far from the lattice origin along axis {a}"
                    ),
                });
            }
            offset[a] = first as i64;
            let n = (last - first).max(1.0);
            if n + 1.0 > MAX_NODES_PER_AXIS as f64 {
                return Err(too_many(a, n));
            }
            cells[a] = n as u32;
        }
        Ok(VirtualGrid {
            origin,
            offset,
            cell_size,
            cells,
        })
    }

    /// Total number of cells.
    pub fn cell_count(&self) -> u64 {
        self.cells.iter().map(|&c| c as u64).product()
    }

    /// Key of node or cell (x, y, z).
    #[inline]
    pub fn key(x: u32, y: u32, z: u32) -> u64 {
        x as u64 | (y as u64) << AXIS_BITS | (z as u64) << (2 * AXIS_BITS)
    }

    /// Coordinates of a node or cell key.
    #[inline]
    pub fn coords(key: u64) -> [u32; 3] {
        [
            (key & AXIS_MASK) as u32,
            (key >> AXIS_BITS & AXIS_MASK) as u32,
            (key >> (2 * AXIS_BITS)) as u32,
        ]
    }

    /// Position of a node.
    #[inline]
    pub fn node_position(&self, node: u64) -> DVec3 {
        let [x, y, z] = Self::coords(node);
        let [ox, oy, oz] = self.offset;
        self.origin
            + DVec3::new(
                (ox + x as i64) as f64,
                (oy + y as i64) as f64,
                (oz + z as i64) as f64,
            ) * self.cell_size
    }

    /// `p` in cell units relative to the window's first node.
    #[inline]
    pub fn to_grid(&self, p: DVec3) -> DVec3 {
        let [ox, oy, oz] = self.offset;
        (p - self.origin) / self.cell_size - DVec3::new(ox as f64, oy as f64, oz as f64)
    }

    /// Key of corner `corner` of cell `cell`.
    #[inline]
    pub fn corner(cell: u64, corner: usize) -> u64 {
        let [dx, dy, dz] = corner_offset(corner);
        cell + Self::key(dx, dy, dz)
    }

    /// The cell across face (axis, side) of `cell`, if inside the grid.
    #[inline]
    pub fn face_neighbour(&self, cell: u64, axis: usize, side: usize) -> Option<u64> {
        let mut c = Self::coords(cell);
        if side == 1 {
            if c[axis] + 1 >= self.cells[axis] {
                return None;
            }
            c[axis] += 1;
        } else {
            if c[axis] == 0 {
                return None;
            }
            c[axis] -= 1;
        }
        Some(Self::key(c[0], c[1], c[2]))
    }

    /// The cell containing `p`, if inside the grid.
    pub fn cell_of(&self, p: DVec3) -> Option<[u32; 3]> {
        let c = self.to_grid(p);
        let mut out = [0u32; 3];
        for a in 0..3 {
            let f = c[a].floor();
            if !(f >= 0.0 && f < self.cells[a] as f64) {
                return None;
            }
            out[a] = f as u32;
        }
        Some(out)
    }
}

/// Key of the grid edge along `axis` from `node`.
#[inline]
pub fn edge_key(node: u64, axis: usize) -> u64 {
    node << 2 | axis as u64
}

/// (lower node, axis) of an edge key.
#[inline]
pub fn edge_node_axis(edge: u64) -> (u64, usize) {
    (edge >> 2, (edge & 3) as usize)
}

/// The upper node of an edge.
#[inline]
pub fn edge_upper_node(edge: u64) -> u64 {
    let (node, axis) = edge_node_axis(edge);
    node + (1u64 << (AXIS_BITS as usize * axis))
}

/// Case index: bit c set when corner c lies above the isovalue (strictly).
#[inline]
pub fn case_index(values: &[f64; 8], iso: f64) -> u8 {
    let mut case = 0u8;
    for (c, v) in values.iter().enumerate() {
        if *v > iso {
            case |= 1 << c;
        }
    }
    case
}

/// A cell the surface passes through, with its case.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct ActiveCell {
    pub key: u64,
    pub case: u8,
}

/// Global keys of the edges cut in each active cell, sorted and unique: the index of an
/// edge in this list is its vertex index, one vertex per crossed grid edge.
pub fn cut_edges(cells: &[ActiveCell]) -> Vec<u64> {
    let mut edges = listed_edges(cells, |_| u16::MAX);
    radix::sort_unique(&mut edges);
    edges
}

/// Keys of the cut edges of each cell among the local edges `listed(cell)` (a bit each),
/// unsorted.
fn listed_edges(cells: &[ActiveCell], listed: impl Fn(&ActiveCell) -> u16 + Sync) -> Vec<u64> {
    let table = case_table();
    let cut = |cell: &ActiveCell| table.edges_cut[cell.case as usize] & listed(cell);
    exact::flat_map(
        cells,
        |cell| cut(cell).count_ones() as usize,
        |cell, out| {
            let cut = cut(cell);
            let edges = (0..12).filter(|e| cut >> e & 1 == 1);
            for (o, e) in out.iter_mut().zip(edges) {
                let (corner, axis) = edge_corner_axis(e);
                *o = edge_key(VirtualGrid::corner(cell.key, corner), axis);
            }
        },
    )
}

/// [`cut_edges`] of a complete surface: every cell of the grid (`cells` per axis) that
/// holds a cut edge of `active` is itself in `active`, as when tracking discarded and
/// clipped nothing. Each edge is then listed by one cell only, the one whose lower corner
/// is the edge's lower node (on the grid's upper faces, where that cell does not exist,
/// the nearest one inside): a quarter of the keys to sort and nothing to deduplicate.
pub fn cut_edges_complete(active: &[ActiveCell], cells: [u32; 3]) -> Vec<u64> {
    // Local edges a cell lists, by which axes it is the grid's last cell along (bit a):
    // an edge whose corner is offset along another axis b belongs to the next cell along
    // b, unless there is none.
    let listed: [u16; 8] = std::array::from_fn(|last| {
        (0..12).fold(0u16, |mask, e| {
            let (corner, axis) = edge_corner_axis(e);
            let offset = corner_offset(corner);
            let own = (0..3).all(|b| b == axis || offset[b] == 0 || last >> b & 1 == 1);
            mask | u16::from(own) << e
        })
    });
    let mut edges = listed_edges(active, |cell| {
        let c = VirtualGrid::coords(cell.key);
        listed[(0..3).fold(0, |m, a| m | usize::from(c[a] + 1 == cells[a]) << a)]
    });
    radix::sort_by_key(&mut edges, |&e| e);
    debug_assert!(
        edges.windows(2).all(|w| w[0] < w[1]),
        "an edge listed twice"
    );
    edges
}

/// Triangles of the active cells, in cell order, indexing `edges` (from [`cut_edges`]).
pub fn triangulate(cells: &[ActiveCell], edges: &[u64]) -> Vec<[u32; 3]> {
    const NONE: u32 = u32::MAX;
    let table = case_table();
    // Each cut edge's vertex index, filed under the edge's lower node by axis: a cell
    // then reads all twelve of its edges with one brick lookup, where a binary search per
    // triangle corner cost about as much as evaluating the cell's corners. In 4³ bricks,
    // which a surface fills about a third of (a fifth of 8³ ones), found by arithmetic over
    // the edges' box unless its index would take more than `INDEX_BYTES`.
    const INDEX_BYTES: u64 = 64 << 20;
    let extent = edges.iter().fold([0u32; 3], |top, &e| {
        let c = VirtualGrid::coords(edge_node_axis(e).0);
        std::array::from_fn(|a| top[a].max(c[a] + 1))
    });
    let mut at_node: BrickMap<[u32; 3], 2> = BrickMap::for_extent(extent, INDEX_BYTES);
    for (i, &e) in edges.iter().enumerate() {
        let (node, axis) = edge_node_axis(e);
        at_node.get_or_insert(node, [NONE; 3])[axis] = i as u32;
    }
    exact::flat_map(
        cells,
        |cell| table.triangles[cell.case as usize].len(),
        |cell, out| {
            let ids = at_node.corners_or(cell.key, [NONE; 3]);
            for (o, tri) in out.iter_mut().zip(&table.triangles[cell.case as usize]) {
                *o = tri.map(|e| {
                    let (corner, axis) = edge_corner_axis(e as usize);
                    let i = ids[corner][axis];
                    assert!(i != NONE, "every cut edge of an active cell is listed");
                    i
                });
            }
        },
    )
}

/// Where the linear interpolant of (0, f0)–(1, f1) crosses `iso`, in [0, 1].
#[inline]
pub fn linear_crossing(f0: f64, f1: f64, iso: f64) -> f64 {
    let d = f1 - f0;
    if d == 0.0 {
        0.5
    } else {
        ((iso - f0) / d).clamp(0.0, 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::unit;

    /// Every cell of a lattice of values whose case is not empty: a complete surface.
    fn active_cells(values: &[f64], nodes: [u32; 3], iso: f64) -> Vec<ActiveCell> {
        let at = |[x, y, z]: [u32; 3]| values[(x + nodes[0] * (y + nodes[1] * z)) as usize];
        let mut out = Vec::new();
        for z in 0..nodes[2] - 1 {
            for y in 0..nodes[1] - 1 {
                for x in 0..nodes[0] - 1 {
                    let corners: [f64; 8] = std::array::from_fn(|c| {
                        let o = corner_offset(c);
                        at([x + o[0], y + o[1], z + o[2]])
                    });
                    let case = case_index(&corners, iso);
                    if case != 0 && case != 255 {
                        out.push(ActiveCell {
                            key: VirtualGrid::key(x, y, z),
                            case,
                        });
                    }
                }
            }
        }
        out
    }

    /// Listing each edge from one designated cell gives every cut edge once, on surfaces
    /// that run through the grid's faces, edges and corners (noise) and on thin grids
    /// (one cell thick along an axis: every cell is the last along it).
    #[test]
    fn complete_cut_edges_are_all_cut_edges_once() {
        let mut next = unit(0x5eed);
        let mut compared = 0;
        for nodes in [[9u32, 8, 7], [2, 6, 5], [5, 2, 2], [2, 2, 2], [12, 11, 3]] {
            let n = (nodes[0] * nodes[1] * nodes[2]) as usize;
            for iso in [0.2, 0.5, 0.8] {
                let values: Vec<f64> = (0..n).map(|_| next()).collect();
                let active = active_cells(&values, nodes, iso);
                let cells = nodes.map(|n| n - 1);
                let all = cut_edges(&active);
                assert_eq!(
                    cut_edges_complete(&active, cells),
                    all,
                    "{nodes:?} at {iso}"
                );
                compared += all.len();
            }
        }
        assert!(compared > 1000, "too few edges to compare: {compared}");
    }
}
