//! High-order FE isosurfaces end to end on files written by real FE codes: an MFEM Poisson
//! solution (third-order hexahedra, VTU Lagrange cells with each cell's nodes repeated,
//! `scripts/make_mfem_solution.py`) and gmsh meshes with `$NodeData`
//! (`scripts/make_gmsh_fixture.py`). Every sample and every marching-cubes vertex is
//! checked by an independent evaluation: find the world point's cell by trying every cell
//! (no binning, no hints: not the point location the extractors use), evaluate.

use glam::DVec3;
use isobar::field::fe::{FeMesh, Scratch};
use isobar::highorder::marching::{extract, McParams};
use isobar::highorder::{sample, Params};
use isobar::progress::Progress;
use std::path::PathBuf;

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("data/fe")
        .join(name)
}

/// |F(x) − C| with x located from scratch, by brute force over the cells.
fn residuals(mesh: &FeMesh, field: &str, points: &[[f64; 3]], iso: f64) -> Vec<f64> {
    let values = &mesh
        .point_data
        .iter()
        .find(|a| a.name == field)
        .unwrap()
        .data;
    let mut scratch = Scratch::default();
    points
        .iter()
        .map(|&x| {
            let x = DVec3::from(x);
            let (c, u) = containing_cell(mesh, x, &mut scratch)
                .unwrap_or_else(|| panic!("{x:?} is in no cell"));
            (mesh.value(values, c, u, &mut scratch) - iso).abs()
        })
        .collect()
}

/// The first cell whose reference domain holds `x` (to 1e-8: surfaces that reach the mesh
/// boundary have points a rounding error outside it), by inverting T in every cell.
fn containing_cell(mesh: &FeMesh, x: DVec3, scratch: &mut Scratch) -> Option<(usize, DVec3)> {
    (0..mesh.cell_count()).find_map(|c| {
        let kind = mesh.shape(c).kind;
        let u = mesh.invert(c, x, kind.centroid(), scratch)?;
        let (d, nf) = kind.face_distances(u);
        d[..nf].iter().all(|&d| d > -1e-8).then_some((c, u))
    })
}

/// Cells whose field crosses `iso` at some point of a reference lattice.
fn cut_cells(mesh: &FeMesh, values: &[f64], iso: f64) -> Vec<usize> {
    let mut scratch = Scratch::default();
    (0..mesh.cell_count())
        .filter(|&c| {
            let kind = mesh.shape(c).kind;
            let n = 8;
            let (mut above, mut below) = (false, false);
            for i in 0..=n {
                for j in 0..=n {
                    for k in 0..=n {
                        let u = DVec3::new(i as f64, j as f64, k as f64) / n as f64;
                        let (d, nf) = kind.face_distances(u);
                        if d[..nf].iter().any(|&d| d < 0.0) {
                            continue;
                        }
                        let f = mesh.value(values, c, u, &mut scratch) - iso;
                        above |= f > 1e-9;
                        below |= f < -1e-9;
                    }
                }
            }
            above && below
        })
        .collect()
}

/// Asserts that more than `min_cut` cells are cut by the isosurface and each holds a sample.
fn every_cut_cell_holds_samples(
    mesh: &FeMesh,
    field: &str,
    iso: f64,
    s: &isobar::samples::PointSamples,
    min_cut: usize,
) {
    let values = &mesh
        .point_data
        .iter()
        .find(|a| a.name == field)
        .unwrap()
        .data;
    let cut = cut_cells(mesh, values, iso);
    let held: std::collections::BTreeSet<usize> = s
        .attribute("Element")
        .unwrap()
        .data
        .iter()
        .map(|&c| c as usize)
        .collect();
    assert!(cut.len() > min_cut, "{}: {cut:?}", mesh.name());
    for c in &cut {
        assert!(
            held.contains(c),
            "{}: cell {c} is cut but holds no sample",
            mesh.name()
        );
    }
}

#[test]
fn mfem_poisson_solution_sampled_and_contoured_end_to_end() {
    let mesh = isobar::io::read_fe_mesh(&data("mfem_poisson_q3.vtu")).unwrap();
    assert_eq!(mesh.cell_count(), 27);
    // MFEM repeats every cell's nodes; the corners are welded so that the 108 interior
    // faces of the 3×3×3 block pair up (the 54 boundary faces do not).
    let paired = (0..27)
        .flat_map(|c| (0..6).map(move |f| (c, f)))
        .filter(|&(c, f)| mesh.neighbour(c, f).is_some())
        .count();
    assert_eq!(paired, 108);
    let iso = 0.03;
    let params = Params {
        iso,
        spacing: 0.06,
        ..Params::default()
    };
    let (s, stats) = sample(&mesh, "u", &params, &mut Progress::none()).unwrap();
    eprintln!("mfem samples: {stats:?}");
    assert!(s.len() > 100, "{stats:?}");
    for (i, r) in residuals(&mesh, "u", &s.positions, iso).iter().enumerate() {
        assert!(
            *r <= params.tolerance * (1.0 + 1e-6),
            "sample {i}: |F − C| = {r}"
        );
    }
    // Every cell the surface cuts holds samples (particles crossed the repeated-node
    // faces).
    every_cut_cell_holds_samples(&mesh, "u", iso, &s, 8);

    let mc = McParams {
        iso,
        spacing: 0.05,
        ..McParams::default()
    };
    let (m, ms) = extract(&mesh, "u", &mc, &mut Progress::none()).unwrap();
    eprintln!("mfem mc: {ms:?}");
    assert!(m.vertex_count() > 100);
    assert_eq!(ms.unresolved_edges, 0);
    assert!(m.topology().is_watertight_oriented(), "{:?}", m.topology());
    for (i, r) in residuals(&mesh, "u", &m.positions, iso).iter().enumerate() {
        assert!(*r <= 1e-6, "vertex {i}: |F − C| = {r}");
    }
}

#[test]
fn gmsh_files_work_through_the_cli_by_extension() {
    let dir = std::env::temp_dir().join(format!("isobar-fe-msh-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = data("gmsh/ball_tet3.msh");
    let run = |method: &str, out: &PathBuf| {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_isobar"))
            .args([
                "fe",
                input.to_str().unwrap(),
                "--field",
                "p",
                "--iso",
                "0.4",
            ])
            .args(["--method", method, "--spacing", "0.08", "--quiet", "-o"])
            .arg(out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).to_string()
    };
    let mesh = isobar::io::read_fe_mesh(&input).unwrap();
    let samples = dir.join("ball.vtp");
    eprintln!("{}", run("samples", &samples));
    let pts = isobar::io::read_particles(&samples).unwrap();
    assert!(pts.positions.len() > 50);
    let p: Vec<[f64; 3]> = pts.positions.iter().map(|q| q.to_array()).collect();
    for r in residuals(&mesh, "p", &p, 0.4) {
        // ε_T, plus the rounding of the .vtp round trip.
        assert!(r <= 1e-6 * (1.0 + 1e-6), "{r}");
    }
    let tris = dir.join("ball.vtp.mc.vtp");
    eprintln!("{}", run("mc", &tris));
    let m = isobar::io::read_mesh(&tris).unwrap();
    assert!(m.vertex_count() > 50);
    assert!(m.topology().is_watertight_oriented(), "{:?}", m.topology());
    for r in residuals(&mesh, "p", &m.positions, 0.4) {
        assert!(r <= 1e-6, "{r}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The particle system on tetrahedra and on wedges (gmsh's third-order tetrahedra of a
/// ball, second-order prisms of a cylinder): every sample within ε_T by an independent
/// evaluation, and every cell the surface cuts holds samples.
#[test]
fn particles_on_tetrahedra_and_wedges_cover_every_cut_cell() {
    for name in ["gmsh/ball_tet3.msh", "gmsh/cylinder_prism2.msh"] {
        let mesh = isobar::io::read_fe_mesh(&data(name)).unwrap();
        let iso = 0.4;
        let params = Params {
            iso,
            spacing: 0.06,
            ..Params::default()
        };
        let (s, stats) = sample(&mesh, "p", &params, &mut Progress::none()).unwrap();
        eprintln!("{name}: {stats:?}");
        assert!(s.len() > 100, "{name}: {stats:?}");
        for (i, r) in residuals(&mesh, "p", &s.positions, iso).iter().enumerate() {
            assert!(
                *r <= params.tolerance * (1.0 + 1e-6),
                "{name} sample {i}: {r}"
            );
        }
        every_cut_cell_holds_samples(&mesh, "p", iso, &s, 5);
    }
}
