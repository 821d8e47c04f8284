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
    let err = FeMesh::new("x", points, &[12], &[0, 8], (0..8).collect(), None, vec![])
        .unwrap_err()
        .to_string();
    assert!(err.contains("VTK type 12"), "{err}");
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
