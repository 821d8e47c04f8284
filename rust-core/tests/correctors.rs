//! Marching Correctors against properties that fail on a wrong surface.

mod common;

use common::{block, Brute, Lcg};
use glam::DVec3;
use isobar::baseline;
use isobar::correctors::{self, Params, Trim};
use isobar::field::kernel::Kernel;
use isobar::field::particles::{Attribute, ParticleData};
use isobar::field::sph::{Quantity, SmoothingLength, SphField, SphSettings, Volumes};
use isobar::progress::Progress;
use isobar::Error;

fn settings(kernel: Kernel, h: f64, quantity: Quantity) -> SphSettings {
    SphSettings {
        kernel,
        smoothing_length: SmoothingLength::Constant(h),
        quantity,
        ..SphSettings::default()
    }
}

fn run(data: &ParticleData, s: &SphSettings, p: &Params) -> correctors::Extraction {
    let field = SphField::new(data, s).unwrap();
    correctors::extract(&field, data, p, &mut Progress::none()).unwrap()
}

/// Radius where a single particle's field a·V·W(r, h) equals iso, by bisection.
fn sphere_radius(kernel: Kernel, h: f64, amplitude: f64, iso: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, kernel.support_factor() * h);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if amplitude * kernel.value(mid, h) > iso {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[test]
fn one_particle_gives_the_kernel_sphere() {
    for kernel in Kernel::ALL {
        let h = 0.7;
        let centre = DVec3::new(0.3, -1.2, 2.0);
        let data = ParticleData {
            positions: vec![centre],
            attributes: vec![
                Attribute::scalar("a", vec![5.0]),
                Attribute::scalar("vol", vec![2.0]),
            ],
            ..Default::default()
        };
        let s = SphSettings {
            volumes: Volumes::Array("vol".into()),
            ..settings(kernel, h, Quantity::Scalar("a".into()))
        };
        let iso = 0.4 * 5.0 * 2.0 * kernel.value(0.0, h);
        let r = sphere_radius(kernel, h, 10.0, iso);
        let p = Params {
            isovalues: vec![iso],
            trim: None,
            grid_factor: 0.1,
            ..Params::default()
        };
        let out = run(&data, &s, &p);
        let m = &out.mesh;
        assert!(
            m.triangles.len() > 100,
            "{kernel:?}: {} triangles",
            m.triangles.len()
        );
        let tol = 1e-6 * iso;
        for (i, x) in m.positions.iter().enumerate() {
            let d = DVec3::from(*x) - centre;
            let f = 10.0 * kernel.value(d.length(), h);
            assert!(
                (f - iso).abs() <= tol,
                "{kernel:?} vertex {i}: |F - iso| = {}",
                (f - iso).abs()
            );
            assert!(
                (d.length() - r).abs() < 1e-5 * r,
                "{kernel:?}: radius {} vs {r}",
                d.length()
            );
            let n = glam::Vec3::from(m.normals[i]).as_dvec3();
            assert!(
                n.dot(d.normalize()) > 0.99999,
                "{kernel:?}: normal {n:?} not radial"
            );
        }
        let topo = m.topology();
        assert!(topo.is_watertight_oriented(), "{kernel:?}: {topo:?}");
        let exact = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        let v = m.signed_volume();
        // Vertices on the sphere: the polyhedron is inscribed, slightly smaller.
        assert!(
            v < exact && v > 0.98 * exact,
            "{kernel:?}: volume {v} vs {exact}"
        );
        assert_eq!(m.duplicate_vertices(), 0);
        assert_eq!(m.components(), 1);
    }
}

#[test]
fn corrected_vertices_lie_on_the_level_set_by_brute_force() {
    let h = 0.1;
    let data = block(DVec3::ZERO, DVec3::new(0.8, 0.5, 0.4), 0.05, 3);
    let kernel = Kernel::CubicSpline;
    let pressure = data.attribute("pressure").unwrap().data.clone();
    let brute = Brute::new(kernel, h, &data.positions, pressure);
    let s = settings(kernel, h, Quantity::Scalar("pressure".into()));
    let iso = 1500.0;
    let p = Params {
        isovalues: vec![iso],
        ..Params::default()
    };
    let out = run(&data, &s, &p);
    assert!(
        out.mesh.triangles.len() > 200,
        "{} triangles",
        out.mesh.triangles.len()
    );
    let tol = 1e-6 * iso;
    let mut worst = 0.0f64;
    for x in &out.mesh.positions {
        worst = worst.max((brute.eval(DVec3::from(*x)).0 - iso).abs());
    }
    assert!(worst <= tol * 1.01, "max |F - iso| = {worst} > {tol}");
    // Preview places vertices by linear interpolation: measurably off the level set.
    let preview = run(
        &data,
        &s,
        &Params {
            correct: false,
            ..p
        },
    );
    let perr = preview
        .mesh
        .positions
        .iter()
        .map(|x| (brute.eval(DVec3::from(*x)).0 - iso).abs())
        .fold(0.0, f64::max);
    assert!(
        perr > 100.0 * tol,
        "preview error {perr} should exceed the corrected tolerance"
    );
    eprintln!("max |F - iso|: corrected {worst:.3e}, preview {perr:.3e}");
}

#[test]
fn free_surface_is_watertight_oriented_and_encloses_the_fluid() {
    let h = 0.1;
    let lo = DVec3::ZERO;
    let hi = DVec3::new(0.6, 0.4, 0.3);
    let data = block(lo, hi, 0.05, 11);
    let s = settings(Kernel::CubicSpline, h, Quantity::SumOfWeights);
    let p = Params {
        isovalues: vec![0.6],
        trim: None,
        grid_factor: 0.375,
        ..Params::default()
    };
    let out = run(&data, &s, &p);
    let m = &out.mesh;
    let topo = m.topology();
    assert!(topo.is_watertight_oriented(), "{topo:?}");
    assert_eq!(m.components(), 1);
    assert_eq!(m.duplicate_vertices(), 0);
    let box_volume = (hi - lo + 0.05).element_product();
    let v = m.signed_volume();
    assert!(
        v > 0.7 * box_volume && v < 1.5 * box_volume,
        "volume {v} vs block {box_volume}"
    );
    // Normals agree with the winding: they point the way the triangles face.
    let mut agree = 0;
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| DVec3::from(m.positions[i as usize]));
        let f = (b - a).cross(c - a);
        let n: DVec3 = t
            .iter()
            .map(|&i| glam::Vec3::from(m.normals[i as usize]).as_dvec3())
            .sum();
        if f.dot(n) > 0.0 {
            agree += 1;
        }
    }
    assert!(
        agree as f64 > 0.999 * m.triangles.len() as f64,
        "{agree}/{}",
        m.triangles.len()
    );
}

#[test]
fn preview_equals_the_full_grid_baseline() {
    let data = block(DVec3::ZERO, DVec3::new(0.5, 0.3, 0.3), 0.05, 5);
    let s = settings(Kernel::WendlandC2, 0.1, Quantity::Scalar("pressure".into()));
    let p = Params {
        isovalues: vec![800.0, 1600.0],
        correct: false,
        trim: Some(Trim::default()),
        ..Params::default()
    };
    let field = SphField::new(&data, &s).unwrap();
    let mc = correctors::extract(&field, &data, &p, &mut Progress::none()).unwrap();
    let full = baseline::extract(&field, &data, &p, &mut Progress::none()).unwrap();
    assert!(mc.mesh.triangles.len() > 100);
    assert_eq!(mc.mesh.positions, full.mesh.positions);
    assert_eq!(mc.mesh.triangles, full.mesh.triangles);
    assert!(
        mc.stats.node_evaluations < full.stats.node_evaluations / 2,
        "virtual grid evaluated {} nodes, full grid {}",
        mc.stats.node_evaluations,
        full.stats.node_evaluations
    );
}

#[test]
fn trimming_keeps_no_vertex_below_the_vertex_threshold() {
    let data = block(DVec3::ZERO, DVec3::new(0.6, 0.4, 0.4), 0.05, 8);
    let s = settings(
        Kernel::CubicSpline,
        0.1,
        Quantity::Scalar("pressure".into()),
    );
    let trim = Trim {
        node: 0.1,
        vertex: 0.5,
    };
    let iso = 1000.0;
    let out = run(
        &data,
        &s,
        &Params {
            isovalues: vec![iso],
            trim: Some(trim),
            ..Params::default()
        },
    );
    let untrimmed = run(
        &data,
        &s,
        &Params {
            isovalues: vec![iso],
            trim: None,
            ..Params::default()
        },
    );
    let m = &out.mesh;
    assert!(
        out.stats.trim_cut_points > 0,
        "the pressure surface meets the free surface"
    );
    assert!(m.triangles.len() < untrimmed.mesh.triangles.len());
    let pressure = data.attribute("pressure").unwrap().data.clone();
    let brute = Brute::new(Kernel::CubicSpline, 0.1, &data.positions, pressure);
    for x in &m.positions {
        let (f, w) = brute.eval(DVec3::from(*x));
        assert!(
            w >= trim.vertex * (1.0 - 1e-6),
            "vertex with sum of weights {w}"
        );
        assert!(
            (f - iso).abs() <= 1e-6 * iso * 1.01,
            "trimmed vertex off the level set: {}",
            (f - iso).abs()
        );
    }
    let topo = m.topology();
    assert_eq!(topo.nonmanifold_edges, 0);
    assert_eq!(topo.misoriented_edges, 0);
    assert!(
        topo.boundary_edges > 0,
        "trimming opens the surface where it meets the free surface"
    );
}

#[test]
fn every_separated_cluster_gives_a_component() {
    let mut rng = Lcg(99);
    let mut positions = Vec::new();
    let clusters = 40;
    for c in 0..clusters {
        let centre = DVec3::new((c % 8) as f64, (c / 8) as f64, 0.5 * (c % 3) as f64) * 1.5;
        let count = 1 + (rng.next() * 12.0) as usize;
        for _ in 0..count {
            positions.push(centre + (DVec3::new(rng.next(), rng.next(), rng.next()) - 0.5) * 0.15);
        }
    }
    let data = common::with_fields(positions, 0.0);
    let s = settings(Kernel::CubicSpline, 0.1, Quantity::SumOfWeights);
    let out = run(
        &data,
        &s,
        &Params {
            isovalues: vec![0.5],
            trim: None,
            ..Params::default()
        },
    );
    assert_eq!(out.mesh.components(), clusters);
    assert!(out.mesh.topology().is_watertight_oriented());
}

/// Empty cavities inside the fluid (bubbles, 2 h and 1.5 h across the hole) have inner
/// surfaces: no particle pair straddles them and no particle lacks a neighbour on a
/// side, so only the cavity probe of the seed search finds them. The preview surface
/// equals the full-grid baseline's; the corrected one has the same three components.
#[test]
fn cavities_inside_the_fluid_give_inner_surfaces() {
    let (dx, h) = (0.05, 0.05);
    let holes = [
        (DVec3::new(0.3, 0.3, 0.3), 2.0 * h),
        (DVec3::new(0.62, 0.55, 0.5), 1.5 * h),
    ];
    let full = block(DVec3::ZERO, DVec3::splat(0.85), dx, 17);
    let positions: Vec<DVec3> = full
        .positions
        .iter()
        .copied()
        .filter(|p| holes.iter().all(|(c, r)| p.distance(*c) > *r))
        .collect();
    assert!(positions.len() < full.positions.len() - 40);
    let data = common::with_fields(positions, 0.85);
    let s = settings(Kernel::CubicSpline, h, Quantity::SumOfWeights);
    let field = SphField::new(&data, &s).unwrap();
    let preview = Params {
        isovalues: vec![0.6],
        correct: false,
        trim: None,
        ..Params::default()
    };
    let mc = correctors::extract(&field, &data, &preview, &mut Progress::none()).unwrap();
    let grid = baseline::extract(&field, &data, &preview, &mut Progress::none()).unwrap();
    assert_eq!(grid.mesh.components(), 3, "the baseline sees both cavities");
    assert_eq!(mc.mesh.components(), 3, "Marching Correctors' components");
    assert!(
        mc.mesh.positions == grid.mesh.positions && mc.mesh.triangles == grid.mesh.triangles,
        "{} triangles, the baseline {}",
        mc.mesh.triangles.len(),
        grid.mesh.triangles.len()
    );
    let corrected = run(
        &data,
        &s,
        &Params {
            correct: true,
            ..preview
        },
    );
    assert_eq!(corrected.mesh.components(), 3);
    assert!(corrected.mesh.topology().is_watertight_oriented());
}

#[test]
fn output_does_not_depend_on_the_thread_count() {
    let data = block(DVec3::ZERO, DVec3::new(0.6, 0.4, 0.4), 0.05, 21);
    let s = settings(
        Kernel::CubicSpline,
        0.1,
        Quantity::Scalar("pressure".into()),
    );
    let p = Params {
        isovalues: vec![900.0],
        attributes: vec!["velocity".into()],
        ..Params::default()
    };
    let go = |threads| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| run(&data, &s, &p).mesh)
    };
    let (one, four) = (go(1), go(4));
    let bits = |m: &isobar::mesh::Mesh| -> Vec<u64> {
        m.positions
            .iter()
            .flatten()
            .map(|v| v.to_bits())
            .chain(
                m.attributes
                    .iter()
                    .flat_map(|a| a.data.iter().map(|v| v.to_bits())),
            )
            .collect()
    };
    assert_eq!(one.triangles, four.triangles);
    assert_eq!(bits(&one), bits(&four));
    assert_eq!(one.normals, four.normals);
}

#[test]
fn bad_input_gets_a_clear_error() {
    let good = block(DVec3::ZERO, DVec3::splat(0.2), 0.05, 1);
    let s = settings(
        Kernel::CubicSpline,
        0.1,
        Quantity::Scalar("pressure".into()),
    );
    let msg =
        |data: &ParticleData, s: &SphSettings| SphField::new(data, s).unwrap_err().to_string();

    let mut nan = good.clone();
    nan.positions[7].y = f64::NAN;
    assert!(msg(&nan, &s).contains("particle 7"), "{}", msg(&nan, &s));
    let mut inf = good.clone();
    inf.positions[3].x = f64::INFINITY;
    assert!(msg(&inf, &s).contains("particle 3"));

    let empty = ParticleData::default();
    assert!(msg(&empty, &s).contains("empty"));

    let zero_h = SphSettings {
        smoothing_length: SmoothingLength::Constant(0.0),
        ..s.clone()
    };
    assert!(msg(&good, &zero_h).contains("smoothing length"));
    let mut neg = good.clone();
    let n = neg.len();
    neg.attributes.push(Attribute::scalar(
        "h",
        (0..n).map(|i| if i == 5 { -1.0 } else { 0.1 }).collect(),
    ));
    let per_particle = SphSettings {
        smoothing_length: SmoothingLength::Array("h".into()),
        ..s.clone()
    };
    let m = msg(&neg, &per_particle);
    assert!(
        m.contains("particle 5") && m.contains("smoothing length"),
        "{m}"
    );

    let missing = SphSettings {
        quantity: Quantity::Scalar("temperature".into()),
        ..s.clone()
    };
    let m = msg(&good, &missing);
    assert!(m.contains("temperature") && m.contains("pressure"), "{m}");
    let vector = SphSettings {
        quantity: Quantity::Scalar("velocity".into()),
        ..s.clone()
    };
    assert!(msg(&good, &vector).contains("velocity:mag"));

    let field = SphField::new(&good, &s).unwrap();
    // Cells far too small are the grid factor's fault, however small (1e-300 used to be
    // reported as data too far from the lattice origin).
    for grid_factor in [1e-9, 1e-300] {
        let tiny = Params {
            isovalues: vec![1.0],
            grid_factor,
            ..Params::default()
        };
        let err = correctors::extract(&field, &good, &tiny, &mut Progress::none()).unwrap_err();
        assert!(
            matches!(
                err,
                Error::InvalidParameter {
                    name: "grid_factor",
                    ..
                }
            ) && err.to_string().contains("raise the grid factor"),
            "{err}"
        );
    }
    // A lattice whose origin lies too far from the data for integer node indices.
    let far = Params {
        isovalues: vec![1.0],
        lattice: Some(correctors::Lattice {
            origin: DVec3::splat(1e30),
            cell_size: 0.05,
        }),
        ..Params::default()
    };
    let err = correctors::extract(&field, &good, &far, &mut Progress::none()).unwrap_err();
    assert!(
        matches!(
            err,
            Error::InvalidParameter {
                name: "lattice origin",
                ..
            }
        ),
        "{err}"
    );
    let err = baseline::extract(
        &field,
        &good,
        &Params {
            isovalues: vec![1.0],
            grid_factor: 0.01,
            memory_budget: 1 << 20,
            ..Params::default()
        },
        &mut Progress::none(),
    )
    .unwrap_err();
    assert!(matches!(err, Error::OverBudget { .. }), "{err}");
    // Marching Correctors stores no grid, but a surface far too fine for the budget is
    // refused before it is tracked: counted on a coarse grid, with the grid factor that fits.
    let fine = |grid_factor: f64| Params {
        isovalues: vec![500.0],
        grid_factor,
        memory_budget: 1 << 20,
        ..Params::default()
    };
    for grid_factor in [0.01, 1e-4, 1e-5] {
        let err = correctors::extract(&field, &good, &fine(grid_factor), &mut Progress::none())
            .unwrap_err();
        assert!(
            matches!(err, Error::OverBudget { needed_bytes, .. } if needed_bytes > 1 << 20)
                && err.to_string().contains("a grid factor of at least"),
            "{err}"
        );
    }
    // Where the estimate counts low (features the coarse grid misses), the seed list and
    // tracking refuse on their own. Far finer than the particles, each pair's segment
    // crosses thousands of cells: the seed list is refused as it passes the budget (it
    // used to grow to gigabytes first).
    let seeds_of = |p: &Params| {
        let grid = correctors::virtual_grid(&field, p)?;
        let search = correctors::seeds::SeedSearch::new(&field, p.memory_budget)?;
        correctors::seeds::seed_cells(&field, &grid, 500.0, &search).map(|s| (grid, s))
    };
    let err = seeds_of(&fine(1e-4)).unwrap_err();
    assert!(
        matches!(err, Error::OverBudget { .. }) && err.to_string().contains("seed cells"),
        "{err}"
    );
    // Between the two, the seeds fit but their eight corners each do not: the first wave
    // is refused before its bricks are allocated (it used to take gigabytes of node
    // cache before the check after the wave).
    let p = fine(0.008);
    let (grid, seeds) = seeds_of(&p).unwrap();
    let index = correctors::tracking::index_bytes(p.memory_budget);
    let mut cache = correctors::cache::NodeCache::for_grid(&field, &grid, index);
    let err = correctors::tracking::track(
        &field,
        &grid,
        seeds,
        500.0,
        &p,
        &mut cache,
        &mut Progress::none(),
    )
    .unwrap_err();
    assert!(
        matches!(err, Error::OverBudget { needed_bytes, .. } if needed_bytes > 1 << 20)
            && err.to_string().contains("0 cells found so far"),
        "{err}"
    );
    let none = Params::default();
    assert!(
        correctors::extract(&field, &good, &none, &mut Progress::none())
            .unwrap_err()
            .to_string()
            .contains("isovalue")
    );
    let attr = Params {
        isovalues: vec![1.0],
        attributes: vec!["vorticity".into()],
        ..Params::default()
    };
    assert!(
        correctors::extract(&field, &good, &attr, &mut Progress::none())
            .unwrap_err()
            .to_string()
            .contains("vorticity")
    );
    // A NaN in an array carried onto the surface is refused naming the array and the
    // particle (it reached the vertices near that particle without a word); the same
    // array left uncarried does not stop the extraction.
    let mut nan_velocity = good.clone();
    let n = nan_velocity.len();
    nan_velocity.attributes.push(Attribute {
        name: "flow".into(),
        components: 3,
        data: (0..3 * n)
            .map(|k| if k == 3 * 9 + 1 { f64::NAN } else { 1.0 })
            .collect(),
    });
    let carried = Params {
        isovalues: vec![1.0],
        attributes: vec!["flow".into()],
        ..Params::default()
    };
    let err = correctors::extract(&field, &nan_velocity, &carried, &mut Progress::none())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("array 'flow'") && err.contains("particle 9") && err.contains("NaN"),
        "{err}"
    );
    let uncarried = Params {
        attributes: vec![],
        ..carried
    };
    correctors::extract(&field, &nan_velocity, &uncarried, &mut Progress::none()).unwrap();
}

/// The least budget in 0..2^30 bytes with which `run` is not refused as over budget, by
/// bisection (any other error fails the test).
fn least_budget<T>(run: impl Fn(u64) -> Result<T, Error>) -> u64 {
    let (mut lo, mut hi) = (0u64, 1u64 << 30);
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        match run(mid) {
            Ok(_) => hi = mid,
            Err(Error::OverBudget { .. }) => lo = mid,
            Err(e) => panic!("{e}"),
        }
    }
    hi
}

/// The surfaces of earlier isovalues stay in memory while later ones are tracked: they
/// count against the budget (a thousand isovalues used to take any amount of memory).
#[test]
fn earlier_isovalues_surfaces_count_against_the_budget() {
    let data = block(DVec3::ZERO, DVec3::new(0.6, 0.4, 0.3), 0.05, 5);
    let s = settings(Kernel::CubicSpline, 0.1, Quantity::SumOfWeights);
    let field = SphField::new(&data, &s).unwrap();
    let params = |isovalues: Vec<f64>, memory_budget: u64| Params {
        isovalues,
        grid_factor: 0.375,
        memory_budget,
        ..Params::default()
    };
    let extract = |isovalues: Vec<f64>, memory_budget: u64| {
        let p = params(isovalues, memory_budget);
        correctors::extract(&field, &data, &p, &mut Progress::none())
    };
    let one = least_budget(|b| extract(vec![0.6], b));
    // The same surface twice tracks through nodes the cache already holds: all the second
    // needs on top of the first's budget is room for the first's mesh.
    let twice = extract(vec![0.6, 0.6], 1 << 30).unwrap();
    let first = twice.mesh.heap_bytes() / 2;
    assert!(first > 0);
    let err = extract(vec![0.6, 0.6], one).unwrap_err();
    match &err {
        Error::OverBudget {
            needed_bytes,
            budget_bytes,
            ..
        } => {
            assert_eq!(*budget_bytes, one, "{err}");
            assert!(*needed_bytes > one, "{err}");
            assert!(err.to_string().contains("earlier isovalues"), "{err}");
        }
        _ => panic!("{err}"),
    }
    let fits = extract(vec![0.6, 0.6], one + first).unwrap();
    assert_eq!(fits.mesh.triangles, twice.mesh.triangles);

    // The full-grid baseline holds its grid and the surfaces so far.
    let grid_only = |isovalues: Vec<f64>, memory_budget: u64| {
        let p = params(isovalues, memory_budget);
        baseline::extract(&field, &data, &p, &mut Progress::none())
    };
    let hi = least_budget(|b| grid_only(vec![0.6], b));
    let err = grid_only(vec![0.6, 0.6], hi).unwrap_err();
    assert!(err.to_string().contains("surfaces of 1 isovalues"), "{err}");
    assert!(grid_only(vec![0.6, 0.6], hi + first).is_ok());
}

/// A grid far finer than the particles is refused before any of it is tracked, naming a
/// grid factor that fits: the estimate, counted on a coarse grid, neither refuses a
/// surface that fits nor asks for a factor far coarser than needed.
#[test]
fn a_surface_too_fine_for_the_budget_is_refused_up_front_naming_a_factor_that_fits() {
    let data = block(DVec3::ZERO, DVec3::new(0.6, 0.4, 0.3), 0.05, 5);
    let s = settings(Kernel::CubicSpline, 0.1, Quantity::SumOfWeights);
    let field = SphField::new(&data, &s).unwrap();
    let budget = 16 << 20;
    let extract = |grid_factor: f64, memory_budget: u64, progress: &mut Progress| {
        let p = Params {
            isovalues: vec![0.6],
            grid_factor,
            memory_budget,
            ..Params::default()
        };
        correctors::extract(&field, &data, &p, progress)
    };
    let mut phases: Vec<String> = Vec::new();
    let mut cb = |_f: f64, phase: &str| {
        if phases.last().map(String::as_str) != Some(phase) {
            phases.push(phase.to_string());
        }
        true
    };
    let err = extract(0.001, budget, &mut Progress::new(&mut cb)).unwrap_err();
    let text = err.to_string();
    assert!(matches!(err, Error::OverBudget { .. }), "{text}");
    assert!(
        !phases.iter().any(|p| p == "surface tracking"),
        "{phases:?}"
    );
    let suggested: f64 = text
        .split("a grid factor of at least ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|g| g.parse().ok())
        .unwrap_or_else(|| panic!("no grid factor in: {text}"));
    assert!(suggested > 0.001 && suggested < 0.5, "{text}");
    // At the named factor the whole extraction fits, with no more than a few times the
    // memory it needs (the estimate leaves half the budget to what it does not count).
    let needs = least_budget(|b| extract(suggested, b, &mut Progress::none()));
    assert!(
        needs <= budget && needs > budget / 8,
        "{needs} of {budget}: {text}"
    );
    // Finer than that by half, four times the cells: refused, by the estimate or tracking.
    assert!(matches!(
        extract(suggested / 2.0, budget, &mut Progress::none()),
        Err(Error::OverBudget { .. })
    ));
}

#[test]
fn cancel_stops_the_extraction() {
    let data = block(DVec3::ZERO, DVec3::splat(0.3), 0.05, 2);
    let s = settings(Kernel::CubicSpline, 0.1, Quantity::SumOfWeights);
    let field = SphField::new(&data, &s).unwrap();
    let mut calls = 0;
    let mut cb = |_f: f64, _phase: &str| {
        calls += 1;
        calls < 3
    };
    let mut progress = Progress::new(&mut cb);
    let err = correctors::extract(
        &field,
        &data,
        &Params {
            isovalues: vec![0.5],
            ..Params::default()
        },
        &mut progress,
    )
    .unwrap_err();
    assert!(matches!(err, Error::Cancelled));
}

/// Seeds are windows around the linear estimate of each crossing; a lone particle is
/// the case where the kernel is least linear. It must be found at every isovalue and
/// every grid resolution, with every kernel.
#[test]
fn lone_particle_is_found_at_every_isovalue() {
    for kernel in Kernel::ALL {
        let data = ParticleData {
            positions: vec![DVec3::new(0.1, 0.2, 0.3)],
            attributes: vec![Attribute::scalar("a", vec![1.0])],
            ..Default::default()
        };
        let s = SphSettings {
            volumes: Volumes::Computed { mass: None },
            ..settings(kernel, 0.5, Quantity::Scalar("a".into()))
        };
        // With a computed volume the peak is exactly 1 (V = 1/W(0)).
        for fraction in [0.02, 0.1, 0.25, 0.5, 0.8, 0.97] {
            for grid_factor in [0.05, 0.2, 0.5, 1.0] {
                let p = Params {
                    isovalues: vec![fraction],
                    trim: None,
                    grid_factor,
                    ..Params::default()
                };
                let m = run(&data, &s, &p).mesh;
                assert_eq!(
                    m.components(),
                    1,
                    "{kernel:?} iso {fraction} grid factor {grid_factor}: {} triangles",
                    m.triangles.len()
                );
            }
        }
    }
}

/// What is not an error but still wrong-looking reaches the caller in the stats, for every
/// host to show: an isovalue the field never crosses, and a kernel wider than the whole
/// particle set (h in other units than the positions). Neither appears on sound input.
#[test]
fn warnings_name_an_isovalue_never_crossed_and_a_kernel_wider_than_the_data() {
    let data = block(DVec3::ZERO, DVec3::ONE, 0.2, 7);
    assert!(data.len() >= 100, "{} particles", data.len());
    let pressure = settings(
        Kernel::CubicSpline,
        0.3,
        Quantity::Scalar("pressure".into()),
    );
    let crossed = Params {
        isovalues: vec![2000.0],
        trim: None,
        ..Params::default()
    };
    let sound = run(&data, &pressure, &crossed);
    assert!(!sound.mesh.triangles.is_empty());
    assert_eq!(sound.stats.warnings, Vec::<String>::new());

    let beyond = Params {
        isovalues: vec![2000.0, 1e12],
        ..crossed.clone()
    };
    let one_empty = run(&data, &pressure, &beyond);
    assert_eq!(one_empty.mesh.triangles.len(), sound.mesh.triangles.len());
    assert_eq!(
        one_empty.stats.warnings,
        ["no surface at isovalue 1000000000000: the field never crosses it"]
    );

    // Trimming that cuts every crossed cell away: the field does cross the isovalue, and
    // the warning says what removed the surface instead of blaming the field.
    let all_trimmed = Params {
        trim: Some(Trim {
            node: 5.0,
            vertex: 5.0,
        }),
        ..crossed.clone()
    };
    // Cells far larger than the particle block: the particles' values straddle the
    // isovalue (seed cells), no cell's corners do. The warning names the grid; it said the
    // field never crosses the isovalue.
    let coarse = Params {
        grid_factor: 20.0,
        ..crossed.clone()
    };
    let blurred = run(&data, &pressure, &coarse);
    assert!(blurred.mesh.triangles.is_empty() && blurred.stats.seed_cells > 0);
    let [warning] = &blurred.stats.warnings[..] else {
        panic!("{:?}", blurred.stats.warnings)
    };
    assert!(
        warning.starts_with("no surface at isovalue 2000 on cells of 6.000e0:")
            && warning.ends_with("try a lower grid factor"),
        "{warning}"
    );

    let trimmed = run(&data, &pressure, &all_trimmed);
    assert!(trimmed.mesh.triangles.is_empty() && trimmed.stats.discarded_cells > 0);
    let [cut_away] = &trimmed.stats.warnings[..] else {
        panic!("{:?}", trimmed.stats.warnings)
    };
    assert_eq!(
        *cut_away,
        format!(
            "no surface at isovalue 2000 after trimming and clipping: the field crosses it in \
             {} cells, all cut away by the trim thresholds or the clip box",
            trimmed.stats.discarded_cells
        )
    );

    let wide = settings(Kernel::CubicSpline, 2.0, Quantity::SumOfWeights);
    let field = SphField::new(&data, &wide).unwrap();
    let [warning] = field.warnings() else {
        panic!("{:?}", field.warnings())
    };
    assert!(
        warning.contains("kernel support (4.0000, from h = 2) is wider than the particles' extent"),
        "{warning}"
    );
    let blob = run(&data, &wide, &crossed);
    assert_eq!(blob.stats.warnings[0], *warning);
    let full_grid = baseline::extract(&field, &data, &crossed, &mut Progress::none()).unwrap();
    assert_eq!(full_grid.stats.warnings, blob.stats.warnings);
    let adaptive = isobar::adaptive::extract_sph(
        &field,
        &isobar::adaptive::Params {
            isovalue: 1e12,
            ..isobar::adaptive::Params::default()
        },
        &mut Progress::none(),
    )
    .unwrap();
    assert_eq!(
        adaptive.stats.warnings,
        [
            warning.clone(),
            "no surface at isovalue 1000000000000: the field never crosses it".into()
        ]
    );
}
