//! Reading Lagrange cells from VTU: a file written by VTK itself, evaluated against VTK's
//! own evaluation, and clear errors for broken input.

use glam::DVec3;
use isobar::field::fe::{Kind, Scratch, Shape};
use isobar::io::read_fe_mesh;
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data/fe")
        .join(name)
}

#[test]
fn vtk_written_cells_evaluate_like_vtk() {
    let mesh = read_fe_mesh(&data("mixed_lagrange.vtu")).unwrap();
    assert_eq!(mesh.cell_count(), 3);
    assert_eq!(mesh.shape(0).order, [2, 2, 3]);
    assert_eq!(mesh.shape(1).kind, Kind::Tetrahedron);
    assert_eq!(mesh.shape(2).kind, Kind::Wedge);
    let p = &mesh.point_data.iter().find(|a| a.name == "p").unwrap().data;
    let probes = std::fs::read_to_string(data("mixed_lagrange_probes.txt")).unwrap();
    let mut sc = Scratch::default();
    let mut n = 0;
    for line in probes.lines().filter(|l| !l.starts_with('#')) {
        let v: Vec<f64> = line
            .split_whitespace()
            .map(|x| x.parse().unwrap())
            .collect();
        let c = v[0] as usize;
        let u = DVec3::new(v[1], v[2], v[3]);
        let e = mesh.evaluate(p, c, u, &mut sc);
        let x = DVec3::new(v[4], v[5], v[6]);
        assert!(
            (e.x - x).length() < 1e-12,
            "cell {c} at {u}: x {} vs VTK {x}",
            e.x
        );
        assert!(
            (e.value - v[7]).abs() < 1e-12,
            "cell {c} at {u}: p {} vs VTK {}",
            e.value,
            v[7]
        );
        n += 1;
    }
    assert_eq!(n, 12);
}

/// An ascii VTU of the given cells with point array "p" = x.
fn vtu(points: &[DVec3], types: &[u8], offsets: &[usize], conn: &[u32], extra: &str) -> String {
    let join = |it: Vec<String>| it.join(" ");
    format!(
        r#"<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="2.2" byte_order="LittleEndian">
 <UnstructuredGrid><Piece NumberOfPoints="{}" NumberOfCells="{}">
  <PointData><DataArray type="Float64" Name="p" format="ascii">{}</DataArray></PointData>
  <Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">{}</DataArray></Points>
  <Cells>
   <DataArray type="Int64" Name="connectivity" format="ascii">{}</DataArray>
   <DataArray type="Int64" Name="offsets" format="ascii">{}</DataArray>
   {}
  </Cells>
 </Piece></UnstructuredGrid>
</VTKFile>
"#,
        points.len(),
        types.len(),
        join(points.iter().map(|p| p.x.to_string()).collect()),
        join(
            points
                .iter()
                .map(|p| format!("{} {} {}", p.x, p.y, p.z))
                .collect()
        ),
        join(conn.iter().map(|c| c.to_string()).collect()),
        join(offsets[1..].iter().map(|c| c.to_string()).collect()),
        if extra == "no types" {
            String::new()
        } else {
            format!(
                r#"<DataArray type="UInt8" Name="types" format="ascii">{}</DataArray>"#,
                join(types.iter().map(|c| c.to_string()).collect())
            )
        }
    )
}

fn write(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("isobar-fe-io-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn hex2() -> Vec<DVec3> {
    let s = Shape::new(Kind::Hexahedron, [2, 2, 2]);
    (0..s.len()).map(|k| s.node_coords(k)).collect()
}

#[test]
fn ascii_file_reads_and_evaluates_the_identity() {
    let pts = hex2();
    let path = write(
        "ok.vtu",
        &vtu(&pts, &[72], &[0, 27], &(0..27).collect::<Vec<_>>(), ""),
    );
    let mesh = read_fe_mesh(&path).unwrap();
    let p = &mesh.point_data[0].data;
    let e = mesh.evaluate(p, 0, DVec3::new(0.3, 0.6, 0.2), &mut Scratch::default());
    assert!((e.x - DVec3::new(0.3, 0.6, 0.2)).length() < 1e-14);
    assert!((e.value - 0.3).abs() < 1e-14 && (e.grad - DVec3::X).length() < 1e-12);
}

#[test]
fn broken_files_are_named_errors() {
    let pts = hex2();
    let all: Vec<u32> = (0..27).collect();
    let cases: Vec<(&str, String, &str)> = vec![
        (
            "type.vtu",
            vtu(&pts, &[14], &[0, 27], &all, ""),
            "VTK type 14 (a pyramid)",
        ),
        (
            "linear.vtu",
            vtu(&pts, &[12], &[0, 27], &all, ""),
            "cell 0 (VTK hexahedron, type 12) has 27 nodes, not 8",
        ),
        (
            "count.vtu",
            vtu(&pts, &[72], &[0, 26], &all[..26], ""),
            "26 nodes",
        ),
        (
            "notypes.vtu",
            vtu(&pts, &[72], &[0, 27], &all, "no types"),
            "'types'",
        ),
        (
            "index.vtu",
            vtu(&pts, &[72], &[0, 27], &[&all[..26], &[99]].concat(), ""),
            "point 99",
        ),
        (
            // A mirrored cell beside an upright one (a mesh mirrored as a whole is read).
            "inverted.vtu",
            vtu(
                &pts.iter()
                    .copied()
                    .chain(pts.iter().map(|p| DVec3::new(-p.x - 1.0, p.y, p.z)))
                    .collect::<Vec<_>>(),
                &[72, 72],
                &[0, 27, 54],
                &(0..54).collect::<Vec<_>>(),
                "",
            ),
            "cell 1 (Lagrange hexahedron of order 2) is inverted",
        ),
    ];
    for (name, text, want) in cases {
        let path = write(name, &text);
        let err = read_fe_mesh(&path).unwrap_err().to_string();
        assert!(err.contains(name), "{name}: {err}");
        assert!(err.contains(want), "{name}: {err}");
        if want != "'types'" {
            assert!(err.contains("cell 0"), "{name}: {err}");
        }
    }
    let err = read_fe_mesh(Path::new("/nonexistent/x.vtu"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("x.vtu"), "{err}");
}

/// `isobar fe` end to end on the VTK-written file: every sample's (Element, Reference)
/// maps to its position and lies on F = C within ε_T; byte-identical for 1 and 2 threads.
#[test]
fn cli_samples_vtk_written_cells() {
    let mut outputs = Vec::new();
    for threads in ["1", "2"] {
        let out = write(&format!("samples_{threads}.vtp"), "");
        let run = std::process::Command::new(env!("CARGO_BIN_EXE_isobar"))
            .args(["fe", "--field", "p", "--iso", "0.5", "--quiet", "-o"])
            .arg(&out)
            .arg(data("mixed_lagrange.vtu"))
            .env("RAYON_NUM_THREADS", threads)
            .output()
            .unwrap();
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        assert!(String::from_utf8_lossy(&run.stdout).contains("samples on 3 cells"));
        outputs.push(std::fs::read(&out).unwrap());
        let samples = isobar::io::read_mesh(&out).unwrap();
        assert!(samples.vertex_count() > 50);
        assert_eq!(samples.normals.len(), samples.vertex_count());
        let mesh = read_fe_mesh(&data("mixed_lagrange.vtu")).unwrap();
        let p = &mesh.point_data[0].data;
        let cell = &samples.attribute("Element").unwrap().data;
        let reference = &samples.attribute("Reference").unwrap().data;
        let mut sc = Scratch::default();
        for (i, x) in samples.positions.iter().enumerate() {
            let u = DVec3::new(reference[3 * i], reference[3 * i + 1], reference[3 * i + 2]);
            let e = mesh.evaluate(p, cell[i] as usize, u, &mut sc);
            assert!((e.x - DVec3::from(*x)).length() < 1e-12, "sample {i}");
            assert!(
                (e.value - 0.5).abs() <= 1e-6,
                "sample {i}: |F - C| = {}",
                (e.value - 0.5).abs()
            );
        }
    }
    assert!(
        outputs[0] == outputs[1],
        "output differs between 1 and 2 threads"
    );
    let bad = std::process::Command::new(env!("CARGO_BIN_EXE_isobar"))
        .args(["fe", "--field", "nope", "--iso", "0", "-o", "/tmp/x.vtp"])
        .arg(data("mixed_lagrange.vtu"))
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("'nope'"));
}
