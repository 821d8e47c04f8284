//! Run time: the isosurface kept in memory and updated coherently as the isovalue slides.
//!
//! State (the paper's §3.2): the active-edge array E (one vertex per active edge, with
//! what its position and normal are interpolated from), the vertex and normal arrays V and
//! N, triangle lists bucketed by the number of triangles their cell has (a cell's
//! triangles are contiguous; a hole left by a removed cell is filled by the bucket's last
//! cell), and maps from edge id to vertex (HE) and from cell id to its case and slot
//! (HC), kept in bricks of the lattice (found by arithmetic, no hashing). An isovalue
//! change walks the store's skip list from the current position to the new one,
//! collecting the net edge changes; removed edges leave holes that added edges fill,
//! leftovers are compacted from the end; only cells around changed edges are
//! re-triangulated, cells around moved vertices get their indices rewritten in place.
//! What only reads (added edges' interpolation data, dirty cells' cases and triangles) is
//! computed on all threads first; what writes the shared lists runs in order on one, so
//! the arrays are the same for any thread count.
//!
//! An update costs what changed, not the surface: the full arrays (every vertex moves
//! when the isovalue does, so V and N are O(surface); I is gathered from the buckets)
//! are computed when first read after an update ([`Slider::positions`],
//! [`Slider::normals`], [`Slider::triangle_array`]), into the previous arrays' memory.
//! Scratch lists and the walk's edge pairs live in the slider and keep their capacity, so
//! a steady slide allocates nothing that grows with the surface but the returned
//! [`Change`] (the radix sort's passes take a 16 KiB digit table each); what a larger
//! update (the first surface, a jump) needed is cut back after it ([`trim`]), and large
//! updates precompute in batches, so memory follows the surface shown
//! ([`Slider::held_bytes`]).

use super::build::node_edges;
use super::lod::{self, LodMesh, LodParams};
use super::store::Store;
use super::window::CellWindow;
use crate::error::{Error, Result};
use crate::field::grid::{node_gradient, Lattice, NodeCoords};
use crate::mc::bricks::BrickMap;
use crate::mc::table::edge_index;
use crate::mc::{
    case_table, corner_offset, edge_corner_axis, linear_crossing, radix, VirtualGrid,
    MOST_TRIANGLES,
};
use crate::prefetch::prefetch;
use crate::progress::Progress;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::cell::{Cell, OnceCell, RefCell};
use std::time::Instant;

/// What one interpolated vertex is computed from besides its edge (which the caller
/// keeps): the two end values and the node gradients (f32, as normals only need f32).
/// 32 bytes: one per vertex of the surface is held.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct EdgeData {
    pub(crate) s0: f32,
    pub(crate) s1: f32,
    pub(crate) g0: [f32; 3],
    pub(crate) g1: [f32; 3],
}

const _: () = assert!(std::mem::size_of::<EdgeData>() == 32);

impl EdgeData {
    /// Position (f64) and unit normal (pointing down the gradient, the side the case
    /// table's triangles face) at isovalue `iso` of the vertex on the edge from node `c`
    /// along `axis`. The slider and the from-scratch extraction both place vertices with
    /// this.
    #[inline]
    pub(crate) fn vertex(
        &self,
        lattice: &Lattice,
        c: [usize; 3],
        axis: usize,
        iso: f64,
    ) -> (DVec3, [f32; 3]) {
        let t = linear_crossing(self.s0 as f64, self.s1 as f64, iso);
        let p = lattice.edge_point(c, axis, t);
        let (g0, g1) = (Vec3::from_array(self.g0), Vec3::from_array(self.g1));
        let g = g0 * (1.0 - t as f32) + g1 * t as f32;
        let n = (-g).normalize_or_zero();
        (p, n.to_array())
    }
}

/// The triangles of one cell: where they sit in the bucketed lists. Packed: 6 bytes,
/// not 8, for each of the lattice's 64 cells of every brick HC holds (the surface
/// crosses a fraction of a brick's cells, so HC is mostly unused entries).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C, packed)]
struct CellEntry {
    case: u8,
    /// Triangles per cell of the bucket (0 never stored).
    bucket: u8,
    slot: u32,
}

/// Cells with `size` triangles each, stored contiguously.
#[derive(Clone, Debug, Default)]
struct Bucket {
    size: usize,
    triangles: Vec<[u32; 3]>,
    cells: Vec<u32>,
}

/// What one isovalue change did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Change {
    /// The isovalue now shown.
    pub isovalue: f64,
    /// Triangles removed, in the vertex numbering before the change.
    pub removed_triangles: Vec<[u32; 3]>,
    /// Triangles added, in the vertex numbering after the change.
    pub added_triangles: Vec<[u32; 3]>,
    /// Vertices that kept their edge but changed index: (before, after).
    pub moved_vertices: Vec<(u32, u32)>,
    pub edges_added: u64,
    pub edges_removed: u64,
    /// Blocks applied per skip-list level (index 0 = level 0).
    pub blocks_per_level: Vec<u64>,
    /// Wall time of the update, seconds.
    pub seconds: f64,
}

/// Running totals.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SliderStats {
    /// Isovalue changes applied.
    pub updates: u64,
    /// Sum of update times, seconds.
    pub total_seconds: f64,
    /// The last update's time, seconds.
    pub last_seconds: f64,
    /// Edge additions and removals applied so far.
    pub edge_changes: u64,
}

/// V and N at one isovalue.
#[derive(Clone, Debug, Default)]
struct Vertices {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
}

/// Net change per edge of a walk (+1 on, −1 off), as (edge, change) pairs netted by
/// sorting rather than through a hash map: a radix sort costs a few instructions per
/// bump where hashing cost about a hundred, and it leaves the edges in order.
#[derive(Default)]
struct Delta {
    pairs: Vec<(u32, i32)>,
    /// Length after the last netting: pairs are netted again once as many have been
    /// added, so a long walk holds at most about twice its distinct edges.
    netted: usize,
    /// Pairs bumped since the walk began (before netting): what the walk read.
    bumped: usize,
    /// The radix sort's second buffer, kept for its capacity.
    spare: Vec<(u32, i32)>,
}

impl Delta {
    /// Empties the pairs for a new walk.
    fn clear(&mut self) {
        self.pairs.clear();
        self.netted = 0;
        self.bumped = 0;
    }

    #[inline]
    fn bump(&mut self, e: u32, d: i32) {
        self.pairs.push((e, d));
        self.bumped += 1;
        if self.pairs.len() >= 2 * self.netted.max(4096) {
            self.net();
        }
    }

    /// Sorts by edge and sums each edge's changes, dropping those that cancel.
    fn net(&mut self) {
        self.sort();
        let p = &mut self.pairs;
        let mut out = 0;
        let mut i = 0;
        while i < p.len() {
            let e = p[i].0;
            let mut sum = 0i32;
            while i < p.len() && p[i].0 == e {
                sum = sum.saturating_add(p[i].1);
                i += 1;
            }
            if sum != 0 {
                p[out] = (e, sum);
                out += 1;
            }
        }
        p.truncate(out);
        self.netted = out;
    }

    /// Sorts the pairs by edge (the grid extractors' radix sort, over the bits edge ids
    /// actually span).
    fn sort(&mut self) {
        radix::sort_by_key_in(&mut self.pairs, &mut self.spare, |&(e, _)| e as u64);
    }
}

/// Lists an update needs, kept between updates so they keep their capacity.
#[derive(Default)]
struct Scratch {
    delta: Delta,
    /// One bit per cell, set while the cell is in `reindex`: removes repeats and, read
    /// in order, gives the cells ascending without sorting (see [`push_unique`],
    /// [`ascending`]); cleared after each use. Cells/8 bytes, 1/32 of an f32 volume,
    /// resident only where cells have been marked.
    marks: Vec<u64>,
    /// List `dirty` from the changed edges, once each and ascending: the lower and the
    /// upper half of the cells, side by side.
    windows: [CellWindow; 2],
    /// The upper half's cells, appended to `dirty` once listed.
    upper: Vec<u32>,
    removed: Vec<u32>,
    added: Vec<u32>,
    dirty: Vec<u32>,
    holes: Vec<u32>,
    reindex: Vec<u32>,
    /// Interpolation data of each added edge, computed in parallel before the edges go in.
    added_data: Vec<EdgeData>,
    /// Each dirty cell's new case and triangles, computed in parallel before the cells go in.
    retriangulated: Vec<CellTriangles>,
}

impl Scratch {
    /// Gives back what a large update left in the lists (see [`trim`]); true when any
    /// list was cut.
    fn trim(&mut self) -> bool {
        let used = self.delta.pairs.len();
        let mut cut = trim(&mut self.delta.pairs, used);
        // What the sort left in its second buffer is not needed.
        self.delta.spare.clear();
        cut |= trim(&mut self.delta.spare, used);
        for v in [
            &mut self.removed,
            &mut self.added,
            &mut self.dirty,
            &mut self.upper,
            &mut self.holes,
            &mut self.reindex,
        ] {
            let used = v.len();
            cut |= trim(v, used);
        }
        let used = self.added_data.len();
        cut |= trim(&mut self.added_data, used);
        let used = self.retriangulated.len();
        cut | trim(&mut self.retriangulated, used)
    }
}

/// Capacity a list keeps whatever it held: below this many bytes [`trim`] leaves it.
const TRIM_FLOOR_BYTES: usize = 1 << 16;

/// Cuts `v`'s capacity to twice `used` when it is above four times `used` and
/// [`TRIM_FLOOR_BYTES`]: after a large update (the first surface, a jump) its lists
/// would otherwise hold their peak for the rest of the session, while steady updates
/// of one size never reallocate (a list grows twice its size before it is cut again).
fn trim<T>(v: &mut Vec<T>, used: usize) -> bool {
    cut_capacity(v, 4 * used, 2 * used)
}

/// Cuts a list of the surface itself (E, its data, a bucket) to an eighth over `used`
/// once it holds a quarter more than that ([`TRIM_FLOOR_BYTES`] at least). Unlike the
/// scratch lists, whose use swings with the size of each step, these follow the surface:
/// one that grew past its capacity was doubled by `push`, and one that shrank by a fifth
/// has taken a large step (whose cost dwarfs the copy). Cutting after the update, not
/// reserving less before it: a capacity check beside the pushes of the cells going back
/// made 0.1 % steps about 4 % slower.
fn trim_to_surface<T>(v: &mut Vec<T>, used: usize) -> bool {
    cut_capacity(v, used + used / 4, used + used / 8)
}

/// Shrinks `v` to `keep` items of capacity when it holds more than `most` and more than
/// [`TRIM_FLOOR_BYTES`]; true when it did.
fn cut_capacity<T>(v: &mut Vec<T>, most: usize, keep: usize) -> bool {
    let bytes = v.capacity() * std::mem::size_of::<T>();
    let cut = bytes > TRIM_FLOOR_BYTES && v.capacity() > most;
    if cut {
        v.shrink_to(keep);
    }
    cut
}

/// Items of an update's parallel phases computed per batch before they are written: the
/// precomputed data of a large update (the first surface: every cell) is then a few
/// megabytes, not tens.
const BATCH: usize = 1 << 13;

/// Pairs a walk bumps (about its bytes of edge lists read) above which the walked
/// sections' pages are handed back once it ends.
const RELEASE_AFTER_PAIRS: usize = 1 << 16;

/// A walk reports progress (and hears a cancel) each time it has passed this many ranks.
const REPORT_RANKS: usize = 1 << 16;

/// A cell's case and its triangles as vertex indices.
#[derive(Clone, Copy, Debug, Default)]
struct CellTriangles {
    case: u8,
    count: u8,
    triangles: [[u32; 3]; MOST_TRIANGLES],
}

impl CellTriangles {
    fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles[..self.count as usize]
    }
}

/// [`BrickMap`] key of lattice node or cell `i` (a cell is keyed by its lower node).
#[inline]
fn grid_key(coords: NodeCoords, i: usize) -> u64 {
    let [x, y, z] = coords.coords(i);
    VirtualGrid::key(x as u32, y as u32, z as u32)
}

/// Lattice index of a [`BrickMap`] key.
fn lattice_index(lattice: &Lattice, key: u64) -> usize {
    let [x, y, z] = VirtualGrid::coords(key).map(|c| c as usize);
    lattice.index(x, y, z)
}

/// HE's bricks are 8³ ([`BrickShape`](crate::mc::bricks::BrickShape) 3): a cell's twelve
/// edges are read from its eight corners, which lie in one 8³ brick for 343 of 512
/// cells but in one 4³ brick for only 27 of 64; with 4³ bricks HE took 9.3 MiB less at
/// MNI152 256³ but 0.1 % steps took about 5 % longer. HE's bricks are chunked (values
/// allocated a 2³ sub-cube at a time): the slider's own memory after a 0.1 % step on
/// MNI152 fell from 46.9 to 31.0 MiB (36.3 with 4³ sub-cubes), for 0.1 % steps about 4 %
/// longer.
const HE_BRICK: u32 = 3;
/// HC's bricks are 4³: a cell is looked up alone, so the smaller bricks cost no time
/// and hold less of what the surface does not cross (HC 11.3 -> 7.6 MiB at MNI152 256³).
/// Unchunked: allocating them a 2³ sub-cube at a time saved 2.7 MiB more but made 0.1 %
/// and 1 % steps 2–8 % slower.
const HC_BRICK: u32 = 2;

/// The [`BrickMap`] of a lattice, indexed densely (4 bytes per brick of the lattice): a
/// lookup is arithmetic and two loads, where a hash map's was a hash, a probe and a
/// cache miss, and memory stays with the bricks the surface occupies (emptied bricks
/// are reused).
fn lattice_map<T: Copy + Default, const S: u32, const C: bool>(
    lattice: &Lattice,
) -> BrickMap<T, S, C> {
    BrickMap::within(lattice.dims.map(|n| n as u32))
}

/// (corner, axis) of each local edge of a cell ([`edge_corner_axis`]), as a table for
/// the per-triangle reads of HE.
const EDGE_CORNER_AXIS: [(u8, u8); 12] = {
    let mut t = [(0u8, 0u8); 12];
    let mut e = 0;
    while e < 12 {
        let (k, axis) = edge_corner_axis(e);
        t[e] = (k as u8, axis as u8);
        e += 1;
    }
    t
};

/// How many items ahead the update's loops prefetch: enough to overlap several misses,
/// few enough that the lines are still cached when their item comes.
const AHEAD: usize = 8;

/// No vertex: the edge on that axis is off.
const NO_VERTEX: u32 = u32::MAX;

/// HE: the vertex of each active edge, stored at the edge's lower node (one entry per
/// axis, [`NO_VERTEX`] where that edge is off), so that a cell's twelve edges are read
/// with the one brick lookup of its eight corners.
struct EdgeVertices {
    coords: NodeCoords,
    map: BrickMap<[u32; 3], HE_BRICK, true>,
}

impl EdgeVertices {
    /// Empty, over `lattice`, whose index-to-coordinates `coords` is (the store's).
    fn new(lattice: &Lattice, coords: NodeCoords) -> EdgeVertices {
        EdgeVertices {
            coords,
            map: lattice_map(lattice),
        }
    }

    /// Node key and axis of edge `e` (`node · 3 + axis`).
    #[inline]
    fn split(&self, e: u32) -> (u64, usize) {
        (grid_key(self.coords, e as usize / 3), e as usize % 3)
    }

    /// Turns edge `e` on with `vertex`; false (and nothing changed) when it was on.
    #[inline]
    fn turn_on(&mut self, e: u32, vertex: u32) -> bool {
        let (key, axis) = self.split(e);
        let v = &mut self.map.get_or_insert(key, [NO_VERTEX; 3])[axis];
        let was_off = *v == NO_VERTEX;
        if was_off {
            *v = vertex;
        }
        was_off
    }

    /// Gives edge `e`, which is on, the vertex `vertex`.
    #[inline]
    fn set(&mut self, e: u32, vertex: u32) {
        let (key, axis) = self.split(e);
        self.map.get_or_insert(key, [NO_VERTEX; 3])[axis] = vertex;
    }

    /// Turns edge `e` off, returning its vertex if it was on.
    #[inline]
    fn turn_off(&mut self, e: u32) -> Option<u32> {
        let (key, axis) = self.split(e);
        let v = self.map.get_mut(key)?;
        let vertex = std::mem::replace(&mut v[axis], NO_VERTEX);
        if *v == [NO_VERTEX; 3] {
            self.map.remove(key);
        }
        (vertex != NO_VERTEX).then_some(vertex)
    }

    /// Starts loading edge `e`'s entry.
    #[inline]
    fn prefetch(&self, e: u32) {
        self.map.prefetch(self.split(e).0);
    }

    /// Vertices of the edges from each corner of the cell keyed `cell` ([`NO_VERTEX`]
    /// where off).
    #[inline]
    fn around(&self, cell: u64) -> [[u32; 3]; 8] {
        self.map.corners_or(cell, [NO_VERTEX; 3])
    }
}

/// HC: case and bucket slot of each active cell, keyed by the cell's lower node
/// ([`grid_key`]).
type CellTable = BrickMap<CellEntry, HC_BRICK>;

const _: () = assert!(std::mem::size_of::<CellEntry>() == 6);

/// An isosurface that slides: open a store, set isovalues, read the arrays.
///
/// Not `Sync`: the full arrays are filled lazily behind `&self`.
pub struct Slider {
    store: Store,
    /// Level-0 position: nodes with rank < `rank` lie at or below the isovalue.
    rank: usize,
    iso: f64,
    edges: Vec<u32>,
    data: Vec<EdgeData>,
    /// Bytes of the store's value bricks held past which [`Slider::trim_values`] frees
    /// those the surface does not read, and the surface's edges at the last trim.
    values_budget: usize,
    values_edges: usize,
    he: EdgeVertices,
    hc: CellTable,
    buckets: Vec<Bucket>,
    /// V and N at `iso`, computed on first read after an update.
    vertices: OnceCell<Vertices>,
    /// The arrays of an earlier isovalue, whose memory the next computation reuses.
    spare_vertices: RefCell<Vertices>,
    /// I gathered from the buckets, on first read after an update.
    all_triangles: OnceCell<Vec<[u32; 3]>>,
    spare_triangles: RefCell<Vec<[u32; 3]>>,
    scratch: Scratch,
    stats: SliderStats,
    /// Level of detail asked for (error bound 0: off, the LOD mesh is the exact one).
    lod: LodParams,
    /// The LOD mesh at `iso`, computed on first read after an update.
    lod_mesh: OnceCell<LodMesh>,
}

impl Slider {
    /// An empty surface below every value of the store's volume.
    pub fn new(store: Store) -> Slider {
        let buckets = (0..=MOST_TRIANGLES)
            .map(|size| Bucket {
                size,
                ..Bucket::default()
            })
            .collect();
        let (he, hc) = (
            EdgeVertices::new(store.lattice(), store.coords),
            lattice_map(store.lattice()),
        );
        let cells = store.nodes;
        let values_budget = values_floor(&store);
        let mut slider = Slider {
            store,
            rank: 0,
            iso: 0.0,
            edges: Vec::new(),
            data: Vec::new(),
            values_budget,
            values_edges: 0,
            he,
            hc,
            buckets,
            vertices: OnceCell::new(),
            spare_vertices: RefCell::default(),
            all_triangles: OnceCell::new(),
            spare_triangles: RefCell::default(),
            scratch: Scratch {
                // Allocated zeroed at open, where zeroing costs no update anything (in
                // a fresh process the system maps the block and zeroes each page as it
                // is first marked). Allocated when a vertex first moved, it came out of
                // the heap the first surface had freed and was written whole there:
                // that step took 0.75 ms longer at 256³ (2 MiB).
                marks: vec![0; cells.div_ceil(64)],
                ..Scratch::default()
            },
            stats: SliderStats::default(),
            lod: LodParams {
                error_bound: 0.0,
                ..LodParams::default()
            },
            lod_mesh: OnceCell::new(),
        };
        slider.clear();
        slider
    }

    /// Frees the store's value bricks that the surface does not read once they pass the
    /// budget: an eighth of the volume, or half again what the surface read at the last
    /// trim, whichever is more (so the trim, a pass over E, comes only after the
    /// surface has moved into as many new bricks again); or, above the eighth, once the
    /// surface has shrunk to half its edges at the last trim. Says whether it freed any.
    fn trim_values(&mut self) -> bool {
        let held = self.store.values_held();
        let floor = values_floor(&self.store);
        let shrunk = held > floor && 2 * self.edges.len() < self.values_edges;
        if held <= self.values_budget && !shrunk {
            return false;
        }
        let (dims, coords) = (self.store.lattice().dims, self.store.coords);
        let edges = &self.edges;
        self.store.retain_values(|keep| {
            for &e in edges {
                let c = coords.coords((e / 3) as usize);
                edge_data_nodes(dims, c, (e % 3) as usize, true, &mut *keep);
            }
        });
        let kept = self.store.values_held();
        self.values_budget = floor.max(kept + kept / 2);
        self.values_edges = self.edges.len();
        true
    }

    /// Back to the empty surface below every value (as [`Slider::new`] leaves it).
    fn clear(&mut self) {
        self.rank = 0;
        self.iso = self.store.value_range().0 as f64 - 1.0;
        self.edges.clear();
        self.data.clear();
        self.he.map.clear();
        self.hc.clear();
        for b in &mut self.buckets {
            b.triangles.clear();
            b.cells.clear();
        }
        self.vertices.take();
        self.all_triangles.take();
        self.lod_mesh.take();
    }

    /// Opens the store at `path`.
    pub fn open(path: &std::path::Path) -> Result<Slider> {
        Ok(Slider::new(Store::open(path)?))
    }

    /// The store.
    pub fn store(&self) -> &Store {
        &self.store
    }

    /// The isovalue shown.
    pub fn isovalue(&self) -> f64 {
        self.iso
    }

    /// Vertex positions (V), computed on the first read after an update.
    pub fn positions(&self) -> &[[f32; 3]] {
        &self.vertices().positions
    }

    /// Unit vertex normals (N), computed on the first read after an update.
    pub fn normals(&self) -> &[[f32; 3]] {
        &self.vertices().normals
    }

    /// Number of vertices (computes nothing).
    pub fn vertex_count(&self) -> usize {
        self.edges.len()
    }

    /// All triangles (I), bucket after bucket, gathered on the first read after an update.
    pub fn triangle_array(&self) -> &[[u32; 3]] {
        self.all_triangles.get_or_init(|| {
            let mut out = self.spare_triangles.take();
            self.triangles_into(&mut out);
            out
        })
    }

    /// V and N at the current isovalue: every vertex moves when the isovalue does, so
    /// this is O(surface) and runs once per update, only when someone reads them.
    fn vertices(&self) -> &Vertices {
        self.vertices.get_or_init(|| {
            let mut v = self.spare_vertices.take();
            self.compute_vertices(&mut v);
            v
        })
    }

    /// Edge id (`node · 3 + axis`) of each vertex.
    pub fn vertex_edges(&self) -> &[u32] {
        &self.edges
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.buckets.iter().map(|b| b.triangles.len()).sum()
    }

    /// All triangles (I), bucket after bucket.
    pub fn triangles(&self) -> Vec<[u32; 3]> {
        let mut out = Vec::new();
        self.triangles_into(&mut out);
        out
    }

    /// [`Slider::triangles`] into `out` (cleared first), reusing its allocation: a host
    /// that reads I after every update need not allocate it anew each time.
    pub fn triangles_into(&self, out: &mut Vec<[u32; 3]>) {
        out.clear();
        out.reserve(self.triangle_count());
        for b in &self.buckets {
            out.extend_from_slice(&b.triangles);
        }
    }

    /// Active cells and their cases, sorted by cell id.
    pub fn cells(&self) -> Vec<(u32, u8)> {
        let lattice = self.store.lattice();
        let mut v: Vec<(u32, u8)> = (self.hc.iter())
            .map(|(key, e)| (lattice_index(lattice, key) as u32, e.case))
            .collect();
        v.sort_unstable();
        v
    }

    /// Bytes the slider holds in its own memory (HE, HC, E and its interpolation data,
    /// the buckets, the scratch lists, the full arrays last read, the bricks of values
    /// read from the store; not the LOD mesh); the store's mapped pages are not counted.
    /// After an update it follows the surface: what a larger surface left behind is given
    /// back (a scratch list keeps at most four times what the last update used, or 64 KiB;
    /// E, its data and the buckets a quarter more than the surface; the brick maps a
    /// quarter more bricks than in use; the values' bricks the surface's, or an eighth of
    /// the volume).
    pub fn held_bytes(&self) -> u64 {
        fn cap<T>(v: &Vec<T>) -> u64 {
            (v.capacity() * std::mem::size_of::<T>()) as u64
        }
        let s = &self.scratch;
        let lists = cap(&s.delta.pairs)
            + cap(&s.delta.spare)
            + cap(&s.marks)
            + s.windows.iter().map(CellWindow::held_bytes).sum::<u64>()
            + [
                &s.removed, &s.added, &s.dirty, &s.upper, &s.holes, &s.reindex,
            ]
            .into_iter()
            .map(cap)
            .sum::<u64>()
            + cap(&s.added_data)
            + cap(&s.retriangulated);
        let buckets: u64 = (self.buckets.iter())
            .map(|b| cap(&b.triangles) + cap(&b.cells))
            .sum();
        let arrays = |v: Option<&Vertices>| v.map_or(0, |v| cap(&v.positions) + cap(&v.normals));
        let spare = self.spare_vertices.borrow();
        let triangles =
            self.all_triangles.get().map_or(0, cap) + cap(&self.spare_triangles.borrow());
        self.he.map.bytes()
            + self.hc.bytes()
            + cap(&self.edges)
            + cap(&self.data)
            + buckets
            + lists
            + arrays(self.vertices.get())
            + arrays(Some(&spare))
            + triangles
            + self.store.values_held() as u64
    }

    /// Running totals.
    pub fn stats(&self) -> &SliderStats {
        &self.stats
    }

    /// Sets the level of detail of [`Slider::lod_mesh`] (error bound 0: the exact mesh).
    /// The exact arrays ([`Slider::positions`] ...) and the [`Change`]s are unaffected.
    pub fn set_lod(&mut self, params: LodParams) -> Result<()> {
        params.validate()?;
        if params != self.lod {
            self.lod = params;
            self.lod_mesh.take();
        }
        Ok(())
    }

    /// The level of detail asked for.
    pub fn lod(&self) -> LodParams {
        self.lod
    }

    /// The level-of-detail mesh of the current surface ([`lod::extract`] over the active
    /// cells), computed on the first read after an update or a change of [`Slider::lod`]:
    /// O(surface), not coherent with the previous isovalue's.
    pub fn lod_mesh(&self) -> Result<&LodMesh> {
        if let Some(m) = self.lod_mesh.get() {
            return Ok(m);
        }
        let lattice = self.store.lattice();
        let mut active: Vec<u32> = (self.hc.iter())
            .map(|(key, _)| lattice_index(lattice, key) as u32)
            .collect();
        active.sort_unstable();
        let mesh = lod::extract(&self.store, self.iso, &active, &self.lod)?;
        Ok(self.lod_mesh.get_or_init(|| mesh))
    }

    /// Moves the surface to isovalue `iso`.
    pub fn set_isovalue(&mut self, iso: f64) -> Result<Change> {
        self.set_isovalue_with(iso, &mut Progress::none())
    }

    /// Moves the surface to isovalue `iso`, reporting progress during long walks.
    pub fn set_isovalue_with(&mut self, iso: f64, progress: &mut Progress) -> Result<Change> {
        if !iso.is_finite() {
            return Err(Error::InvalidParameter {
                name: "isovalue",
                message: format!("must be finite, got {iso}"),
            });
        }
        let start = Instant::now();
        self.store.check_length()?;
        let target = self.store.rank_of(iso)?;
        let mut change = Change {
            isovalue: iso,
            blocks_per_level: vec![0; self.store.levels.len() + 1],
            ..Change::default()
        };
        // The full arrays of the old isovalue are stale; keep their memory for reuse.
        if let Some(v) = self.vertices.take() {
            *self.spare_vertices.get_mut() = v;
        }
        if let Some(t) = self.all_triangles.take() {
            *self.spare_triangles.get_mut() = t;
        }
        self.lod_mesh.take();
        let mut delta = std::mem::take(&mut self.scratch.delta);
        delta.clear();
        let walked = self
            .walk(target, &mut delta, &mut change, progress)
            .map(|()| delta.net());
        let walk_failed = walked.is_err();
        let long_walk = delta.bumped >= RELEASE_AFTER_PAIRS;
        if long_walk {
            // A long walk read megabytes of edge lists that the next small steps will
            // not read again (they read the few blocks around the new rank), and its
            // pairs needed room for twice its distinct edges and a sort buffer as long:
            // given back before the surface grows.
            self.store.release_lists();
            delta.spare = Vec::new();
            let used = delta.pairs.len();
            trim(&mut delta.pairs, used);
        }
        let applied = walked.and_then(|()| {
            self.rank = target;
            self.iso = iso;
            if delta.pairs.len() >= PARALLEL_MIN {
                // On one of rayon's threads: its parallel phases then wake one worker
                // each, not two plus this thread.
                rayon::scope(|_| self.apply(&delta, &mut change))
            } else {
                self.apply(&delta, &mut change)
            }
        });
        self.scratch.delta = delta;
        let cut = self.scratch.trim() | self.trim_surface_lists();
        // The bricks of values read so far stay while they are few (the next small steps
        // read mostly the same ones) and go after a jump that read many.
        let cut = self.trim_values() | cut;
        if long_walk || cut {
            crate::heap::return_freed_memory();
        }
        if applied.is_err() && !walk_failed {
            // A chunk found corrupt while applying leaves cells, edges and buckets half
            // updated; the empty surface is the one state known to be right, so the next
            // update walks up from it. A walk that stopped (a cancel, a corrupt list)
            // changed nothing but `delta`: the surface stays as it was.
            self.clear();
        }
        applied?;
        change.seconds = start.elapsed().as_secs_f64();
        self.stats.updates += 1;
        self.stats.total_seconds += change.seconds;
        self.stats.last_seconds = change.seconds;
        self.stats.edge_changes += change.edges_added + change.edges_removed;
        Ok(change)
    }

    /// Walks the skip list from the current rank to `target`, taking the highest level
    /// whose block fits, and puts the net change per edge (+1 on, −1 off) into `delta`.
    fn walk(
        &self,
        target: usize,
        delta: &mut Delta,
        change: &mut Change,
        progress: &mut Progress,
    ) -> Result<()> {
        let store = &self.store;
        let lattice = *store.lattice();
        let limit = 3 * store.nodes as u32;
        let mut bump = |e: u32, d: i32| -> Result<()> {
            if e >= limit {
                return Err(inconsistent(
                    &self.store,
                    format!("edge {e} is out of range"),
                ));
            }
            delta.bump(e, d);
            Ok(())
        };
        progress.phase("walking the skip list", 0.0, 1.0)?;
        let mut r = self.rank;
        let span = r.abs_diff(target).max(1) as f64;
        // Reported by ranks passed, not by steps: a long jump is a few steps over large
        // blocks, and a host's cancel must still get a word in.
        let mut reported = r;
        while r != target {
            if r.abs_diff(reported) >= REPORT_RANKS {
                reported = r;
                progress.report(1.0 - r.abs_diff(target) as f64 / span)?;
            }
            let up = target > r;
            // Levels nest: a boundary of level L is one of every lower level, so the
            // search stops at the first level where `r` is not a boundary.
            let mut used = None;
            for (l, level) in store.levels.iter().enumerate() {
                let block = if up {
                    store
                        .block_starting_at(level, r)
                        .filter(|&k| k < level.blocks && store.start(level, k + 1) <= target)
                } else {
                    store
                        .block_starting_at(level, r)
                        .filter(|&k| k > 0 && store.start(level, k - 1) >= target)
                        .map(|k| k - 1)
                };
                match block {
                    Some(k) => used = Some((l, k)),
                    None => {
                        if store.block_starting_at(level, r).is_none() {
                            break;
                        }
                    }
                }
            }
            let sign = if up { 1 } else { -1 };
            match used {
                Some((l, k)) => {
                    let level = &store.levels[l];
                    let (plus, minus) = store.block_edges(level, k)?;
                    for e in plus {
                        bump(e, sign)?;
                    }
                    for e in minus {
                        bump(e, -sign)?;
                    }
                    change.blocks_per_level[l + 1] += 1;
                    r = if up {
                        store.start(level, k + 1)
                    } else {
                        store.start(level, k)
                    };
                }
                None => {
                    let b = if up { r } else { r - 1 };
                    let j = store.order_checked(b)?;
                    let m = store.mask_checked(b)?;
                    for (d, e) in node_edges(&lattice, j) {
                        bump(e, if m >> d & 1 == 1 { sign } else { -sign })?;
                    }
                    change.blocks_per_level[0] += 1;
                    r = if up { r + 1 } else { r - 1 };
                }
            }
        }
        Ok(())
    }

    /// Calls `each` with the (up to four) cells around edge `e`.
    #[inline]
    fn edge_cells(lattice: &Lattice, coords: NodeCoords, e: u32, mut each: impl FnMut(u32)) {
        let (node, axis) = ((e / 3) as usize, (e % 3) as usize);
        let c = coords.coords(node);
        let (b, d) = ((axis + 1) % 3, (axis + 2) % 3);
        for (sb, sd) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            if c[b] < sb || c[d] < sd {
                continue;
            }
            let mut cell = c;
            cell[b] -= sb;
            cell[d] -= sd;
            if (0..3).all(|a| cell[a] + 1 < lattice.dims[a]) {
                each(lattice.index(cell[0], cell[1], cell[2]) as u32);
            }
        }
    }

    /// Lists the cells around the changed edges `pairs` (ascending by edge) into `dirty`,
    /// once each and ascending: the cells below the middle pair's node from one pass
    /// over the pairs, those above it from another, side by side when `parallel`.
    fn list_dirty(
        lattice: &Lattice,
        coords: NodeCoords,
        pairs: &[(u32, i32)],
        [low, high]: &mut [CellWindow; 2],
        dirty: &mut Vec<u32>,
        upper: &mut Vec<u32>,
        parallel: bool,
    ) {
        // An edge's cells lie at most a slab and a row below its node, never above it.
        let reach = lattice.stride(1) + lattice.stride(2);
        let node = |&(e, _): &(u32, i32)| e as usize / 3;
        let split = pairs.get(pairs.len() / 2).map_or(usize::MAX, node);
        let below = &pairs[..pairs.partition_point(|p| node(p) < split.saturating_add(reach))];
        let above = &pairs[pairs.partition_point(|p| node(p) < split)..];
        let pass = |pairs: &[(u32, i32)],
                    keep: std::ops::Range<usize>,
                    window: &mut CellWindow,
                    out: &mut Vec<u32>| {
            window.start(reach);
            for p in pairs {
                window.advance(node(p), out);
                Self::edge_cells(lattice, coords, p.0, |c| {
                    if keep.contains(&(c as usize)) {
                        window.mark(c);
                    }
                });
            }
            window.finish(out);
        };
        both(
            parallel,
            || pass(below, 0..split, low, dirty),
            || pass(above, split..usize::MAX, high, upper),
        );
        dirty.extend_from_slice(upper);
    }

    /// Applies the net edge changes: cells first out, edges out (holes), edges in (filling
    /// holes), compaction, cells in.
    fn apply(&mut self, delta: &Delta, change: &mut Change) -> Result<()> {
        let mut scratch = std::mem::take(&mut self.scratch);
        let result = self.apply_with(delta, change, &mut scratch);
        self.scratch = scratch;
        result
    }

    /// [`Slider::apply`] with the scratch lists taken out of `self`.
    fn apply_with(
        &mut self,
        delta: &Delta,
        change: &mut Change,
        scratch: &mut Scratch,
    ) -> Result<()> {
        let lattice = *self.store.lattice();
        let coords = self.store.coords;
        let Scratch {
            marks,
            windows,
            upper,
            removed,
            added,
            dirty,
            holes,
            reindex,
            added_data,
            retriangulated,
            ..
        } = scratch;
        for v in [
            &mut *removed,
            &mut *added,
            &mut *dirty,
            &mut *upper,
            &mut *holes,
            &mut *reindex,
        ] {
            v.clear();
        }
        // Netted pairs come sorted by edge, so `added` and `removed` are sorted.
        for &(e, d) in &delta.pairs {
            match d {
                1 => added.push(e),
                -1 => removed.push(e),
                _ => {
                    return Err(inconsistent(
                        &self.store,
                        format!("edge {e} changes {d} times"),
                    ))
                }
            }
        }
        change.edges_added = added.len() as u64;
        change.edges_removed = removed.len() as u64;
        // Two chains that share nothing but the store, side by side: the cells around
        // changed edges leave HC and the buckets (their triangles go), while the edges
        // out leave holes in E that the edges in fill (their interpolation data computed
        // a batch at a time, in parallel: it only reads the store).
        let Slider {
            store,
            edges,
            data,
            he,
            hc,
            buckets,
            ..
        } = &mut *self;
        let store = &*store;
        let removed_triangles = &mut change.removed_triangles;
        let mut cells = CellSide {
            coords,
            hc,
            buckets,
        };
        let parallel = delta.pairs.len() >= PARALLEL_MIN;
        Self::list_dirty(
            &lattice,
            coords,
            &delta.pairs,
            windows,
            dirty,
            upper,
            parallel,
        );
        // The change's lists are new each update: sized once from the dirty cells (the
        // surface has about two triangles a cell) rather than doubled a dozen times;
        // only cells in HC have triangles to remove (none before the first surface).
        removed_triangles.reserve(2 * dirty.len().min(cells.hc.len()));
        let cells_out = || {
            for (k, &cell) in dirty.iter().enumerate() {
                cells.take_out(dirty, k, cell, removed_triangles);
            }
        };
        let mut vertices = EdgeSide {
            store,
            edges,
            data,
            he,
        };
        let edges_out_in = || -> Result<()> {
            for (k, &e) in removed.iter().enumerate() {
                if let Some(&next) = removed.get(k + AHEAD) {
                    vertices.he.prefetch(next);
                }
                holes.push(vertices.turn_off(e)?);
            }
            holes.sort_unstable_by(|a, b| b.cmp(a));
            added_data.clear();
            added_data.resize(added.len().min(BATCH), EdgeData::default());
            for (first, batch) in (0..).step_by(BATCH).zip(added.chunks(BATCH)) {
                let batch_data = &mut added_data[..batch.len()];
                in_chunks(batch, batch_data, |e, d| edges_data(store, e, d))?;
                for (k, (&e, &d)) in (first..).zip(batch.iter().zip(batch_data.iter())) {
                    vertices.turn_on(added, holes, k, e, d)?;
                }
            }
            Ok(())
        };
        let ((), edges_done) = both(parallel, cells_out, edges_out_in);
        edges_done?;
        // Leftover holes: move vertices from the end into them.
        holes.sort_unstable();
        for &h in holes.iter() {
            while self.edges.last() == Some(&u32::MAX) {
                self.edges.pop();
                self.data.pop();
            }
            let last = self.edges.len();
            if (h as usize) >= last {
                continue;
            }
            let e = self.edges.pop().expect("non-empty: h < len");
            let d = self.data.pop().expect("data parallels edges");
            self.edges[h as usize] = e;
            self.data[h as usize] = d;
            self.he.set(e, h);
            change.moved_vertices.push(((last - 1) as u32, h));
            Self::edge_cells(&lattice, coords, e, |c| push_unique(reindex, marks, c));
        }
        ascending(reindex, marks);
        // HE is final now: what re-triangulating reads, beside the cells it rewrites.
        let Slider {
            store,
            he,
            hc,
            buckets,
            iso,
            ..
        } = &mut *self;
        let reader = CellReader {
            store: &*store,
            he: &*he,
            iso: *iso,
        };
        let mut cells = CellSide {
            coords,
            hc,
            buckets,
        };
        // Cells whose vertices moved keep their case; their triangles name the new ones.
        for &cell in reindex.iter() {
            let key = grid_key(coords, cell as usize);
            if let Some(entry) = cells.hc.get(key) {
                let t = reader.triangles(cell, key, entry.case)?;
                let b = &mut cells.buckets[entry.bucket as usize];
                let s = entry.slot as usize * b.size;
                b.triangles[s..s + b.size].copy_from_slice(t.triangles());
            }
        }
        // Cells around changed edges come back with their new case. Cases and triangles
        // only read the store and HE: computed a batch at a time, in parallel; then the
        // batch's cells go into the buckets and HC in ascending order, one thread.
        change.added_triangles.reserve(2 * dirty.len());
        retriangulated.clear();
        retriangulated.resize(dirty.len().min(BATCH), CellTriangles::default());
        for (first, batch) in (0..).step_by(BATCH).zip(dirty.chunks(BATCH)) {
            let batch_out = &mut retriangulated[..batch.len()];
            in_chunks(batch, batch_out, |c, out| reader.retriangulate(c, out))?;
            for (k, (&cell, new)) in (first..).zip(batch.iter().zip(batch_out.iter())) {
                cells.put_back(dirty, k, cell, new, &mut change.added_triangles);
            }
        }
        Ok(())
    }

    /// Cuts the surface's own lists and maps after it shrank a lot (see [`trim`],
    /// [`BrickMap::release_free`]); true when any list was cut or brick freed.
    fn trim_surface_lists(&mut self) -> bool {
        let mut cut = self.he.map.release_free() + self.hc.release_free() > 0;
        let used = self.edges.len();
        cut |= trim_to_surface(&mut self.edges, used);
        cut |= trim_to_surface(&mut self.data, used);
        let vertices = used;
        for b in &mut self.buckets {
            let used = b.triangles.len();
            cut |= trim_to_surface(&mut b.triangles, used);
            let used = b.cells.len();
            cut |= trim_to_surface(&mut b.cells, used);
        }
        // The full arrays a host read before: the next read refills them.
        let spare = self.spare_vertices.get_mut();
        for v in [&mut spare.positions, &mut spare.normals] {
            v.clear();
            cut |= trim(v, vertices);
        }
        let triangles = self.triangle_count();
        let spare = self.spare_triangles.get_mut();
        spare.clear();
        cut | trim(spare, triangles)
    }

    /// Computes V and N from E into `out`, reusing its memory.
    fn compute_vertices(&self, out: &mut Vertices) {
        let lattice = *self.store.lattice();
        let coords = self.store.coords;
        let iso = self.iso;
        let n = self.data.len();
        out.positions.resize(n, [0.0; 3]);
        out.normals.resize(n, [0.0; 3]);
        out.positions
            .par_iter_mut()
            .zip(out.normals.par_iter_mut())
            .zip(self.data.par_iter().zip(self.edges.par_iter()))
            .with_min_len(4096)
            .for_each(|((p, nrm), (d, &e))| {
                let (node, axis) = ((e / 3) as usize, (e % 3) as usize);
                let (q, m) = d.vertex(&lattice, coords.coords(node), axis, iso);
                *p = q.as_vec3().to_array();
                *nrm = m;
            });
    }
}

/// The surface's cells, borrowed apart from its vertices so that edges and cells can
/// change side by side: HC and the buckets of triangles.
struct CellSide<'a> {
    coords: NodeCoords,
    hc: &'a mut CellTable,
    buckets: &'a mut [Bucket],
}

impl CellSide<'_> {
    /// Takes dirty cell `cell`, the `k`-th of `dirty`, out of HC and its bucket (if it
    /// had triangles), its triangles appended to `removed`.
    #[inline]
    fn take_out(&mut self, dirty: &[u32], k: usize, cell: u32, removed: &mut Vec<[u32; 3]>) {
        let coords = self.coords;
        // Two stages: HC entries far ahead, then (their entries now cached) the
        // triangles they point to nearer.
        if let Some(&next) = dirty.get(k + AHEAD) {
            self.hc.prefetch(grid_key(coords, next as usize));
        }
        if let Some(&next) = dirty.get(k + AHEAD / 2) {
            if let Some(entry) = self.hc.get(grid_key(coords, next as usize)) {
                let b = &self.buckets[entry.bucket as usize];
                if let Some(t) = b.triangles.get(entry.slot as usize * b.size) {
                    prefetch(t);
                }
            }
        }
        if let Some(entry) = self.hc.remove(grid_key(coords, cell as usize)) {
            let b = &self.buckets[entry.bucket as usize];
            let s = entry.slot as usize * b.size;
            push_each(removed, &b.triangles[s..s + b.size]);
            self.remove_slot(entry);
        }
    }

    /// Removes a cell's triangles (its HC entry `entry`, already taken out of HC),
    /// filling the hole with the bucket's last cell.
    fn remove_slot(&mut self, entry: CellEntry) {
        let b = &mut self.buckets[entry.bucket as usize];
        let last = b.cells.len() - 1;
        let slot = entry.slot as usize;
        if slot != last {
            let moved = b.cells[last];
            b.triangles
                .copy_within(last * b.size..(last + 1) * b.size, slot * b.size);
            b.cells[slot] = moved;
            if let Some(m) = self.hc.get_mut(grid_key(self.coords, moved as usize)) {
                m.slot = slot as u32;
            }
        }
        b.cells.pop();
        b.triangles.truncate(last * b.size);
    }

    /// Puts dirty cell `cell`, the `k`-th of `dirty`, back with its new case and
    /// triangles `new` (nothing when it has none), its triangles appended to `added`.
    #[inline]
    fn put_back(
        &mut self,
        dirty: &[u32],
        k: usize,
        cell: u32,
        new: &CellTriangles,
        added: &mut Vec<[u32; 3]>,
    ) {
        let coords = self.coords;
        if let Some(&next) = dirty.get(k + AHEAD) {
            self.hc.prefetch(grid_key(coords, next as usize));
        }
        if new.count == 0 {
            return;
        }
        push_each(added, new.triangles());
        let b = &mut self.buckets[new.count as usize];
        push_each(&mut b.triangles, new.triangles());
        b.cells.push(cell);
        let entry = CellEntry {
            case: new.case,
            bucket: new.count,
            slot: (b.cells.len() - 1) as u32,
        };
        self.hc.insert(grid_key(coords, cell as usize), entry);
    }
}

/// The surface's vertices, borrowed apart from its cells so that edges and cells can
/// change side by side: E, the interpolation data parallel to it, and HE.
struct EdgeSide<'a> {
    store: &'a Store,
    edges: &'a mut Vec<u32>,
    data: &'a mut Vec<EdgeData>,
    he: &'a mut EdgeVertices,
}

impl EdgeSide<'_> {
    /// Turns edge `e` off, returning the vertex it leaves free (a hole in E).
    #[inline]
    fn turn_off(&mut self, e: u32) -> Result<u32> {
        let Some(v) = self.he.turn_off(e) else {
            return Err(inconsistent(
                self.store,
                format!("edge {e} turns off but is not on"),
            ));
        };
        self.edges[v as usize] = u32::MAX;
        Ok(v)
    }

    /// Turns on edge `e`, the `k`-th of `added`, whose interpolation data is `data`: its
    /// vertex fills the hole at the end of `holes`, or is appended.
    #[inline]
    fn turn_on(
        &mut self,
        added: &[u32],
        holes: &mut Vec<u32>,
        k: usize,
        e: u32,
        data: EdgeData,
    ) -> Result<()> {
        if let Some(&next) = added.get(k + AHEAD) {
            self.he.prefetch(next);
        }
        // Holes are taken from the end of `holes`: the one AHEAD later is written then.
        if let Some(&h) = holes.len().checked_sub(AHEAD + 1).map(|i| &holes[i]) {
            prefetch(&self.data[h as usize]);
            prefetch(&self.edges[h as usize]);
        }
        let v = holes.last().copied().unwrap_or(self.edges.len() as u32);
        if !self.he.turn_on(e, v) {
            return Err(inconsistent(
                self.store,
                format!("edge {e} turns on but is already on"),
            ));
        }
        if holes.pop().is_some() {
            self.edges[v as usize] = e;
            self.data[v as usize] = data;
        } else {
            self.edges.push(e);
            self.data.push(data);
        }
        Ok(())
    }
}

/// The error for a store whose edge lists contradict themselves or the lattice.
fn inconsistent(store: &Store, what: String) -> Error {
    Error::format(
        store.path(),
        format!("the store's edge lists are inconsistent ({what}); rebuild it"),
    )
}

/// Below this many items an update's parallel phases run on the calling thread: waking
/// rayon's workers costs more than a few hundred cells' work.
const PARALLEL_MIN: usize = 1024;
/// Items per parallel task.
const CHUNK: usize = 512;

/// Runs `f` over matching chunks of `items` and `out` (one output per item): on rayon's
/// threads when there are at least [`PARALLEL_MIN`] items, else once on this thread.
fn in_chunks<I: Sync, O: Send>(
    items: &[I],
    out: &mut [O],
    f: impl Fn(&[I], &mut [O]) -> Result<()> + Sync,
) -> Result<()> {
    if items.len() < PARALLEL_MIN {
        return f(items, out);
    }
    (items.par_chunks(CHUNK).zip(out.par_chunks_mut(CHUNK))).try_for_each(|(i, o)| f(i, o))
}

/// Runs `a` and `b`, side by side on rayon's threads when `parallel` (waking them costs
/// more than a small update's work), else one after the other here.
fn both<A: Send, B: Send>(
    parallel: bool,
    a: impl FnOnce() -> A + Send,
    b: impl FnOnce() -> B + Send,
) -> (A, B) {
    if parallel {
        rayon::join(a, b)
    } else {
        (a(), b())
    }
}

/// What re-triangulating a cell reads (the store's values, HE, the isovalue): shared by
/// the threads of an update's parallel phase.
#[derive(Clone, Copy)]
struct CellReader<'a> {
    store: &'a Store,
    he: &'a EdgeVertices,
    iso: f64,
}

impl CellReader<'_> {
    /// Each of `cells`' case and triangles at the current isovalue into `out`.
    fn retriangulate(&self, cells: &[u32], out: &mut [CellTriangles]) -> Result<()> {
        for (k, (&cell, new)) in cells.iter().zip(out.iter_mut()).enumerate() {
            if let Some(&next) = cells.get(k + AHEAD) {
                self.prefetch(next);
            }
            let key = grid_key(self.store.coords, cell as usize);
            let around = self.he.around(key);
            let on = edges_on(&around);
            if on == 0 {
                // No edge on: the cell is all above or all below, and has no triangles.
                *new = CellTriangles::default();
                continue;
            }
            let case = case_from_edges(on, self.lower_corner_above(cell)?).ok_or_else(|| {
                inconsistent(
                    self.store,
                    format!("the edges on in cell {cell} do not split its corners"),
                )
            })?;
            *new = self.triangles_around(cell, &around, case)?;
        }
        Ok(())
    }

    /// Starts loading what re-triangulating `cell` reads: its lower corner's value and
    /// its edges' vertices in HE.
    #[inline]
    fn prefetch(&self, cell: u32) {
        let lattice = self.store.lattice();
        let (cell, y, z) = (cell as usize, lattice.stride(1), lattice.stride(2));
        self.store.prefetch_value_at(self.store.coords.coords(cell));
        for node in [cell, cell + y, cell + z, cell + y + z] {
            self.he.map.prefetch(grid_key(self.store.coords, node));
        }
    }

    /// Whether `cell`'s lower corner lies above the current isovalue.
    #[inline]
    fn lower_corner_above(&self, cell: u32) -> Result<bool> {
        Ok(self.store.checked_value(cell as usize)? as f64 > self.iso)
    }

    /// Triangles of `cell` (keyed `key`) in `case`, as vertex indices through HE.
    fn triangles(&self, cell: u32, key: u64, case: u8) -> Result<CellTriangles> {
        self.triangles_around(cell, &self.he.around(key), case)
    }

    /// Triangles of `cell` in `case` from its edges' vertices `around` (one HE brick
    /// lookup, eight where the cell straddles bricks).
    fn triangles_around(
        &self,
        cell: u32,
        around: &[[u32; 3]; 8],
        case: u8,
    ) -> Result<CellTriangles> {
        let table = &case_table().triangles[case as usize];
        let mut out = CellTriangles {
            case,
            count: table.len() as u8,
            ..CellTriangles::default()
        };
        for (tri, slot) in table.iter().zip(out.triangles.iter_mut()) {
            for (k, &local) in tri.iter().enumerate() {
                let (corner, axis) = EDGE_CORNER_AXIS[local as usize];
                slot[k] = around[corner as usize][axis as usize];
                if slot[k] == NO_VERTEX {
                    let e = edge_id(self.store.lattice(), cell, local as usize);
                    return Err(inconsistent(
                        self.store,
                        format!("cell {cell} in case {case} needs edge {e}, not on"),
                    ));
                }
            }
        }
        Ok(out)
    }
}

/// Which of a cell's twelve edges are on (bit e: local edge e), from its edges'
/// vertices `around` ([`EdgeVertices::around`]).
fn edges_on(around: &[[u32; 3]; 8]) -> u16 {
    (EDGE_CORNER_AXIS.iter().enumerate()).fold(0, |on, (e, &(c, axis))| {
        on | u16::from(around[c as usize][axis as usize] != NO_VERTEX) << e
    })
}

/// Case of a cell (bit c: corner c above the isovalue) from the edges on (`on`, as
/// [`edges_on`]) and whether its lower corner is above: each corner differs from the one
/// before it along its highest axis exactly where that edge is on. One value read where
/// reading the eight corners took four lines of the volume; `None` when the case so found
/// does not cut exactly those edges (a corrupt store).
fn case_from_edges(on: u16, lower_above: bool) -> Option<u8> {
    let mut case = u8::from(lower_above);
    for c in 1..8usize {
        let axis = c.ilog2() as usize;
        let from = c ^ 1 << axis;
        let flips = on >> edge_index(from, axis) & 1 == 1;
        case |= u8::from((case >> from & 1 == 1) ^ flips) << c;
    }
    (case_table().edges_cut[case as usize] == on).then_some(case)
}

/// Id (`node · 3 + axis`) of local edge `local` of `cell` (an error names it).
fn edge_id(lattice: &Lattice, cell: u32, local: usize) -> usize {
    let (corner, axis) = edge_corner_axis(local);
    let d = corner_offset(corner);
    let node = cell as usize
        + (0..3)
            .map(|a| d[a] as usize * lattice.stride(a))
            .sum::<usize>();
    3 * node + axis
}

/// Interpolation data of each of `edges` into `out`, checking that each is a lattice edge.
fn edges_data(store: &Store, edges: &[u32], out: &mut [EdgeData]) -> Result<()> {
    let lattice = store.lattice();
    for (k, (&e, d)) in edges.iter().zip(out.iter_mut()).enumerate() {
        if let Some(&next) = edges.get(k + AHEAD) {
            prefetch_edge_data(store, next);
        }
        let (node, axis) = ((e / 3) as usize, (e % 3) as usize);
        if node >= store.nodes || store.coords.coords(node)[axis] + 1 >= lattice.dims[axis] {
            return Err(inconsistent(
                store,
                format!("edge {e} is not a lattice edge"),
            ));
        }
        *d = store_edge_data(store, e)?;
    }
    Ok(())
}

/// Starts loading the values [`store_edge_data`] reads for edge `e`: its two nodes and
/// their neighbours across the other axes (central differences).
#[inline]
fn prefetch_edge_data(store: &Store, e: u32) {
    let (node, axis) = ((e / 3) as usize, (e % 3) as usize);
    if node >= store.nodes {
        return; // not checked yet: the caller refuses it
    }
    let c = store.coords.coords(node);
    // Not the neighbours along x: they share the node's cache line but at a brick's x
    // faces, and naming them made 0.1 % steps about 5 % slower.
    edge_data_nodes(store.lattice().dims, c, axis, false, |n| {
        store.prefetch_value_at(n)
    });
}

/// Calls `f` with each node [`edge_data_from`] reads for the edge from node `c` along
/// `axis`: both ends and each end's neighbours along every axis (along x only if
/// `along_x`), clamped at the volume's faces (where the gradient is one-sided), with
/// repeats. What prefetching an edge's data names and what keeping the surface's value
/// bricks keeps.
#[inline(always)]
fn edge_data_nodes(
    dims: [usize; 3],
    c: [usize; 3],
    axis: usize,
    along_x: bool,
    mut f: impl FnMut([usize; 3]),
) {
    let mut up = c;
    up[axis] = (up[axis] + 1).min(dims[axis] - 1);
    for n in [c, up] {
        f(n);
        for a in usize::from(!along_x)..3 {
            let (mut lo, mut hi) = (n, n);
            lo[a] = lo[a].saturating_sub(1);
            hi[a] = (hi[a] + 1).min(dims[a] - 1);
            f(lo);
            f(hi);
        }
    }
}

/// Interpolation data of edge `e` (`node · 3 + axis`) from `store`'s values, each read
/// from its brick (one bit test once the brick has been read and checked; read and
/// checked first if not): the first failure is the error.
pub(crate) fn store_edge_data(store: &Store, e: u32) -> Result<EdgeData> {
    let lattice = store.lattice();
    let (node, axis) = ((e / 3) as usize, (e % 3) as usize);
    let c = store.coords.coords(node);
    let mut up = c;
    up[axis] += 1;
    // Once the neighbourhood's bricks have been read (every edge after the first few in a
    // region), each value is a bit test and a load: no error plumbing per value.
    let unverified = Cell::new(false);
    let fast = |n: [usize; 3]| {
        store.verified_value_at(n).unwrap_or_else(|| {
            unverified.set(true);
            0.0
        })
    };
    let data = edge_data_from(lattice, fast, c, up);
    if !unverified.get() {
        return Ok(data);
    }
    // Some brick is needed for the first time: read and check it (the first failure is
    // the error).
    let failed: Cell<Option<Error>> = Cell::new(None);
    let value = |n: [usize; 3]| {
        store.checked_value_at(n).unwrap_or_else(|err| {
            let first = failed.take().unwrap_or(err);
            failed.set(Some(first));
            0.0
        })
    };
    let data = edge_data_from(lattice, value, c, up);
    match failed.into_inner() {
        Some(err) => Err(err),
        None => Ok(data),
    }
}

/// Appends a cell's few triangles one by one: `extend_from_slice` calls `memmove` for
/// every cell's dozen to sixty bytes, which cost more than the copy.
#[inline]
fn push_each(out: &mut Vec<[u32; 3]>, tris: &[[u32; 3]]) {
    for &t in tris {
        out.push(t);
    }
}

/// The bricks of values a slider keeps between updates before it frees those the
/// surface does not read: this fraction of the volume's bytes...
const VALUES_HELD_FRACTION: usize = 8;
/// ...or this many bytes, whichever is more.
const VALUES_HELD_MIN: usize = 4 << 20;

/// The least budget of value bricks a slider on `store` keeps between updates.
fn values_floor(store: &Store) -> usize {
    (store.values_bytes() / VALUES_HELD_FRACTION).max(VALUES_HELD_MIN)
}

/// Scanning a word of `marks` costs about what sorting costs per cell; the scan is taken
/// while the marked words' span is at most this many words per cell.
const SCAN_WORDS_PER_CELL: usize = 8;

/// Appends `cell` to `cells` unless it is marked in `marks`, marking it: a cell around
/// several changed edges is listed once, so the list is as long as the cells, not four
/// times the edges.
#[inline]
fn push_unique(cells: &mut Vec<u32>, marks: &mut [u64], cell: u32) {
    let (w, bit) = (cell as usize / 64, 1u64 << (cell % 64));
    if marks[w] & bit == 0 {
        marks[w] |= bit;
        cells.push(cell);
    }
}

/// Puts `cells` (listed by [`push_unique`]: each once, each marked in `marks`) in
/// ascending order and clears their marks.
///
/// The order is part of the output: dirty cells leave and re-enter their buckets in this
/// order, so it decides the order of I. Ascending cell id (as the sort it replaces gave)
/// makes I the same however the walk reached the isovalue, which hosts rely on when they
/// slide away and back; the order cells first occur in would depend on the path. Where
/// the changed cells are dense, the marked words are read in order (no sort); where they
/// are sparse in a large volume, the unique cells are sorted instead, so the cost stays
/// with the change and not the volume.
fn ascending(cells: &mut Vec<u32>, marks: &mut [u64]) {
    let Some((first, last)) = cells.iter().fold(None, |span, &c| {
        let w = c as usize / 64;
        Some(span.map_or((w, w), |(lo, hi): (usize, usize)| (lo.min(w), hi.max(w))))
    }) else {
        return;
    };
    if last - first < SCAN_WORDS_PER_CELL * cells.len() {
        cells.clear();
        for (w, word) in marks[first..=last].iter_mut().enumerate() {
            let mut bits = std::mem::take(word);
            while bits != 0 {
                cells.push(((first + w) * 64) as u32 + bits.trailing_zeros());
                bits &= bits - 1;
            }
        }
    } else {
        for &c in cells.iter() {
            marks[c as usize / 64] &= !(1u64 << (c % 64));
        }
        radix::sort_by_key(cells, |&c| c as u64);
    }
}

/// Interpolation data of the edge from node `c` to its neighbour `up`.
#[inline]
pub(crate) fn edge_data_from(
    lattice: &Lattice,
    value: impl Fn([usize; 3]) -> f32 + Copy,
    c: [usize; 3],
    up: [usize; 3],
) -> EdgeData {
    let g0 = node_gradient(lattice, value, c).as_vec3().to_array();
    let g1 = node_gradient(lattice, value, up).as_vec3().to_array();
    EdgeData {
        s0: value(c),
        s1: value(up),
        g0,
        g1,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    /// Every node the interpolation data of an edge reads is among the nodes
    /// `edge_data_nodes` names (what prefetching and keeping value bricks rely on), for
    /// edges inside the volume and on each of its faces.
    #[test]
    fn edge_data_reads_only_the_nodes_named_for_it() {
        let dims = [5, 4, 3];
        let lattice = Lattice::new(dims, glam::DVec3::ZERO, glam::DVec3::ONE).unwrap();
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    for axis in 0..3 {
                        let c = [x, y, z];
                        if c[axis] + 1 == dims[axis] {
                            continue;
                        }
                        let mut up = c;
                        up[axis] += 1;
                        let read = std::cell::RefCell::new(Vec::new());
                        let value = |n: [usize; 3]| {
                            read.borrow_mut().push(n);
                            (n[0] + 7 * n[1] + 31 * n[2]) as f32
                        };
                        edge_data_from(&lattice, value, c, up);
                        let mut named = Vec::new();
                        edge_data_nodes(dims, c, axis, true, |n| named.push(n));
                        for n in read.into_inner() {
                            assert!(named.contains(&n), "edge {c:?} axis {axis} reads {n:?}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn lists_are_cut_back_to_what_they_use() {
        // Items of 4 bytes: above the floor.
        let big = 1 << 20;
        // Scratch lists: cut to twice their use only above four times it.
        let mut v: Vec<u32> = Vec::with_capacity(big);
        assert!(!trim(&mut v, big / 4));
        assert!(trim(&mut v, big / 5) && v.capacity() < big / 2);
        // The surface's lists: cut to an eighth over their use above a quarter over.
        let mut v: Vec<u32> = Vec::with_capacity(big);
        assert!(!trim_to_surface(&mut v, big * 5 / 6));
        assert!(trim_to_surface(&mut v, big * 3 / 4));
        assert!(v.capacity() >= big * 3 / 4 + big * 3 / 32 && v.capacity() < big * 7 / 8);
        // Below the floor nothing is cut.
        let mut v: Vec<u32> = Vec::with_capacity(1000);
        assert!(!trim(&mut v, 0) && !trim_to_surface(&mut v, 0));
    }

    /// A small deterministic random source for the tests' inputs.
    fn xorshift(mut state: u64) -> impl FnMut() -> u64 {
        move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        }
    }

    /// The case found from a cell's edges and its lower corner is the case of the
    /// corners' signs, for all 256; an edge switched against the corners (a corrupt
    /// store) is caught, whichever edge it is.
    #[test]
    fn cases_from_edges_are_the_corners_cases() {
        for case in 0..=255u8 {
            let above = |c: usize| case >> c & 1 == 1;
            let mut around = [[NO_VERTEX; 3]; 8];
            for &(c, axis) in &EDGE_CORNER_AXIS {
                let (c, axis) = (c as usize, axis as usize);
                if above(c) != above(c | 1 << axis) {
                    around[c][axis] = (3 * c + axis) as u32;
                }
            }
            let on = edges_on(&around);
            assert_eq!(case_from_edges(on, above(0)), Some(case), "case {case}");
            for &(c, axis) in &EDGE_CORNER_AXIS {
                let mut wrong = around;
                let v = &mut wrong[c as usize][axis as usize];
                *v = if *v == NO_VERTEX { 7 } else { NO_VERTEX };
                assert_eq!(
                    case_from_edges(edges_on(&wrong), above(0)),
                    None,
                    "case {case}"
                );
            }
        }
    }

    /// Netting by (radix) sorting gives each edge's sum, nonzero ones only, in edge order,
    /// for walks short and long (re-netted as they grow) and any key width.
    #[test]
    fn delta_nets_like_a_map() {
        let mut next = xorshift(0x9e37_79b9_7f4a_7c15);
        for (limit, bumps) in [
            (50u32, 300),
            (5_000, 3_000),
            (6_000_000, 40_000),
            (u32::MAX, 9_000),
        ] {
            let mut delta = Delta::default();
            delta.clear();
            let mut want: BTreeMap<u32, i32> = BTreeMap::new();
            for _ in 0..bumps {
                let r = next();
                // Few distinct edges for short limits, so changes cancel and repeat.
                let e = (r % limit as u64) as u32;
                let d = if r >> 40 & 1 == 1 { 1 } else { -1 };
                delta.bump(e, d);
                *want.entry(e).or_insert(0) += d;
            }
            delta.net();
            let want: Vec<(u32, i32)> = want.into_iter().filter(|&(_, d)| d != 0).collect();
            assert_eq!(delta.pairs, want, "limit {limit}");
        }
    }

    /// Unique cells in ascending order (what sort + dedup gives), by the bit scan when
    /// the cells are dense and by sorting when sparse, with every mark clear afterwards.
    #[test]
    fn unique_then_ascending_is_sort_and_dedup() {
        let mut next = xorshift(0x2545_f491_4f6c_dd1d);
        let cells = 1usize << 20;
        let mut marks = vec![0u64; cells / 64];
        // (first cell, cells drawn from, how many): dense with repeats at the start and at
        // the end (the bit scan), sparse over the whole range (the sort), one cell, none.
        let top = cells as u64 - 300;
        for (base, span, n) in [
            (0u64, 300u64, 2_000),
            (top, 300, 2_000),
            (0, cells as u64, 500),
            (top, 1, 1),
            (0, 1, 0),
        ] {
            let drawn: Vec<u32> = (0..n).map(|_| (base + next() % span) as u32).collect();
            let mut want = drawn.clone();
            want.sort_unstable();
            want.dedup();
            let mut list = Vec::new();
            for &c in &drawn {
                push_unique(&mut list, &mut marks, c);
            }
            assert_eq!(list.len(), want.len(), "each cell listed once");
            ascending(&mut list, &mut marks);
            assert_eq!(list, want, "{n} cells from {base} on");
            assert!(marks.iter().all(|&w| w == 0), "marks left set");
        }
    }
}
