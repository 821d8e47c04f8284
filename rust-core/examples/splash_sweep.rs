//! Splash-rule sweep for issue #9 (session 10): on one SPH frame (splashsurf's settings:
//! cubic spline, h = 0.05, sum of weights, iso 0.6) and one grid factor, the uniform
//! finest mesh once, then for each rule spec the levels it gives (splash cells, dilation,
//! error criterion, balancing), the adaptive mesh, triangles uniform / adaptive and the
//! symmetric Hausdorff distance in finest cells. Rules are prototyped here, outside the
//! library, so they can be compared before one is adopted.
//!
//! Specs (the last two fields are always `DILATION:MAX_ERROR`):
//! - `paper:T:D:E`   the library's rule: a cell holding 1..=T particles;
//! - `nbr:N:D:E`     a cell holding particles whose 3×3×3 block holds at most N;
//! - `nbr0:N:D:E`    a cell whose 3×3×3 block holds 1..=N particles (empty cells too);
//! - `pn:N:F:D:E`    a cell holding a particle with at most N particles (itself
//!   included) within F × the kernel support;
//! - `vanish:S:D:E`  a cell holding particles none of whose nodes of spacing S finest
//!   cells (2: level 2, 4: level 1) lies above the isovalue.
//!
//! Every spec then gets the hidden-surface rule as the library applies it (`NO_HIDDEN=1`
//! leaves it out) and the error criterion. `DIAG=1` prints the six worst sample points
//! each way (vertices, edge midpoints, centroids, as the Hausdorff distance samples them)
//! with their cell's level, particle count and 3×3×3 block count; `DIAG=2` adds the point
//! in finest cells from the cell's first node, F and |∇F| (per finest cell) there, and
//! F − iso on the cell's 5³ finest lattice.
//!
//! `cargo run --release -p isobar --example splash_sweep -- FRAME G SPEC...`
use glam::{DVec3, IVec3};
use isobar::adaptive::{self, grid, refine, Params};
use isobar::field::kernel::Kernel;
use isobar::field::sph::{Quantity, SmoothingLength, SphField, SphSettings};
use isobar::field::ScalarField;
use isobar::io;
use isobar::mesh::Mesh;
use isobar::progress::Progress;
use std::collections::HashMap;
use std::time::Instant;

const ISO: f64 = 0.6;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 4 {
        eprintln!("usage: splash_sweep FRAME GRID_FACTOR SPEC...");
        std::process::exit(2);
    }
    let path = &args[1];
    let gf: f64 = args[2].parse().expect("grid factor");
    let data = io::read_particles(std::path::Path::new(path)).expect("frame");
    let settings = SphSettings {
        kernel: Kernel::CubicSpline,
        smoothing_length: SmoothingLength::Constant(0.05),
        quantity: Quantity::SumOfWeights,
        ..SphSettings::default()
    };
    let field = SphField::new(&data, &settings).expect("field");
    let params = Params {
        isovalue: ISO,
        grid_factor: gf,
        ..Params::default()
    };
    let g = adaptive::grid_for(&field, &params).expect("grid");
    let all3 = vec![3u8; g.cell_count()];
    let uniform =
        adaptive::extract(&field, &g, &all3, &params, &mut Progress::none()).expect("uniform");
    let positions: Vec<DVec3> = (0..field.len()).map(|i| field.position(i)).collect();
    let counts = grid::register(&g, &positions).expect("registration");
    let block = |i: usize| -> u32 { g.block(i).map(|n| counts[n]).sum() };
    let arg = |p: &[&str], i: usize| -> f64 { p[i].parse().expect("number in spec") };
    for spec in &args[3..] {
        let p: Vec<&str> = spec.split(':').collect();
        let t = Instant::now();
        let cells = 0..counts.len();
        let mut levels: Vec<u8> = match p[0] {
            "paper" => grid::split(&counts, arg(&p, 1) as u32),
            "nbr" => cells
                .map(|i| level(counts[i] >= 1 && block(i) as f64 <= arg(&p, 1)))
                .collect(),
            "nbr0" => cells
                .map(|i| level(block(i) >= 1 && block(i) as f64 <= arg(&p, 1)))
                .collect(),
            "pn" => {
                let r = arg(&p, 2) * field.max_support();
                let neighbours = neighbour_counts(&positions, r);
                let mut l = vec![1u8; counts.len()];
                for (x, &m) in positions.iter().zip(&neighbours) {
                    if m as f64 <= arg(&p, 1) {
                        l[g.cell_of(*x).expect("inside")] = 3;
                    }
                }
                l
            }
            "vanish" => {
                let step = arg(&p, 1) as i64;
                let m = 4 / step + 1;
                cells
                    .map(|i| {
                        let c = g.coords(i);
                        let seen = (0..m * m * m).any(|v| {
                            let l = [v % m, v / m % m, v / (m * m)];
                            let sub: [i64; 3] =
                                std::array::from_fn(|a| c[a] as i64 * 4 + l[a] * step);
                            field.value(g.point(sub, 0)) > ISO
                        });
                        level(counts[i] >= 1 && !seen)
                    })
                    .collect()
            }
            other => panic!("unknown rule {other}"),
        };
        let dilation = arg(&p, p.len() - 2) as u32;
        let max_error = arg(&p, p.len() - 1);
        let splash = levels.iter().filter(|&&l| l == 3).count();
        grid::dilate(&g, &mut levels, dilation, &mut Progress::none()).expect("dilate");
        let mut lattice = adaptive::lattice::Lattice::new(&g);
        lattice
            .cover_corners(&field, &g, u64::MAX, &mut Progress::none())
            .expect("corners");
        if std::env::var("NO_HIDDEN").is_err() {
            refine::hidden_surfaces(&field, &g, &lattice, &positions, &mut levels, ISO);
        }
        let mut r = refine::refine(
            &field,
            &g,
            &counts,
            &mut levels,
            ISO,
            max_error,
            &mut lattice,
            u64::MAX,
            &mut Progress::none(),
        )
        .expect("refine");
        // Cells balancing raised to a level off by more than max_error, and cells whose
        // cracks are off, count as raised (as in the library's stats).
        let balanced = refine::balance_within(
            &g,
            &lattice,
            &mut levels,
            ISO,
            max_error,
            &mut Progress::none(),
        )
        .expect("balance");
        r.raised[0] += balanced[0];
        r.raised[1] += balanced[1];
        let levels_s = t.elapsed().as_secs_f64();
        let out = adaptive::extract(&field, &g, &levels, &params, &mut Progress::none())
            .expect("adaptive");
        let d = isobar::mesh::hausdorff::hausdorff(&out.mesh, &uniform.mesh, 8.0 * g.fine) / g.fine;
        let ratio = uniform.stats.triangles as f64 / out.stats.triangles as f64;
        if std::env::var("DIAG").is_ok() {
            for (name, a, b) in [
                ("adaptive->uniform", &out.mesh, &uniform.mesh),
                ("uniform->adaptive", &uniform.mesh, &out.mesh),
            ] {
                for (dist, pt) in worst(a, b, 8.0 * g.fine) {
                    let Some(i) = g.cell_of(pt) else { continue };
                    println!(
                        "  {name} {:.3} at cell {:?} level {} count {} block {}",
                        dist / g.fine,
                        g.coords(i),
                        levels[i],
                        counts[i],
                        block(i)
                    );
                    if std::env::var("DIAG").as_deref() == Ok("2") {
                        let c = g.coords(i);
                        let base = c.map(|x| x as i64 * 4);
                        let o = g.point(base, 0);
                        let (f, gr) = field.value_and_gradient(pt);
                        println!(
                            "    at {:.2?} fine, F {f:.4} |grad| {:.4}",
                            ((pt - o) / g.fine).to_array(),
                            gr.length() * g.fine
                        );
                        for z in 0..5i64 {
                            let mut line = String::new();
                            for y in 0..5i64 {
                                for x in 0..5i64 {
                                    let v = field
                                        .value(g.point([base[0] + x, base[1] + y, base[2] + z], 0));
                                    line += &format!("{:+.3} ", v - ISO);
                                }
                                line += "| ";
                            }
                            println!("    z{z}: {line}");
                        }
                    }
                }
            }
        }
        let mut per = [0; 3];
        for &l in &levels {
            per[l as usize - 1] += 1;
        }
        println!(
            "{path} G{gf} {spec}: ratio {ratio:.2} H {d:.3} splash {splash} levels {per:?} raised {:?} watertight {} levels_s {levels_s:.2}",
            r.raised,
            out.mesh.topology().is_watertight_oriented()
        );
    }
}

fn level(splash: bool) -> u8 {
    if splash {
        3
    } else {
        1
    }
}

/// Particles (each itself included) within `r` of each particle.
fn neighbour_counts(positions: &[DVec3], r: f64) -> Vec<usize> {
    let key = |x: DVec3| (x / r).floor().as_ivec3();
    let mut hash: HashMap<IVec3, Vec<usize>> = HashMap::new();
    for (i, &x) in positions.iter().enumerate() {
        hash.entry(key(x)).or_default().push(i);
    }
    positions
        .iter()
        .map(|&x| {
            (0..27)
                .filter_map(|d| {
                    hash.get(&(key(x) + IVec3::new(d % 3 - 1, d / 3 % 3 - 1, d / 9 - 1)))
                })
                .flatten()
                .filter(|&&j| positions[j].distance(x) < r)
                .count()
        })
        .collect()
}

/// The six worst samples of `from` (vertices, edge midpoints, centroids, as the Hausdorff
/// distance samples them) (at least `bucket` apart) by distance to `to`.
fn worst(from: &Mesh, to: &Mesh, bucket: f64) -> Vec<(f64, DVec3)> {
    let pos = |m: &Mesh, i: u32| DVec3::from(m.positions[i as usize]);
    let key = |p: DVec3| (p / bucket).floor().as_ivec3();
    let mut buckets: HashMap<IVec3, Vec<usize>> = HashMap::new();
    for (t, tri) in to.triangles.iter().enumerate() {
        let [a, b, c] = tri.map(|i| pos(to, i));
        let (lo, hi) = (key(a.min(b).min(c)), key(a.max(b).max(c)));
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    buckets.entry(IVec3::new(x, y, z)).or_default().push(t);
                }
            }
        }
    }
    let samples: Vec<DVec3> = from
        .triangles
        .iter()
        .flat_map(|t| {
            let [a, b, c] = t.map(|i| pos(from, i));
            [a, (a + b) / 2.0, (a + b + c) / 3.0]
        })
        .collect();
    let mut v: Vec<(f64, DVec3)> = samples
        .into_iter()
        .map(|p| {
            let best = (0..27)
                .filter_map(|d| {
                    buckets.get(&(key(p) + IVec3::new(d % 3 - 1, d / 3 % 3 - 1, d / 9 - 1)))
                })
                .flatten()
                .map(|&t| {
                    let [a, b, c] = to.triangles[t].map(|i| pos(to, i));
                    isobar::mesh::hausdorff::point_triangle(p, a, b, c)
                })
                .fold(f64::INFINITY, f64::min);
            (best, p)
        })
        .collect();
    v.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut out: Vec<(f64, DVec3)> = Vec::new();
    for x in v {
        if out.iter().all(|y| y.1.distance(x.1) > bucket) {
            out.push(x);
        }
        if out.len() == 6 {
            break;
        }
    }
    out
}
