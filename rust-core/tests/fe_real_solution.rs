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

/// A cell the isosurface cuts: the fraction of its reference lattice points on the side of
/// `iso` that holds fewer of them, and those points' world positions.
struct Cut {
    cell: usize,
    minority: f64,
    minority_points: Vec<DVec3>,
}

/// Cells whose field crosses `iso` at some point of a reference lattice.
fn cut_cells(mesh: &FeMesh, values: &[f64], iso: f64) -> Vec<Cut> {
    let mut scratch = Scratch::default();
    (0..mesh.cell_count())
        .filter_map(|c| {
            let kind = mesh.shape(c).kind;
            let n = 8;
            let (mut above, mut below) = (Vec::new(), Vec::new());
            let mut total = 0;
            for i in 0..=n {
                for j in 0..=n {
                    for k in 0..=n {
                        let u = DVec3::new(i as f64, j as f64, k as f64) / n as f64;
                        let (d, nf) = kind.face_distances(u);
                        if d[..nf].iter().any(|&d| d < 0.0) {
                            continue;
                        }
                        total += 1;
                        let f = mesh.value(values, c, u, &mut scratch) - iso;
                        if f > 1e-9 {
                            above.push(u);
                        } else if f < -1e-9 {
                            below.push(u);
                        }
                    }
                }
            }
            if above.is_empty() || below.is_empty() {
                return None;
            }
            let fewer = if above.len() < below.len() {
                above
            } else {
                below
            };
            Some(Cut {
                cell: c,
                minority: fewer.len() as f64 / total as f64,
                minority_points: fewer
                    .iter()
                    .map(|&u| mesh.map(c, u, &mut scratch).0)
                    .collect(),
            })
        })
        .collect()
}

/// Asserts that more than `min_cut` cells are cut by the isosurface and each holds a sample.
/// With `sliver` > 0, a cell with less than that fraction of its lattice on one side (the
/// surface only clips a corner or an edge, a patch far smaller than the spacing) may hold
/// none, if a sample lies within `spacing` of that clipped part: the neighbouring cells'
/// samples cover it. At most a tenth of the cut cells may be such slivers.
fn every_cut_cell_holds_samples(
    mesh: &FeMesh,
    field: &str,
    iso: f64,
    s: &isobar::samples::PointSamples,
    min_cut: usize,
    sliver: f64,
    spacing: f64,
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
    let cells: Vec<usize> = cut.iter().map(|c| c.cell).collect();
    assert!(cut.len() > min_cut, "{}: {cells:?}", mesh.name());
    let mut slivers = 0;
    for c in &cut {
        if held.contains(&c.cell) {
            continue;
        }
        let near = s.positions.iter().any(|&p| {
            let p = DVec3::from(p);
            c.minority_points.iter().any(|q| q.distance(p) <= spacing)
        });
        assert!(
            c.minority < sliver && near,
            "{}: cell {} is cut ({:.2} % of its lattice on the smaller side) but holds no \
             sample{}",
            mesh.name(),
            c.cell,
            100.0 * c.minority,
            if near { "" } else { " and none is near" }
        );
        slivers += 1;
    }
    eprintln!(
        "{}: {} cut cells, {slivers} slivers without a sample of their own",
        mesh.name(),
        cut.len()
    );
    assert!(
        10 * slivers <= cut.len(),
        "{}: {slivers} slivers",
        mesh.name()
    );
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
    every_cut_cell_holds_samples(&mesh, "u", iso, &s, 8, 0.0, 0.0);

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

/// `isobar fe` on gmsh files (third-order tetrahedra of a ball, third-order hexahedra of a
/// cylinder, gmsh type 92), both methods: every sample and vertex within ε_T by the
/// independent evaluation.
#[test]
fn gmsh_files_work_through_the_cli_by_extension() {
    let dir = std::env::temp_dir().join(format!("isobar-fe-msh-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // The ball's surface is closed; the cylinder's meets the bottom face (p grows with z
    // there), so its triangles have a boundary but must still be manifold and oriented.
    for (stem, iso, spacing, min_samples, closed) in [
        ("ball_tet3", 0.4, "0.08", 50, true),
        ("cylinder_hex3", 0.7, "0.06", 300, false),
    ] {
        let input = data(&format!("gmsh/{stem}.msh"));
        let run = |method: &str, out: &PathBuf| {
            let o = std::process::Command::new(env!("CARGO_BIN_EXE_isobar"))
                .args(["fe", input.to_str().unwrap(), "--field", "p"])
                .args(["--iso", &iso.to_string(), "--method", method])
                .args(["--spacing", spacing, "--quiet", "-o"])
                .arg(out)
                .output()
                .unwrap();
            assert!(
                o.status.success(),
                "{stem}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
            String::from_utf8_lossy(&o.stdout).to_string()
        };
        let mesh = isobar::io::read_fe_mesh(&input).unwrap();
        let samples = dir.join(format!("{stem}.vtp"));
        eprintln!("{stem}: {}", run("samples", &samples));
        let pts = isobar::io::read_particles(&samples).unwrap();
        assert!(pts.positions.len() > min_samples, "{stem}");
        let p: Vec<[f64; 3]> = pts.positions.iter().map(|q| q.to_array()).collect();
        for r in residuals(&mesh, "p", &p, iso) {
            // ε_T, plus the rounding of the .vtp round trip.
            assert!(r <= 1e-6 * (1.0 + 1e-6), "{stem}: {r}");
        }
        let tris = dir.join(format!("{stem}.mc.vtp"));
        eprintln!("{stem}: {}", run("mc", &tris));
        let m = isobar::io::read_mesh(&tris).unwrap();
        assert!(m.vertex_count() > min_samples, "{stem}");
        let t = m.topology();
        if closed {
            assert!(t.is_watertight_oriented(), "{stem}: {t:?}");
        } else {
            let faults = (
                t.nonmanifold_edges,
                t.misoriented_edges,
                t.degenerate_triangles,
            );
            assert!(faults == (0, 0, 0) && t.boundary_edges > 0, "{stem}: {t:?}");
        }
        for r in residuals(&mesh, "p", &m.positions, iso) {
            assert!(r <= 1e-6, "{stem}: {r}");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The particle system on gmsh's tetrahedra, hexahedra and wedges (third-order tetrahedra
/// of a ball, third-order hexahedra and second-order prisms of a cylinder): every sample
/// within ε_T by an independent evaluation, and every cell the surface cuts holds samples.
/// On the cubic cylinder the surface meets the bottom face and clips corners of a few
/// cells by less than 1 % of their volume (cell 66: p exceeds 0.4 by at most 0.007, at
/// one corner); those only need a sample nearby.
#[test]
fn particles_on_gmsh_tetrahedra_hexahedra_and_wedges_cover_every_cut_cell() {
    for (name, sliver) in [
        ("gmsh/ball_tet3.msh", 0.0),
        ("gmsh/cylinder_hex3.msh", 0.01),
        ("gmsh/cylinder_prism2.msh", 0.0),
    ] {
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
        every_cut_cell_holds_samples(&mesh, "p", iso, &s, 5, sliver, params.spacing);
    }
}
