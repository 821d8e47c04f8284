//! Error-driven refinement, added to the paper's splash criterion (which counts particles
//! and never looks at the surface). Each coarse cell at or next to the surface samples
//! the field on its finest lattice (5³ nodes) and contours it three ways: every node
//! (level 3), every second (level 2) and the corners (level 1), edge points placed by
//! bisecting the lattice values as the extractor bisects the field. The cell takes the
//! lowest level whose surface lies within `max_error` finest cells of the level-3 one
//! ([`surfaces_within`]); balancing runs after, and each cell it raises is tested at its
//! new level, and the crack triangles between the final levels are tested too
//! ([`balance_within`], in `levels_from_counts`).
//!
//! The meshes are compared, not the fields: an interpolation error |F − F_lin| / |∇F| at
//! the next level's nodes (this module's first estimate) misses how far a flat piece
//! cuts across a bump between the nodes, the side of a small droplet, where the adaptive
//! surface strayed most; and a level-by-level test (1 against 2, then 2 against 3) let
//! the two steps' errors add up in cells kept at level 1.
//!
//! Every cell's decision reads only the field and its neighbours' levels of the round
//! before, so the result does not depend on the order of the cells or the thread count.
//! The GPU back end takes its levels from the same function, its samples evaluated here
//! on the CPU.

use super::cracks;
use super::grid::{self, subdivisions, CoarseGrid, FINE_PER_COARSE};
use super::lattice::Lattice;
use crate::error::Result;
use crate::field::ScalarField;
use crate::mesh::hausdorff::point_triangle;
use crate::progress::{chunked, collect_ranges, Progress};
use glam::DVec3;
use rayon::prelude::*;

/// Finest nodes along a coarse cell's edge, both ends included, and in the cell.
const M: usize = FINE_PER_COARSE as usize + 1;
const M3: usize = M * M * M;

/// What the criteria did: cells the error criterion raised to level 2 and to 3, cells the
/// hidden-surface rule raised ([`hidden_surfaces`]), and the field evaluations (with
/// gradient for the error criterion) both took.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Refined {
    pub raised: [u64; 2],
    pub hidden: u64,
    pub evaluations: u64,
}

/// The hidden-surface rule. A cell contours its sub-cells from their corner values, so a
/// closed piece of level set that lies strictly inside one sub-cell (a droplet between
/// the corners, or a bubble) is invisible to it, and to the error criterion as well when
/// the next level's samples miss it too. The field's extremum of such a piece sits near
/// the particles that make it, so the field at each particle is the witness: a particle
/// whose value lies on the other side of `iso` from every corner of the sub-cell holding
/// it at level L is hidden at level L.
///
/// Each particle asks for the lowest level whose sub-cell holding it has a node on its
/// side (level 1: the coarse cell's corners; level 2: the corners of its half-size
/// sub-cell; 3 if neither). Nodes nest across levels (every level-L node is a node of
/// level L + 1), so once the cell is at that level or above, its contouring has a node on
/// the particle's side within one level-L sub-cell of it and the piece gets a surface.
/// The level asked for does not depend on the cell's current level, so the rule reads
/// nothing but the field and the particles (any order, any thread count, both back
/// ends) and only raises levels; a cell already at level 2 is compared on its level-2
/// sub-cell, which the ask already includes. Balancing runs after it (in [`refine`] and
/// in `levels_from_counts`). One field evaluation per particle in a cell below level 3,
/// plus the level-2 sub-cell nodes it needs; a node `lattice` holds is read there (after
/// [`Lattice::cover_corners`], every coarse corner, evaluated once for the eight cells
/// that share it).
pub fn hidden_surfaces<F: ScalarField + ?Sized>(
    field: &F,
    grid: &CoarseGrid,
    lattice: &Lattice,
    positions: &[DVec3],
    levels: &mut [u8],
    iso: f64,
) -> Refined {
    // (cell, particle position, field there) for every particle whose cell can still rise.
    let mut at: Vec<(usize, DVec3, f64)> = positions
        .par_iter()
        .filter_map(|&p| {
            let i = grid.cell_of(p)?;
            (levels[i] < 3).then(|| (i, p, field.value(p)))
        })
        .collect();
    let mut out = Refined {
        evaluations: at.len() as u64,
        ..Refined::default()
    };
    // Stable: within a cell the particles keep their order, so the lazily evaluated
    // nodes (and the evaluation count) do not depend on the thread count.
    at.par_sort_by_key(|a| a.0);
    let groups: Vec<&[(usize, DVec3, f64)]> = at.chunk_by(|a, b| a.0 == b.0).collect();
    let asks: Vec<(usize, u8, u64)> = groups
        .par_iter()
        .map(|g| {
            let i = g[0].0;
            let base = grid.coords(i).map(|x| (x * FINE_PER_COARSE) as i64);
            let origin = grid.point(base, 0);
            // The cell's finest-lattice node values, evaluated when first needed (NaN:
            // not yet), at the same lattice points the levels contour; its corners are
            // the lattice's.
            let mut nodes = [f64::NAN; M3];
            let mut evaluations = 0u64;
            let mut value = |l: [usize; 3]| {
                let v = &mut nodes[l[0] + M * (l[1] + M * l[2])];
                if v.is_nan() {
                    let sub: [i64; 3] = std::array::from_fn(|a| base[a] + l[a] as i64);
                    *v = lattice.get(sub.map(|x| x as u32)).unwrap_or_else(|| {
                        evaluations += 1;
                        field.value(grid.point(sub, 0))
                    });
                }
                *v
            };
            let mut need = 1u8;
            for &(_, p, f) in g.iter() {
                let side = f > iso;
                // The particle's position in finest cells from the cell's first node.
                let local = (p - origin) / grid.fine;
                let mut ask = 3;
                for level in 1..=2u8 {
                    let step = (FINE_PER_COARSE / subdivisions(level)) as usize;
                    let lo: [usize; 3] = std::array::from_fn(|a| {
                        let k = (local[a] / step as f64).floor().max(0.0) as usize;
                        k.min(subdivisions(level) as usize - 1) * step
                    });
                    let seen = (0..8).any(|v| {
                        let n = [v & 1, v >> 1 & 1, v >> 2 & 1];
                        let l = std::array::from_fn(|a| lo[a] + n[a] * step);
                        (value(l) > iso) == side
                    });
                    if seen {
                        ask = level;
                        break;
                    }
                }
                need = need.max(ask);
                if need == 3 {
                    break;
                }
            }
            (i, need, evaluations)
        })
        .collect();
    for (i, need, evaluations) in asks {
        out.evaluations += evaluations;
        if need > levels[i] {
            levels[i] = need;
            out.hidden += 1;
        }
    }
    out
}

/// Raises each coarse cell of `levels` (after splitting and dilation; to be balanced after)
/// at or next to the surface to the lowest level, from its own up, whose surface lies
/// within `max_error` finest cells of the finest one in that cell ([`needed_level`]). `counts` are the
/// particles per coarse cell (a cell holding particles but no corner inside the fluid
/// may hide a droplet between its corners, and its neighbours parts of that droplet's
/// surface). `max_error` ≤ 0 leaves the levels as they are. The finest nodes of the
/// candidates and of every cell above level 1 are evaluated into `lattice` (within
/// `budget` bytes), where the level surfaces read them again. Reports between its
/// passes over the grid.
#[allow(clippy::too_many_arguments)]
pub fn refine<F: ScalarField + ?Sized>(
    field: &F,
    grid: &CoarseGrid,
    counts: &[u32],
    levels: &mut [u8],
    iso: f64,
    max_error: f64,
    lattice: &mut Lattice,
    budget: u64,
    progress: &mut Progress,
) -> Result<Refined> {
    let mut out = Refined::default();
    if max_error <= 0.0 {
        return Ok(out);
    }
    out.evaluations +=
        progress.nested(0.0, 0.2, |p| lattice.cover_corners(field, grid, budget, p))?;
    let corner_list = |c: [u32; 3]| -> [f64; 8] {
        std::array::from_fn(|v| {
            lattice.corner([
                c[0] + (v as u32 & 1),
                c[1] + (v as u32 >> 1 & 1),
                c[2] + (v as u32 >> 2 & 1),
            ])
        })
    };
    // Sign of each cell's corners: bit 0 some corner inside, bit 1 some corner outside.
    let signs: Vec<u8> = progress.nested(0.2, 0.25, |p| {
        collect_ranges(levels.len(), p, |cells| {
            cells
                .into_par_iter()
                .map(|i| {
                    corner_list(grid.coords(i))
                        .iter()
                        .fold(0u8, |s, &v| s | if v > iso { 1 } else { 2 })
                })
                .collect()
        })
    })?;
    // Candidates: cells in the 3×3×3 block of a cell the surface crosses at the corners,
    // or of a cell holding particles with no corner inside (a droplet between the corners
    // reaches into its neighbours too).
    let marked = |i: usize| signs[i] == 3 || (counts[i] > 0 && signs[i] & 1 == 0);
    let candidate = |i: usize| grid.block(i).any(marked);
    let levels_now = &*levels;
    let candidates: Vec<usize> = progress.nested(0.25, 0.3, |p| {
        collect_ranges(levels_now.len(), p, |cells| {
            cells
                .into_par_iter()
                .filter(|&i| levels_now[i] < 3 && candidate(i))
                .collect()
        })
    })?;
    // The cells already above level 1 are covered in the same pass: the level surfaces
    // read their nodes, and most share tiles with the candidates (a tile's particles are
    // gathered once per pass, whatever it evaluates).
    let mut covered: Vec<usize> = (0..levels.len())
        .into_par_iter()
        .filter(|&i| levels[i] > 1)
        .collect();
    covered.extend(candidates.iter().filter(|&&i| levels[i] == 1));
    progress.report(0.3)?;
    out.evaluations += progress.nested(0.3, 0.8, |p| {
        lattice.cover(field, grid, &covered, 1, budget, p)
    })?;
    let lattice = &*lattice;
    let needs: Vec<(usize, u8)> = progress.nested(0.8, 1.0, |p| {
        chunked(&candidates, p, |part| {
            part.par_iter()
                .map(|&i| {
                    let c = grid.coords(i);
                    let need = needed_level(grid, lattice, c, iso, max_error, levels_now[i]);
                    (i, need)
                })
                .collect()
        })
    })?;
    for (i, need) in needs {
        if need > levels[i] {
            levels[i] = need;
            out.raised[need as usize - 2] += 1;
        }
    }
    progress.report(1.0)?;
    Ok(out)
}

/// Balances `levels` ([`grid::balance`]) and holds the error criterion's promise through
/// it. Balancing raises cells the criterion passed at a lower level, and a surface one
/// level finer is not always nearer the finest one (dam_break_23 at G 0.25: a level-1
/// cell within 0.35 finest cells, balanced to level 2, lay 0.54 off). Each cell balancing
/// raised whose finest lattice [`refine`] covered (a candidate: the surface crosses its
/// block's corners or a droplet may hide in it) is tested at its new level
/// ([`needed_level`]); those off by more than `max_error` go to level 3. The levels being
/// final only now, so are the crack triangles between them: a cell whose cracks against
/// a finer neighbour are off ([`cracks_within`]) goes one level up, where the next round
/// tests its surface. Balancing runs again from the raised cells, until no cell is off.
/// A cell no candidate test reached stays as balanced, as [`refine`] leaves such cells.
/// Returns the raises this made, to level 2 and to level 3 (not counting the cells
/// balancing raised and passed).
pub fn balance_within(
    grid: &CoarseGrid,
    lattice: &Lattice,
    levels: &mut [u8],
    iso: f64,
    max_error: f64,
    progress: &mut Progress,
) -> Result<[u64; 2]> {
    if max_error <= 0.0 {
        return grid::balance(grid, levels, progress).map(|()| [0; 2]);
    }
    // One copy of the levels at a time: the per-cell arrays' budget counts one.
    let mut was = levels.to_vec();
    grid::balance(grid, levels, progress)?;
    let mut raised = [0; 2];
    let mut first = true;
    loop {
        // Between rounds, so that a cancel is seen here too.
        progress.report(1.0)?;
        let now = &*levels;
        // A face's cracks depend on the levels of its two cells: after the first round
        // only those next to a change are tested again.
        let moved = |i: usize| now[i] != was[i];
        let near_change =
            |i: usize| moved(i) || grid.face_neighbours(i).into_iter().flatten().any(moved);
        let off: Vec<(usize, u8)> = (0..now.len())
            .into_par_iter()
            .filter_map(|i| {
                if now[i] == 3 {
                    return None;
                }
                let c = grid.coords(i);
                let surface_off = now[i] > was[i]
                    && lattice.stored_cell(c).is_some()
                    && needed_level(grid, lattice, c, iso, max_error, now[i]) > now[i];
                if surface_off {
                    Some((i, 3))
                } else if (first || near_change(i))
                    && !cracks_within(grid, lattice, now, c, iso, max_error)
                {
                    Some((i, now[i] + 1))
                } else {
                    None
                }
            })
            .collect();
        if off.is_empty() {
            return Ok(raised);
        }
        first = false;
        was.copy_from_slice(levels);
        for &(i, level) in &off {
            levels[i] = level;
            raised[level as usize - 2] += 1;
        }
        let changed: Vec<usize> = off.iter().map(|&(i, _)| i).collect();
        grid::rebalance(grid, levels, &changed)?;
    }
}

/// The lowest level from `from` on whose marching-cubes surface in coarse cell `c` lies
/// within `max_error` finest cells of the finest level's, from the field on the cell's
/// finest lattice (covered in `lattice`). A cell another rule has already raised is
/// tested at its own level, not below it: a level-2 surface is not always nearer the
/// finest one than the level-1 surface that passed.
fn needed_level(
    grid: &CoarseGrid,
    lattice: &Lattice,
    c: [u32; 3],
    iso: f64,
    max_error: f64,
    from: u8,
) -> u8 {
    let mut values = [0.0; M3];
    lattice.cell(c, &mut values);
    let finest = lattice_surface(&values, 1, iso);
    let finest_targets = targets(&finest.triangles, max_error);
    let size = (M - 1) as f64;
    // The face neighbours' lattices (faces numbered 2·axis + side), when stored.
    let neighbour = |axis: usize, side: usize| -> Option<[f64; M3]> {
        let mut n = c;
        if side == 0 {
            n[axis] = n[axis].checked_sub(1)?;
        } else if c[axis] + 1 < grid.cells[axis] {
            n[axis] += 1;
        } else {
            return None;
        }
        lattice.stored_cell(n)
    };
    // Computed on first need: most samples are close to their own cell's surface.
    let near: [std::cell::OnceCell<Option<[f64; M3]>>; 6] = Default::default();
    let lattice_of = |f: usize| near[f].get_or_init(|| neighbour(f / 2, f % 2)).as_ref();
    let beyond = |f: usize, stride: usize| {
        lattice_of(f).map(|v| beyond_face(lattice_surface(v, stride, iso).triangles, f, max_error))
    };
    let finest_beyond: [std::cell::OnceCell<Option<Vec<Target>>>; 6] = Default::default();
    let finest_of = |f: usize| finest_beyond[f].get_or_init(|| beyond(f, 1)).as_deref();
    for level in from.max(1)..=2u8 {
        let stride = (FINE_PER_COARSE / subdivisions(level)) as usize;
        let surface = lattice_surface(&values, stride, iso);
        let surface_beyond: [std::cell::OnceCell<Option<Vec<Target>>>; 6] = Default::default();
        let surface_of = |f: usize| {
            surface_beyond[f]
                .get_or_init(|| beyond(f, stride))
                .as_deref()
        };
        if surfaces_within(&surface, &finest_targets, size, max_error, &finest_of)
            && surfaces_within(
                &finest,
                &targets(&surface.triangles, max_error),
                size,
                max_error,
                &surface_of,
            )
        {
            return level;
        }
    }
    3
}

/// Targets of a face neighbour's `triangles` (in its lattice frame) in the frame of the
/// cell whose face `f` (2·axis + side) they share.
fn beyond_face(mut triangles: Vec<[DVec3; 3]>, f: usize, max_error: f64) -> Vec<Target> {
    let mut d = DVec3::ZERO;
    d[f / 2] = [-1.0, 1.0][f % 2] * (M - 1) as f64;
    for t in &mut triangles {
        *t = t.map(|p| p + d);
    }
    targets(&triangles, max_error)
}

/// Whether the crack triangles in the faces of coarse cell `c` against its finer face
/// neighbours (`levels` balanced) lie within `max_error` finest cells of the finest
/// surface on one side of their face or the other. The per-cell test samples the coarse
/// trace in the face, one side of a crack triangle; the triangle spans from there to the
/// fine side's polyline, and its middle can stray further than either (a saddle on the
/// face of double_dam_break_26 at G 0.25: 0.507 finest cells off the uniform surface).
/// A face is excused when the cell's or the neighbour's lattice is not stored, as in
/// [`surfaces_within`], and a sample may match only the finest surface of these two
/// cells, not that of the cells beside them (near a face's border such a sample may then
/// fail, which only raises a level).
fn cracks_within(
    grid: &CoarseGrid,
    lattice: &Lattice,
    levels: &[u8],
    c: [u32; 3],
    iso: f64,
    max_error: f64,
) -> bool {
    let i = grid.index(c);
    let level = levels[i];
    let neighbours = grid.face_neighbours(i);
    let finer: Vec<(usize, usize)> = (0..6)
        .filter_map(|f| neighbours[f].filter(|&n| levels[n] > level).map(|n| (f, n)))
        .collect();
    if finer.is_empty() {
        return true;
    }
    let Some(values) = lattice.stored_cell(c) else {
        return true;
    };
    finer.into_iter().all(|(f, n)| {
        debug_assert_eq!(levels[n], level + 1, "levels are balanced");
        let cracks = crack_triangles(&values, f, level, iso);
        if cracks.is_empty() {
            return true;
        }
        let Some(theirs) = lattice.stored_cell(grid.coords(n)) else {
            return true;
        };
        // The finest surface in the layers of finest cells on either side of the face;
        // of those, only targets within the tolerance of the face's plane can be near a
        // sample in it (their boxes are grown by the tolerance).
        let (a, plane) = (f / 2, (f % 2 * (M - 1)) as f64);
        let at_face = |t: &Target| t.lo[a] <= plane && plane <= t.hi[a];
        // The layer is enough below one finest cell: triangles beyond it lie further.
        let layer = |f: usize| (max_error < 1.0).then_some(f);
        let own = lattice_surface_at(&values, 1, iso, layer(f)).triangles;
        let theirs = lattice_surface_at(&theirs, 1, iso, layer(f ^ 1)).triangles;
        let mut near: Vec<Target> = targets(&own, max_error);
        near.extend(beyond_face(theirs, f, max_error));
        near.retain(at_face);
        // The target close enough to the previous sample first, as in [`surfaces_within`].
        let mut last = 0;
        cracks.iter().all(|t| {
            crack_samples(t, max_error).all(|p| {
                if last < near.len() && near[last].near(p, max_error) {
                    return true;
                }
                near.iter()
                    .position(|t| t.near(p, max_error))
                    .map(|k| last = k)
                    .is_some()
            })
        })
    })
}

/// Points of triangle `t` on a barycentric grid fine enough that every point of it lies
/// within a third of `tolerance` of one (its corners among them): a crack triangle is
/// long and thin, from a chord to a polyline, up to a coarse face across, and where it
/// strays most is inside, not at a few fixed points. At most [`MOST_PARTS`] steps a side:
/// a tolerance far below a finest cell samples a triangle across a coarse face (4 finest
/// cells) 1/16 of a cell apart, not millions of times.
fn crack_samples(t: &[DVec3; 3], tolerance: f64) -> impl Iterator<Item = DVec3> + '_ {
    // The grid's small triangles have sides of at most half the tolerance, and a point
    // of one lies within 1/√3 of its longest side of a corner.
    let longest = (t[1] - t[0])
        .length()
        .max((t[2] - t[1]).length())
        .max((t[0] - t[2]).length());
    let parts = ((2.0 * longest / tolerance).ceil() as usize).clamp(1, MOST_PARTS);
    (0..=parts).flat_map(move |i| {
        (0..=parts - i).map(move |j| {
            let k = parts - i - j;
            (t[0] * i as f64 + t[1] * j as f64 + t[2] * k as f64) / parts as f64
        })
    })
}

/// Most grid steps along a crack triangle's side in [`crack_samples`] (2,145 samples).
const MOST_PARTS: usize = 64;

/// The crack triangles the extractor fills in face `f` (2·axis + side) of a coarse cell
/// at `level` whose neighbour across it is one level finer ([`cracks::face_fill`]), their
/// points placed on the lattice `values` as [`lattice_surface`] places the finer level's,
/// in the cell's lattice frame.
fn crack_triangles(values: &[f64; M3], f: usize, level: u8, iso: f64) -> Vec<[DVec3; 3]> {
    let at = |n: [u32; 3]| values[n[0] as usize + M * (n[1] as usize + M * n[2] as usize)];
    let mut origin = [0; 3];
    origin[f / 2] = (f % 2) as u32 * FINE_PER_COARSE;
    // The finer level's lattice edges.
    let length = (FINE_PER_COARSE / subdivisions(level + 1)) as usize;
    let mut out = Vec::new();
    cracks::face_fill(
        origin,
        f / 2,
        level,
        |n| at(n) > iso,
        |n, axis| edge_point(values, n.map(|x| x as usize), axis, length, iso),
        &mut out,
    );
    out
}

/// Marching-cubes triangles of a coarse cell's finest lattice, and which of each
/// triangle's corners appear there first (bit k for corner k): [`surfaces_within`]
/// samples a point shared by several triangles once.
struct Contour {
    triangles: Vec<[DVec3; 3]>,
    fresh: Vec<u8>,
}

/// The [`Contour`] of the node values `values` (`M`³, x fastest) taking every `stride`-th
/// node (a power of two), in node units. A cut edge's point is found as the extractor
/// finds it: bisection (here on the lattice values along the edge) down to one lattice
/// step, then linearly in that step; once per edge, so every triangle holding it has the
/// same point to the bit.
fn lattice_surface(values: &[f64; M3], stride: usize, iso: f64) -> Contour {
    lattice_surface_at(values, stride, iso, None)
}

/// [`lattice_surface`], of the layer of cells along face `face` (2·axis + side) only
/// when given.
fn lattice_surface_at(values: &[f64; M3], stride: usize, iso: f64, face: Option<usize>) -> Contour {
    let table = crate::mc::case_table();
    let at = |l: [usize; 3]| values[l[0] + M * (l[1] + M * l[2])];
    let cells = (M - 1) / stride;
    // Each lattice edge's point, by (lower node, axis): an index into `points`.
    let mut slot = [u16::MAX; M3 * 3];
    let mut points: Vec<DVec3> = Vec::new();
    let mut out = Contour {
        triangles: Vec::new(),
        fresh: Vec::new(),
    };
    for v in 0..cells * cells * cells {
        let origin = [v % cells, v / cells % cells, v / (cells * cells)].map(|x| x * stride);
        if face.is_some_and(|f| origin[f / 2] != f % 2 * (M - 1 - stride)) {
            continue;
        }
        let node = |corner: usize| -> [usize; 3] {
            let o = crate::mc::corner_offset(corner);
            std::array::from_fn(|a| origin[a] + o[a] as usize * stride)
        };
        let corners: [f64; 8] = std::array::from_fn(|corner| at(node(corner)));
        let case = crate::mc::case_index(&corners, iso);
        for tri in &table.triangles[case as usize] {
            let mut corners = [DVec3::ZERO; 3];
            let mut fresh = 0u8;
            for (k, &e) in tri.iter().enumerate() {
                let (corner, axis) = crate::mc::edge_corner_axis(e as usize);
                let n = node(corner);
                let id = (n[0] + M * (n[1] + M * n[2])) * 3 + axis;
                if slot[id] == u16::MAX {
                    slot[id] = points.len() as u16;
                    points.push(edge_point(values, n, axis, stride, iso));
                    fresh |= 1 << k;
                }
                corners[k] = points[slot[id] as usize];
            }
            out.triangles.push(corners);
            out.fresh.push(fresh);
        }
    }
    out
}

/// The point where the lattice edge from node `lo` along `axis`, `length` lattice steps
/// long (a power of two), crosses `iso`, as the extractor places it: bisection on the
/// lattice values down to one step, then linearly in that step.
fn edge_point(
    values: &[f64; M3],
    mut lo: [usize; 3],
    axis: usize,
    mut length: usize,
    iso: f64,
) -> DVec3 {
    let at = |l: [usize; 3]| values[l[0] + M * (l[1] + M * l[2])];
    while length > 1 {
        length /= 2;
        let mut mid = lo;
        mid[axis] += length;
        if (at(lo) > iso) == (at(mid) > iso) {
            lo = mid;
        }
    }
    let mut hi = lo;
    hi[axis] += 1;
    let mut p = DVec3::new(lo[0] as f64, lo[1] as f64, lo[2] as f64);
    p[axis] += crate::mc::linear_crossing(at(lo), at(hi), iso);
    p
}

/// A triangle [`surfaces_within`] measures samples against, with what rejects most far
/// samples before the exact distance: its box grown by the tolerance, and its plane (no
/// point is nearer the triangle than its plane). Both margins are wider than the
/// tolerance by more than rounding can move them, so neither rejects what the exact test
/// would accept.
#[derive(Clone, Copy, Debug)]
struct Target {
    corners: [DVec3; 3],
    lo: DVec3,
    hi: DVec3,
    /// Unit normal; zero for a sliver, whose computed normal may point off its plane.
    normal: DVec3,
    /// The tolerance with the plane test's margin.
    grow: f64,
}

impl Target {
    /// Whether `p` lies within `tolerance` of the triangle (the tolerance `grow` was
    /// made for).
    #[inline]
    fn near(&self, p: DVec3, tolerance: f64) -> bool {
        let [a, b, c] = self.corners;
        p.cmpge(self.lo).all()
            && p.cmple(self.hi).all()
            && self.normal.dot(p - a).abs() <= self.grow
            && point_triangle(p, a, b, c) <= tolerance
    }
}

/// `triangles` prepared as targets for samples within `tolerance`.
fn targets(triangles: &[[DVec3; 3]], tolerance: f64) -> Vec<Target> {
    let grow = tolerance * (1.0 + 1e-9) + 1e-12;
    triangles
        .iter()
        .map(|&corners| {
            let [a, b, c] = corners;
            // The cross product's direction is off by about ε / sin θ: with sin θ above
            // 1e-3 the plane distance of a point a few lattice steps away is off by
            // ~1e-12, well inside the 1e-9 margin.
            let (ab, ac) = (b - a, c - a);
            let cross = ab.cross(ac);
            let upright = cross.length() > 1e-3 * ab.length() * ac.length();
            Target {
                corners,
                lo: a.min(b).min(c) - grow,
                hi: a.max(b).max(c) + grow,
                normal: if upright {
                    cross.normalize()
                } else {
                    DVec3::ZERO
                },
                grow: grow + 1e-9,
            }
        })
        .collect()
}

/// Whether every sample of `from` (its triangles' vertices, edge midpoints and
/// centroids, in the cell's box [0, size]³) lies within `tolerance` of `to`, the other
/// surface of the same cell.
///
/// A sample inside the box within the tolerance of a face may instead lie within the
/// tolerance of the face neighbour's `to` surface (`beyond(face)`, faces numbered
/// 2·axis + side, in this box's coordinates; None when the neighbour's lattice is not
/// stored, which excuses the sample): a piece of the finer surface grazing a face may be
/// matched on the other side. Without that second look such a piece was excused outright
/// and left to the neighbour, which excused it too (double_dam_break_26 at G 0.5 and
/// max_error 0.4: 0.571 finest cells off the uniform surface, 0.480 with it). Samples on a
/// face are never excused: both cells' surfaces end in the same trace there, and a coarse
/// trace off the fine one is what the crack triangles between a coarse and a fine cell
/// would span.
///
/// A predicate rather than a distance so that it can stop early: a sample stops at the
/// first triangle close enough, the test at the first sample with none (the point
/// distances were most of the criterion's time).
fn surfaces_within<'a>(
    from: &Contour,
    to: &[Target],
    size: f64,
    tolerance: f64,
    beyond: &dyn Fn(usize) -> Option<&'a [Target]>,
) -> bool {
    // The triangle close enough to the previous sample is tried first: samples come
    // triangle by triangle, and neighbours usually share their nearest target.
    let near = |p: DVec3, t: &Target| t.near(p, tolerance);
    let mut last = 0;
    from.triangles.iter().zip(&from.fresh).all(|(t, &fresh)| {
        let samples = [
            t[0],
            t[1],
            t[2],
            (t[0] + t[1]) / 2.0,
            (t[1] + t[2]) / 2.0,
            (t[2] + t[0]) / 2.0,
            (t[0] + t[1] + t[2]) / 3.0,
        ];
        // A corner already tested in an earlier triangle is not tested again.
        let tested = |k: usize| k >= 3 || fresh >> k & 1 == 1;
        samples
            .iter()
            .enumerate()
            .filter(|&(k, _)| tested(k))
            .all(|(_, &p)| {
                if last < to.len() && near(p, &to[last]) {
                    return true;
                }
                if let Some(k) = (0..to.len()).find(|&k| near(p, &to[k])) {
                    last = k;
                    return true;
                }
                // Within the tolerance of a face (not on it): the neighbour's surface there.
                let mut faces = (0..6).filter(|&f| {
                    let d = [p[f / 2], size - p[f / 2]][f % 2];
                    d > 0.0 && d <= tolerance
                });
                faces.any(|f| beyond(f).is_none_or(|b| b.iter().any(|u| near(p, u))))
            })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The box and plane tests only reject what the exact distance would: `near` agrees
    /// with `point_triangle` on points around ordinary triangles, slivers and triangles
    /// just upright enough for the plane test, and accepts the points just inside the
    /// tolerance.
    #[test]
    fn target_tests_agree_with_the_exact_distance() {
        fn unit(state: &mut u64) -> f64 {
            *state ^= *state << 13;
            *state ^= *state >> 7;
            *state ^= *state << 17;
            (*state >> 11) as f64 / (1u64 << 53) as f64
        }
        // Points of a 4-wide box at a random place in [-4, 8]³ (neighbour surfaces are
        // shifted by a cell, 4 lattice steps).
        fn point(state: &mut u64, base: DVec3) -> DVec3 {
            base + DVec3::new(unit(state), unit(state), unit(state)) * 4.0
        }
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let tolerance = 0.4;
        let mut compared = [0usize; 2];
        for t in 0..2000 {
            let base = DVec3::new(unit(&mut state), unit(&mut state), unit(&mut state)) * 8.0
                - DVec3::splat(4.0);
            let (a, b) = (point(&mut state, base), point(&mut state, base));
            // Every fourth triangle a sliver (c a hair off the line through a and b: no
            // plane test), every fourth one just upright enough for the plane test
            // (sin θ about 2e-3), the rest ordinary.
            let along = a + (b - a) * unit(&mut state);
            let across = (b - a).any_orthonormal_vector();
            let c = match t % 4 {
                0 => along + across * 1e-9,
                1 => along + across * 2e-3 * (b - a).length(),
                _ => point(&mut state, base),
            };
            let target = targets(&[[a, b, c]], tolerance)[0];
            for _ in 0..50 {
                let p = point(&mut state, base);
                let d = point_triangle(p, a, b, c);
                assert_eq!(
                    target.near(p, tolerance),
                    d <= tolerance,
                    "{p:?} vs {a:?} {b:?} {c:?}"
                );
                compared[usize::from(d <= tolerance)] += 1;
                // Toward the centroid, bisected to the point just inside the tolerance:
                // the margins must not reject it.
                if d > tolerance {
                    let g = (a + b + c) / 3.0;
                    let (mut outside, mut inside) = (p, g);
                    for _ in 0..80 {
                        let mid = (outside + inside) / 2.0;
                        if point_triangle(mid, a, b, c) <= tolerance {
                            inside = mid;
                        } else {
                            outside = mid;
                        }
                    }
                    assert!(target.near(inside, tolerance), "{inside:?} at the edge");
                }
            }
        }
        assert!(
            compared.iter().all(|&n| n > 1_000),
            "both outcomes tested: {compared:?}"
        );
    }

    struct Linear;

    impl ScalarField for Linear {
        fn value(&self, x: DVec3) -> f64 {
            0.3 - x.dot(DVec3::new(1.0, 0.5, -0.25))
        }
        fn value_and_gradient(&self, x: DVec3) -> (f64, DVec3) {
            (self.value(x), -DVec3::new(1.0, 0.5, -0.25))
        }
    }

    /// R² − |x − c|²: a sphere of radius R at iso 0, |∇F| = 2R on it.
    struct Ball(f64);

    impl ScalarField for Ball {
        fn value(&self, x: DVec3) -> f64 {
            self.0 * self.0 - (x - DVec3::splat(1.0)).length_squared()
        }
        fn value_and_gradient(&self, x: DVec3) -> (f64, DVec3) {
            (self.value(x), -2.0 * (x - DVec3::splat(1.0)))
        }
    }

    fn grid() -> CoarseGrid {
        CoarseGrid {
            origin: DVec3::ZERO,
            fine: 0.05,
            cells: [10; 3],
        }
    }

    /// The trilinear interpolant of a linear field is the field: nothing rises however
    /// small the tolerance.
    #[test]
    fn a_plane_is_never_refined() {
        let g = grid();
        let mut levels = vec![1u8; g.cell_count()];
        let r = refine(
            &Linear,
            &g,
            &vec![0; g.cell_count()],
            &mut levels,
            0.0,
            1e-9,
            &mut Lattice::new(&g),
            u64::MAX,
            &mut Progress::none(),
        )
        .unwrap();
        assert_eq!(r.raised, [0, 0]);
        assert!(levels.iter().all(|&l| l == 1));
    }

    /// The criterion's promise, checked on the meshes themselves: on a sphere of radius
    /// 9 finest cells (level 1's surface lies up to 0.58 finest cells off level 3's in a
    /// cell, level 2's up to 0.13), the adaptive mesh at the levels it picks lies within
    /// the tolerance of the uniform finest mesh by an independent Hausdorff distance
    /// (measured 0.13 at 0.25 and 0.33 at 0.4), with over 3× fewer triangles; a tolerance
    /// below level 2's error gives the uniform mesh, one above level 1's raises nothing,
    /// and only cells near the surface rise.
    #[test]
    fn a_sphere_stays_within_the_tolerance_of_the_finest_surface() {
        let g = grid();
        let ball = Ball(0.45);
        let none = vec![0; g.cell_count()];
        let params = crate::adaptive::Params {
            isovalue: 0.0,
            normals: false,
            ..crate::adaptive::Params::default()
        };
        let extract = |levels: &[u8]| {
            crate::adaptive::extract(
                &ball,
                &g,
                levels,
                &params,
                &mut crate::progress::Progress::none(),
            )
            .unwrap()
        };
        let uniform = extract(&vec![3u8; g.cell_count()]);
        let mut levels = vec![1u8; g.cell_count()];
        assert_eq!(
            refine(
                &ball,
                &g,
                &none,
                &mut levels,
                0.0,
                2.0,
                &mut Lattice::new(&g),
                u64::MAX,
                &mut Progress::none(),
            )
            .unwrap()
            .raised,
            [0, 0]
        );
        for tolerance in [0.1, 0.25, 0.4] {
            let mut levels = vec![1u8; g.cell_count()];
            let r = refine(
                &ball,
                &g,
                &none,
                &mut levels,
                0.0,
                tolerance,
                &mut Lattice::new(&g),
                u64::MAX,
                &mut Progress::none(),
            )
            .unwrap();
            crate::adaptive::grid::balance(&g, &mut levels, &mut Progress::none()).unwrap();
            let out = extract(&levels);
            assert!(out.mesh.topology().is_watertight_oriented());
            let d =
                crate::mesh::hausdorff::hausdorff(&out.mesh, &uniform.mesh, 8.0 * g.fine) / g.fine;
            if tolerance < 0.13 {
                // Below level 2's error anywhere on this sphere (0.13): every surface cell
                // is raised to level 3, and the mesh is the uniform one.
                assert!(r.raised[1] > 0 && r.raised[0] == 0, "{r:?}");
                assert_eq!(out.stats.triangles, uniform.stats.triangles);
                assert!(d < 1e-9, "{d}");
            } else {
                assert!(r.raised[0] > 0, "{tolerance}: {r:?}");
                assert!(out.stats.triangles < uniform.stats.triangles / 3);
                assert!(
                    d <= tolerance + 0.05,
                    "{tolerance}: Hausdorff {d} finest cells"
                );
            }
            let coarse = 4.0 * g.fine;
            for (i, &l) in levels.iter().enumerate() {
                if l > 1 {
                    let c = g.coords(i).map(|x| x as f64 * coarse);
                    let centre = DVec3::new(c[0], c[1], c[2]) + DVec3::splat(coarse / 2.0);
                    let d = ((centre - DVec3::splat(1.0)).length() - 0.45).abs();
                    assert!(d < 3.0 * coarse, "cell {i} raised {d} from the surface");
                }
            }
        }
    }

    /// The crack triangles [`crack_triangles`] places close exactly the gap the two sides
    /// leave in the face: the edges they hold an odd number of times are the coarse
    /// level's trace in the face, the finer level's trace, and the pieces of a quad's
    /// border between two finer points where the coarse side sees no crossing, each once
    /// (modulo 2), point for point. Random smooth fields on a cell's lattice, every face,
    /// coarse levels 1 and 2.
    #[test]
    fn crack_triangles_close_the_gap_between_the_traces() {
        type Key = [u64; 3];
        type Edge = (Key, Key);
        fn key(p: DVec3) -> Key {
            p.to_array().map(f64::to_bits)
        }
        fn edge(a: DVec3, b: DVec3) -> Edge {
            let (a, b) = (key(a), key(b));
            if a < b {
                (a, b)
            } else {
                (b, a)
            }
        }
        fn toggle(set: &mut std::collections::BTreeSet<Edge>, e: Edge) {
            if !set.remove(&e) {
                set.insert(e);
            }
        }
        let mut unit = crate::test_rng::unit(41);
        let mut faces_with_cracks = 0;
        for _ in 0..300 {
            // Three Gaussian bumps of about a cell's width, placed around the cell.
            let bumps: Vec<(DVec3, f64)> = (0..3)
                .map(|_| {
                    let c = DVec3::new(unit(), unit(), unit()) * 6.0 - DVec3::splat(1.0);
                    (c, 1.0 + 2.0 * unit())
                })
                .collect();
            let mut values = [0.0; M3];
            for (v, value) in values.iter_mut().enumerate() {
                let p = DVec3::new((v % M) as f64, (v / M % M) as f64, (v / (M * M)) as f64);
                *value = bumps
                    .iter()
                    .map(|&(c, w)| (-(p - c).length_squared() / (w * w)).exp())
                    .sum();
            }
            let iso = 0.2 + 0.4 * unit();
            for level in 1..=2u8 {
                let stride = |l: u8| (FINE_PER_COARSE / subdivisions(l)) as usize;
                let coarse = lattice_surface(&values, stride(level), iso).triangles;
                let fine = lattice_surface(&values, stride(level + 1), iso).triangles;
                for f in 0..6 {
                    let (a, plane) = (f / 2, ((f % 2) * (M - 1)) as f64);
                    let in_face = |p: DVec3| p[a] == plane;
                    let mut expected = std::collections::BTreeSet::new();
                    for t in coarse.iter().chain(&fine) {
                        for k in 0..3 {
                            let (p, q) = (t[k], t[(k + 1) % 3]);
                            if in_face(p) && in_face(q) {
                                toggle(&mut expected, edge(p, q));
                            }
                        }
                    }
                    // Border pieces: a quad side whose ends agree in sign but whose
                    // middle does not.
                    let (u, v) = ((a + 1) % 3, (a + 2) % 3);
                    let quads = subdivisions(level) as usize;
                    let side = (M - 1) / quads;
                    let at = |n: [usize; 3]| values[n[0] + M * (n[1] + M * n[2])];
                    for qv in 0..quads {
                        for qu in 0..quads {
                            for (start, dir) in [((0, 0), u), ((0, 0), v), ((1, 0), v), ((0, 1), u)]
                            {
                                let mut n = [0; 3];
                                n[a] = f % 2 * (M - 1);
                                n[u] = (qu + start.0) * side;
                                n[v] = (qv + start.1) * side;
                                let (mut mid, mut end) = (n, n);
                                mid[dir] += side / 2;
                                end[dir] += side;
                                let sign = |n| at(n) > iso;
                                if sign(n) == sign(end) && sign(n) != sign(mid) {
                                    let first = edge_point(&values, n, dir, side / 2, iso);
                                    let second = edge_point(&values, mid, dir, side / 2, iso);
                                    toggle(&mut expected, edge(first, second));
                                }
                            }
                        }
                    }
                    let cracks = crack_triangles(&values, f, level, iso);
                    let mut odd = std::collections::BTreeSet::new();
                    for t in &cracks {
                        assert!(t.iter().all(|&p| in_face(p)), "{t:?} off face {f}");
                        for k in 0..3 {
                            toggle(&mut odd, edge(t[k], t[(k + 1) % 3]));
                        }
                    }
                    // A degenerate crack triangle (two corners the same point) holds
                    // its doubled edge twice: no edge of a point with itself counts.
                    odd.retain(|e| e.0 != e.1);
                    expected.retain(|e| e.0 != e.1);
                    assert_eq!(odd, expected, "face {f}, coarse level {level}, iso {iso}");
                    faces_with_cracks += usize::from(!cracks.is_empty());
                }
            }
        }
        assert!(
            faces_with_cracks > 300,
            "{faces_with_cracks} faces had cracks"
        );
    }

    /// Every point of a crack triangle lies within a third of the tolerance of one of its
    /// samples, and a tolerance far below a finest cell takes a bounded number of them.
    #[test]
    fn crack_samples_cover_the_triangle_within_a_third_of_the_tolerance() {
        let mut unit = crate::test_rng::unit(7);
        for _ in 0..200 {
            let mut corner = || DVec3::new(unit(), unit(), 0.0) * 4.0;
            let t = [corner(), corner(), corner()];
            let tolerance = 0.1 + 0.4 * unit();
            let samples: Vec<DVec3> = crack_samples(&t, tolerance).collect();
            for _ in 0..100 {
                let (a, b) = (unit(), unit());
                let (a, b) = if a + b > 1.0 {
                    (1.0 - a, 1.0 - b)
                } else {
                    (a, b)
                };
                let p = t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b;
                let nearest = samples
                    .iter()
                    .map(|s| s.distance(p))
                    .fold(f64::INFINITY, f64::min);
                assert!(nearest <= tolerance / 3.0, "{p:?} {nearest} from {t:?}");
            }
            let most = (MOST_PARTS + 1) * (MOST_PARTS + 2) / 2;
            assert!(crack_samples(&t, 1e-9).count() <= most);
        }
    }
}
