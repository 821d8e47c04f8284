//! The adaptive extractor on real SPH frames from ../shared/data (splashsurf's test data
//! and SPlisHSPlasH dam breaks) at splashsurf's field settings (r = 0.025, h = 2r, cubic
//! spline, iso 0.6): every level mix the splash criterion produces must give a closed,
//! oriented mesh whose shared points coincide, equal to itself whatever the thread count.

use isobar::adaptive::grid::CoarseGrid;
use isobar::adaptive::{self, Params};
use isobar::field::kernel::Kernel;
use isobar::field::sph::{Quantity, SmoothingLength, SphField, SphSettings};
use isobar::io;
use isobar::progress::Progress;
use std::path::PathBuf;

const R: f64 = 0.025;

fn field(name: &str) -> SphField {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/splashsurf")
        .join(name);
    let data = io::read_particles(&path).unwrap();
    let s = SphSettings {
        kernel: Kernel::CubicSpline,
        smoothing_length: SmoothingLength::Constant(2.0 * R),
        quantity: Quantity::SumOfWeights,
        ..SphSettings::default()
    };
    SphField::new(&data, &s).unwrap()
}

/// The coarse grid of `params` and uniform marching cubes at its finest level through the
/// adaptive extractor (every cell at level 3): what the adaptive mesh is measured against.
fn uniform_finest(field: &SphField, params: &Params) -> (CoarseGrid, adaptive::Extraction) {
    let grid = adaptive::grid_for(field, params).unwrap();
    let all_finest = vec![3u8; grid.cell_count()];
    let uniform = adaptive::extract(field, &grid, &all_finest, params, &mut Progress::none());
    (grid, uniform.unwrap())
}

#[test]
fn real_frames_are_watertight_at_every_setting() {
    for name in [
        "bunny_frame_14_7705_particles.vtk",
        "cube_2366_particles.vtk",
        "dam_break_frame_9_6859_particles.bgeo",
        "dam_break_frame_23_24389_particles.bgeo",
        "double_dam_break_frame_01_4732_particles.vtk",
        "double_dam_break_frame_26_4732_particles.vtk",
    ] {
        let field = field(name);
        for (grid_factor, threshold, dilation) in [(0.375, 1, 1), (1.0, 1, 0), (1.0, 3, 1)] {
            let params = Params {
                isovalue: 0.6,
                grid_factor,
                splash_threshold: threshold,
                splash_dilation: dilation,
                ..Params::default()
            };
            let out = adaptive::extract_sph(&field, &params, &mut Progress::none()).unwrap();
            let what = format!(
                "{name} grid factor {grid_factor} threshold {threshold} dilation {dilation}: {:?}",
                out.stats
            );
            assert!(out.stats.triangles > 0, "{what}");
            assert_eq!(out.stats.point_mismatches, 0, "{what}");
            let topo = out.mesh.topology();
            assert!(topo.is_watertight_oriented(), "{what}: {topo:?}");
            assert!(out.mesh.signed_volume() > 0.0, "{what}");
            assert_eq!(out.mesh.duplicate_vertices(), 0, "{what}");
        }
    }
}

/// Issue #9's quality target on the splashing frames with the default parameters: the
/// adaptive surface within half a finest cell (Hausdorff) of the uniform finest-level
/// one, with fewer triangles than uniform and than the paper's splash rule gives (the
/// defaults until session 25: threshold 1, dilation 1, max_error 0.4). The hidden-surface
/// rule is independent of max_error (it guards topology, not distance), so max_error 0
/// keeps it; neither max_error 0 nor the rule off is asserted (both only print).
/// Measured 2026-12-05 at the defaults (no splash cells, max_error 0.4), grid factor
/// 0.375 / 0.5: dam_break_23 0.447 / 0.412 fine cells, 2.55 / 2.27x fewer triangles;
/// double_dam_01 0.403 / 0.227, 6.07 / 12.97x; double_dam_26 0.462 / 0.480, 1.44 / 2.27x
/// (0.571 at G 0.5 before face samples were checked against the neighbour's surface)
/// (the paper's rule: 1.34 / 1.64x, 1.23 / 4.10x, 1.09 / 1.70x, all within 0.48).
#[test]
fn default_refinement_stays_within_half_a_fine_cell_of_uniform_finest() {
    let mut failures = Vec::new();
    for name in [
        "dam_break_frame_23_24389_particles.bgeo",
        "double_dam_break_frame_01_4732_particles.vtk",
        "double_dam_break_frame_26_4732_particles.vtk",
    ] {
        let field = field(name);
        for grid_factor in [0.375, 0.5] {
            let params = Params {
                isovalue: 0.6,
                grid_factor,
                ..Params::default()
            };
            let paper = Params {
                splash_threshold: 1,
                splash_dilation: 1,
                max_error: 0.4,
                ..params.clone()
            };
            let paper = adaptive::extract_sph(&field, &paper, &mut Progress::none()).unwrap();
            let (grid, uniform) = uniform_finest(&field, &params);
            for (max_error, hidden_surfaces) in [
                (params.max_error, true),
                (0.0, true),
                (params.max_error, false),
            ] {
                let p = Params {
                    max_error,
                    hidden_surfaces,
                    ..params.clone()
                };
                let out = adaptive::extract_sph(&field, &p, &mut Progress::none()).unwrap();
                let d =
                    isobar::mesh::hausdorff::hausdorff(&out.mesh, &uniform.mesh, 8.0 * grid.fine)
                        / grid.fine;
                let ratio = uniform.stats.triangles as f64 / out.stats.triangles as f64;
                let what = format!(
                    "{name} grid factor {grid_factor} max_error {max_error} hidden {hidden_surfaces}: Hausdorff {d:.3} fine cells, {ratio:.2}x fewer triangles, hidden raised {}",
                    out.stats.hidden_raised
                );
                eprintln!("{what}");
                if !out.mesh.topology().is_watertight_oriented() || ratio <= 1.0 {
                    failures.push(format!("not closed or not fewer: {what}"));
                }
                if max_error > 0.0 && hidden_surfaces && d >= 0.5 {
                    failures.push(format!("default off target: {what}"));
                }
                if max_error > 0.0 && hidden_surfaces && out.stats.triangles > paper.stats.triangles
                {
                    failures.push(format!(
                        "more triangles than the paper's splash rule ({}): {what}",
                        paper.stats.triangles
                    ));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Issue #9's targets where the finest cells are finer than the particle spacing (the
/// paper's own finest grid is finer still): at least 3× fewer triangles than uniform
/// finest marching cubes, within half a finest cell (Hausdorff), the mesh closed. The first two
/// settings caught a level the error criterion had never tested: balancing raised a
/// level-1 cell it passed to level 2 (dam_break_23 at G 0.25: 0.542 finest cells off),
/// and a cell the hidden-surface rule raised was taken as it stood (sailors_knot at
/// G 0.3: 0.516). Measured after the fix: 3.44× / 0.417 and 5.43× / 0.415. The third
/// caught crack triangles the criterion had not sampled (double_dam_break_26 at G 0.25:
/// 0.507 inside one spanning a saddle on a level-2/level-3 face; after: 4.03× / 0.425).
#[test]
fn fine_grids_meet_the_triangle_target_within_half_a_fine_cell() {
    let mut failures = Vec::new();
    for (name, grid_factor) in [
        ("dam_break_frame_23_24389_particles.bgeo", 0.25),
        ("sailors_knot_19539_particles.vtk", 0.3),
        ("double_dam_break_frame_26_4732_particles.vtk", 0.25),
    ] {
        let field = field(name);
        let params = Params {
            isovalue: 0.6,
            grid_factor,
            ..Params::default()
        };
        let (grid, uniform) = uniform_finest(&field, &params);
        let out = adaptive::extract_sph(&field, &params, &mut Progress::none()).unwrap();
        let d = isobar::mesh::hausdorff::hausdorff(&out.mesh, &uniform.mesh, 8.0 * grid.fine)
            / grid.fine;
        let ratio = uniform.stats.triangles as f64 / out.stats.triangles as f64;
        let what = format!(
            "{name} grid factor {grid_factor}: Hausdorff {d:.3} fine cells, {ratio:.2}x fewer triangles"
        );
        eprintln!("{what}");
        if d >= 0.5 || ratio < 3.0 || !out.mesh.topology().is_watertight_oriented() {
            failures.push(what);
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
