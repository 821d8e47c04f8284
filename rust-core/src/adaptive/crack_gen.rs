//! Derives every crack pattern of a transition face, the paper's §4.2, and renders the
//! table that `crack_table.rs` commits.
//!
//! A transition face is a coarse quad seen whole by the coarse cell and as 2×2 quads by
//! the finer cell across it. In face coordinates (u, v) = (axis+1, axis+2) the fine side
//! has 3×3 vertices (i, j), i, j ∈ {0, 1, 2}; sign bit `i + 3j` of a configuration is set
//! when vertex (i, j) lies above the isovalue. The coarse side sees only the four corners.
//! Surface points sit on the 12 fine edges of the face: u-edge (i, j)→(i+1, j) is point
//! `i + 2j`, v-edge (i, j)→(i, j+1) is point `6 + i + 3j`. A coarse edge's point is the
//! point of whichever half carries the sign change (bisection makes them coincide).
//!
//! Why a crack appears, as chains: marching cubes cuts a cell face by the face rule of
//! `mc::table` (inside corners on an ambiguous face are kept apart), and a cell's triangles
//! together with the inside parts of its six faces bound the cell's inside region. Summed
//! over all cells, faces shared by equal cells cancel; a transition face leaves
//! (inside-region of the coarse side − inside-region of the fine side), oriented by the
//! face normal from coarse to fine. Filling exactly that signed region closes the surface.
//! Its boundary consists of the coarse chords, the fine chords reversed, and pieces of the
//! face's border where the two sides disagree (a coarse edge whose ends agree in sign but
//! whose midpoint does not). Every vertex of that boundary is a surface point, each loop
//! is triangulated by ear clipping at nominal positions, keeping its orientation.

use std::collections::BTreeMap;
use std::fmt::Write as _;

/// Number of sign configurations of a transition face (9 fine vertices).
pub(crate) const CONFIGURATIONS: usize = 512;
/// Most fill triangles a configuration may need (the paper's bound).
pub(crate) const MAX_TRIANGLES: usize = 12;
/// Integers per table row: the triangle count, then 3 × `MAX_TRIANGLES` point indices.
pub(crate) const ROW: usize = 1 + 3 * MAX_TRIANGLES;

/// A station on the face: a surface point (0..12) or a fine grid vertex (`GRID + i + 3j`).
type Node = u8;
const GRID: Node = 100;

fn grid(i: usize, j: usize) -> Node {
    GRID + (i + 3 * j) as Node
}

/// Point index of the u-edge from (i, j).
pub const fn u_edge(i: usize, j: usize) -> usize {
    i + 2 * j
}

/// Point index of the v-edge from (i, j).
pub const fn v_edge(i: usize, j: usize) -> usize {
    6 + i + 3 * j
}

/// (start vertex, axis 0 = u / 1 = v) of face point `p`.
pub const fn point_edge(p: usize) -> ((usize, usize), usize) {
    if p < 6 {
        ((p % 2, p / 2), 0)
    } else {
        (((p - 6) % 3, (p - 6) / 3), 1)
    }
}

/// Nominal position of a surface point: the middle of its fine edge.
fn nominal(p: Node) -> (f64, f64) {
    let ((i, j), axis) = point_edge(p as usize);
    if axis == 0 {
        (i as f64 + 0.5, j as f64)
    } else {
        (i as f64, j as f64 + 0.5)
    }
}

/// A ring edge of a quad, traversed counter-clockwise: (from vertex, to vertex, point).
type RingEdge = ((usize, usize), (usize, usize), Node);

/// The four edges of the fine quad (si, sj), counter-clockwise.
fn fine_ring(si: usize, sj: usize) -> [RingEdge; 4] {
    [
        ((si, sj), (si + 1, sj), u_edge(si, sj) as Node),
        ((si + 1, sj), (si + 1, sj + 1), v_edge(si + 1, sj) as Node),
        ((si + 1, sj + 1), (si, sj + 1), u_edge(si, sj + 1) as Node),
        ((si, sj + 1), (si, sj), v_edge(si, sj) as Node),
    ]
}

/// Chords of a quad by the face rule of `mc::table`: each run of inside corners along the
/// ring is closed by a chord from its exit point back to its entry point (inside on the
/// left, counter-clockwise). `cut[r]` is the point on ring edge r when it is cut.
fn chords(inside: [bool; 4], cut: [Option<Node>; 4]) -> Vec<(Node, Node)> {
    let mut out = Vec::new();
    for r in 0..4 {
        let exit = inside[r] && !inside[(r + 1) % 4];
        if !exit {
            continue;
        }
        // Walk back to the entry edge (outside → inside) that opened this run.
        let mut e = (r + 3) % 4;
        while inside[e] || !inside[(e + 1) % 4] {
            e = (e + 3) % 4;
        }
        out.push((
            cut[r].expect("an exit edge is cut"),
            cut[e].expect("an entry edge is cut"),
        ));
    }
    out
}

/// The chords the fine side draws on the face (its four quads), counter-clockwise.
fn fine_chords(config: usize) -> Vec<(Node, Node)> {
    let inside = |(i, j): (usize, usize)| config >> (i + 3 * j) & 1 == 1;
    let mut out = Vec::new();
    for sj in 0..2 {
        for si in 0..2 {
            let ring = fine_ring(si, sj);
            let ins = ring.map(|(a, _, _)| inside(a));
            let cut = ring.map(|(a, b, p)| (inside(a) != inside(b)).then_some(p));
            out.extend(chords(ins, cut));
        }
    }
    out
}

/// The signed crack region's boundary for configuration `config`, as directed edges
/// between surface points (counter-clockwise in (u, v) around coarse-inside regions).
pub fn crack_boundary(config: usize) -> Vec<(Node, Node)> {
    let inside = |(i, j): (usize, usize)| config >> (i + 3 * j) & 1 == 1;
    // Multiplicity of each directed edge; opposite edges cancel.
    let mut chain: BTreeMap<(Node, Node), i32> = BTreeMap::new();
    let mut add = |a: Node, b: Node, m: i32| {
        if a == b || m == 0 {
            return;
        }
        let (key, m) = if a < b { ((a, b), m) } else { ((b, a), -m) };
        *chain.entry(key).or_default() += m;
    };
    // Fine side: every quad's chords, negated.
    for (a, b) in fine_chords(config) {
        add(a, b, -1);
    }
    // Coarse side: corners and edges (each coarse edge = two fine halves through M).
    let corners = [(0, 0), (2, 0), (2, 2), (0, 2)];
    let mut coarse_cut = [None; 4];
    let mut halves = [[0 as Node; 2]; 4];
    let mut mids = [(0, 0); 4];
    for r in 0..4 {
        let (a, b) = (corners[r], corners[(r + 1) % 4]);
        let m = ((a.0 + b.0) / 2, (a.1 + b.1) / 2);
        mids[r] = m;
        let half = |x: (usize, usize), y: (usize, usize)| -> Node {
            let lo = (x.0.min(y.0), x.1.min(y.1));
            (if x.1 == y.1 {
                u_edge(lo.0, lo.1)
            } else {
                v_edge(lo.0, lo.1)
            }) as Node
        };
        halves[r] = [half(a, m), half(m, b)];
        if inside(a) != inside(b) {
            coarse_cut[r] = Some(if inside(a) != inside(m) {
                halves[r][0]
            } else {
                halves[r][1]
            });
        }
    }
    for (a, b) in chords(corners.map(inside), coarse_cut) {
        add(a, b, 1);
    }
    // Border pieces: along each coarse edge (A → M → B), the difference between the
    // coarse and fine inside indicators, one elementary interval at a time.
    for r in 0..4 {
        let (a, b, m) = (corners[r], corners[(r + 1) % 4], mids[r]);
        let mut stations: Vec<(Node, bool)> = vec![]; // (station, is a fine cut point)
        stations.push((grid(a.0, a.1), false));
        if inside(a) != inside(m) {
            stations.push((halves[r][0], true));
        }
        stations.push((grid(m.0, m.1), false));
        if inside(m) != inside(b) {
            stations.push((halves[r][1], true));
        }
        stations.push((grid(b.0, b.1), false));
        let mut fine_in = inside(a);
        let mut coarse_in = inside(a);
        for w in stations.windows(2) {
            let (from, to) = (w[0].0, w[1].0);
            let d = coarse_in as i32 - fine_in as i32;
            add(from, to, d);
            if w[1].1 {
                fine_in = !fine_in;
                if coarse_cut[r] == Some(to) {
                    coarse_in = !coarse_in;
                }
            }
        }
        debug_assert_eq!(fine_in, inside(b));
    }
    // Directed edges with multiplicity ±1.
    let mut edges: Vec<(Node, Node)> = Vec::new();
    for (&(a, b), &m) in &chain {
        match m {
            0 => {}
            1 => edges.push((a, b)),
            -1 => edges.push((b, a)),
            _ => panic!("config {config}: edge {a}-{b} has multiplicity {m}"),
        }
    }
    // Pass through grid stations (only coarse edge midpoints can carry the chain).
    while let Some(g) = edges.iter().map(|e| e.1).find(|&n| n >= GRID) {
        let i = edges.iter().position(|e| e.1 == g).expect("incoming");
        let o = edges
            .iter()
            .position(|e| e.0 == g)
            .unwrap_or_else(|| panic!("config {config}: station {g} has no outgoing edge"));
        let merged = (edges[i].0, edges[o].1);
        edges.retain(|e| e.0 != g && e.1 != g);
        edges.push(merged);
    }
    assert!(
        edges.iter().all(|e| e.0 < GRID && e.1 < GRID),
        "config {config}: the crack boundary touches a grid vertex"
    );
    edges.sort_unstable();
    edges
}

/// Splits directed edges into closed loops (each point has one edge in and one out).
fn loops(edges: &[(Node, Node)], config: usize) -> Vec<Vec<Node>> {
    let mut next: BTreeMap<Node, Node> = BTreeMap::new();
    for &(a, b) in edges {
        assert!(
            next.insert(a, b).is_none(),
            "config {config}: point {a} starts two boundary edges"
        );
    }
    let mut out = Vec::new();
    while let Some((&start, _)) = next.iter().next() {
        let mut lp = vec![start];
        let mut at = next.remove(&start).expect("present");
        while at != start {
            lp.push(at);
            at = next
                .remove(&at)
                .unwrap_or_else(|| panic!("config {config}: open crack boundary at {at}"));
        }
        out.push(lp);
    }
    out
}

fn cross(o: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
}

/// Ear clipping at nominal positions, keeping the loop's orientation. Ears must turn the
/// loop's way with positive area and hold no other loop point; when none qualifies (all
/// remaining points collinear) the rest is fanned, which keeps the chain right.
fn triangulate(lp: &[Node], out: &mut Vec<[Node; 3]>) {
    let area: f64 = (0..lp.len())
        .map(|k| {
            let (a, b) = (nominal(lp[k]), nominal(lp[(k + 1) % lp.len()]));
            a.0 * b.1 - a.1 * b.0
        })
        .sum();
    let sign = if area >= 0.0 { 1.0 } else { -1.0 };
    let mut rest: Vec<Node> = lp.to_vec();
    while rest.len() > 3 {
        let n = rest.len();
        let ear = (0..n).find(|&k| {
            let (p, c, q) = (rest[(k + n - 1) % n], rest[k], rest[(k + 1) % n]);
            let (pp, cp, qp) = (nominal(p), nominal(c), nominal(q));
            if sign * cross(pp, cp, qp) <= 1e-12 {
                return false;
            }
            rest.iter().all(|&o| {
                if o == p || o == c || o == q {
                    return true;
                }
                let op = nominal(o);
                let inside = sign * cross(pp, cp, op) >= -1e-12
                    && sign * cross(cp, qp, op) >= -1e-12
                    && sign * cross(qp, pp, op) >= -1e-12;
                !inside
            })
        });
        match ear {
            Some(k) => {
                out.push([rest[(k + n - 1) % n], rest[k], rest[(k + 1) % n]]);
                rest.remove(k);
            }
            None => break,
        }
    }
    for k in 1..rest.len() - 1 {
        out.push([rest[0], rest[k], rest[k + 1]]);
    }
}

/// Fill triangles of configuration `config` as face points, counter-clockwise in (u, v)
/// where the coarse side is inside and the fine side outside (clockwise where reversed).
pub fn crack_triangles(config: usize) -> Vec<[Node; 3]> {
    let edges = crack_boundary(config);
    let mut out = Vec::new();
    for lp in loops(&edges, config) {
        triangulate(&lp, &mut out);
    }
    out
}

/// Every configuration's row: count, then the triangles' points, zero-padded.
pub fn generate() -> Vec<[u8; ROW]> {
    (0..CONFIGURATIONS)
        .map(|config| {
            let tris = crack_triangles(config);
            assert!(
                tris.len() <= MAX_TRIANGLES,
                "config {config} needs {} triangles",
                tris.len()
            );
            let mut row = [0u8; ROW];
            row[0] = tris.len() as u8;
            for (k, t) in tris.iter().enumerate() {
                row[1 + 3 * k..4 + 3 * k].copy_from_slice(t);
            }
            row
        })
        .collect()
}

/// The Rust source of `crack_table.rs` for `rows`.
pub fn render(rows: &[[u8; ROW]]) -> String {
    let mut s = String::new();
    s.push_str(
        "//! Crack patterns of a transition face, one row per configuration of its nine fine\n\
         //! vertices: the triangle count, then triangles as face points (see `crack_gen`).\n\
         //! Generated by `crack_gen::render(&crack_gen::generate())`; do not edit. To\n\
         //! regenerate: `ISOBAR_REGENERATE=1 cargo test --release --lib adaptive::crack_gen`.\n\n",
    );
    let _ = writeln!(
        s,
        "/// Fill triangles per configuration (the paper's Fig. 6 layout)."
    );
    let _ = writeln!(s, "#[rustfmt::skip]");
    let _ = writeln!(
        s,
        "pub static CRACK_PATTERNS: [[u8; {ROW}]; {CONFIGURATIONS}] = ["
    );
    for row in rows {
        let used = 1 + 3 * row[0] as usize;
        let body: Vec<String> = row[..used].iter().map(|v| v.to_string()).collect();
        let pad = ROW - used;
        if pad == 0 {
            let _ = writeln!(s, "    [{}],", body.join(", "));
        } else {
            let _ = writeln!(s, "    pad([{}]),", body.join(", "));
        }
    }
    s.push_str("];\n\n");
    s.push_str(
        "/// Zero-pads a row prefix to the full row length.\n\
         const fn pad<const N: usize>(prefix: [u8; N]) -> [u8; ROW] {\n    \
             let mut row = [0u8; ROW];\n    \
             let mut k = 0;\n    \
             while k < N {\n        \
                 row[k] = prefix[k];\n        \
                 k += 1;\n    \
             }\n    \
             row\n\
         }\n\n",
    );
    let _ = writeln!(s, "const ROW: usize = {ROW};");
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    #[test]
    fn committed_table_is_the_generated_one() {
        let text = render(&generate());
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/src/adaptive/crack_table.rs");
        if std::env::var_os("ISOBAR_REGENERATE").is_some() {
            std::fs::write(path, &text).expect("write crack_table.rs");
        }
        let committed = std::fs::read_to_string(path).expect("read crack_table.rs");
        assert!(committed == text, "crack_table.rs is stale; regenerate it");
        let rows = generate();
        assert!(
            rows.as_slice() == &super::super::crack_table::CRACK_PATTERNS[..],
            "the compiled table differs from the generator's; rebuild after regenerating"
        );
    }

    /// Directed boundary of a set of triangles after cancelling opposite edges.
    fn boundary(tris: &[[Node; 3]]) -> BTreeSet<(Node, Node)> {
        let mut count: BTreeMap<(Node, Node), i32> = BTreeMap::new();
        for t in tris {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                if a < b {
                    *count.entry((a, b)).or_default() += 1;
                } else {
                    *count.entry((b, a)).or_default() -= 1;
                }
            }
        }
        count
            .into_iter()
            .filter(|&(_, m)| m != 0)
            .map(|((a, b), m)| {
                assert!(m.abs() == 1, "edge {a}-{b} used {m} times one way");
                if m > 0 {
                    (a, b)
                } else {
                    (b, a)
                }
            })
            .collect()
    }

    #[test]
    fn every_pattern_fills_exactly_its_crack() {
        let mut needed = 0;
        for config in 0..CONFIGURATIONS {
            let tris = crack_triangles(config);
            needed = needed.max(tris.len());
            // No repeated point, no repeated triangle.
            for t in &tris {
                assert!(
                    t[0] != t[1] && t[1] != t[2] && t[0] != t[2],
                    "{config}: {t:?}"
                );
            }
            // The fill's boundary is the crack boundary, edge for edge.
            let want: BTreeSet<_> = crack_boundary(config).into_iter().collect();
            assert_eq!(boundary(&tris), want, "config {config}");
            // An interior fill edge may border no other triangle: it must not be a
            // chord of either side (those already border a cell triangle) and must be
            // used by exactly two fill triangles.
            let mut uses: BTreeMap<(Node, Node), u32> = BTreeMap::new();
            for t in &tris {
                for k in 0..3 {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    *uses.entry((a.min(b), a.max(b))).or_default() += 1;
                }
            }
            let chord_set = all_chords(config);
            for (&(a, b), &n) in &uses {
                let on_boundary = want.contains(&(a, b)) || want.contains(&(b, a));
                if on_boundary {
                    assert_eq!(n, 1, "config {config}: boundary edge {a}-{b}");
                } else {
                    assert_eq!(n, 2, "config {config}: interior edge {a}-{b}");
                    assert!(
                        !chord_set.contains(&(a, b)),
                        "config {config}: fill diagonal {a}-{b} is a cell chord"
                    );
                }
            }
        }
        assert!(needed <= MAX_TRIANGLES, "{needed}");
    }

    /// Every chord the fine side draws on the face, as unordered pairs (the coarse
    /// side's chords join points the fine side also joins or the crack boundary holds).
    fn all_chords(config: usize) -> BTreeSet<(Node, Node)> {
        fine_chords(config)
            .into_iter()
            .map(|(a, b)| (a.min(b), a.max(b)))
            .collect()
    }

    #[test]
    fn uniform_faces_need_no_fill() {
        // All fine vertices agree with the coarse corners' bilinear picture: nothing to fill.
        assert!(crack_triangles(0).is_empty());
        assert!(crack_triangles(511).is_empty());
        // Only the centre differs: a diamond of four inner points, two triangles.
        assert_eq!(crack_triangles(1 << 4).len(), 2);
        // Only a coarse edge's midpoint inside: a crack along that edge's two halves.
        let tris = crack_triangles(1 << 1);
        assert_eq!(tris.len(), 1);
        let mut pts = tris[0].to_vec();
        pts.sort_unstable();
        assert_eq!(pts, vec![0, 1, v_edge(1, 0) as u8]);
    }
}
