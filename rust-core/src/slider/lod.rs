//! Level of detail for the slider's surface (the paper's §2.2): 2×2×2 blocks of cells
//! merge into parent cells, recursively, where the merge keeps the surface's topology and
//! its error bound, and the mesh stays watertight where merged cells meet finer ones.
//!
//! A cell of level L (edge 2^L lattice cells) merges when
//! - its 8 children are merged cells of level L − 1 or hold no surface (bottom-up);
//! - every axis-parallel line of samples inside it changes side of the isovalue at most
//!   once (the paper's constraint 1, "the merged edge may not have two crossings", asked
//!   of every line, so it holds for every edge a neighbour may subdivide; it also rules out
//!   closed pieces and tubes that a coarse cell would drop);
//! - its corner configuration has no ambiguous face and one surface loop, so the coarse
//!   cell's surface is one disk as the fine one is (constraint 2: no active edge is
//!   deleted in a way that changes topology);
//! - the trilinear interpolant of its 8 corners differs from every deleted sample by at
//!   most Δ = error bound × value range (the fine interpolant is then within Δ of the
//!   coarse one everywhere in the cell).
//!
//! Vertices: because every edge of a merged cell changes side at most once, its crossing
//! is the crossing of exactly one level-0 edge, and the vertex is that level-0 edge's
//! exact vertex ("cell C10 is forced to use the end vertices of edge AB"). Every LOD
//! vertex on a cell edge is therefore a vertex of the exact marching-cubes mesh, named by
//! the same edge id, whatever the levels of the cells that use it.
//!
//! Triangles: a cell whose crossed faces meet cells of its own size or larger triangulates
//! its corner case with the shared table (`mc::case_table`). A cell with a finer neighbour
//! across a crossed face (a transition cell) instead chains the segments of the finer
//! faces: each face of the cell is covered by the faces of the leaves across it when
//! those are smaller, else by itself, and each such face is cut by `mc::face_segments`
//! from its own four corners — the segments the cell across draws, reversed. The chained
//! loop is fanned from an apex: the point nearest the loop's centroid, along the loop's
//! normal and strictly inside the cell, where the level-0 (trilinear) field equals the
//! isovalue — so every vertex, apexes included, lies on the exact surface.
//!
//! Why this is watertight: every segment lies on a face of the finer of the two leaves
//! sharing it and is drawn by exactly those two, once each way (the table's faces depend
//! on the face's corners only, and a table cell has no finer neighbour on a crossed face).
//! A crossing point on a cell's boundary lies on exactly one crossed face edge on either
//! side of its lattice line (one level-0 edge carries it), so it has one segment in and
//! one out: the segments close into simple loops. Fan spokes end at an apex interior to
//! one cell, so each borders exactly two of that fan's triangles. A transition cell whose
//! segments do not make exactly one loop, or whose normal line misses the surface, is split back into its children and the leaves are recomputed; level-0 cells
//! never need either, so the loop ends.

use super::runtime::store_edge_data;
use super::store::Store;
use crate::error::{Error, Result};
use crate::field::grid::{trilinear, Lattice};
use crate::mc::{case_table, corner_offset, edge_corner_axis, face_segments, linear_crossing};
use crate::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;
use rustc_hash::{FxHashMap, FxHashSet};
use std::sync::OnceLock;
use std::time::Instant;

/// The paper's error bound: 0.1 % of the value range.
pub(crate) const DEFAULT_ERROR_BOUND: f64 = 0.001;
/// Merge levels above the lattice by default (cells of up to 8×8×8 lattice cells).
pub(crate) const DEFAULT_MAX_LEVEL: u32 = 3;
/// Most merge levels accepted.
pub(crate) const MAX_LEVEL: u32 = 6;

/// [`LodMesh::vertex_edges`] of a fan apex, a vertex on no lattice edge.
pub const APEX: u32 = u32::MAX;

/// How far to simplify.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LodParams {
    /// Largest difference between a deleted sample and the merged cell's interpolant, as
    /// a fraction of the value range. 0 merges nothing: the exact mesh.
    pub error_bound: f64,
    /// Most merge levels (a level-L cell spans 2^L lattice cells per axis).
    pub max_level: u32,
}

impl Default for LodParams {
    fn default() -> Self {
        LodParams {
            error_bound: DEFAULT_ERROR_BOUND,
            max_level: DEFAULT_MAX_LEVEL,
        }
    }
}

impl LodParams {
    /// Refuses bounds that are negative, not finite or 1 and above, and too many levels.
    pub fn validate(&self) -> Result<()> {
        if !(self.error_bound.is_finite() && (0.0..1.0).contains(&self.error_bound)) {
            return Err(Error::InvalidParameter {
                name: "lod error bound",
                message: format!(
                    "must be a fraction of the value range in [0, 1), got {}",
                    self.error_bound
                ),
            });
        }
        if self.max_level > MAX_LEVEL {
            return Err(Error::InvalidParameter {
                name: "lod levels",
                message: format!("at most {MAX_LEVEL}, got {}", self.max_level),
            });
        }
        Ok(())
    }
}

/// One cell of the LOD mesh: `level` (edge 2^level lattice cells) and its lowest node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct LodCell {
    pub level: u8,
    pub origin: [u32; 3],
}

/// A level-of-detail surface.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LodMesh {
    pub positions: Vec<[f32; 3]>,
    /// Unit normals, down the gradient like the exact mesh's.
    pub normals: Vec<[f32; 3]>,
    /// Counter-clockwise seen from below the isovalue, like the exact mesh's.
    pub triangles: Vec<[u32; 3]>,
    /// Edge id (`node · 3 + axis`) of each vertex, whose exact vertex it is: sorted, then
    /// [`APEX`] for each fan apex (on the level-0 trilinear surface inside its cell).
    pub vertex_edges: Vec<u32>,
    /// Cells with surface, sorted; those of level ≥ 1 replaced merged blocks.
    pub cells: Vec<LodCell>,
    /// Cells per level (index 0 = lattice cells).
    pub cells_per_level: Vec<u64>,
    /// Cells fanned because a finer cell meets them across a crossed face.
    pub transition_cells: u64,
    /// Merged cells split back: transition cells that could not be fanned, and cells
    /// that would have drawn more triangles than the exact cells they cover.
    pub splits: u64,
    /// Wall time, seconds.
    pub seconds: f64,
}

impl LodMesh {
    /// As a [`Mesh`] (f64 positions), for the shared checks.
    pub fn mesh(&self) -> Mesh {
        Mesh {
            positions: self.positions.iter().map(|p| p.map(|c| c as f64)).collect(),
            normals: self.normals.clone(),
            triangles: self.triangles.clone(),
            attributes: Vec::new(),
        }
    }
}

/// Corner cases whose surface is one disk bounded by one loop with no ambiguous face:
/// the only ones a merged cell may have.
fn simple_cases() -> &'static [bool; 256] {
    static SIMPLE: OnceLock<[bool; 256]> = OnceLock::new();
    SIMPLE.get_or_init(|| {
        let mut simple = [false; 256];
        for (case, out) in simple.iter_mut().enumerate() {
            let mut next = [usize::MAX; 12];
            let mut segments = 0;
            let mut ambiguous = false;
            for a in 0..3 {
                for s in 0..2 {
                    let segs = face_segments(case, a, s);
                    ambiguous |= segs.len() > 1;
                    for (p, q) in segs {
                        next[p] = q;
                        segments += 1;
                    }
                }
            }
            let Some(start) = (0..12).find(|&e| next[e] != usize::MAX) else {
                continue;
            };
            let (mut e, mut len) = (next[start], 1);
            while e != start && len <= 12 {
                e = next[e];
                len += 1;
            }
            *out = !ambiguous && len == segments;
        }
        simple
    })
}

/// The level-of-detail surface of `store`'s volume at `iso`, from the level-0 cells the
/// surface passes through (`active`, lattice cell ids as [`super::Slider::cells`] gives).
pub fn extract(store: &Store, iso: f64, active: &[u32], params: &LodParams) -> Result<LodMesh> {
    params.validate()?;
    let start = Instant::now();
    let (lo, hi) = store.value_range();
    let lod = Lod {
        store,
        lattice: *store.lattice(),
        iso,
        delta: params.error_bound * (hi as f64 - lo as f64),
        max_level: params.max_level as usize,
    };
    let mut merged = if params.error_bound > 0.0 {
        lod.merge(active)?
    } else {
        vec![FxHashSet::default(); 1]
    };
    // Triangles of the exact mesh in each active cell. A merged leaf may draw no more
    // than the exact cells it covers, so the LOD mesh never has more triangles than the
    // exact one: a transition cell's fan has one triangle per segment of the finer faces
    // around it, and where a merged cell sits among unmerged ones (small bounds merge
    // only a few) that is as many segments as its cells' exact triangles have, or more.
    let exact: Vec<usize> = if params.error_bound > 0.0 {
        let table = case_table();
        active
            .par_iter()
            .map(|&c| Ok(table.triangles[lod.case(lod.lattice.coords(c as usize), 1)?].len()))
            .collect::<Result<_>>()?
    } else {
        Vec::new()
    };
    let mut splits = 0u64;
    let (cells, outs) = loop {
        let leaves: Vec<LodCell> = active.iter().map(|&c| lod.leaf_of(&merged, c)).collect();
        let mut cells = leaves.clone();
        cells.par_sort_unstable();
        cells.dedup();
        let outs = cells
            .par_iter()
            .map(|&cell| lod.triangulate(&merged, cell))
            .collect::<Result<Vec<_>>>()?;
        let mut budget = vec![0usize; cells.len()];
        for (leaf, &n) in leaves.iter().zip(&exact) {
            if let Ok(k) = cells.binary_search(leaf) {
                budget[k] += n;
            }
        }
        // Split back: leaves that could not be fanned, and merged leaves drawing more
        // triangles than their exact cells (their children draw those, or fewer).
        let split: Vec<LodCell> = cells
            .iter()
            .zip(&outs)
            .zip(&budget)
            .filter(|((c, o), &b)| match o {
                None => true,
                Some((tris, _)) => c.level > 0 && tris.len() > b,
            })
            .map(|((c, _), _)| *c)
            .collect();
        if split.is_empty() {
            break (cells, outs.into_iter().flatten().collect::<Vec<_>>());
        }
        splits += split.len() as u64;
        for c in split {
            let id = lod.id(c.origin.map(|v| v as usize));
            merged[c.level as usize].remove(&id);
        }
    };
    // Lattice-edge vertices first (sorted by edge id), then one apex per transition cell.
    let mut edges: Vec<u32> = outs
        .iter()
        .flat_map(|o| o.0.iter().flatten())
        .copied()
        .filter(|&e| e != APEX)
        .collect();
    edges.par_sort_unstable();
    edges.dedup();
    let data = edges
        .par_iter()
        .map(|&e| store_edge_data(store, e))
        .collect::<Result<Vec<_>>>()?;
    let coords = store.coords;
    let (mut positions, mut normals): (Vec<[f32; 3]>, Vec<[f32; 3]>) = data
        .par_iter()
        .zip(edges.par_iter())
        .map(|(d, &e)| {
            let (node, axis) = ((e / 3) as usize, (e % 3) as usize);
            let (p, n) = d.vertex(&lod.lattice, coords.coords(node), axis, iso);
            (p.as_vec3().to_array(), n)
        })
        .unzip();
    let mut vertex_edges = edges.clone();
    let mut triangles = Vec::new();
    let mut transition_cells = 0;
    for (tris, apex) in &outs {
        let apex_index = positions.len() as u32;
        if let Some(g) = apex {
            let (p, n) = lod.apex_vertex(*g)?;
            positions.push(p);
            normals.push(n);
            vertex_edges.push(APEX);
            transition_cells += 1;
        }
        triangles.extend(tris.iter().map(|t| {
            t.map(|e| match e {
                APEX => apex_index,
                _ => edges.binary_search(&e).expect("every corner is listed") as u32,
            })
        }));
    }
    let mut cells_per_level = vec![0u64; lod.max_level + 1];
    for c in &cells {
        cells_per_level[c.level as usize] += 1;
    }
    Ok(LodMesh {
        positions,
        normals,
        triangles,
        vertex_edges,
        cells,
        cells_per_level,
        transition_cells,
        splits,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// A leaf's triangles (edge ids, [`APEX`] for its fan apex) and its apex, if fanned.
type LeafTriangles = (Vec<[u32; 3]>, Option<DVec3>);

/// What one extraction reads: the store, its lattice, the isovalue and Δ.
struct Lod<'a> {
    store: &'a Store,
    lattice: Lattice,
    iso: f64,
    delta: f64,
    max_level: usize,
}

impl Lod<'_> {
    fn id(&self, c: [usize; 3]) -> u32 {
        self.lattice.index(c[0], c[1], c[2]) as u32
    }

    /// Whether node `c` lies above the isovalue (as `mc::case_index` counts corners).
    fn above(&self, c: [usize; 3]) -> Result<bool> {
        Ok(self.store.checked_value_at(c)? as f64 > self.iso)
    }

    /// Case of the cube of edge `size` at `o`.
    fn case(&self, o: [usize; 3], size: usize) -> Result<usize> {
        let mut case = 0;
        for k in 0..8 {
            if self.above(offset(o, corner_offset(k), size))? {
                case |= 1 << k;
            }
        }
        Ok(case)
    }

    /// The edge id of the level-0 edge where the side changes along the `len` edges from
    /// `n` along `axis` (the first such edge; merged cells have at most one).
    fn crossing(&self, n: [usize; 3], axis: usize, len: usize) -> Result<u32> {
        let mut c = n;
        let mut prev = self.above(c)?;
        for _ in 0..len {
            let mut up = c;
            up[axis] += 1;
            let next = self.above(up)?;
            if next != prev {
                return Ok(self.id(c) * 3 + axis as u32);
            }
            (c, prev) = (up, next);
        }
        Err(Error::format(
            self.store.path(),
            format!("no crossing on the edge from {n:?} along axis {axis}"),
        ))
    }

    /// The merged cells per level (index = level; level 0 unused), bottom-up.
    fn merge(&self, active: &[u32]) -> Result<Vec<FxHashSet<u32>>> {
        let cells = self.lattice.dims.map(|d| d - 1);
        let align = |id: u32, level: usize| -> u32 {
            let c = self
                .lattice
                .coords(id as usize)
                .map(|v| v >> level << level);
            self.id(c)
        };
        // Level-L cells holding surface.
        let mut holds: Vec<FxHashSet<u32>> = vec![active.iter().copied().collect()];
        let mut merged: Vec<FxHashSet<u32>> = vec![FxHashSet::default()];
        for level in 1..=self.max_level {
            let size = 1usize << level;
            holds.push(holds[level - 1].iter().map(|&c| align(c, level)).collect());
            let mut candidates: Vec<u32> = if level == 1 {
                holds[1].iter().copied().collect()
            } else {
                merged[level - 1].iter().map(|&c| align(c, level)).collect()
            };
            candidates.sort_unstable();
            candidates.dedup();
            let (below_merged, below_holds) = (&merged[level - 1], &holds[level - 1]);
            let ok = candidates
                .par_iter()
                .map(|&id| {
                    let o = self.lattice.coords(id as usize);
                    if (0..3).any(|a| o[a] + size > cells[a]) {
                        return Ok(false);
                    }
                    if level > 1 {
                        let half = size / 2;
                        for k in 0..8 {
                            let child = self.id(offset(o, corner_offset(k), half));
                            if below_holds.contains(&child) && !below_merged.contains(&child) {
                                return Ok(false);
                            }
                        }
                    }
                    self.mergeable(o, size)
                })
                .collect::<Result<Vec<bool>>>()?;
            let set: FxHashSet<u32> = candidates
                .iter()
                .zip(ok)
                .filter(|(_, ok)| *ok)
                .map(|(&c, _)| c)
                .collect();
            let done = set.is_empty();
            merged.push(set);
            if done {
                break;
            }
        }
        Ok(merged)
    }

    /// The merge tests on the block of edge `size` at `o`: one crossing at most per line,
    /// a simple corner case, every sample within Δ of the corners' interpolant.
    fn mergeable(&self, o: [usize; 3], size: usize) -> Result<bool> {
        let n = size + 1;
        let mut v = Vec::with_capacity(n * n * n);
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let n = [o[0] + x, o[1] + y, o[2] + z];
                    v.push(self.store.checked_value_at(n)? as f64);
                }
            }
        }
        let at = |x: usize, y: usize, z: usize| v[x + n * (y + n * z)];
        let stride = [1, n, n * n];
        for axis in 0..3 {
            let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
            for i in 0..n {
                for j in 0..n {
                    let first = i * stride[b] + j * stride[c];
                    let changes = (0..size)
                        .filter(|&k| {
                            let p = first + k * stride[axis];
                            (v[p] > self.iso) != (v[p + stride[axis]] > self.iso)
                        })
                        .count();
                    if changes > 1 {
                        return Ok(false);
                    }
                }
            }
        }
        let case = (0..8).fold(0usize, |case, k| {
            let [x, y, z] = corner_offset(k).map(|d| d as usize * size);
            case | usize::from(at(x, y, z) > self.iso) << k
        });
        if !simple_cases()[case] {
            return Ok(false);
        }
        let corner: [f64; 8] = std::array::from_fn(|k| {
            let [x, y, z] = corner_offset(k).map(|d| d as usize * size);
            at(x, y, z)
        });
        let s = size as f64;
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let t = DVec3::new(x as f64, y as f64, z as f64) / s;
                    if (trilinear(&corner, t).0 - at(x, y, z)).abs() > self.delta {
                        return Ok(false);
                    }
                }
            }
        }
        Ok(true)
    }

    /// The leaf holding lattice cell `id`: its highest merged ancestor, else itself.
    fn leaf_of(&self, merged: &[FxHashSet<u32>], id: u32) -> LodCell {
        let c = self.lattice.coords(id as usize);
        for level in (1..merged.len()).rev() {
            let o = c.map(|v| v >> level << level);
            if merged[level].contains(&self.id(o)) {
                return LodCell {
                    level: level as u8,
                    origin: o.map(|v| v as u32),
                };
            }
        }
        LodCell {
            level: 0,
            origin: c.map(|v| v as u32),
        }
    }

    /// Triangles of leaf `cell` as edge-id triples ([`APEX`] for the fan apex) and, for a
    /// transition cell, the apex; `None` when it must be split.
    fn triangulate(
        &self,
        merged: &[FxHashSet<u32>],
        cell: LodCell,
    ) -> Result<Option<LeafTriangles>> {
        let table = case_table();
        let level = cell.level as usize;
        let size = 1usize << level;
        let o = cell.origin.map(|v| v as usize);
        let case = self.case(o, size)?;
        // Crossed faces whose neighbour across is finer.
        let mut finer = [false; 6];
        if level > 0 {
            for (f, fine) in finer.iter_mut().enumerate() {
                let (a, s) = (f / 2, f % 2);
                if table.faces_crossed[case] >> f & 1 == 0 {
                    continue;
                }
                let mut across = o;
                if s == 0 {
                    if o[a] == 0 {
                        continue;
                    }
                    across[a] -= 1;
                } else {
                    across[a] += size;
                    if across[a] + 1 >= self.lattice.dims[a] {
                        continue;
                    }
                }
                *fine = (self.leaf_of(merged, self.id(across)).level as usize) < level;
            }
        }
        if !finer.contains(&true) {
            let mut out = Vec::with_capacity(table.triangles[case].len());
            for tri in &table.triangles[case] {
                let mut t = [0u32; 3];
                for (k, &e) in tri.iter().enumerate() {
                    let (corner, axis) = edge_corner_axis(e as usize);
                    t[k] = self.crossing(offset(o, corner_offset(corner), size), axis, size)?;
                }
                out.push(t);
            }
            return Ok(Some((out, None)));
        }
        // Transition cell: segments of the finest faces on its boundary.
        let mut next: FxHashMap<u32, u32> = FxHashMap::default();
        let mut incoming: FxHashSet<u32> = FxHashSet::default();
        for (f, &fine) in finer.iter().enumerate() {
            if table.faces_crossed[case] >> f & 1 == 0 {
                continue;
            }
            let (a, s) = (f / 2, f % 2);
            let (b, c) = ((a + 1) % 3, (a + 2) % 3);
            let plane = o[a] + s * size;
            // Sub-faces as cubes on this cell's side: (edge, lowest node).
            let mut faces: Vec<(usize, [usize; 3])> = Vec::new();
            if fine {
                for u in 0..size {
                    for w in 0..size {
                        let mut across = o;
                        across[b] += u;
                        across[c] += w;
                        across[a] = if s == 0 { plane - 1 } else { plane };
                        let leaf = self.leaf_of(merged, self.id(across));
                        let m = 1usize << leaf.level;
                        let mut cube = leaf.origin.map(|v| v as usize);
                        cube[a] = if s == 0 { plane } else { plane - m };
                        faces.push((m, cube));
                    }
                }
                faces.sort_unstable();
                faces.dedup();
            } else {
                faces.push((size, o));
            }
            for (m, cube) in faces {
                let mut sub_case = 0;
                for k in (0..8).filter(|k| k >> a & 1 == s) {
                    if self.above(offset(cube, corner_offset(k), m))? {
                        sub_case |= 1 << k;
                    }
                }
                for (p, q) in face_segments(sub_case, a, s) {
                    let [from, to] = [p, q].map(|e| {
                        let (corner, axis) = edge_corner_axis(e);
                        self.crossing(offset(cube, corner_offset(corner), m), axis, m)
                    });
                    let (from, to) = (from?, to?);
                    if next.insert(from, to).is_some() || !incoming.insert(to) {
                        return Ok(None);
                    }
                }
            }
        }
        // Exactly one loop, of three vertices or more.
        let Some(&first) = next.keys().min() else {
            return Ok(None);
        };
        let mut ring = vec![first];
        let mut v = next[&first];
        while v != first {
            ring.push(v);
            match next.get(&v) {
                Some(&w) => v = w,
                None => return Ok(None),
            }
            if ring.len() > next.len() {
                return Ok(None);
            }
        }
        if ring.len() != next.len() || ring.len() < 3 {
            return Ok(None);
        }
        let Some(apex) = self.centre(o, size, &ring)? else {
            return Ok(None);
        };
        let fan = (0..ring.len())
            .map(|i| [APEX, ring[i], ring[(i + 1) % ring.len()]])
            .collect();
        Ok(Some((fan, Some(apex))))
    }

    /// Crossing point of level-0 edge `e`, in lattice index coordinates.
    fn point(&self, e: u32) -> Result<DVec3> {
        let (node, axis) = ((e / 3) as usize, (e % 3) as usize);
        let c = self.lattice.coords(node);
        let mut up = c;
        up[axis] += 1;
        let value = |p: [usize; 3]| -> Result<f64> { Ok(self.store.checked_value_at(p)? as f64) };
        let mut g = DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64);
        g[axis] += linear_crossing(value(c)?, value(up)?, self.iso);
        Ok(g)
    }

    /// The level-0 (trilinear) field at `g`, in lattice index coordinates, and its
    /// gradient per lattice step.
    fn field(&self, g: DVec3) -> Result<(f64, DVec3)> {
        let (c, f) = self.lattice.cell_at(g);
        let mut v = [0.0; 8];
        for (k, v) in v.iter_mut().enumerate() {
            let n = offset(c, corner_offset(k), 1);
            *v = self.store.checked_value_at(n)? as f64;
        }
        Ok(trilinear(&v, f))
    }

    /// The fan's apex, in lattice index coordinates: where the level-0 field crosses the
    /// isovalue on the line through the loop's centroid along the loop's normal, nearest
    /// the centroid and strictly inside the cell. A new vertex, on the exact (trilinear)
    /// surface, that no other cell uses. `None` when that line misses the surface.
    fn centre(&self, o: [usize; 3], size: usize, ring: &[u32]) -> Result<Option<DVec3>> {
        let pts = ring
            .iter()
            .map(|&e| self.point(e))
            .collect::<Result<Vec<DVec3>>>()?;
        let c = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
        let area: DVec3 = (0..pts.len())
            .map(|i| (pts[i] - c).cross(pts[(i + 1) % pts.len()] - c))
            .sum();
        let Some(n) = area.try_normalize() else {
            return Ok(None);
        };
        // The part of the line inside the cell, kept off its faces.
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        let eps = 1e-6;
        for a in 0..3 {
            let (min, max) = (o[a] as f64 + eps, (o[a] + size) as f64 - eps);
            if n[a].abs() < 1e-12 {
                if c[a] <= min || c[a] >= max {
                    return Ok(None);
                }
                continue;
            }
            let (s0, s1) = ((min - c[a]) / n[a], (max - c[a]) / n[a]);
            lo = lo.max(s0.min(s1));
            hi = hi.min(s0.max(s1));
        }
        if lo.partial_cmp(&hi) != Some(std::cmp::Ordering::Less) {
            return Ok(None);
        }
        // Brackets of 1/8 cell outwards from the centroid, nearest first; then bisection.
        let f = |s: f64| -> Result<f64> { Ok(self.field(c + n * s)?.0 - self.iso) };
        let step = 0.125;
        let f0 = f(0.0_f64.clamp(lo, hi))?;
        let mut bracket = None;
        for k in 1..=(16 * size) {
            for dir in [1.0, -1.0] {
                let (s0, s1) = (dir * (k - 1) as f64 * step, dir * k as f64 * step);
                let (a, b) = (s0.clamp(lo, hi), s1.clamp(lo, hi));
                if a == b {
                    continue;
                }
                let (fa, fb) = (if k == 1 { f0 } else { f(a)? }, f(b)?);
                if (fa > 0.0) != (fb > 0.0) {
                    bracket = Some((a, b, fa));
                    break;
                }
            }
            if bracket.is_some() {
                break;
            }
        }
        let Some((mut a, mut b, fa)) = bracket else {
            return Ok(None);
        };
        for _ in 0..48 {
            let m = 0.5 * (a + b);
            if (f(m)? > 0.0) == (fa > 0.0) {
                a = m;
            } else {
                b = m;
            }
        }
        Ok(Some(c + n * (0.5 * (a + b))))
    }

    /// Position (world) and unit normal (down the gradient) of a fan apex at `g`.
    fn apex_vertex(&self, g: DVec3) -> Result<([f32; 3], [f32; 3])> {
        let grad = self.field(g)?.1 / self.lattice.spacing;
        let p = self.lattice.origin + g * self.lattice.spacing;
        Ok((
            p.as_vec3().to_array(),
            (-grad).normalize_or_zero().as_vec3().to_array(),
        ))
    }
}

/// `o + d · size`.
fn offset(o: [usize; 3], d: [u32; 3], size: usize) -> [usize; 3] {
    [
        o[0] + d[0] as usize * size,
        o[1] + d[1] as usize * size,
        o[2] + d[2] as usize * size,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simple_cases_are_the_single_disk_ones() {
        let s = simple_cases();
        assert!(!s[0] && !s[255]);
        // One corner, two adjacent corners, a face of four: one disk.
        for case in [1usize, 3, 15, 254, 252, 240] {
            assert!(s[case], "case {case}");
        }
        // Two opposite corners (two disks) and a face diagonal (ambiguous face).
        for case in [1usize | 1 << 7, 1 | 1 << 3] {
            assert!(!s[case], "case {case}");
        }
    }
}
