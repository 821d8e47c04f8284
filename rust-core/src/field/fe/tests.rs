use super::curvature::principal_curvatures;
use super::*;
use crate::field::particles::Attribute;
use glam::{DMat3, DVec3};

const KINDS: [Kind; 3] = [Kind::Hexahedron, Kind::Tetrahedron, Kind::Wedge];

fn shape(kind: Kind, p: usize) -> Shape {
    Shape::new(kind, [p, p, p])
}

/// Deterministic points inside each reference domain.
fn inside_points(kind: Kind) -> Vec<DVec3> {
    let mut out = Vec::new();
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    while out.len() < 12 {
        let u = DVec3::new(next(), next(), next());
        let ok = match kind {
            Kind::Hexahedron => true,
            Kind::Tetrahedron => u.x + u.y + u.z < 1.0,
            Kind::Wedge => u.x + u.y < 1.0,
        };
        if ok {
            out.push(u);
        }
    }
    out
}

#[test]
fn node_order_matches_vtk() {
    let text = include_str!("../../../data/fe/vtk_lagrange_nodes.txt");
    let mut checked = 0;
    for line in text.lines().filter(|l| !l.starts_with('#')) {
        let mut it = line.split_whitespace();
        let kind = match it.next().unwrap() {
            "hex" => Kind::Hexahedron,
            "tet" => Kind::Tetrahedron,
            "wedge" => Kind::Wedge,
            other => panic!("unknown kind {other}"),
        };
        let p: usize = it.next().unwrap().parse().unwrap();
        let n: usize = it.next().unwrap().parse().unwrap();
        let coords: Vec<f64> = it.map(|v| v.parse().unwrap()).collect();
        let s = shape(kind, p);
        assert_eq!(s.len(), n, "{kind:?} order {p}: node count");
        for k in 0..n {
            let ours = s.node_coords(k);
            let vtk = DVec3::new(coords[3 * k], coords[3 * k + 1], coords[3 * k + 2]);
            assert!(
                (ours - vtk).abs().max_element() < 1e-12,
                "{kind:?} order {p} node {k}: ours {ours}, VTK {vtk}"
            );
        }
        checked += 1;
    }
    assert_eq!(checked, 18);
}

#[test]
fn basis_is_nodal_and_sums_to_one() {
    let mut b = BasisValues::default();
    for kind in KINDS {
        for p in 1..=4 {
            let s = shape(kind, p);
            for k in 0..s.len() {
                s.evaluate(s.node_coords(k), &mut b);
                for (a, v) in b.values.iter().enumerate() {
                    let want = if a == k { 1.0 } else { 0.0 };
                    assert!(
                        (v - want).abs() < 1e-10,
                        "{kind:?} p{p}: φ{a}(node {k}) = {v}"
                    );
                }
            }
            for u in inside_points(kind) {
                s.evaluate(u, &mut b);
                let sum: f64 = b.values.iter().sum();
                let gsum: DVec3 = b.gradients.iter().sum();
                let hsum = b.hessians.iter().fold(DMat3::ZERO, |a, h| a + *h);
                assert!((sum - 1.0).abs() < 1e-11, "{kind:?} p{p}: Σφ = {sum}");
                assert!(
                    gsum.abs().max_element() < 1e-9,
                    "{kind:?} p{p}: Σ∇φ = {gsum}"
                );
                assert!(
                    hsum.abs_diff_eq(DMat3::ZERO, 1e-7),
                    "{kind:?} p{p}: Σ∇²φ = {hsum}"
                );
            }
        }
    }
}

#[test]
fn derivatives_match_finite_differences() {
    let (mut b, mut bp, mut bm) = Default::default();
    let h = 1e-5;
    for kind in KINDS {
        for p in 1..=4 {
            let s = shape(kind, p);
            for u in inside_points(kind) {
                s.evaluate(u, &mut b);
                for axis in 0..3 {
                    let e = DVec3::AXES[axis] * h;
                    s.evaluate(u + e, &mut bp);
                    s.evaluate(u - e, &mut bm);
                    let bp: &BasisValues = &bp;
                    let bm: &BasisValues = &bm;
                    for a in 0..s.len() {
                        let fd = (bp.values[a] - bm.values[a]) / (2.0 * h);
                        let g = b.gradients[a][axis];
                        assert!(
                            (fd - g).abs() < 1e-6 * (1.0 + g.abs()),
                            "{kind:?} p{p} φ{a} ∂{axis}: {g} vs {fd}"
                        );
                        let fdh = (bp.gradients[a] - bm.gradients[a]) / (2.0 * h);
                        let col = b.hessians[a].col(axis);
                        assert!(
                            (fdh - col).abs().max_element()
                                < 1e-5 * (1.0 + col.abs().max_element()),
                            "{kind:?} p{p} φ{a} ∂∇/∂{axis}: {col} vs {fdh}"
                        );
                    }
                }
            }
        }
    }
}

/// A one-cell mesh whose nodes are `map` of the reference nodes, with point array `field`.
pub(crate) fn single_cell(
    kind: Kind,
    p: usize,
    map: impl Fn(DVec3) -> DVec3,
    field: impl Fn(DVec3) -> f64,
) -> FeMesh {
    let s = shape(kind, p);
    let points: Vec<DVec3> = (0..s.len()).map(|k| map(s.node_coords(k))).collect();
    let values = points.iter().map(|&x| field(x)).collect();
    FeMesh::new(
        "test",
        points,
        &[kind.vtk_type()],
        &[0, s.len()],
        (0..s.len() as u32).collect(),
        None,
        vec![Attribute {
            name: "f".into(),
            components: 1,
            data: values,
        }],
    )
    .unwrap()
}

fn curved(u: DVec3) -> DVec3 {
    DVec3::new(
        2.0 * u.x + 0.3 * u.y * u.y,
        1.5 * u.y + 0.2 * u.x * u.z,
        u.z + 0.25 * u.x * u.x - 0.1 * u.y,
    )
}

#[test]
fn world_gradient_and_hessian_follow_the_chain_rule() {
    // F*_u = Jᵀ F_x and ∂F_x/∂u_a = F_xx J e_a, checked by differences in reference space,
    // on curved cells (no inverse mapping involved).
    let field = |x: DVec3| (x.x * 1.3).sin() + x.y * x.z - 0.5 * x.z * x.z * x.x;
    let mut sc = Scratch::default();
    let h = 1e-5;
    for kind in KINDS {
        for p in 2..=4 {
            let mesh = single_cell(kind, p, curved, field);
            let v = &mesh.point_data[0].data;
            for u in inside_points(kind) {
                let e = mesh.evaluate(v, 0, u, &mut sc);
                let back = e.jacobian.transpose() * e.grad;
                assert!((back - e.grad_ref).abs().max_element() < 1e-10);
                for a in 0..3 {
                    let d = DVec3::AXES[a] * h;
                    let gp = mesh.evaluate(v, 0, u + d, &mut sc).grad;
                    let gm = mesh.evaluate(v, 0, u - d, &mut sc).grad;
                    let fd = (gp - gm) / (2.0 * h);
                    let want = e.hessian * e.jacobian.col(a);
                    assert!(
                        (fd - want).abs().max_element() < 1e-5 * (1.0 + want.abs().max_element()),
                        "{kind:?} p{p} at {u}: ∂F_x/∂u{a} {fd} vs F_xx J e_a {want}"
                    );
                }
                assert!(e.hessian.abs_diff_eq(e.hessian.transpose(), 1e-8));
            }
        }
    }
}

#[test]
fn exact_quadratic_field_on_affine_cells_and_sphere_curvature() {
    // Affine geometry and a quadratic world field are represented exactly from order 2:
    // gradient, Hessian and the curvature of the sphere |x − c| = R must be exact.
    let c = DVec3::new(0.3, -0.2, 0.1);
    let affine = |u: DVec3| {
        DVec3::new(
            2.0 * u.x + 0.5 * u.y,
            1.5 * u.y - 0.3 * u.z,
            1.2 * u.z + 0.4 * u.x,
        ) - DVec3::splat(0.5)
    };
    let field = |x: DVec3| (x - c).length_squared();
    let mut sc = Scratch::default();
    for kind in KINDS {
        for p in 2..=4 {
            let mesh = single_cell(kind, p, affine, field);
            let v = &mesh.point_data[0].data;
            for u in inside_points(kind) {
                let e = mesh.evaluate(v, 0, u, &mut sc);
                assert!((e.x - affine(u)).length() < 1e-12);
                assert!((e.value - field(e.x)).abs() < 1e-11);
                assert!((e.grad - 2.0 * (e.x - c)).abs().max_element() < 1e-10);
                assert!(
                    e.hessian.abs_diff_eq(DMat3::IDENTITY * 2.0, 1e-9),
                    "{}",
                    e.hessian
                );
                let r = (e.x - c).length();
                let (k1, k2) = principal_curvatures(e.grad, e.hessian);
                assert!(
                    (k1 - 1.0 / r).abs() < 1e-8 && (k2 - 1.0 / r).abs() < 1e-8,
                    "{k1} {k2} vs {}",
                    1.0 / r
                );
            }
        }
    }
}

#[test]
fn inverted_and_degenerate_cells_are_named() {
    let s = shape(Kind::Hexahedron, 2);
    let mut points: Vec<DVec3> = (0..s.len()).map(|k| s.node_coords(k)).collect();
    // Second cell: the first mirrored in x (inverted).
    let mirrored: Vec<DVec3> = points
        .iter()
        .map(|p| DVec3::new(-p.x - 2.0, p.y, p.z))
        .collect();
    points.extend(mirrored);
    let n = s.len();
    let types = [72u8, 72];
    let err = FeMesh::new(
        "bad.vtu",
        points.clone(),
        &types,
        &[0, n, 2 * n],
        (0..2 * n as u32).collect(),
        None,
        vec![],
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("bad.vtu") && err.contains("cell 1") && err.contains("inverted"),
        "{err}"
    );
    // Collapse a face of cell 0: degenerate.
    let mut flat = points[..n].to_vec();
    for p in flat.iter_mut() {
        p.z = 0.0;
    }
    let err = FeMesh::new(
        "flat.vtu",
        flat,
        &[72],
        &[0, n],
        (0..n as u32).collect(),
        None,
        vec![],
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("cell 0") && err.contains("degenerate"),
        "{err}"
    );
    // Wrong node count and unknown type.
    let err = FeMesh::new(
        "x",
        points.clone(),
        &[72],
        &[0, 26],
        (0..26).collect(),
        None,
        vec![],
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("cell 0") && err.contains("26 nodes"), "{err}");
    let err = FeMesh::new("x", points, &[14], &[0, 5], (0..5).collect(), None, vec![])
        .unwrap_err()
        .to_string();
    assert!(err.contains("VTK type 14"), "{err}");
}

#[test]
fn points_cross_faces_into_neighbours_at_the_same_world_point() {
    // Two curved quadratic hexahedra side by side sharing the face x = 1 (node ids shared),
    // and a tetrahedron + wedge pair sharing a triangle.
    let s = shape(Kind::Hexahedron, 2);
    let bend = |u: DVec3| DVec3::new(u.x, u.y + 0.1 * (u.x * 3.0).sin(), u.z + 0.05 * u.x * u.y);
    let mut points: Vec<DVec3> = Vec::new();
    let mut ids: Vec<u32> = Vec::new();
    let mut index = std::collections::HashMap::new();
    for shift in [0.0, 1.0] {
        for k in 0..s.len() {
            let r = s.node_coords(k) + DVec3::new(shift, 0.0, 0.0);
            let key = (r * 1e6).round().as_ivec3().to_array();
            let id = *index.entry(key).or_insert_with(|| {
                points.push(bend(r));
                points.len() as u32 - 1
            });
            ids.push(id);
        }
    }
    let n = s.len();
    let mesh = FeMesh::new("pair", points, &[72, 72], &[0, n, 2 * n], ids, None, vec![]).unwrap();
    assert_eq!(mesh.neighbour(0, 1), Some((1, 0)));
    assert_eq!(mesh.neighbour(1, 0), Some((0, 1)));
    assert_eq!(mesh.neighbour(0, 0), None);
    let mut sc = Scratch::default();
    let u = DVec3::new(1.2, 0.4, 0.7);
    let x = mesh.map(0, u, &mut sc).0;
    let (c, v) = mesh.relocate(0, u, &mut sc).unwrap();
    assert_eq!(c, 1);
    assert!((mesh.map(1, v, &mut sc).0 - x).length() < 1e-12);
    assert!((v - DVec3::new(0.2, 0.4, 0.7)).length() < 0.05, "{v}");
    // Leaving through a boundary face: no cell.
    assert!(mesh
        .relocate(0, DVec3::new(0.5, -0.2, 0.5), &mut sc)
        .is_none());
}

#[test]
fn lower_order_evaluations_agree_with_the_full_one() {
    let (mut full, mut low) = (BasisValues::default(), BasisValues::default());
    for kind in KINDS {
        let s = shape(kind, 3);
        for u in inside_points(kind) {
            s.evaluate(u, &mut full);
            s.evaluate_to(u, 1, &mut low);
            assert_eq!(full.values, low.values);
            assert_eq!(full.gradients, low.gradients);
            assert!(low.hessians.is_empty());
            s.evaluate_to(u, 0, &mut low);
            assert_eq!(full.values, low.values);
            assert!(low.gradients.is_empty());
        }
    }
}

/// A xorshift stream of uniform numbers in [0, 1), seeded.
fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A random point of `kind`'s reference domain; half of them on its boundary (faces,
/// edges, corners), where a cell's extremes usually are.
fn random_reference(kind: Kind, next: &mut impl FnMut() -> f64) -> DVec3 {
    // Barycentric weights, some zeroed (a face, edge or corner of a simplex).
    let mut simplex = |n: usize| -> [f64; 4] {
        let mut w = [0.0; 4];
        for x in w.iter_mut().take(n) {
            *x = if next() < 0.25 {
                0.0
            } else {
                -(1.0 - next()).ln()
            };
        }
        let sum: f64 = w.iter().sum();
        if sum == 0.0 {
            w[0] = 1.0;
            return w;
        }
        w.map(|x| x / sum)
    };
    let unit = |next: &mut dyn FnMut() -> f64| match next() {
        x if x < 0.2 => 0.0,
        x if x < 0.4 => 1.0,
        _ => next(),
    };
    match kind {
        Kind::Hexahedron => DVec3::new(unit(next), unit(next), unit(next)),
        Kind::Tetrahedron => {
            let w = simplex(4);
            DVec3::new(w[1], w[2], w[3])
        }
        Kind::Wedge => {
            let w = simplex(3);
            DVec3::new(w[1], w[2], unit(next))
        }
    }
}

/// A one-cell mesh of `kind` and order `p` whose nodes are a strongly bent map of the
/// reference nodes moved by random offsets of up to a third of the node spacing (redrawn
/// until the cell is valid, i.e. det J > 0 at its nodes).
fn jittered_cell(kind: Kind, p: usize, seed: u64) -> FeMesh {
    let s = shape(kind, p);
    let bend = |u: DVec3| {
        DVec3::new(
            u.x + 0.4 * (2.0 * u.y).sin() * u.z,
            u.y + 0.5 * u.x * u.x - 0.3 * u.z * u.x,
            u.z + 0.6 * (3.0 * u.x).sin() * u.y,
        )
    };
    let mut next = uniform(seed);
    for amplitude in [1.0 / 3.0, 0.2, 0.1, 0.05, 0.0] {
        for _try in 0..20 {
            let points: Vec<DVec3> = (0..s.len())
                .map(|k| {
                    let jitter = DVec3::new(next(), next(), next()) * 2.0 - 1.0;
                    bend(s.node_coords(k)) + jitter * (amplitude / p as f64)
                })
                .collect();
            let cell = FeMesh::new(
                "jittered",
                points,
                &[kind.vtk_type()],
                &[0, s.len()],
                (0..s.len() as u32).collect(),
                None,
                vec![],
            );
            if let Ok(cell) = cell {
                return cell;
            }
        }
    }
    panic!("{kind:?} p{p}: no valid jittered cell");
}

/// Every element type at orders 1–4 and higher ones (the conversion's conditioning grows
/// with the order).
fn box_cases() -> Vec<(Kind, usize)> {
    let mut cases: Vec<(Kind, usize)> = KINDS
        .iter()
        .flat_map(|&k| (1..=4).map(move |p| (k, p)))
        .collect();
    cases.extend([
        (Kind::Hexahedron, 6),
        (Kind::Hexahedron, 8),
        (Kind::Tetrahedron, 6),
        (Kind::Tetrahedron, 8),
        (Kind::Wedge, 6),
    ]);
    cases
}

/// The Bernstein function paired with node `n` of `s` at `u`, written out per element type
/// from the textbook definitions (independently of `bernstein.rs`'s factoring): the
/// hexahedron's tensor product of 1-D B_i^p(r) B_j^q(s) B_k^w(t); the tetrahedron's
/// p!/(i! j! k! l!) λ0^i r^j s^k t^l; the wedge's triangle Bernstein times a 1-D one in t.
/// Its multi-index is the node's lattice point (degree indices).
fn bernstein(s: &Shape, n: usize, u: DVec3) -> f64 {
    let fact = |k: u16| (1..=k as u64).product::<u64>() as f64;
    let one_d = |p: usize, i: u16, x: f64| {
        fact(p as u16) / (fact(i) * fact(p as u16 - i))
            * x.powi(i as i32)
            * (1.0 - x).powi(p as i32 - i as i32)
    };
    let d = s.nodes[n];
    match s.kind {
        Kind::Hexahedron => {
            one_d(s.order[0], d[0], u.x)
                * one_d(s.order[1], d[1], u.y)
                * one_d(s.order[2], d[2], u.z)
        }
        Kind::Tetrahedron => {
            let l = [1.0 - u.x - u.y - u.z, u.x, u.y, u.z];
            let p = s.order[0] as u16;
            (0..4).fold(fact(p), |b, m| b * l[m].powi(d[m] as i32) / fact(d[m]))
        }
        Kind::Wedge => {
            let l = [1.0 - u.x - u.y, u.x, u.y];
            let p = s.order[0] as u16;
            (0..3).fold(fact(p), |b, m| b * l[m].powi(d[m] as i32) / fact(d[m]))
                * one_d(s.order[2], d[3], u.z)
        }
    }
}

#[test]
fn bernstein_control_points_reproduce_the_mapping() {
    let mut sc = Scratch::default();
    let mut row = Vec::new();
    for (kind, p) in box_cases() {
        let mesh = jittered_cell(kind, p, 11 * p as u64 + kind as u64);
        let s = mesh.shape(0);
        let map = super::bernstein::control_map(s);
        let x: Vec<DVec3> = mesh
            .nodes(0)
            .iter()
            .map(|&n| mesh.points[n as usize])
            .collect();
        let mut c = x.clone();
        map.control_points(&mut c, &mut row);
        if p == 1 {
            // Linear Bernstein functions are the linear Lagrange ones: C = X exactly.
            assert_eq!(c, x, "{kind:?}: linear control points are the nodes");
        }
        let reach = x.iter().fold(0.0f64, |r, q| r.max(q.abs().max_element()));
        // The conversion's own rounding bound, plus the Lagrange evaluation's.
        let tol = (map.rounding() + 1e-12) * reach;
        let mut next = uniform(p as u64);
        // Random points, and the nodes themselves (the Bernstein form at the nodes is
        // M C, which must give back X: this checks the computed M⁻¹ too).
        let points: Vec<DVec3> = (0..200)
            .map(|_| random_reference(kind, &mut next))
            .chain((0..s.len()).map(|k| s.node_coords(k)))
            .collect();
        for u in points {
            let b: Vec<f64> = (0..s.len()).map(|n| bernstein(s, n, u)).collect();
            let sum: f64 = b.iter().sum();
            assert!((sum - 1.0).abs() < 1e-12, "{kind:?} p{p}: ΣB = {sum}");
            // ≥ 0 up to the rounding of λ0 = 1 − r − s − t on the boundary.
            assert!(
                b.iter().all(|&v| v >= -1e-15),
                "{kind:?} p{p}: B < 0 at {u}"
            );
            let bezier = b.iter().zip(&c).fold(DVec3::ZERO, |a, (&w, &q)| a + q * w);
            let lagrange = mesh.map(0, u, &mut sc).0;
            assert!(
                (bezier - lagrange).abs().max_element() <= tol,
                "{kind:?} p{p} at {u}: Bernstein {bezier} vs Lagrange {lagrange} (tol {tol:e})"
            );
        }
    }
}

#[test]
fn cell_boxes_contain_strongly_curved_cells() {
    let mut sc = Scratch::default();
    let mut outside_nodes_box = 0;
    for (kind, p) in box_cases() {
        for seed in 0..4 {
            let mesh = jittered_cell(kind, p, 1000 * seed + 7 * p as u64 + kind as u64);
            let (lo, hi) = mesh.cell_box(0);
            assert_eq!(
                mesh.bounds(),
                (lo, hi),
                "one cell: the mesh box is the cell's"
            );
            let nodes = crate::field::neighbours::bounds(&mesh.points);
            let mut next = uniform(seed + 99);
            for _ in 0..2000 {
                let u = random_reference(kind, &mut next);
                // Also the point moved out of the domain by at most 0.5e-8 per face (the
                // search accepts up to PROBE_SLACK, 1e-8, outside).
                let c = kind.centroid();
                for u in [u, c + (u - c) * (1.0 + 1e-8)] {
                    let x = mesh.map(0, u, &mut sc).0;
                    assert!(
                        x.cmpge(lo).all() && x.cmple(hi).all(),
                        "{kind:?} p{p} seed {seed}: T({u}) = {x} outside the box {lo}..{hi}"
                    );
                    if x.cmplt(nodes.0).any() || x.cmpgt(nodes.1).any() {
                        outside_nodes_box += 1;
                    }
                }
            }
        }
    }
    // The cells do bulge past their nodes (else this test would prove nothing).
    assert!(outside_nodes_box > 1000, "{outside_nodes_box}");
}

#[test]
fn a_point_in_a_bulge_past_the_old_padding_is_located() {
    // A thin quadratic hexahedron, T(r,s,t) = (r, w s + 2r² − r, w t): its edge s = t = 0
    // has nodes at y = 0, 0, 1 but dips to y = −1/8 at r = 1/4. The nodes' box has largest
    // side 1 + w, so the old search's 10 % padding reached down to y = −0.11 only.
    let w = 0.1;
    let mesh = single_cell(
        Kind::Hexahedron,
        2,
        |u| DVec3::new(u.x, w * u.y + 2.0 * u.x * u.x - u.x, w * u.z),
        |x| x.x,
    );
    let u = DVec3::new(0.25, 0.05, 0.5);
    let mut sc = Scratch::default();
    let x = mesh.map(0, u, &mut sc).0;
    assert!((x.y + 0.12).abs() < 1e-12, "{x}");
    let (lo, hi) = crate::field::neighbours::bounds(&mesh.points);
    let old_pad = 0.1 * (hi - lo).max_element();
    assert!(x.y < lo.y - old_pad, "the point is past the old padded box");
    let index = CellIndex::new(&mesh);
    let mut evaluations = 0;
    for found in [
        index.locate(&mesh, x, None, &mut sc, &mut evaluations),
        index.locate_thorough(&mesh, x, &mut sc, &mut evaluations),
    ] {
        let (c, v) = found.expect("the point is located");
        assert_eq!(c, 0);
        assert!((v - u).length() < 1e-10, "{v} vs {u}");
    }
    // And the probe gives the field there (F = x, the point's own x).
    let values = &mesh.point_data[0].data;
    let hits = probe(&mesh, &index, values, &[x]);
    assert!((hits[0].unwrap().value - x.x).abs() < 1e-12);
}

/// Each face's normal is the unit gradient of its distance (checked by differences), and
/// points inside: the particle system's boundary steps remove these components.
#[test]
fn face_normals_are_the_gradients_of_the_face_distances() {
    for kind in [Kind::Hexahedron, Kind::Tetrahedron, Kind::Wedge] {
        let (_, nf) = kind.face_distances(DVec3::ZERO);
        let u = kind.centroid();
        for f in 0..nf {
            let h = 1e-6;
            let d = |v: DVec3| kind.face_distances(v).0[f];
            let grad = DVec3::new(
                d(u + DVec3::X * h) - d(u - DVec3::X * h),
                d(u + DVec3::Y * h) - d(u - DVec3::Y * h),
                d(u + DVec3::Z * h) - d(u - DVec3::Z * h),
            ) / (2.0 * h);
            let n = kind.face_normal(f);
            assert!((n.length() - 1.0).abs() < 1e-12, "{kind:?} face {f}");
            assert!(
                (grad.normalize() - n).length() < 1e-9,
                "{kind:?} face {f}: {n} vs {grad}"
            );
            // Crossing the face from the centroid along its outward normal is seen.
            let out = -n * 2.0;
            assert_eq!(
                kind.crossed_face(u, out, 1e-9),
                Some(f),
                "{kind:?} face {f}"
            );
        }
    }
}
