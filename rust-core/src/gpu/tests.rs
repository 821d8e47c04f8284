//! GPU against CPU. Without an adapter these tests FAIL, unless `ISOBAR_GPU_TESTS=skip`
//! is set: CI must not pass by skipping (it installs lavapipe, `mesa-vulkan-drivers`).
//!
//! Tolerance rule. The kernels evaluate the field in f32, the CPU in f64; their values
//! agree to a relative ~1e-6. Every sign test at a finest node takes the CPU's side
//! (`gpu::sides`), so cases, cut edges, the finest edge each point lies on, triangles
//! and crack fills are compared exactly; node values within 1e-5 of the largest and
//! positions within 1e-5 of the grid's extent (bisection steps between finest nodes keep
//! their f32 side and move a point within its last interval).

use super::device;
use super::level::{build_level, scan};
use super::sides::Sides;
use super::sph::GpuField;
use crate::adaptive::grid::{self, CoarseGrid};
use crate::adaptive::lattice::Lattice;
use crate::adaptive::levels::{self, LevelArrays};
use crate::adaptive::{self, grid_for, Params};
use crate::field::kernel::Kernel;
use crate::field::particles::ParticleData;
use crate::field::sph::{SmoothingLength, SphField, SphSettings};
use crate::field::ScalarField;
use crate::gpu::Backend;
use crate::progress::Progress;
use glam::DVec3;
use std::collections::HashSet;

const TOL: f64 = 1e-5;

/// The device, or None when `ISOBAR_GPU_TESTS=skip` and there is none; otherwise a
/// missing adapter fails the test.
fn gpu() -> Option<&'static device::Gpu> {
    match device::get() {
        Ok(g) => Some(g),
        Err(e) if std::env::var("ISOBAR_GPU_TESTS").as_deref() == Ok("skip") => {
            eprintln!("skipped (ISOBAR_GPU_TESTS=skip): {e}");
            None
        }
        Err(e) => panic!("{e}; install mesa-vulkan-drivers or set ISOBAR_GPU_TESTS=skip"),
    }
}

/// `Auto` picks the adapter exactly when it is hardware, and otherwise says why not.
#[test]
fn auto_falls_back_from_a_software_adapter_and_says_why() {
    let Some(g) = gpu() else { return };
    let why = super::auto_fallback_reason();
    assert_eq!(why.is_none(), !g.software, "{why:?}");
    let expected = if g.software {
        Backend::Cpu
    } else {
        Backend::Gpu
    };
    assert_eq!(Backend::Auto.resolve().unwrap(), expected);
    if let Some(why) = why {
        assert!(
            why.contains(&g.name) && why.contains("software rasteriser"),
            "{why}"
        );
    }
}

/// A small pseudo-random generator, so the tests need no crate.
fn lcg(seed: &mut u64) -> f64 {
    *seed = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*seed >> 11) as f64 / (1u64 << 53) as f64
}

/// A ball of fluid on a jittered lattice, a thin slab, and a few lone splash particles
/// and pairs: every level appears, with transition faces of both kinds.
fn body(kernel: Kernel) -> SphField {
    field_of(body_positions(), kernel)
}

/// [`body`]'s particles, spacing 0.05 (h = 0.1).
fn body_positions() -> Vec<DVec3> {
    let r = 0.05;
    let mut seed = 7u64;
    let mut positions = Vec::new();
    for z in -8..=8 {
        for y in -8..=8 {
            for x in -8..=8 {
                let p = DVec3::new(x as f64, y as f64, z as f64) * r;
                if p.length() < 0.38 {
                    let j = DVec3::new(lcg(&mut seed), lcg(&mut seed), lcg(&mut seed)) - 0.5;
                    positions.push(p + j * 0.2 * r);
                }
            }
        }
    }
    for (x, y) in [(9, 0), (10, 0), (9, 1)] {
        for z in -3..=3 {
            positions.push(DVec3::new(x as f64, y as f64, z as f64) * r);
        }
    }
    for p in [
        DVec3::new(0.0, 0.75, 0.0),
        DVec3::new(0.0, -0.8, 0.3),
        DVec3::new(0.05, -0.8, 0.3),
        DVec3::new(-0.7, 0.1, -0.6),
    ] {
        positions.push(p);
    }
    positions
}

/// The field of `positions` with [`body`]'s settings.
fn field_of(positions: Vec<DVec3>, kernel: Kernel) -> SphField {
    let data = ParticleData {
        positions,
        ..ParticleData::default()
    };
    let settings = SphSettings {
        kernel,
        smoothing_length: SmoothingLength::Constant(0.1),
        ..SphSettings::default()
    };
    SphField::new(&data, &settings).unwrap()
}

/// The defaults but for the paper's splash rule (threshold 1, off by default): levels
/// then follow the particle counts per coarse cell too, which the registration tests
/// compare between the back ends.
fn params(iso: f64) -> Params {
    Params {
        isovalue: iso,
        grid_factor: 0.5,
        splash_threshold: 1,
        ..Params::default()
    }
}

/// Largest coordinate extent of the grid: positions are compared relative to it.
fn extent(g: &CoarseGrid) -> f64 {
    g.cells.iter().map(|&c| c as f64).fold(0.0, f64::max) * g.fine * 4.0
}

/// Finest node of entry `i` of `a.values`.
fn value_node(grid: &CoarseGrid, a: &LevelArrays, i: usize) -> [u32; 3] {
    let (k, n) = (a.k(), a.k() + 1);
    let step = grid::FINE_PER_COARSE / k;
    let nnn = (n * n * n) as usize;
    let c = grid.coords(a.cells[i / nnn] as usize);
    let v = (i % nnn) as u32;
    let l = [v % n, v / n % n, v / (n * n)];
    std::array::from_fn(|x| c[x] * grid::FINE_PER_COARSE + l[x] * step)
}

/// The first way `gpu`'s arrays of a level differ from `cpu`'s, if any: node values
/// beyond TOL of the largest, positions beyond TOL of the extent, normals more than
/// 2.6° apart; cells, cases, scan, cut edges, the finest edge each point lies on and
/// triangles not equal (module doc).
fn level_difference(grid: &CoarseGrid, cpu: &LevelArrays, gpu: &LevelArrays) -> Option<String> {
    if cpu.cells != gpu.cells {
        return Some("cells".into());
    }
    let vmax = cpu.values.iter().fold(1e-30f64, |m, v| m.max(v.abs()));
    let worst = cpu
        .values
        .iter()
        .zip(&gpu.values)
        .map(|(a, b)| (a - b).abs() / vmax)
        .fold(0.0, f64::max);
    if worst >= TOL {
        return Some(format!("node values differ by {worst:e} relative"));
    }
    if let Some(s) = (0..cpu.cases.len()).find(|&s| cpu.cases[s] != gpu.cases[s]) {
        let cell = cpu.cells[s / cpu.k().pow(3) as usize];
        return Some(format!(
            "case of sub-cell {s} (coarse cell {cell}): {} against {}",
            cpu.cases[s], gpu.cases[s]
        ));
    }
    if cpu.triangle_offsets != gpu.triangle_offsets {
        return Some("scan".into());
    }
    if cpu.edges != gpu.edges {
        return Some(format!(
            "cut edges: {} against {}",
            cpu.edges.len(),
            gpu.edges.len()
        ));
    }
    if cpu.triangles != gpu.triangles {
        return Some("triangles".into());
    }
    let scale = extent(grid);
    for (key, (a, b)) in cpu.edges.iter().zip(cpu.points.iter().zip(&gpu.points)) {
        if a.id != b.id {
            return Some(format!("point of edge {key} on another finest edge"));
        }
        let d = (a.position - b.position).abs().max_element() / scale;
        if d >= TOL {
            return Some(format!("point of edge {key} moved {d:e} of the extent"));
        }
        if a.normal != DVec3::ZERO && a.normal.dot(b.normal) <= 0.999 {
            return Some(format!("normal of edge {key}"));
        }
    }
    None
}

fn assert_level_equal(grid: &CoarseGrid, cpu: &LevelArrays, gpu: &LevelArrays, what: &str) {
    if let Some(d) = level_difference(grid, cpu, gpu) {
        panic!("{what}: {d}");
    }
}

/// The CPU's arrays of `level`.
fn cpu_level(
    field: &SphField,
    grid: &CoarseGrid,
    levels: &[u8],
    level: u8,
    p: &Params,
) -> LevelArrays {
    let mut lattice = Lattice::new(grid);
    lattice
        .cover_level(field, grid, levels, level, u64::MAX, &mut Progress::none())
        .unwrap();
    levels::build_level(
        field,
        grid,
        levels,
        level,
        &lattice,
        p.isovalue,
        p.bisection_iterations,
        p.normals,
        &mut Progress::none(),
    )
    .unwrap()
}

/// The GPU's arrays of `level`, node values and cases read back.
fn gpu_level(
    g: &device::Gpu,
    on_device: &GpuField,
    grid: &CoarseGrid,
    levels: &[u8],
    level: u8,
    sides: &mut Sides,
    p: &Params,
) -> LevelArrays {
    let mut built = build_level(
        g,
        on_device,
        grid,
        levels,
        level,
        sides,
        p.bisection_iterations,
        p.normals,
        &mut Progress::none(),
    )
    .unwrap();
    built.read_values(g).unwrap();
    built.arrays
}

#[test]
fn scan_equals_a_sequential_prefix_sum() {
    let Some(g) = gpu() else { return };
    let mut seed = 3u64;
    for n in [1usize, 63, 64, 65, 4097, 300_001] {
        let data: Vec<u32> = (0..n).map(|_| (lcg(&mut seed) * 9.0) as u32).collect();
        let buf = g.upload("data", &data);
        scan(g, &buf, n as u64).unwrap();
        let got: Vec<u32> = g.read(&buf, n).unwrap();
        let mut want = Vec::with_capacity(n);
        let mut total = 0u32;
        for &v in &data {
            want.push(total);
            total += v;
        }
        assert_eq!(got, want, "n = {n}");
    }
}

/// Every level's arrays, GPU against CPU, for each kernel, with levels from the splash
/// criterion and with a forced mix (1, 2, 3 in stripes, balanced).
#[test]
fn level_arrays_equal_the_cpu_ones() {
    let Some(g) = gpu() else { return };
    for kernel in Kernel::ALL {
        let field = body(kernel);
        let p = params(0.5);
        let grid = grid_for(&field, &p).unwrap();
        let natural = adaptive::levels_for(&field, &grid, &p).unwrap();
        let forced = striped_levels(&grid);
        let on_device = GpuField::new(g, &field, grid.origin).unwrap();
        for (name, levels) in [("splash", &natural), ("forced", &forced)] {
            let mut triangles = 0;
            let mut sides = Sides::new(g, &field, &grid, p.isovalue);
            for level in 1..=3u8 {
                let what = format!("{kernel:?} {name} level {level}");
                let cpu = cpu_level(&field, &grid, levels, level, &p);
                let gpu = gpu_level(g, &on_device, &grid, levels, level, &mut sides, &p);
                assert_level_equal(&grid, &cpu, &gpu, &what);
                triangles += gpu.triangles.len();
            }
            assert!(triangles > 0, "{kernel:?} {name}: no surface to compare");
            eprintln!("{kernel:?} {name}: {} nodes settled", sides.settled());
        }
    }
}

/// The cubic-spline [`body`] at isovalue 0.5 without normals, and its grid.
fn body_without_normals() -> (SphField, Params, CoarseGrid) {
    let field = body(Kernel::CubicSpline);
    let p = Params {
        normals: false,
        ..params(0.5)
    };
    let grid = grid_for(&field, &p).unwrap();
    (field, p, grid)
}

/// A finest node whose f32 value lies on the other side of the isovalue than its f64
/// value takes the CPU's side (`gpu::sides`). The isovalue is set to the f64 value of a
/// node whose f32 value rounds above it: once a node of level-3 cells (their cases),
/// once the midpoint of a cut level-1 edge (where that edge's bisection first lands).
/// Unsettled, the GPU's arrays differ from the CPU's (so the case is real); settled,
/// they are equal, and so are the whole extractions.
#[test]
fn nodes_within_rounding_of_the_isovalue_take_the_cpus_side() {
    let Some(g) = gpu() else { return };
    let (field, p, grid) = body_without_normals();
    let striped = striped_levels(&grid);
    // Level 1 on the lower half along x, 2 on the upper: level-1 cells on the surface
    // (balancing the stripes leaves none there).
    let halves: Vec<u8> = (0..grid.cell_count())
        .map(|i| 1 + (grid.coords(i)[0] >= grid.cells[0] / 2) as u8)
        .collect();
    let on_device = GpuField::new(g, &field, grid.origin).unwrap();
    let unsettled = |iso: f64| {
        let mut sides = Sides::new(g, &field, &grid, iso);
        sides.margin = -1.0; // every value decides by itself
        sides
    };
    // Every finest node's f32 value, from level 3 on every cell.
    let all_fine = vec![3u8; grid.cell_count()];
    let fine = gpu_level(
        g,
        &on_device,
        &grid,
        &all_fine,
        3,
        &mut unsettled(p.isovalue),
        &p,
    );
    let mut f32_value = std::collections::BTreeMap::new();
    for (i, &v) in fine.values.iter().enumerate() {
        f32_value.insert(value_node(&grid, &fine, i), v);
    }
    let cpu_value = |node: [u32; 3]| field.value(grid.point(node.map(i64::from), 0));
    // At the isovalue `cpu_value(node)` the CPU puts the node below; unsettled, the GPU
    // above.
    let flips = |node: [u32; 3]| -> Option<f64> {
        let v = cpu_value(node);
        ((0.2..0.8).contains(&v) && f32_value[&node] as f32 > v as f32).then_some(v)
    };
    let cell_of = |node: [u32; 3]| -> Vec<usize> {
        // The cells holding `node` (up to eight).
        let mut out = Vec::new();
        for c in 0..8u32 {
            let cell: [i64; 3] = std::array::from_fn(|a| {
                (node[a] as i64 - (c >> a & 1) as i64).div_euclid(grid::FINE_PER_COARSE as i64)
            });
            if (0..3).all(|a| cell[a] >= 0 && cell[a] < grid.cells[a] as i64) {
                out.push(grid.index(cell.map(|x| x as u32)));
            }
        }
        out
    };
    let on_level_3 = f32_value
        .keys()
        .filter(|&&n| cell_of(n).iter().all(|&c| striped[c] == 3))
        .find_map(|&n| flips(n))
        .expect("a level-3 node whose f32 value rounds above its f64 value");
    let mid_of_level_1_edge = f32_value
        .keys()
        .find_map(|&n| {
            let a = (0..3).find(|&a| n[a] % 4 == 2)?;
            if (0..3).any(|b| b != a && n[b] % 4 != 0)
                || !cell_of(n).iter().any(|&c| halves[c] == 1)
            {
                return None;
            }
            let iso = flips(n)?;
            let (mut lo, mut hi) = (n, n);
            lo[a] -= 2;
            hi[a] += 2;
            ((cpu_value(lo) > iso) != (cpu_value(hi) > iso)).then_some(iso)
        })
        .expect("a cut level-1 edge whose midpoint's f32 value rounds above its f64 value");
    for (case, iso, levels) in [
        ("level-3 node", on_level_3, &striped),
        ("level-1 midpoint", mid_of_level_1_edge, &halves),
    ] {
        let p = Params {
            isovalue: iso,
            ..p.clone()
        };
        let cpu: Vec<LevelArrays> = (1..=3)
            .map(|l| cpu_level(&field, &grid, levels, l, &p))
            .collect();
        let mut raw = unsettled(iso);
        let differs = (1..=3u8).any(|l| {
            let gpu = gpu_level(g, &on_device, &grid, levels, l, &mut raw, &p);
            level_difference(&grid, &cpu[l as usize - 1], &gpu).is_some()
        });
        assert!(
            differs,
            "{case}: unsettled, the GPU's arrays equal the CPU's"
        );
        let mut sides = Sides::new(g, &field, &grid, iso);
        for l in 1..=3u8 {
            let gpu = gpu_level(g, &on_device, &grid, levels, l, &mut sides, &p);
            assert_level_equal(
                &grid,
                &cpu[l as usize - 1],
                &gpu,
                &format!("{case}, level {l}"),
            );
        }
        let cpu = adaptive::extract(&field, &grid, levels, &p, &mut Progress::none()).unwrap();
        let gpu = adaptive::extract_gpu(&field, &grid, levels, &p, &mut Progress::none()).unwrap();
        assert_same_extraction(&cpu, &gpu, extent(&grid), case);
        eprintln!("{case}: isovalue {iso}, {} nodes settled", sides.settled());
    }
}

/// `Sides::last_interval` on the CPU's level-3 points of the body, each on its interval
/// [lo, lo + 1] strictly inside its finest edge with the field monotone over the units
/// around it. Given f32 ends closer than the margin, on that interval the host's f64 ends
/// give the CPU's point to the bit; on the unit below or above (a halving between finest
/// nodes that went the other way in f32) it moves back to the CPU's interval first. Ends
/// farther apart than the margin are kept as the kernel gave them.
#[test]
fn last_intervals_too_flat_for_f32_are_placed_on_f64_ends() {
    let Some(g) = gpu() else { return };
    let (field, p, grid) = body_without_normals();
    let all_fine = vec![3u8; grid.cell_count()];
    let cpu = cpu_level(&field, &grid, &all_fine, 3, &p);
    let sides = Sides::new(g, &field, &grid, p.isovalue);
    let (iso, shift) = (p.isovalue, p.bisection_iterations);
    let units = 1i64 << shift;
    let mut checked = 0;
    for (&key, point) in cpu.edges.iter().zip(&cpu.points) {
        let (node, axis) = crate::mc::edge_node_axis(key);
        let along = |t: i64| levels::along(&grid, key, shift, t);
        let t = (point.position[axis] - along(0)[axis]) / (along(1)[axis] - along(0)[axis]);
        let lo = t.floor() as i64;
        let start_inside = field.value(along(0)) > iso;
        let side = |t: i64| field.value(along(t)) > iso;
        if lo < 1
            || lo + 2 >= units
            || (t - t.floor()).min(t.ceil() - t) < 1e-6
            || side(lo - 1) != start_inside
            || side(lo + 2) == start_inside
        {
            continue;
        }
        assert_eq!(
            node,
            crate::mc::edge_node_axis(point.id).0,
            "a level-3 edge is finest"
        );
        let flat = (iso, iso);
        for given in [lo - 1, lo, lo + 1] {
            let (got, ends, evaluations) =
                sides.last_interval(key, shift, given, flat, start_inside);
            assert_eq!(got, lo, "edge {key}: from unit {given}");
            assert_eq!(evaluations, if given == lo { 2 } else { 3 });
            let placed = levels::edge_point(&grid, key, shift, got, ends, iso, |_| DVec3::ZERO);
            assert_eq!(placed.id, point.id);
            assert_eq!(
                placed.position, point.position,
                "edge {key}: from unit {given}"
            );
        }
        let steep = (iso - 1.0, iso + 1.0);
        assert_eq!(
            sides.last_interval(key, shift, lo, steep, start_inside),
            (lo, steep, 0)
        );
        checked += 1;
    }
    assert!(checked > 100, "{checked} points checked");
}

/// Whole extractions: same triangles (vertices are ordered by finest-edge identity, so
/// equal triangle lists are equal triangle sets; the crack fills come last, face by
/// face, so a missing or wrong fill changes the list), positions within TOL of the
/// extent, and the GPU mesh closed and oriented on its own.
fn assert_same_extraction(
    cpu: &adaptive::Extraction,
    gpu: &adaptive::Extraction,
    scale: f64,
    what: &str,
) {
    assert_eq!(cpu.stats.backend, Backend::Cpu);
    assert_eq!(gpu.stats.backend, Backend::Gpu);
    let topo = gpu.mesh.topology();
    assert!(topo.is_watertight_oriented(), "{what}: GPU mesh {topo:?}");
    assert_eq!(gpu.stats.point_mismatches, 0, "{what}");
    assert_eq!(
        cpu.stats.cells_per_level, gpu.stats.cells_per_level,
        "{what}"
    );
    assert_eq!(
        cpu.stats.transition_faces, gpu.stats.transition_faces,
        "{what}"
    );
    assert_eq!(
        cpu.stats.crack_triangles, gpu.stats.crack_triangles,
        "{what}"
    );
    assert_eq!(
        cpu.mesh.triangles.len(),
        gpu.mesh.triangles.len(),
        "{what}: triangles"
    );
    if let Some(i) =
        (0..cpu.mesh.triangles.len()).find(|&i| cpu.mesh.triangles[i] != gpu.mesh.triangles[i])
    {
        panic!(
            "{what}: triangle {i} is {:?} on the CPU, {:?} on the GPU",
            cpu.mesh.triangles[i], gpu.mesh.triangles[i]
        );
    }
    for (i, (a, b)) in cpu
        .mesh
        .positions
        .iter()
        .zip(&gpu.mesh.positions)
        .enumerate()
    {
        let d = (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0, f64::max) / scale;
        assert!(d < TOL, "{what}: vertex {i} moved {d:e} of the extent");
    }
}

/// [`assert_same_extraction`] of `extract_sph` on both back ends; the triangle count.
fn assert_same_surface(field: &SphField, p: &Params, what: &str) -> u64 {
    let cpu = adaptive::extract_sph(field, p, &mut Progress::none()).unwrap();
    let gp = Params {
        backend: Backend::Gpu,
        ..p.clone()
    };
    let gpu = adaptive::extract_sph(field, &gp, &mut Progress::none()).unwrap();
    assert_same_extraction(&cpu, &gpu, extent(&grid_for(field, p).unwrap()), what);
    gpu.stats.triangles
}

/// Levels 1, 2, 3 in stripes along x, balanced: transition faces on most cells.
fn striped_levels(grid: &CoarseGrid) -> Vec<u8> {
    let mut levels: Vec<u8> = (0..grid.cell_count())
        .map(|i| 1 + (grid.coords(i)[0] % 3) as u8)
        .collect();
    grid::balance(grid, &mut levels, &mut Progress::none()).unwrap();
    levels
}

/// Crack filling alone: the GPU's fills from the GPU's level arrays equal the CPU's fills
/// from the same arrays, exactly and in order, on meshes with many transition faces of
/// both kinds (level 1 | 2 and 2 | 3, fine cell on either side).
#[test]
fn gpu_crack_fills_equal_cpu_crack_fills() {
    use crate::adaptive::cracks;
    let Some(g) = gpu() else { return };
    for kernel in [Kernel::CubicSpline, Kernel::QuinticSpline] {
        let field = body(kernel);
        let p = params(0.5);
        let grid = grid_for(&field, &p).unwrap();
        let natural = adaptive::levels_for(&field, &grid, &p).unwrap();
        let on_device = GpuField::new(g, &field, grid.origin).unwrap();
        let (mut all_kinds, mut fine_levels) = (HashSet::new(), HashSet::new());
        for (name, levels) in [("splash", natural), ("striped", striped_levels(&grid))] {
            let what = format!("{kernel:?} {name}");
            let mut sides = Sides::new(g, &field, &grid, p.isovalue);
            let iso = sides.iso32;
            let built: Vec<_> = (1..=3u8)
                .map(|level| {
                    let mut l = build_level(
                        g,
                        &on_device,
                        &grid,
                        &levels,
                        level,
                        &mut sides,
                        p.bisection_iterations,
                        false,
                        &mut Progress::none(),
                    )
                    .unwrap();
                    l.read_values(g).unwrap();
                    l
                })
                .collect();
            let arrays: Vec<LevelArrays> = built.iter().map(|l| l.arrays.clone()).collect();
            let faces = cracks::transition_faces(&grid, &levels, &mut Progress::none()).unwrap();
            let cpu = cracks::fill(
                &grid,
                &levels,
                &arrays,
                &faces,
                iso as f64,
                &mut Progress::none(),
            )
            .unwrap();
            let fine = [built[1].buffers.as_ref(), built[2].buffers.as_ref()];
            let gpu = super::cracks::fill(g, &grid, &levels, fine, &faces, iso).unwrap();
            let kinds: HashSet<(u8, u8)> = faces
                .iter()
                .map(|f| {
                    let mut upper = grid.coords(f.cell);
                    upper[f.axis] += 1;
                    (levels[f.cell], levels[grid.index(upper)])
                })
                .collect();
            eprintln!(
                "{what}: {} faces, {} fills, kinds {kinds:?}",
                faces.len(),
                cpu.len()
            );
            assert!(
                faces.len() > 100,
                "{what}: {} transition faces",
                faces.len()
            );
            assert!(cpu.len() > 50, "{what}: {} fill triangles", cpu.len());
            all_kinds.extend(kinds);
            fine_levels.extend(cpu.iter().map(|t| t[0].0));
            assert_eq!(cpu.len(), gpu.len(), "{what}: fill triangles");
            assert_eq!(cpu, gpu, "{what}");
        }
        // Faces of every kind (lower | upper level) were walked. On this body the 1 | 2
        // faces happen to need no fill (cubic spline: every fill is on level 3); a wrong
        // level-2 walk would still show as fills the CPU lacks.
        assert_eq!(all_kinds.len(), 4, "{kernel:?}: {all_kinds:?}");
        assert!(fine_levels.contains(&3), "{kernel:?}: {fine_levels:?}");
    }
}

/// The GPU back end registers particles on the device (`gpu::register`), whose counts
/// must equal the CPU's f64 ones even for particles on a face, or a splash cell would
/// change level. (The neighbour grid's buckets stay CPU-made; the GPU's only f32 cell
/// index is the neighbour-search window of a sample point, `search_lo` in sph.wgsl:
/// shifted by one cell it drops or adds only particles within f32 rounding of their
/// support radius, whose weight is zero to f32 precision.) This guards that through the
/// whole extraction: splash particles exactly on coarse-cell faces, edges and corners,
/// and one ulp either side, give the same levels and the same surface on both back ends.
#[test]
fn particles_on_coarse_cell_boundaries_give_the_same_levels_and_surface() {
    if gpu().is_none() {
        return;
    }
    let p = params(0.5);
    let mut positions = body_positions();
    let grid = grid_for(&field_of(positions.clone(), Kernel::CubicSpline), &p).unwrap();
    let coarse = grid.fine * 4.0;
    // Lone particles in the empty corners of the body's bounds (so the grid stays), each
    // snapped to the coarse lattice on the first `on` axes (face, edge, corner), the other
    // axes at a cell centre, then nudged by `ulps` along the snapped axes.
    let lone = [
        ([-0.6, 0.6, -0.5], 1, 0),
        ([0.4, 0.6, -0.5], 1, -1),
        ([-0.6, -0.6, -0.5], 2, 0),
        ([0.4, -0.6, -0.5], 2, 1),
        ([-0.6, 0.6, 0.2], 3, 0),
        ([0.4, 0.6, 0.2], 3, -1),
    ];
    let mut placed = Vec::new();
    for (target, on, ulps) in lone {
        let q: [f64; 3] = std::array::from_fn(|a| {
            let k = ((target[a] - grid.origin[a]) / coarse).round();
            let boundary = grid.origin[a] + k * coarse;
            match (a < on, ulps) {
                (false, _) => boundary + 0.5 * coarse,
                (true, 0) => boundary,
                (true, -1) => boundary.next_down(),
                (true, _) => boundary.next_up(),
            }
        });
        placed.push(DVec3::from(q));
    }
    positions.extend(&placed);
    let field = field_of(positions, Kernel::CubicSpline);
    assert_eq!(
        grid_for(&field, &p).unwrap(),
        grid,
        "the lone particles moved the grid"
    );
    // Each lone particle alone in its cell makes it level 3 (threshold 1).
    let levels = adaptive::levels_for(&field, &grid, &p).unwrap();
    for q in &placed {
        let cell = grid.cell_of(*q).unwrap();
        assert_eq!(levels[cell], 3, "particle at {q} in cell {cell}");
    }
    assert!(assert_same_surface(&field, &p, "boundary particles") > 0);
}

/// Whole extractions with the striped levels: GPU levels and cracks against the CPU's.
#[test]
fn gpu_surface_equals_cpu_surface_with_striped_levels() {
    let Some(_) = gpu() else { return };
    let field = body(Kernel::CubicSpline);
    // The paper's 5 halvings, and none (linear on level-3 edges).
    for n in [5, 0] {
        let p = Params {
            bisection_iterations: n,
            ..params(0.5)
        };
        let grid = grid_for(&field, &p).unwrap();
        let levels = striped_levels(&grid);
        let cpu = adaptive::extract(&field, &grid, &levels, &p, &mut Progress::none()).unwrap();
        let gpu = adaptive::extract_gpu(&field, &grid, &levels, &p, &mut Progress::none()).unwrap();
        assert!(cpu.stats.transition_faces > 100, "{:?}", cpu.stats);
        assert!(cpu.stats.crack_triangles > 50, "{:?}", cpu.stats);
        assert_same_extraction(&cpu, &gpu, extent(&grid), &format!("striped, n = {n}"));
    }
}

#[test]
fn gpu_surface_equals_cpu_surface_on_closed_bodies() {
    if gpu().is_none() {
        return;
    }
    let field = body(Kernel::CubicSpline);
    for (threshold, dilation) in [(0, 0), (1, 0), (1, 1), (3, 1)] {
        let p = Params {
            splash_threshold: threshold,
            splash_dilation: dilation,
            ..params(0.5)
        };
        let what = format!("threshold {threshold} dilation {dilation}");
        assert!(assert_same_surface(&field, &p, &what) > 0, "{what}");
    }
}

#[test]
fn explicit_gpu_without_adapter_is_an_error_not_a_panic() {
    // With an adapter Auto picks it when it is hardware, not a software rasteriser
    // (lavapipe in CI); without one, Gpu says so.
    match device::get() {
        Ok(g) => {
            let want = if g.software {
                Backend::Cpu
            } else {
                Backend::Gpu
            };
            assert_eq!(Backend::Auto.resolve().unwrap(), want, "{}", g.name);
            assert_eq!(Backend::Gpu.resolve().unwrap(), Backend::Gpu);
        }
        Err(e) => {
            assert!(e.to_string().contains("no GPU adapter"), "{e}");
            assert_eq!(Backend::Auto.resolve().unwrap(), Backend::Cpu);
            assert!(Backend::Gpu.resolve().is_err());
        }
    }
}

/// A real frame at splashsurf's settings (r = 0.025, h = 2r, cubic spline).
fn frame(name: &str) -> SphField {
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/splashsurf")
        .join(name);
    let data = crate::io::read_particles(&path).unwrap();
    let s = SphSettings {
        kernel: Kernel::CubicSpline,
        smoothing_length: SmoothingLength::Constant(0.05),
        ..SphSettings::default()
    };
    SphField::new(&data, &s).unwrap()
}

const FRAMES: [&str; 2] = [
    "dam_break_frame_23_24389_particles.bgeo",
    "double_dam_break_frame_01_4732_particles.vtk",
];

/// Whole extractions on real frames; pentagonal_hexecontahedron at G 0.375 has nodes
/// within f32 rounding of the isovalue (its triangle lists differed before `gpu::sides`).
#[test]
fn gpu_surface_equals_cpu_surface_on_real_frames() {
    if gpu().is_none() {
        return;
    }
    for name in FRAMES
        .into_iter()
        .chain(["pentagonal_hexecontahedron_32286_particles.bgeo"])
    {
        let field = frame(name);
        let p = Params {
            isovalue: 0.6,
            grid_factor: 0.375,
            ..Params::default()
        };
        assert!(assert_same_surface(&field, &p, name) > 0, "{name}");
    }
}

/// GPU seed cells (neighbour search on the device, exact tests on the CPU) against the
/// CPU's, exactly, on the analytic body at several isovalues and on real frames.
#[test]
fn gpu_seed_cells_equal_cpu_seed_cells() {
    use crate::correctors::{self, seeds};
    let Some(g) = gpu() else { return };
    let cases = [
        (body(Kernel::CubicSpline), vec![0.05, 0.5, 0.7, 0.9]),
        (body(Kernel::QuinticSpline), vec![0.5]),
        (frame(FRAMES[0]), vec![0.3, 0.6]),
        (frame(FRAMES[1]), vec![0.6]),
    ];
    for (k, (field, isos)) in cases.iter().enumerate() {
        let search = seeds::SeedSearch::new(field, crate::field::DEFAULT_MEMORY_BUDGET).unwrap();
        let on_device = GpuField::new(g, field, field.bounds().0).unwrap();
        let candidates = super::seeds::Candidates::new(g, &on_device, field).unwrap();
        for &iso in isos {
            let cp = correctors::Params {
                isovalues: vec![iso],
                ..correctors::Params::default()
            };
            let grid = correctors::virtual_grid(field, &cp).unwrap();
            let cpu = seeds::seed_cells(field, &grid, iso, &search).unwrap();
            let gpu = super::seeds::seed_cells(&candidates, field, &grid, iso, &search).unwrap();
            assert!(!cpu.is_empty(), "case {k} iso {iso}");
            assert_eq!(cpu, gpu, "case {k} iso {iso}");
        }
    }
}

/// `isobar sph --backend gpu`'s path: Marching Correctors with the seed search on the GPU
/// gives the CPU's mesh exactly (same vertices, triangles, normals) on real frames, and
/// says which back end ran.
#[test]
fn correctors_gpu_backend_mesh_equals_cpu_mesh_on_real_frames() {
    use crate::correctors;
    if gpu().is_none() {
        return;
    }
    for name in FRAMES {
        let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../shared/data/splashsurf")
            .join(name);
        let data = crate::io::read_particles(&path).unwrap();
        let field = frame(name);
        let run = |backend| {
            let p = correctors::Params {
                isovalues: vec![0.6],
                backend,
                ..correctors::Params::default()
            };
            correctors::extract(&field, &data, &p, &mut Progress::none()).unwrap()
        };
        let (cpu, gpu) = (run(Backend::Cpu), run(Backend::Gpu));
        assert_eq!(cpu.stats.backend, Backend::Cpu);
        assert_eq!(gpu.stats.backend, Backend::Gpu, "{name}");
        assert!(!cpu.mesh.triangles.is_empty(), "{name}");
        assert_eq!(cpu.stats.seed_cells, gpu.stats.seed_cells, "{name}");
        assert_eq!(cpu.mesh.positions, gpu.mesh.positions, "{name}");
        assert_eq!(cpu.mesh.triangles, gpu.mesh.triangles, "{name}");
        assert_eq!(cpu.mesh.normals, gpu.mesh.normals, "{name}");
        if name == FRAMES[1] {
            // Auto takes a hardware GPU only (lavapipe is slower than the CPU path).
            let auto = run(Backend::Auto);
            let software = device::get().unwrap().software;
            let expected = if software { Backend::Cpu } else { Backend::Gpu };
            assert_eq!(auto.stats.backend, expected);
            assert_eq!(auto.mesh.triangles, cpu.mesh.triangles);
        }
    }
}

/// `gpu::register` on `grid` against `grid::register` (the CPU reference): equal counts
/// or the same error. Returns the GPU's registration (None on an error).
fn assert_same_registration(
    g: &device::Gpu,
    field: &SphField,
    grid: &CoarseGrid,
    what: &str,
) -> Option<super::register::Registration> {
    let positions: Vec<DVec3> = (0..field.len()).map(|i| field.position(i)).collect();
    let cpu = grid::register(grid, &positions);
    let on_device = GpuField::new(g, field, grid.origin).unwrap();
    let gpu = super::register::register(g, &on_device, field, grid);
    match (cpu, gpu) {
        (Ok(cpu), Ok(gpu)) => {
            assert_eq!(cpu.len(), grid.cell_count(), "{what}");
            assert_eq!(
                cpu.iter().map(|&c| c as usize).sum::<usize>(),
                field.len(),
                "{what}"
            );
            assert!(
                cpu == gpu.counts,
                "{what}: GPU counts differ from the CPU's"
            );
            Some(gpu)
        }
        (Err(cpu), Err(gpu)) => {
            assert_eq!(cpu.to_string(), gpu.to_string(), "{what}");
            None
        }
        (cpu, gpu) => panic!("{what}: CPU {:?}, GPU {:?}", cpu.err(), gpu.err()),
    }
}

/// Registration counts on real data (both shared frames, the embedded demo frame) at
/// several grid factors, and the levels and surface they lead to.
#[test]
fn gpu_registration_equals_cpu_registration_on_real_frames() {
    let Some(g) = gpu() else { return };
    let demo = {
        let path =
            std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/demo_dam_break.npz");
        let data = crate::io::read_particles(&path).unwrap();
        let s = SphSettings {
            kernel: Kernel::CubicSpline,
            smoothing_length: SmoothingLength::Constant(0.027),
            ..SphSettings::default()
        };
        SphField::new(&data, &s).unwrap()
    };
    let fields = [
        (FRAMES[0], frame(FRAMES[0])),
        (FRAMES[1], frame(FRAMES[1])),
        ("demo", demo),
    ];
    for (name, field) in &fields {
        for factor in [0.25, 0.375, 0.5, 1.0] {
            let p = Params {
                grid_factor: factor,
                ..params(0.6)
            };
            let grid = grid_for(field, &p).unwrap();
            let what = format!("{name} factor {factor}");
            let r = assert_same_registration(g, field, &grid, &what).unwrap();
            eprintln!("{what}: {} particles, {} deferred", field.len(), r.deferred);
        }
    }
}

/// Adversarial positions: every coarse face of a grid at the origin (so d = p exactly),
/// at its exact f64 threshold and 1, 2 and 2^29 f64 ulps either side (the last straddles
/// the f32 rounding: not a tie), on faces, edges and corners; then the same positions on
/// a grid whose origin makes p - origin round, a lattice whose particles all lie on
/// faces, particles outside (same error as the CPU), and the whole extraction of such a
/// set on both back ends.
#[test]
fn gpu_registration_equals_cpu_registration_on_cell_boundaries() {
    let Some(g) = gpu() else { return };
    let base = CoarseGrid {
        origin: DVec3::ZERO,
        fine: 0.1 / 3.0,
        cells: [5, 4, 3],
    };
    let t = base.registration_thresholds();
    // Every threshold of every axis and its neighbours, as one coordinate each.
    let near = |a: usize| -> Vec<f64> {
        let mut v = Vec::new();
        for &x in &t[a] {
            v.extend([x, x.next_up(), x.next_down()]);
            v.extend([x.next_up().next_up(), x.next_down().next_down()]);
            let far = f64::EPSILON * x.abs().max(f64::MIN_POSITIVE) * (1u64 << 29) as f64;
            v.push(x + far);
            v.push(x - far);
        }
        v.retain(|&x| x > 0.0 && x < t[a][t[a].len() - 1]);
        v
    };
    let centre = |a: usize, k: usize| (t[a][k] + t[a][k + 1]) / 2.0;
    let mut positions = Vec::new();
    // Faces (one axis on a boundary), edges (two), corners (three).
    for &x in &near(0) {
        positions.push(DVec3::new(x, centre(1, 1), centre(2, 1)));
        for &y in &near(1) {
            positions.push(DVec3::new(x, y, centre(2, 0)));
        }
    }
    for &x in near(0).iter().step_by(3) {
        for &y in near(1).iter().step_by(2) {
            for &z in &near(2) {
                positions.push(DVec3::new(x, y, z));
            }
        }
    }
    let field = field_of(positions.clone(), Kernel::CubicSpline);
    let r = assert_same_registration(g, &field, &base, "origin 0").unwrap();
    // Each threshold itself rounds to its own f32: those particles must take the
    // deferred path, and the 2^29-ulp ones must not (the kernel decided most).
    assert!(r.deferred > 0, "no tie exercised");
    assert!(
        r.deferred < field.len(),
        "{} of {} deferred",
        r.deferred,
        field.len()
    );
    eprintln!(
        "boundaries: {} particles, {} deferred",
        field.len(),
        r.deferred
    );

    // The same positions on grids whose origin is not 0: p - origin rounds in f64.
    for origin in [
        DVec3::new(-0.3, -1e-3, 0.7),
        DVec3::new(-1.0 / 3.0, 0.1, -7.0),
    ] {
        let shifted = CoarseGrid {
            origin: origin.min(DVec3::ZERO) - 1.0,
            cells: [60, 60, 250],
            ..base
        };
        assert_same_registration(g, &field, &shifted, &format!("origin {origin}")).unwrap();
    }

    // A lattice of spacing = a quarter coarse cell from the origin: a quarter of the
    // particles lie on a face along each axis.
    let coarse = base.fine * 4.0;
    let lattice: Vec<DVec3> = (0..20 * 16 * 12)
        .map(|i| {
            DVec3::new((i % 20) as f64, (i / 20 % 16) as f64, (i / 320) as f64) * (coarse / 4.0)
        })
        .collect();
    let field = field_of(lattice, Kernel::CubicSpline);
    let r = assert_same_registration(g, &field, &base, "lattice").unwrap();
    eprintln!(
        "lattice: {} particles, {} deferred",
        field.len(),
        r.deferred
    );

    // Outside the grid below, above and exactly at the far face: the CPU's error.
    for bad in [
        DVec3::new(t[0][0].next_down(), 0.05, 0.05),
        DVec3::new(0.05, t[1][4], 0.05),
        DVec3::new(0.05, 0.05, 50.0),
    ] {
        let mut p = positions.clone();
        p.insert(17, bad);
        let field = field_of(p, Kernel::CubicSpline);
        assert!(assert_same_registration(g, &field, &base, &format!("outside {bad}")).is_none());
    }
}

/// The GPU back end's registration costs one small upload (the thresholds and a uniform,
/// O(cells)) and no per-particle upload: the field upload it reads is the one the
/// per-level work needs anyway.
#[test]
fn gpu_registration_uploads_only_the_thresholds() {
    let Some(g) = gpu() else { return };
    let field = frame(FRAMES[1]);
    let p = params(0.6);
    let grid = grid_for(&field, &p).unwrap();
    let on_device = GpuField::new(g, &field, grid.origin).unwrap();
    let before = g.transfers();
    super::register::register(g, &on_device, &field, &grid).unwrap();
    let used = g.transfers() - before;
    let thresholds = grid.cells.iter().map(|&c| c as u64 + 1).sum::<u64>() * 4;
    assert_eq!(used.uploads, 2, "{used:?}");
    assert_eq!(
        used.upload_bytes,
        thresholds.max(16).next_multiple_of(4) + 32,
        "{used:?}"
    );
    assert_eq!(used.dispatches, 1, "{used:?}");
    assert!(used.readbacks <= 2, "{used:?}");
}

/// Figures, not a check (lavapipe times say nothing about a GPU): run with
/// `cargo test --release --lib gpu::tests::figures -- --ignored --nocapture`.
#[test]
#[ignore]
fn figures() {
    if gpu().is_none() {
        return;
    }
    for name in FRAMES {
        let field = frame(name);
        for backend in [Backend::Cpu, Backend::Gpu] {
            let p = Params {
                isovalue: 0.6,
                grid_factor: 0.375,
                backend,
                ..Params::default()
            };
            let t = std::time::Instant::now();
            let out = adaptive::extract_sph(&field, &p, &mut Progress::none()).unwrap();
            println!(
                "{name} {:?}: {:.3} s, {} triangles, {} array bytes, {} field evaluations",
                backend,
                t.elapsed().as_secs_f64(),
                out.stats.triangles,
                out.stats.array_bytes,
                out.stats.field_evaluations
            );
        }
    }
}

/// Registration figures, not a check: best of 7 wall times of the CPU registration
/// (`grid::register`, rayon) and the GPU one (`gpu::register`: thresholds, upload,
/// dispatch, read-back, deferred particles; the field upload it reads is shared with the
/// per-level work and not timed), and the GPU extraction's whole traffic. On lavapipe the
/// times are a CPU emulating a GPU. Run with
/// `cargo test --release --lib gpu::tests::registration_figures -- --ignored --nocapture`.
#[test]
#[ignore]
fn registration_figures() {
    let Some(g) = gpu() else { return };
    println!("adapter: {}", g.name);
    for name in FRAMES {
        let field = frame(name);
        let p = Params {
            isovalue: 0.6,
            grid_factor: 0.375,
            ..Params::default()
        };
        let grid = grid_for(&field, &p).unwrap();
        let positions: Vec<DVec3> = (0..field.len()).map(|i| field.position(i)).collect();
        let on_device = GpuField::new(g, &field, grid.origin).unwrap();
        let best = |f: &mut dyn FnMut()| {
            (0..7)
                .map(|_| {
                    let t = std::time::Instant::now();
                    f();
                    t.elapsed().as_secs_f64()
                })
                .fold(f64::INFINITY, f64::min)
        };
        let cpu = best(&mut || {
            grid::register(&grid, &positions).unwrap();
        });
        let before = g.transfers();
        let mut deferred = 0;
        let gpu_t = best(&mut || {
            deferred = super::register::register(g, &on_device, &field, &grid)
                .unwrap()
                .deferred;
        });
        let per_call = g.transfers() - before;
        let before = g.transfers();
        let gp = Params {
            backend: Backend::Gpu,
            ..p.clone()
        };
        adaptive::extract_sph(&field, &gp, &mut Progress::none()).unwrap();
        let whole = g.transfers() - before;
        println!(
            "{name}: {} particles, {} coarse cells, {deferred} deferred; registration best of 7: \
             CPU {:.3} ms, GPU (lavapipe) {:.3} ms; GPU registration traffic per call: {} uploads, \
             {} bytes, {} dispatches, {} read-backs; whole GPU extraction: {:?}",
            field.len(),
            grid.cell_count(),
            cpu * 1e3,
            gpu_t * 1e3,
            per_call.uploads / 7,
            per_call.upload_bytes / 7,
            per_call.dispatches / 7,
            per_call.readbacks / 7,
            whole
        );
    }
}

/// Host-to-device traffic of crack filling (counts, not times): run with
/// `cargo test --release --lib gpu::tests::crack_fill_traffic -- --ignored --nocapture`.
#[test]
#[ignore]
fn crack_fill_traffic() {
    use crate::adaptive::cracks;
    let Some(g) = gpu() else { return };
    for name in FRAMES {
        let field = frame(name);
        let p = Params {
            isovalue: 0.6,
            grid_factor: 0.375,
            ..Params::default()
        };
        let grid = grid_for(&field, &p).unwrap();
        let levels = adaptive::levels_for(&field, &grid, &p).unwrap();
        let on_device = GpuField::new(g, &field, grid.origin).unwrap();
        let mut sides = Sides::new(g, &field, &grid, p.isovalue);
        let iso = sides.iso32;
        let before = g.transfers();
        let built: Vec<_> = (1..=3u8)
            .map(|level| {
                build_level(
                    g,
                    &on_device,
                    &grid,
                    &levels,
                    level,
                    &mut sides,
                    p.bisection_iterations,
                    false,
                    &mut Progress::none(),
                )
                .unwrap()
            })
            .collect();
        let after_levels = g.transfers();
        let fine = [built[1].buffers.as_ref(), built[2].buffers.as_ref()];
        for call in 0..2 {
            let t = g.transfers();
            let faces = cracks::transition_faces(&grid, &levels, &mut Progress::none()).unwrap();
            let fills = super::cracks::fill(g, &grid, &levels, fine, &faces, iso).unwrap();
            println!(
                "{name}: {} cells, {} faces, {} fills; crack fill call {call}: {:?}",
                levels.len(),
                faces.len(),
                fills.len(),
                g.transfers() - t
            );
        }
        println!("{name}: levels 1-3: {:?}", after_levels - before);
    }
}
