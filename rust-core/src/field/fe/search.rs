//! World-point location: the cell holding a world point x and its reference coordinates
//! there (T⁻¹ by Newton), over a uniform binning of the cells' bounding boxes. This is the
//! numerical inversion the particle system avoids and the marching-cubes baseline needs
//! (the paper's Sect. 2: "the world-space location of each grid node is numerically
//! inverted within each potential element").

use super::locate::INSIDE_SLACK;
use super::mesh::{FeMesh, Scratch};
use glam::DVec3;

/// How far outside a cell's reference domain (in reference units) the second pass of
/// [`CellIndex::locate_thorough`] still takes a point to be in it; the field there is the
/// cell's polynomial continued by at most this much.
pub(crate) const PROBE_SLACK: f64 = 1e-8;

/// Cells binned by bounding box, for [`CellIndex::locate`].
#[derive(Clone, Debug)]
pub struct CellIndex {
    lo: DVec3,
    bin: f64,
    dims: [usize; 3],
    /// Bin b's cells are `cells[starts[b]..starts[b + 1]]`, ascending.
    starts: Vec<u32>,
    cells: Vec<u32>,
}

impl CellIndex {
    /// Bins every cell of `mesh` (about one cell per bin).
    pub fn new(mesh: &FeMesh) -> CellIndex {
        // Binned by boxes that provably hold their cells (`FeMesh::cell_box`), so a point
        // in a cell is always among that cell's candidates.
        let count = mesh.cell_count();
        let (lo, hi) = mesh.bounds();
        let extent = (hi - lo).max(DVec3::splat(1e-300));
        // About one cell per bin, never more than a few million bins.
        let n = (count as f64).clamp(1.0, 4e6);
        let bin = (extent.x * extent.y * extent.z / n)
            .cbrt()
            .max(extent.max_element() / 256.0);
        let dims = [0, 1, 2].map(|a| ((extent[a] / bin).ceil() as usize).clamp(1, 256));
        let bin_of = |p: DVec3, a: usize| (((p[a] - lo[a]) / bin) as usize).min(dims[a] - 1);
        let total = dims[0] * dims[1] * dims[2];
        let mut counts = vec![0u32; total + 1];
        let each = |b: &(DVec3, DVec3), f: &mut dyn FnMut(usize)| {
            for z in bin_of(b.0, 2)..=bin_of(b.1, 2) {
                for y in bin_of(b.0, 1)..=bin_of(b.1, 1) {
                    for x in bin_of(b.0, 0)..=bin_of(b.1, 0) {
                        f(x + dims[0] * (y + dims[1] * z));
                    }
                }
            }
        };
        for c in 0..count {
            each(&mesh.cell_box(c), &mut |k| counts[k + 1] += 1);
        }
        for k in 0..total {
            counts[k + 1] += counts[k];
        }
        let mut fill = counts.clone();
        let mut cells = vec![0u32; counts[total] as usize];
        for c in 0..count {
            each(&mesh.cell_box(c), &mut |k| {
                cells[fill[k] as usize] = c as u32;
                fill[k] += 1;
            });
        }
        CellIndex {
            lo,
            bin,
            dims,
            starts: counts,
            cells,
        }
    }

    /// The cell holding world point `x` and the reference point there, or None when no
    /// cell does (x is outside the mesh). `hint` (a cell and reference point near x) is
    /// tried first; then the binned cells in ascending order, so the answer does not
    /// depend on threads. Adds the forward evaluations (mappings) it makes to
    /// `evaluations`.
    pub fn locate(
        &self,
        mesh: &FeMesh,
        x: DVec3,
        hint: Option<(usize, DVec3)>,
        scratch: &mut Scratch,
        evaluations: &mut u64,
    ) -> Option<(usize, DVec3)> {
        let inside = |c: usize, u: DVec3| {
            let (d, nf) = mesh.shape(c).kind.face_distances(u);
            d[..nf].iter().all(|&d| d >= -INSIDE_SLACK)
        };
        if let Some((c, guess)) = hint {
            if let Some(u) = mesh.invert_counted(c, x, guess, 1.0, scratch, evaluations) {
                if inside(c, u) {
                    return Some((c, u));
                }
            }
        }
        for &c in self.candidates(x) {
            let c = c as usize;
            if hint.is_some_and(|h| h.0 == c) || !in_box(mesh, c, x) {
                continue;
            }
            let guess = mesh.shape(c).kind.centroid();
            if let Some(u) = mesh.invert_counted(c, x, guess, 1.0, scratch, evaluations) {
                if inside(c, u) {
                    return Some((c, u));
                }
            }
        }
        None
    }

    /// [`CellIndex::locate`] without a hint that, where the quick search finds no cell,
    /// tries the binned cells again with Newton never giving up early (a strongly curved
    /// cell can send the first iterates from its centroid far outside its reference
    /// domain) and accepting points up to `PROBE_SLACK` (1e-8) outside a cell: surfaces
    /// that reach the mesh boundary have points a rounding error outside it (the particle
    /// system keeps particles within INSIDE_SLACK of their cell, and the inverse of such
    /// a point lands a few ulps further out). For probing arbitrary points, where a
    /// missed cell is a wrong answer.
    pub fn locate_thorough(
        &self,
        mesh: &FeMesh,
        x: DVec3,
        scratch: &mut Scratch,
        evaluations: &mut u64,
    ) -> Option<(usize, DVec3)> {
        if let Some(found) = self.locate(mesh, x, None, scratch, evaluations) {
            return Some(found);
        }
        self.candidates(x).iter().find_map(|&c| {
            let c = c as usize;
            if !in_box(mesh, c, x) {
                return None;
            }
            let kind = mesh.shape(c).kind;
            let u =
                mesh.invert_counted(c, x, kind.centroid(), f64::INFINITY, scratch, evaluations)?;
            let (d, nf) = kind.face_distances(u);
            d[..nf].iter().all(|&d| d >= -PROBE_SLACK).then_some((c, u))
        })
    }

    /// The cells binned where `x` lies, ascending (none outside the binned box).
    fn candidates(&self, x: DVec3) -> &[u32] {
        let mut k = 0;
        for a in 0..3 {
            let f = (x[a] - self.lo[a]) / self.bin;
            if !(f >= 0.0 && f < self.dims[a] as f64) {
                return &[];
            }
            k += f as usize * [1, self.dims[0], self.dims[0] * self.dims[1]][a];
        }
        &self.cells[self.starts[k] as usize..self.starts[k + 1] as usize]
    }
}

/// Whether `x` lies in cell `c`'s bounding box.
fn in_box(mesh: &FeMesh, c: usize, x: DVec3) -> bool {
    let (a, b) = mesh.cell_box(c);
    !(x.cmplt(a).any() || x.cmpgt(b).any())
}
