//! Marching cubes level by level with the per-level arrays of the paper's Fig. 3
//! (Algorithm 2): for the cells of one level, V/I (vertex values, (k+1)³ per cell), the
//! sub-cell cases and C (triangles per sub-cell, scanned into offsets), E/H (cut edges,
//! compacted, with their bisected points and gradient normals) and T (triangles into E).
//!
//! Edge points are found by bisection in integer coordinates of a lattice 2^n times finer
//! than the finest cells, with n, n+1, n+2 iterations on level-3, -2 and -1 edges: every
//! edge ends on the same interval of one sub-unit whatever its level, and an edge cut on a
//! coarse level takes the same path as the finer edges lying on it, so shared points
//! coincide bit for bit. A point is named by the finest edge holding it.

use super::grid::{subdivisions, CoarseGrid, FINE_PER_COARSE};
use super::lattice::Lattice;
use crate::error::{Error, Result};
use crate::field::ScalarField;
use crate::mc::{case_index, case_table, corner_offset, edge_corner_axis, edge_key, VirtualGrid};
use crate::progress::{chunked, collect_ranges, Progress};
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

/// A point on the surface, found on a grid edge.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgePoint {
    /// Key of the finest edge holding the point (`mc::edge_key` of finest nodes): the
    /// point's identity across levels.
    pub id: u64,
    pub position: DVec3,
    /// Unit normal down the gradient (out of the region above the isovalue).
    pub normal: DVec3,
}

/// The arrays of one level.
#[derive(Clone, Debug, Default)]
pub struct LevelArrays {
    pub level: u8,
    /// Coarse cells of this level, ascending (position = the paper's per-level cell index).
    pub cells: Vec<u32>,
    /// I: values at the (k+1)³ vertices of each cell, x fastest.
    pub values: Vec<f64>,
    /// Marching-cubes case of each of the k³ sub-cells of each cell.
    pub cases: Vec<u8>,
    /// C after the scan: first triangle of each sub-cell (one extra entry at the end).
    pub triangle_offsets: Vec<u32>,
    /// E: keys of this level's cut edges (`mc::edge_key` of the lower finest node and
    /// axis), sorted and unique.
    pub edges: Vec<u64>,
    /// E/H: the point on each edge of `edges`.
    pub points: Vec<EdgePoint>,
    /// T: triangles as indices into `edges`.
    pub triangles: Vec<[u32; 3]>,
    /// Field evaluations made for this level.
    pub evaluations: u64,
}

impl LevelArrays {
    /// Sub-cells per axis.
    pub fn k(&self) -> u32 {
        subdivisions(self.level)
    }

    /// Index in `cells` of coarse cell `cell`, if it has this level.
    pub fn slot(&self, cell: usize) -> Option<usize> {
        self.cells.binary_search(&(cell as u32)).ok()
    }

    /// Value at finest node `node` of the cell in slot `slot` (the node must be one of
    /// the cell's vertices).
    pub fn value_at(&self, grid: &CoarseGrid, slot: usize, node: [u32; 3]) -> f64 {
        let k = self.k();
        let step = FINE_PER_COARSE / k;
        let c = grid.coords(self.cells[slot] as usize);
        let l: [u32; 3] = std::array::from_fn(|a| (node[a] - c[a] * FINE_PER_COARSE) / step);
        let n = (k + 1) as usize;
        self.values[slot * n * n * n + l[0] as usize + n * (l[1] as usize + n * l[2] as usize)]
    }

    /// Index in `edges` of the edge of this level along `axis` from finest node `node`.
    pub fn edge_index(&self, node: [u32; 3], axis: usize) -> Option<usize> {
        let key = edge_key(VirtualGrid::key(node[0], node[1], node[2]), axis);
        self.edges.binary_search(&key).ok()
    }
}

/// Bytes the arrays of `cells` cells of `level` take before edges are known.
pub fn bytes_per_cell(level: u8) -> u64 {
    let k = subdivisions(level) as u64;
    (k + 1).pow(3) * 8 + k.pow(3) * 5 + 4
}

/// Runs Algorithm 2 for the cells of `level`, their vertex values read from `lattice`,
/// which must cover them (level 1: the coarse nodes; 2 and 3: the cells).
#[allow(clippy::too_many_arguments)]
pub fn build_level<F: ScalarField + ?Sized>(
    field: &F,
    grid: &CoarseGrid,
    levels: &[u8],
    level: u8,
    lattice: &Lattice,
    iso: f64,
    iterations: u32,
    normals: bool,
    progress: &mut Progress,
) -> Result<LevelArrays> {
    let k = subdivisions(level);
    let step = FINE_PER_COARSE / k;
    let n = (k + 1) as usize;
    let cells: Vec<u32> = (0..levels.len() as u32)
        .filter(|&i| levels[i as usize] == level)
        .collect();
    // Step 4: vertex values, cell by cell, read from the lattice (a node shared by
    // several cells was evaluated once there).
    let nnn = n * n * n;
    // Every pass over the cells or sub-cells reports as it goes: on a fine grid each
    // takes seconds, and a cancel must not wait for all of them.
    let values: Vec<f64> = progress.nested(0.0, 0.2, |p| {
        chunked(&cells, p, |part| {
            part.par_iter()
                .flat_map_iter(|&cell| {
                    let first = grid.coords(cell as usize).map(|x| x * FINE_PER_COARSE);
                    let mut block = [0.0; (FINE_PER_COARSE as usize + 1).pow(3)];
                    lattice.block(first, n, step, &mut block[..nnn]);
                    block.into_iter().take(nnn)
                })
                .collect()
        })
    })?;
    let mut evaluations = 0;
    // Step 5: cases and triangle counts of the sub-cells.
    let kk = (k * k * k) as usize;
    let table = case_table();
    let case_of = |s: usize| {
        let (slot, local) = (s / kk, s % kk);
        let l = [
            local % k as usize,
            local / k as usize % k as usize,
            local / (k * k) as usize,
        ];
        let base = slot * n * n * n;
        let corners: [f64; 8] = std::array::from_fn(|c| {
            let o = corner_offset(c);
            values[base
                + (l[0] + o[0] as usize)
                + n * ((l[1] + o[1] as usize) + n * (l[2] + o[2] as usize))]
        });
        case_index(&corners, iso)
    };
    let cases: Vec<u8> = progress.nested(0.2, 0.3, |p| {
        collect_ranges(cells.len() * kk, p, |range| {
            range.into_par_iter().map(case_of).collect()
        })
    })?;
    let mut triangle_offsets = Vec::with_capacity(cases.len() + 1);
    let mut total = 0u32;
    for &case in &cases {
        triangle_offsets.push(total);
        total += table.triangles[case as usize].len() as u32;
    }
    triangle_offsets.push(total);
    // Step 6: cut edges, compacted, with the values at their ends.
    let finest_node = |slot: usize, local: usize, corner: usize| -> [u32; 3] {
        let c = grid.coords(cells[slot] as usize);
        let l = [
            local % k as usize,
            local / k as usize % k as usize,
            local / (k * k) as usize,
        ];
        let o = corner_offset(corner);
        std::array::from_fn(|a| c[a] * FINE_PER_COARSE + (l[a] as u32 + o[a]) * step)
    };
    let cut_edges_of = |s: usize| {
        let (slot, local) = (s / kk, s % kk);
        let bits = table.edges_cut[cases[s] as usize];
        let values = &values;
        let finest_node = &finest_node;
        (0..12).filter(move |e| bits >> e & 1 == 1).map(move |e| {
            let (corner, axis) = edge_corner_axis(e);
            let node = finest_node(slot, local, corner);
            let value = |corner: usize| {
                let o = corner_offset(corner);
                let l = [
                    local % k as usize,
                    local / k as usize % k as usize,
                    local / (k * k) as usize,
                ];
                values[slot * n * n * n
                    + (l[0] + o[0] as usize)
                    + n * ((l[1] + o[1] as usize) + n * (l[2] + o[2] as usize))]
            };
            let key = edge_key(VirtualGrid::key(node[0], node[1], node[2]), axis);
            (key, value(corner), value(corner | 1 << axis))
        })
    };
    let mut cut: Vec<(u64, f64, f64)> = progress.nested(0.3, 0.4, |p| {
        collect_ranges(cases.len(), p, |range| {
            range
                .into_par_iter()
                .filter(|&s| cases[s] != 0 && cases[s] != 255)
                .flat_map_iter(cut_edges_of)
                .collect()
        })
    })?;
    cut.par_sort_unstable_by_key(|e| e.0);
    cut.dedup_by_key(|e| e.0);
    let edges: Vec<u64> = cut.iter().map(|e| e.0).collect();
    let shift = iterations;
    let steps = iterations + (3 - level as u32);
    let bisected = AtomicU64::new(0);
    let points: Vec<EdgePoint> = progress.nested(0.4, 0.9, |p| {
        chunked(&cut, p, |part| {
            part.par_iter()
                .map(|&(key, f0, f1)| {
                    let (point, made) = bisect(
                        field, grid, lattice, key, f0, f1, iso, step, shift, steps, normals,
                    );
                    bisected.fetch_add(made, Ordering::Relaxed);
                    point
                })
                .collect()
        })
    })?;
    evaluations += bisected.into_inner();
    // Step 7: triangles of the active sub-cells into E.
    let triangles_of = |s: usize| {
        let (slot, local) = (s / kk, s % kk);
        let edges = &edges;
        let finest_node = &finest_node;
        table.triangles[cases[s] as usize].iter().map(move |tri| {
            tri.map(|e| {
                let (corner, axis) = edge_corner_axis(e as usize);
                let node = finest_node(slot, local, corner);
                let key = edge_key(VirtualGrid::key(node[0], node[1], node[2]), axis);
                edges
                    .binary_search(&key)
                    .expect("every cut edge of an active sub-cell is in E") as u32
            })
        })
    };
    let triangles: Vec<[u32; 3]> = progress.nested(0.9, 1.0, |p| {
        collect_ranges(cases.len(), p, |range| {
            range.into_par_iter().flat_map_iter(triangles_of).collect()
        })
    })?;
    Ok(LevelArrays {
        level,
        cells,
        values,
        cases,
        triangle_offsets,
        edges,
        points,
        triangles,
        evaluations,
    })
}

/// Bisection on the edge `key` (length `step` finest cells, end values `f0`, `f1` on
/// either side of `iso`) in units of 2^-`shift` finest cells, `steps` halvings, then linear
/// interpolation in the last interval of one unit. Midpoints on finest nodes (the first
/// halvings of level-1 and -2 edges) are read from `lattice` where it holds them. Also
/// returns the field evaluations made.
#[allow(clippy::too_many_arguments)]
fn bisect<F: ScalarField + ?Sized>(
    field: &F,
    grid: &CoarseGrid,
    lattice: &Lattice,
    key: u64,
    f0: f64,
    f1: f64,
    iso: f64,
    step: u32,
    shift: u32,
    steps: u32,
    normals: bool,
) -> (EdgePoint, u64) {
    let (mut lo, mut hi) = (0i64, (step as i64) << shift);
    let (mut flo, mut fhi) = (f0, f1);
    let lo_inside = f0 > iso;
    let (start, axis) = crate::mc::edge_node_axis(key);
    let start = VirtualGrid::coords(start);
    let mut evaluations = normals as u64;
    for _ in 0..steps {
        let mid = (lo + hi) / 2;
        let on_node = (mid & ((1 << shift) - 1) == 0).then(|| {
            let mut node = start;
            node[axis] += (mid >> shift) as u32;
            node
        });
        let fm = match on_node.and_then(|node| lattice.get(node)) {
            Some(value) => value,
            None => {
                evaluations += 1;
                field.value(along(grid, key, shift, mid))
            }
        };
        if (fm > iso) == lo_inside {
            lo = mid;
            flo = fm;
        } else {
            hi = mid;
            fhi = fm;
        }
    }
    debug_assert_eq!(hi - lo, 1);
    let point = edge_point(grid, key, shift, lo, (flo, fhi), iso, |position| {
        if normals {
            let (_, g) = field.value_and_gradient(position);
            (-g).try_normalize().unwrap_or(DVec3::Z)
        } else {
            DVec3::ZERO
        }
    });
    (point, evaluations)
}

/// The point `t` bisection units (2^-`shift` finest cells) along edge `key` from its start.
pub(crate) fn along(grid: &CoarseGrid, key: u64, shift: u32, t: i64) -> DVec3 {
    let (node, axis) = crate::mc::edge_node_axis(key);
    let mut s = VirtualGrid::coords(node).map(|c| (c as i64) << shift);
    s[axis] += t;
    grid.point(s, shift)
}

/// The surface point of edge `key` whose bisection (CPU or GPU) ended on the interval
/// [`lo`, `lo` + 1] bisection units with end values `(flo, fhi)`: linear interpolation
/// there, named by the finest edge holding that interval, with `normal(position)`. One
/// definition for both back ends, so their points agree wherever their intervals do.
pub(crate) fn edge_point(
    grid: &CoarseGrid,
    key: u64,
    shift: u32,
    lo: i64,
    (flo, fhi): (f64, f64),
    iso: f64,
    normal: impl FnOnce(DVec3) -> DVec3,
) -> EdgePoint {
    let (p0, p1) = (along(grid, key, shift, lo), along(grid, key, shift, lo + 1));
    let position = p0 + (p1 - p0) * crate::mc::linear_crossing(flo, fhi, iso);
    let (node, axis) = crate::mc::edge_node_axis(key);
    let mut finest = VirtualGrid::coords(node);
    finest[axis] += (lo >> shift) as u32;
    EdgePoint {
        id: edge_key(VirtualGrid::key(finest[0], finest[1], finest[2]), axis),
        position,
        normal: normal(position),
    }
}

/// Cells of level 1, 2, 3.
fn counts(levels: &[u8]) -> [u64; 3] {
    let mut count = [0u64; 3];
    for &l in levels {
        count[l as usize - 1] += 1;
    }
    count
}

/// Bytes the level arrays of `levels` take before edges are known.
fn needed_bytes(levels: &[u8]) -> u64 {
    let count = counts(levels);
    (1..=3u8)
        .map(|l| count[l as usize - 1] * bytes_per_cell(l))
        .sum::<u64>()
        + levels.len() as u64 * 5
}

/// Refuses levels whose arrays, with `held` bytes held besides, would not fit `budget`
/// bytes, before allocating them.
pub fn check_budget(levels: &[u8], held: u64, budget: u64) -> Result<()> {
    let count = counts(levels);
    let needed = needed_bytes(levels) + held;
    if needed > budget {
        let besides = if held > 0 {
            format!(" with {held} bytes of field values held")
        } else {
            String::new()
        };
        return Err(Error::OverBudget {
            what: format!(
                "adaptive grid arrays for {} / {} / {} cells of level 1 / 2 / 3{besides}",
                count[0], count[1], count[2]
            ),
            needed_bytes: needed,
            budget_bytes: budget,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::progress::Progress;
    use std::collections::HashSet;

    /// A field with no surface (every edge uncut), distinct at every point.
    struct Below;

    impl ScalarField for Below {
        fn value(&self, x: DVec3) -> f64 {
            -1.0 - x.x - 3.0 * x.y - 7.0 * x.z
        }

        fn value_and_gradient(&self, x: DVec3) -> (f64, DVec3) {
            (self.value(x), DVec3::new(-1.0, -3.0, -7.0))
        }
    }

    /// Each cell of a level reads the field at its vertices (bit for bit), which the
    /// lattice evaluated once each: a node shared by cells of the level, whatever the
    /// mix of levels around it, costs one evaluation.
    #[test]
    fn every_cell_of_a_level_gets_the_field_at_its_nodes_evaluated_once() {
        let grid = CoarseGrid {
            origin: DVec3::new(0.1, -0.2, 0.3),
            fine: 0.25,
            cells: [3, 3, 2],
        };
        // Every level, with cells of each level touching across faces, edges and corners.
        let levels: Vec<u8> = (0..grid.cell_count())
            .map(|i| [1, 2, 3, 2, 3, 3][i % 6])
            .collect();
        for level in 1..=3u8 {
            let mut lattice = Lattice::new(&grid);
            let covering = lattice
                .cover_level(
                    &Below,
                    &grid,
                    &levels,
                    level,
                    u64::MAX,
                    &mut Progress::none(),
                )
                .unwrap();
            let a = build_level(
                &Below,
                &grid,
                &levels,
                level,
                &lattice,
                0.0,
                5,
                false,
                &mut Progress::none(),
            )
            .unwrap();
            let k = subdivisions(level);
            let step = FINE_PER_COARSE / k;
            let mut distinct = HashSet::new();
            for (slot, &cell) in a.cells.iter().enumerate() {
                let c = grid.coords(cell as usize);
                for v in 0..(k + 1).pow(3) {
                    let l = [v % (k + 1), v / (k + 1) % (k + 1), v / (k + 1).pow(2)];
                    let node: [u32; 3] =
                        std::array::from_fn(|x| c[x] * FINE_PER_COARSE + l[x] * step);
                    distinct.insert(node);
                    let sub = node.map(|x| (x as i64) << 5);
                    assert_eq!(
                        a.value_at(&grid, slot, node).to_bits(),
                        Below.value(grid.point(sub, 5)).to_bits(),
                        "level {level}, cell {cell}, node {node:?}"
                    );
                }
            }
            assert!(a.edges.is_empty());
            assert_eq!(
                a.evaluations, 0,
                "level {level}: nothing cut, nothing bisected"
            );
            // Level 1 takes every coarse node (4 × 4 × 3 here), the others their own.
            let want = if level == 1 {
                48
            } else {
                distinct.len() as u64
            };
            assert_eq!(covering, want, "level {level}");
        }
    }
}
