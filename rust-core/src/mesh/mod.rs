//! Output triangle meshes and the checks every extractor's tests share.

pub mod hausdorff;

use crate::field::particles::Attribute;
use std::collections::HashMap;

/// An indexed triangle mesh. Positions stay in f64 so that vertices placed on the level
/// set to 1e-6 relative stay there; hosts convert to f32 at their boundary.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<[f64; 3]>,
    /// Unit vertex normals, one per vertex, or empty.
    pub normals: Vec<[f32; 3]>,
    /// Counter-clockwise seen from the side the normals point to.
    pub triangles: Vec<[u32; 3]>,
    /// Per-vertex arrays (SumOfWeights, interpolated particle attributes ...).
    pub attributes: Vec<Attribute>,
}

/// What `Mesh::topology` finds out about a mesh.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Topology {
    /// Undirected edges used by exactly one triangle.
    pub boundary_edges: usize,
    /// Undirected edges used by more than two triangles.
    pub nonmanifold_edges: usize,
    /// Directed edges used twice in the same direction (neighbours wound oppositely).
    pub misoriented_edges: usize,
    /// Triangles that repeat a vertex index.
    pub degenerate_triangles: usize,
}

impl Topology {
    /// Closed, 2-manifold and consistently oriented.
    pub fn is_watertight_oriented(&self) -> bool {
        *self == Topology::default()
    }
}

impl Mesh {
    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Bytes its arrays hold, as counted against a memory budget.
    pub fn heap_bytes(&self) -> u64 {
        let arrays = std::mem::size_of_val(self.positions.as_slice())
            + std::mem::size_of_val(self.normals.as_slice())
            + std::mem::size_of_val(self.triangles.as_slice())
            + self
                .attributes
                .iter()
                .map(|a| std::mem::size_of_val(a.data.as_slice()))
                .sum::<usize>();
        arrays as u64
    }

    /// The per-vertex attribute called `name`, if present.
    pub fn attribute(&self, name: &str) -> Option<&Attribute> {
        self.attributes.iter().find(|a| a.name == name)
    }

    /// Counts the edge faults that separate a closed oriented surface from anything else.
    pub fn topology(&self) -> Topology {
        let mut directed: HashMap<(u32, u32), u32> =
            HashMap::with_capacity(self.triangles.len() * 3);
        let mut t = Topology::default();
        for tri in &self.triangles {
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                t.degenerate_triangles += 1;
            }
            for k in 0..3 {
                *directed.entry((tri[k], tri[(k + 1) % 3])).or_default() += 1;
            }
        }
        let mut undirected: HashMap<(u32, u32), u32> = HashMap::with_capacity(directed.len());
        for (&(a, b), &n) in &directed {
            if n > 1 {
                t.misoriented_edges += 1;
            }
            *undirected.entry((a.min(b), a.max(b))).or_default() += n;
        }
        for &n in undirected.values() {
            match n {
                1 => t.boundary_edges += 1,
                2 => {}
                _ => t.nonmanifold_edges += 1,
            }
        }
        t
    }

    /// Signed enclosed volume (divergence theorem); positive when triangles wind
    /// counter-clockwise seen from outside.
    pub fn signed_volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| glam::DVec3::from(self.positions[i as usize]));
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// Total triangle area.
    pub fn area(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| glam::DVec3::from(self.positions[i as usize]));
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    }

    /// Number of pairs of vertices at the same position (a shared-vertex mesh has none).
    pub fn duplicate_vertices(&self) -> usize {
        let mut keys: Vec<[u64; 3]> = self.positions.iter().map(|p| p.map(f64::to_bits)).collect();
        keys.sort_unstable();
        keys.windows(2).filter(|w| w[0] == w[1]).count()
    }

    /// Number of connected components (through shared vertices).
    pub fn components(&self) -> usize {
        let n = self.positions.len();
        let mut parent: Vec<u32> = (0..n as u32).collect();
        fn find(p: &mut [u32], mut x: u32) -> u32 {
            while p[x as usize] != x {
                p[x as usize] = p[p[x as usize] as usize];
                x = p[x as usize];
            }
            x
        }
        for t in &self.triangles {
            for k in 1..3 {
                let (a, b) = (find(&mut parent, t[0]), find(&mut parent, t[k]));
                if a != b {
                    parent[a.max(b) as usize] = a.min(b);
                }
            }
        }
        let mut used = vec![false; n];
        for t in &self.triangles {
            for &v in t {
                used[v as usize] = true;
            }
        }
        (0..n as u32)
            .filter(|&v| used[v as usize] && find(&mut parent, v) == v)
            .count()
    }

    /// Appends `other`, renumbering its triangles. Attributes present in both are joined;
    /// those missing from one side are dropped, as a mesh needs every array on every vertex.
    pub fn append(&mut self, other: Mesh) {
        if self.positions.is_empty() && self.triangles.is_empty() {
            *self = other;
            return;
        }
        let offset = self.positions.len() as u32;
        let keep_normals = self.normals.len() == self.positions.len()
            && other.normals.len() == other.positions.len();
        self.positions.extend(other.positions);
        if keep_normals {
            self.normals.extend(other.normals);
        } else {
            self.normals.clear();
        }
        self.triangles
            .extend(other.triangles.into_iter().map(|t| t.map(|i| i + offset)));
        let mut joined = Vec::new();
        for mut a in std::mem::take(&mut self.attributes) {
            if let Some(b) = other
                .attributes
                .iter()
                .find(|b| b.name == a.name && b.components == a.components)
            {
                a.data.extend_from_slice(&b.data);
                joined.push(a);
            }
        }
        self.attributes = joined;
    }
}

/// The warning for an isovalue that gave no triangle: an empty mesh is a valid answer, but
/// usually means an isovalue outside the field's range or the wrong field.
pub(crate) fn no_surface(iso: f64) -> String {
    format!("no surface at isovalue {iso}: the field never crosses it")
}

/// The warning for an isovalue that the particles' values straddle (seed cells were found)
/// although no grid cell's corners do: most often features thinner than the cells of edge
/// `cell`. "Never crosses" would send the user to the isovalue instead of the grid.
pub(crate) fn no_surface_on_grid(iso: f64, cell: f64) -> String {
    format!(
        "no surface at isovalue {iso} on cells of {cell:.3e}: the particles' values lie on \
         both sides of it, but no cell's corners do; its features may be thinner than the \
         cells: try a lower grid factor"
    )
}

/// The warning for an isovalue whose surface was all cut away although the field crosses
/// it in `cells` cells: blaming the field would send the user to the wrong setting.
pub(crate) fn surface_cut_away(iso: f64, cells: u64) -> String {
    format!(
        "no surface at isovalue {iso} after trimming and clipping: the field crosses it in \
         {cells} cells, all cut away by the trim thresholds or the clip box"
    )
}
