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
        assert_eq!(v.lattice.len(), v.kind.node_count([v.order; 3]));
    }
    // The families and orders gmsh 4.15 describes.
    let count = |k: Kind| VOLUME_TYPES.iter().filter(|v| v.kind == k).count();
    assert_eq!(count(Kind::Tetrahedron), 6);
    assert_eq!(count(Kind::Hexahedron), 6);
    assert_eq!(count(Kind::Wedge), 2);
}

/// gmsh's own evaluation of world position (getJacobians) and field (its Lagrange basis
/// over the element's node values) at reference points of each element: the node
/// permutation is right exactly when our mapping and field agree on curved cells.
#[test]
fn evaluations_match_gmsh_at_probe_points() {
    for stem in ["ball_tet3", "cylinder_hex2", "cylinder_prism2"] {
        let mesh = read(&format!("{stem}.msh"));
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
    for stem in ["ball_tet3", "cylinder_hex2", "cylinder_prism2"] {
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
    // Serendipity elements are refused by name.
    let e = read_err(text.replacen("\n3 1 29 ", "\n3 1 17 ", 1).as_bytes());
    assert!(e.contains("Hexahedron 20") || e.contains("type 17"), "{e}");
}
