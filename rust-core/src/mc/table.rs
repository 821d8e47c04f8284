//! The marching-cubes case table, generated rather than transcribed.
//!
//! Corner `c` of a cell sits at offset (c&1, c>>1&1, c>>2&1). Edge `4a + k` runs along
//! axis `a` from the corner whose bit `a` is clear (the other two bits are `k` spread over
//! the remaining axes) to the corner with bit `a` set, so an edge is named by its lower
//! corner and its axis, the same way the global grid names edges.
//!
//! Generation: on each of the six faces the cut edges are paired into segments; a face
//! with two inside corners on a diagonal (the ambiguous face) pairs them so the inside
//! corners are separated. That choice depends on the face's four corners only, so the
//! two cells sharing a face always cut it the same way and meshes are watertight. The
//! segments, oriented with the inside on their left as seen from outside the cube, chain
//! into closed loops. Each loop is triangulated by dynamic programming over its diagonals:
//! no triangle may lie flat in a cell face (the neighbour across an ambiguous face would
//! emit the same triangle, wound the other way, and the mesh would stop being manifold),
//! and among the rest the triangles closest to equilateral win. Triangles therefore wind
//! counter-clockwise seen from the outside region (values below the isovalue), i.e.
//! their normals point down the gradient, out of the region above the isovalue.

use std::sync::OnceLock;

/// Most triangles any case has (the table test checks it is reached): what a consumer
/// that stores a cell's triangles in fixed slots sizes them by.
pub(crate) const MOST_TRIANGLES: usize = 5;

/// Offset of corner `c` in cell units.
pub const fn corner_offset(c: usize) -> [u32; 3] {
    [(c & 1) as u32, ((c >> 1) & 1) as u32, ((c >> 2) & 1) as u32]
}

/// (lower corner, axis) of local edge `e`.
pub const fn edge_corner_axis(e: usize) -> (usize, usize) {
    let a = e / 4;
    let k = e % 4;
    let (b, c) = ((a + 1) % 3, (a + 2) % 3);
    ((k & 1) << b | ((k >> 1) & 1) << c, a)
}

/// The local edge that runs along `axis` from `corner` (whose bit `axis` must be clear).
pub const fn edge_index(corner: usize, axis: usize) -> usize {
    let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
    axis * 4 + ((corner >> b) & 1) + 2 * ((corner >> c) & 1)
}

/// Triangles and crossing information for every one of the 256 corner configurations.
pub struct CaseTable {
    /// Triangles as triples of local edges.
    pub triangles: Vec<Vec<[u8; 3]>>,
    /// Bit `2a + s` set when the surface crosses face (axis a, side s).
    pub faces_crossed: [u8; 256],
    /// Bit `e` set when local edge `e` is cut.
    pub edges_cut: [u16; 256],
}

/// The table, generated on first use.
pub fn case_table() -> &'static CaseTable {
    static TABLE: OnceLock<CaseTable> = OnceLock::new();
    TABLE.get_or_init(generate)
}

fn generate() -> CaseTable {
    let mut triangles = Vec::with_capacity(256);
    let mut faces_crossed = [0u8; 256];
    let mut edges_cut = [0u16; 256];
    for case in 0..256usize {
        let inside = |c: usize| case >> c & 1 == 1;
        for e in 0..12 {
            let (c, a) = edge_corner_axis(e);
            if inside(c) != inside(c | 1 << a) {
                edges_cut[case] |= 1 << e;
            }
        }
        // next[e] = the edge that follows e along its loop.
        let mut next = [usize::MAX; 12];
        for a in 0..3 {
            for s in 0..2 {
                let segs = face_segments(case, a, s);
                if !segs.is_empty() {
                    faces_crossed[case] |= 1 << (2 * a + s);
                }
                for (p, q) in segs {
                    debug_assert_eq!(next[p], usize::MAX);
                    next[p] = q;
                }
            }
        }
        let mut tris = Vec::new();
        let mut seen = [false; 12];
        for start in 0..12 {
            if next[start] == usize::MAX || seen[start] {
                continue;
            }
            let mut lp = Vec::new();
            let mut e = start;
            while !seen[e] {
                seen[e] = true;
                lp.push(e as u8);
                e = next[e];
            }
            triangulate_loop(&lp, &mut tris);
        }
        triangles.push(tris);
    }
    CaseTable {
        triangles,
        faces_crossed,
        edges_cut,
    }
}

/// Triangulates the polygon `lp` (local edges in loop order), keeping its orientation.
fn triangulate_loop(lp: &[u8], out: &mut Vec<[u8; 3]>) {
    let n = lp.len();
    let pos: Vec<[f64; 3]> = lp.iter().map(|&e| edge_midpoint(e as usize)).collect();
    // A diagonal (a triangle side that is not a side of the loop) between two vertices of
    // one cell face would lie in that face, where the neighbour cell may draw the same
    // diagonal: the edge would then border four triangles.
    let is_diagonal = |i: usize, j: usize| j - i > 1 && !(i == 0 && j == n - 1);
    let cost = |a: usize, b: usize, c: usize| -> f64 {
        let in_face = shares_a_face(&[lp[a], lp[b], lp[c]])
            || [(a, b), (b, c), (a, c)]
                .iter()
                .any(|&(i, j)| is_diagonal(i, j) && shares_a_face(&[lp[i], lp[j]]));
        if in_face {
            return 1e9;
        }
        // Squared perimeter over area: 20.8 for an equilateral triangle, more when thin.
        let (p, q, r) = (pos[a], pos[b], pos[c]);
        let area = 0.5 * norm(cross(sub(q, p), sub(r, p)));
        let perimeter = norm(sub(q, p)) + norm(sub(r, q)) + norm(sub(p, r));
        perimeter * perimeter / area.max(1e-12)
    };
    // best[i][j]: cheapest triangulation of the sub-polygon i..=j (j > i + 1).
    let mut best = vec![vec![0.0f64; n]; n];
    let mut split = vec![vec![0usize; n]; n];
    for len in 2..n {
        for i in 0..n - len {
            let j = i + len;
            best[i][j] = f64::INFINITY;
            for k in i + 1..j {
                let c = best[i][k] + best[k][j] + cost(i, k, j);
                if c < best[i][j] {
                    best[i][j] = c;
                    split[i][j] = k;
                }
            }
        }
    }
    fn emit(i: usize, j: usize, split: &[Vec<usize>], lp: &[u8], out: &mut Vec<[u8; 3]>) {
        if j < i + 2 {
            return;
        }
        let k = split[i][j];
        out.push([lp[i], lp[k], lp[j]]);
        emit(i, k, split, lp, out);
        emit(k, j, split, lp, out);
    }
    emit(0, n - 1, &split, lp, out);
}

/// True when the three local edges all lie on one face of the cell.
fn shares_a_face(edges: &[u8]) -> bool {
    (0..3).any(|a| {
        (0..2).any(|s| {
            edges.iter().all(|&e| {
                let (c, axis) = edge_corner_axis(e as usize);
                axis != a && (c >> a & 1) == s
            })
        })
    })
}

/// Oriented segments (from local edge, to local edge) cutting face (axis `a`, side `s`)
/// of a cell in `case`, the inside on their left as seen from outside the cell. They
/// depend on the face's four corners only; the level-of-detail extraction applies them to
/// faces of finer cells seen from a coarser one.
pub fn face_segments(case: usize, a: usize, s: usize) -> Vec<(usize, usize)> {
    let (b, c) = ((a + 1) % 3, (a + 2) % 3);
    let base = s << a;
    // The face's corners in cyclic order.
    let ring = [base, base | 1 << b, base | 1 << b | 1 << c, base | 1 << c];
    let inside = |corner: usize| case >> corner & 1 == 1;
    // Cut ring edges, each named by its position i (between ring[i] and ring[i+1]).
    let cut: Vec<usize> = (0..4)
        .filter(|&i| inside(ring[i]) != inside(ring[(i + 1) % 4]))
        .collect();
    let ring_edge = |i: usize| {
        let (p, q) = (ring[i], ring[(i + 1) % 4]);
        let lower = p & q;
        let axis = (p ^ q).trailing_zeros() as usize;
        edge_index(lower, axis)
    };
    let pairs: Vec<(usize, usize)> = match cut.len() {
        0 => vec![],
        2 => vec![(cut[0], cut[1])],
        4 => {
            // Pair the two cut ring edges on either side of each inside corner.
            (0..4)
                .filter(|&i| inside(ring[i]))
                .map(|i| ((i + 3) % 4, i))
                .collect()
        }
        _ => unreachable!("a 4-cycle has an even number of sign changes"),
    };
    let outward = {
        let mut n = [0.0f64; 3];
        n[a] = if s == 1 { 1.0 } else { -1.0 };
        n
    };
    pairs
        .into_iter()
        .map(|(i, j)| {
            let (ei, ej) = (ring_edge(i), ring_edge(j));
            let (pi, pj) = (edge_midpoint(ei), edge_midpoint(ej));
            // An inside corner adjacent to the segment: an endpoint of ring edge i.
            let cin = if inside(ring[i]) {
                ring[i]
            } else {
                ring[(i + 1) % 4]
            };
            let ci = corner_offset(cin).map(f64::from);
            let d = sub(pj, pi);
            if dot(cross(d, outward), sub(ci, pi)) > 0.0 {
                (ei, ej)
            } else {
                (ej, ei)
            }
        })
        .collect()
}

fn edge_midpoint(e: usize) -> [f64; 3] {
    let (c, a) = edge_corner_axis(e);
    let mut p = corner_offset(c).map(f64::from);
    p[a] += 0.5;
    p
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edges_are_named_consistently() {
        for e in 0..12 {
            let (c, a) = edge_corner_axis(e);
            assert_eq!(c >> a & 1, 0);
            assert_eq!(edge_index(c, a), e);
        }
    }

    #[test]
    fn every_case_uses_each_cut_edge_and_closes_its_loops() {
        let t = case_table();
        assert!(t.triangles[0].is_empty() && t.triangles[255].is_empty());
        for case in 0..256 {
            // Each cut edge is a vertex of the case's surface; no uncut edge is.
            let mut used = 0u16;
            for tri in &t.triangles[case] {
                for &e in tri {
                    used |= 1 << e;
                }
            }
            assert_eq!(used, t.edges_cut[case], "case {case}");
            // At most 12 triangles a case (the loops' orientation and closure are checked
            // by triangles_keep_the_loop_orientation), and at most MOST_TRIANGLES.
            let tris = &t.triangles[case];
            assert!(tris.len() <= 12, "case {case}: {} triangles", tris.len());
            assert!(
                tris.len() <= MOST_TRIANGLES,
                "case {case}: {} triangles",
                tris.len()
            );
        }
        let most = t.triangles.iter().map(Vec::len).max();
        assert_eq!(most, Some(MOST_TRIANGLES), "MOST_TRIANGLES is reached");
    }

    #[test]
    fn no_triangle_lies_in_a_cell_face() {
        // Such a triangle would be emitted again, reversed, by the neighbour across that face.
        let t = case_table();
        for case in 0..256 {
            for tri in &t.triangles[case] {
                assert!(
                    !shares_a_face(tri),
                    "case {case}: triangle {tri:?} lies in a face"
                );
            }
        }
    }

    #[test]
    fn no_interior_edge_lies_in_a_cell_face() {
        // A triangle side used by two triangles of the same cell is interior to the cell's
        // surface; if it lay in a face, the neighbour could use it too (four triangles).
        let t = case_table();
        for case in 0..256 {
            let mut uses = std::collections::HashMap::new();
            for tri in &t.triangles[case] {
                for k in 0..3 {
                    let (a, b) = (tri[k], tri[(k + 1) % 3]);
                    *uses.entry((a.min(b), a.max(b))).or_insert(0) += 1;
                }
            }
            for (&(a, b), &n) in &uses {
                if n == 2 {
                    assert!(
                        !shares_a_face(&[a, b]),
                        "case {case}: interior edge {a}-{b} lies in a face"
                    );
                }
            }
        }
    }

    #[test]
    fn triangles_keep_the_loop_orientation() {
        // Each interior edge of a case's triangles is used once in each direction.
        let t = case_table();
        for case in 0..256 {
            let mut directed = std::collections::HashMap::new();
            for tri in &t.triangles[case] {
                for k in 0..3 {
                    *directed.entry((tri[k], tri[(k + 1) % 3])).or_insert(0) += 1;
                }
            }
            for (&(a, b), &n) in &directed {
                assert_eq!(n, 1, "case {case}: edge {a}->{b} used {n} times");
                if let Some(&m) = directed.get(&(b, a)) {
                    assert_eq!(m, 1, "case {case}");
                }
            }
        }
    }

    #[test]
    fn complementary_cases_cut_the_same_edges_and_faces() {
        let t = case_table();
        for case in 0..256 {
            assert_eq!(t.edges_cut[case], t.edges_cut[255 - case]);
            assert_eq!(t.faces_crossed[case], t.faces_crossed[255 - case]);
        }
    }

    #[test]
    fn single_corner_triangle_faces_away_from_the_corner() {
        let t = case_table();
        for c in 0..8 {
            let tris = &t.triangles[1 << c];
            assert_eq!(tris.len(), 1);
            let p = tris[0].map(|e| edge_midpoint(e as usize));
            let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
            let corner = corner_offset(c).map(f64::from);
            assert!(dot(n, sub(p[0], corner)) > 0.0, "corner {c}");
        }
    }
}
