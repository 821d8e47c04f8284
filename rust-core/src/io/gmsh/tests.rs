use super::*;
use crate::field::fe::{Kind, Scratch};

fn fixture(name: &str) -> (Vec<u8>, String) {
    let path = format!("{}/data/fe/gmsh/{name}", env!("CARGO_MANIFEST_DIR"));
    (std::fs::read(&path).unwrap(), path)
}

fn read(name: &str) -> FeMesh {
    let (bytes, path) = fixture(name);
    read_fe_mesh(&bytes, &path).unwrap()
}

fn read_err(bytes: &[u8]) -> String {
    read_fe_mesh(bytes, "bad.msh").unwrap_err().to_string()
}

#[test]
fn permutations_are_bijections_that_keep_the_corners() {
    for (t, v) in VOLUME_TYPES.iter().enumerate() {
        let p = permutation(t);
        let mut sorted = p.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..p.len()).collect::<Vec<_>>(), "type {}", v.ty);
        let corners = v.kind.corners().len();
        assert_eq!(&p[..corners], &(0..corners).collect::<Vec<_>>()[..]);
        let nodes = match v.serendipity {
            // VTK's 20-node hexahedron, 15-node wedge.
            true => [20, 15][(v.kind == Kind::Wedge) as usize],
            false => v.kind.node_count([v.order; 3]),
        };
        assert_eq!(v.lattice.len(), nodes, "type {}", v.ty);
    }
    // The families and orders gmsh 4.15 describes (and its two second-order serendipity
    // cells).
    let count = |k: Kind, s: bool| {
        VOLUME_TYPES
            .iter()
            .filter(|v| v.kind == k && v.serendipity == s)
            .count()
    };
    assert_eq!(count(Kind::Tetrahedron, false), 10);
    assert_eq!(count(Kind::Hexahedron, false), 9);
    assert_eq!(count(Kind::Wedge, false), 2);
    assert_eq!(count(Kind::Hexahedron, true), 1);
    assert_eq!(count(Kind::Wedge, true), 1);
    assert_eq!(count(Kind::Tetrahedron, true), 0);
}

/// gmsh's own evaluation of world position (getJacobians) and field (its Lagrange basis
/// over the element's node values) at reference points of each element: the node
/// permutation is right exactly when our mapping and field agree on curved cells.
#[test]
fn evaluations_match_gmsh_at_probe_points() {
    for stem in [
        "ball_tet3",
        "cylinder_hex2",
        "cylinder_hex3",
        "cylinder_prism2",
    ] {
        let mesh = read(&format!("{stem}.msh"));
        if stem == "cylinder_hex3" {
            // gmsh type 92: the file must hold cubic hexahedra for this case to test them.
            let s = mesh.shape(0);
            assert_eq!((s.kind, s.order), (Kind::Hexahedron, [3; 3]));
        }
        let (probes, _) = fixture(&format!("{stem}_probes.txt"));
        let values = &mesh.point_data.iter().find(|a| a.name == "p").unwrap().data;
        let mut scratch = Scratch::default();
        let mut n = 0;
        let mut curved = 0.0f64;
        for line in std::str::from_utf8(&probes).unwrap().lines() {
            if line.starts_with('#') {
                continue;
            }
            let v: Vec<f64> = line
                .split_whitespace()
                .map(|t| t.parse().unwrap())
                .collect();
            let c = v[0] as usize;
            let u = DVec3::new(v[1], v[2], v[3]);
            let want = DVec3::new(v[4], v[5], v[6]);
            let (x, _) = mesh.map(c, u, &mut scratch);
            assert!(
                x.distance(want) < 1e-12,
                "{stem} cell {c} at {u}: {x} vs gmsh {want}"
            );
            let f = mesh.value(values, c, u, &mut scratch);
            assert!(
                (f - v[7]).abs() < 1e-12,
                "{stem} cell {c} at {u}: p {f} vs gmsh {}",
                v[7]
            );
            // How far the cell is from its corners' linear map: the test only means
            // something if the cells are curved.
            let linear = {
                let shape = Shape::new(mesh.shape(c).kind, [1; 3]);
                let mut b = crate::field::fe::BasisValues::default();
                shape.evaluate_to(u, 0, &mut b);
                (0..shape.len())
                    .map(|k| mesh.points[mesh.nodes(c)[k] as usize] * b.values[k])
                    .sum::<DVec3>()
            };
            curved = curved.max(linear.distance(want));
            n += 1;
        }
        assert!(n >= 45, "{stem}: {n} probes");
        assert!(curved > 1e-3, "{stem}: cells are not curved ({curved})");
    }
}

#[test]
fn binary_and_ascii_files_give_the_same_mesh() {
    // The ASCII file rounds to 16 significant digits.
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-15 * a.abs().max(1.0);
    let a = read("ball_tet3.msh");
    let b = read("ball_tet3_binary.msh");
    assert_eq!(a.points.len(), b.points.len());
    for (p, q) in a.points.iter().zip(&b.points) {
        assert!((0..3).all(|k| close(p[k], q[k])), "{p} vs {q}");
    }
    let (va, vb) = (&a.point_data[0], &b.point_data[0]);
    assert_eq!((&va.name, va.components), (&vb.name, vb.components));
    assert!(va.data.iter().zip(&vb.data).all(|(&x, &y)| close(x, y)));
    assert_eq!(a.cell_count(), b.cell_count());
    for c in 0..a.cell_count() {
        assert_eq!(a.nodes(c), b.nodes(c));
    }
}

/// The same cells written by VTK (nodes placed in VTK's order by VTK's own parametric
/// coordinates) and by gmsh: identical cells node by node, identical samples.
#[test]
fn msh_and_vtu_of_the_same_cells_agree() {
    for stem in [
        "ball_tet3",
        "cylinder_hex2",
        "cylinder_hex3",
        "cylinder_prism2",
    ] {
        let m = read(&format!("{stem}.msh"));
        let (bytes, path) = fixture(&format!("{stem}.vtu"));
        let v = crate::io::vtk_xml::read_fe_mesh(&bytes, &path).unwrap();
        assert_eq!(m.cell_count(), v.cell_count(), "{stem}");
        let (pm, pv) = (&m.point_data[0].data, &v.point_data[0].data);
        for c in 0..m.cell_count() {
            let (a, b) = (m.shape(c), v.shape(c));
            assert_eq!((a.kind, a.order), (b.kind, b.order), "{stem} cell {c}");
            for (&a, &b) in m.nodes(c).iter().zip(v.nodes(c)) {
                assert_eq!(
                    m.points[a as usize], v.points[b as usize],
                    "{stem} cell {c}"
                );
                assert_eq!(pm[a as usize], pv[b as usize], "{stem} cell {c}");
            }
        }
        let params = crate::highorder::Params {
            iso: 0.5,
            spacing: 0.15,
            levels: 1,
            ..Default::default()
        };
        let progress = &mut crate::progress::Progress::none();
        let (sm, _) = crate::highorder::sample(&m, "p", &params, progress).unwrap();
        let (sv, _) = crate::highorder::sample(&v, "p", &params, progress).unwrap();
        assert!(!sm.is_empty(), "{stem}");
        assert_eq!(sm.positions, sv.positions, "{stem}");
    }
}

#[test]
fn the_last_time_step_is_read() {
    // Step 0 holds p = 0 everywhere; step 1 the field.
    let m = read("ball_tet3.msh");
    assert!(m.point_data[0].data.iter().any(|&v| v != 0.0));
    let (bytes, _) = fixture("ball_tet3.msh");
    let text = String::from_utf8(bytes).unwrap();
    // Keep only the first $NodeData: all zeros.
    let second = text.rfind("$NodeData").unwrap();
    let end = text.rfind("$EndNodeData").unwrap() + "$EndNodeData\n".len();
    let first_only = format!("{}{}", &text[..second], &text[end..]);
    let m = read_fe_mesh(first_only.as_bytes(), "x.msh").unwrap();
    assert!(m.point_data[0].data.iter().all(|&v| v == 0.0));
}

#[test]
fn truncated_files_are_refused_without_panicking() {
    for name in ["ball_tet3.msh", "ball_tet3_binary.msh"] {
        let (bytes, _) = fixture(name);
        let cuts = (1..40).map(|k| bytes.len() * k / 40);
        for cut in cuts {
            let part = &bytes[..cut];
            match read_fe_mesh(part, "cut.msh") {
                Err(e) => {
                    let s = e.to_string();
                    assert!(s.starts_with("cut.msh: "), "{s}");
                }
                // Cutting inside the (skipped) data of a trailing section may leave a
                // complete mesh only if every section it needs is whole.
                Ok(_) => panic!("{name} cut at {cut} of {} was accepted", bytes.len()),
            }
        }
        let e = read_err(&bytes[..bytes.len() / 2]);
        assert!(e.contains("truncated"), "{e}");
    }
}

#[test]
fn bad_files_name_the_problem() {
    let (bytes, _) = fixture("ball_tet3.msh");
    let text = String::from_utf8(bytes).unwrap();
    let e = read_err(text.replacen("4.1 0 8", "2.2 0 8", 1).as_bytes());
    assert!(e.contains("version 2.2") && e.contains("line 2"), "{e}");
    let e = read_err(b"hello\n");
    assert!(e.contains("$MeshFormat") || e.contains("$Section"), "{e}");
    // An element referring to a node that does not exist.
    let header = text.find("\n3 1 29 ").unwrap() + 1;
    let first = text[header..].find('\n').unwrap() + header + 1;
    let node = text[first..].split_whitespace().nth(1).unwrap().to_string();
    let broken = format!(
        "{}{}",
        &text[..first],
        text[first..].replacen(&format!(" {node} "), " 999999 ", 1)
    );
    let e = read_err(broken.as_bytes());
    assert!(e.contains("node 999999") && e.contains("element"), "{e}");
    // A node value missing from $NodeData.
    let last = text.rfind("$NodeData").unwrap();
    let nd = &text[last..];
    // Lines: $NodeData, 1, "p", 1, time, 4, step, components, count, partition, values.
    let count_line = nd.lines().nth(8).unwrap().to_string();
    let n: usize = count_line.trim().parse().unwrap();
    let mut lines: Vec<&str> = nd.lines().collect();
    lines.remove(10);
    let fewer = (n - 1).to_string();
    lines[8] = &fewer;
    let broken = format!("{}{}\n", &text[..last], lines.join("\n"));
    let e = read_err(broken.as_bytes());
    assert!(e.contains("'p'") && e.contains("no value for node"), "{e}");
    // Serendipity elements above order 2 are refused by name (type 99: the 32-node
    // hexahedron of order 3).
    let e = read_err(text.replacen("\n3 1 29 ", "\n3 1 99 ", 1).as_bytes());
    assert!(e.contains("Hexahedron 32") || e.contains("type 99"), "{e}");
    // Cubic and quartic prisms, which gmsh numbers but cannot describe, are refused saying
    // why (and naming the file, the line and the type), not as an unknown type.
    for (ty, order) in [(90, 3), (91, 4)] {
        let e = read_err(
            text.replacen("\n3 1 29 ", &format!("\n3 1 {ty} "), 1)
                .as_bytes(),
        );
        for part in [
            "bad.msh".to_string(),
            "$Elements, line ".into(),
            format!("element type {ty} (prisms of order {order})"),
            "no node-ordering definition for prisms above order 2".into(),
            format!("FaceClosureFull not implemented for prisms of order {order}"),
        ] {
            assert!(e.contains(&part), "{part}: {e}");
        }
        assert!(!e.contains("unknown"), "{e}");
    }
    let e = read_err(text.replacen("\n3 1 29 ", "\n3 1 111 ", 1).as_bytes());
    assert!(e.contains("(incomplete prisms of order 3)"), "{e}");
    // A pyramid is refused without the advice for incomplete cells, which cannot help it.
    let e = read_err(text.replacen("\n3 1 29 ", "\n3 1 7 ", 1).as_bytes());
    assert!(e.contains("type 7 (Pyramid 5)"), "{e}");
    assert!(e.contains("pyramids are not read"), "{e}");
    assert!(!e.contains("SecondOrderIncomplete"), "{e}");
}

/// gmsh orders a hexahedron's nodes recursively: the 8 vertices, the nodes inside each of
/// its 12 edges (from the edge's first vertex), the inside of each of its 6 faces as a
/// quadrilateral of order p − 2 (itself vertices, edges, inside) and the inside as a
/// hexahedron of order p − 2. Derived here from that rule alone, the lattices equal the
/// ones `order.rs` holds from gmsh's getElementProperties, for every order gmsh has (the
/// mesh fixtures only reach order 3).
#[test]
fn hexahedron_lattices_follow_gmsh_recursive_order() {
    type P = [i32; 3];
    const CORNERS: [P; 8] = [
        [0, 0, 0],
        [1, 0, 0],
        [1, 1, 0],
        [0, 1, 0],
        [0, 0, 1],
        [1, 0, 1],
        [1, 1, 1],
        [0, 1, 1],
    ];
    const EDGES: [[usize; 2]; 12] = [
        [0, 1],
        [0, 3],
        [0, 4],
        [1, 2],
        [1, 5],
        [2, 3],
        [2, 6],
        [3, 7],
        [4, 5],
        [4, 7],
        [5, 6],
        [6, 7],
    ];
    const FACES: [[usize; 4]; 6] = [
        [0, 3, 2, 1],
        [0, 1, 5, 4],
        [0, 4, 7, 3],
        [1, 2, 6, 5],
        [2, 3, 7, 6],
        [4, 5, 6, 7],
    ];
    /// The nodes strictly inside the segment a→b of order p, from a.
    fn edge(out: &mut Vec<P>, a: P, b: P, p: i32) {
        out.extend((1..p).map(|i| -> P { std::array::from_fn(|k| a[k] + (b[k] - a[k]) * i / p) }));
    }
    /// The corners of the loop `c` (order p) one lattice step inwards.
    fn inset(c: [P; 4], p: i32) -> [P; 4] {
        let step = |to: usize, k: usize| (c[to][k] - c[0][k]) / p;
        let at = |q: P, s1: i32, s3: i32| -> P {
            std::array::from_fn(|k| q[k] + s1 * step(1, k) + s3 * step(3, k))
        };
        [
            at(c[0], 1, 1),
            at(c[1], -1, 1),
            at(c[2], -1, -1),
            at(c[3], 1, -1),
        ]
    }
    fn quad(out: &mut Vec<P>, c: [P; 4], p: i32) {
        if p == 0 {
            out.push(c[0]);
            return;
        }
        out.extend(c);
        for (a, b) in [(0, 1), (1, 2), (2, 3), (3, 0)] {
            edge(out, c[a], c[b], p);
        }
        if p >= 2 {
            quad(out, inset(c, p), p - 2);
        }
    }
    fn hex(out: &mut Vec<P>, o: P, p: i32) {
        if p == 0 {
            out.push(o);
            return;
        }
        let c: [P; 8] = std::array::from_fn(|v| std::array::from_fn(|k| o[k] + CORNERS[v][k] * p));
        out.extend(c);
        for [a, b] in EDGES {
            edge(out, c[a], c[b], p);
        }
        if p >= 2 {
            for f in FACES {
                quad(out, inset(f.map(|v| c[v]), p), p - 2);
            }
            hex(out, o.map(|x| x + 1), p - 2);
        }
    }
    let mut orders = Vec::new();
    for v in VOLUME_TYPES
        .iter()
        .filter(|v| v.kind == Kind::Hexahedron && !v.serendipity)
    {
        let mut derived = Vec::new();
        hex(&mut derived, [0; 3], v.order as i32);
        let table: Vec<P> = v.lattice.iter().map(|l| l.map(i32::from)).collect();
        assert_eq!(derived, table, "gmsh type {} (order {})", v.ty, v.order);
        orders.push(v.order);
    }
    assert_eq!(orders, (1..=9).collect::<Vec<_>>());
}
