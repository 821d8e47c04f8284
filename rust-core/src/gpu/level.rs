//! Algorithm 2 for one level on the GPU (`shaders/level.wgsl`), giving the same
//! [`LevelArrays`] as `adaptive::levels::build_level`:
//!
//! | step | where |
//! |---|---|
//! | vertex values of every cell of the level (SPH field at the finest-lattice nodes) | GPU |
//! | the CPU's side at nodes within rounding of the isovalue ([`Sides`]) | CPU, then GPU |
//! | sub-cell cases, triangle and cut-edge counts (table uploaded from `mc::case_table`) | GPU |
//! | prefix sums of both counts (compaction offsets) | GPU |
//! | cut edges (key, end values) and triangles (as edge keys) at the scanned offsets | GPU |
//! | sort + dedup of the cut-edge keys into E | CPU |
//! | bisection of each edge of E (settled sides at finest nodes) and its gradient normal | GPU |
//! | positions from the bisected interval in f64, triangle keys to E indices | CPU |
//!
//! The level's cells, node values and E stay on the device ([`LevelBuffers`]) for crack
//! filling (`gpu::cracks`); node values and cases come back to the host only when asked
//! ([`GpuLevel::read_values`], for the tests that compare them with the CPU's).
//!
//! A node shared by cells of the level is evaluated by each of them (the same kernel on
//! the same integer coordinates gives the same bits), so `evaluations` counts (k+1)³ per
//! cell.

use super::device::{gpu_error, Gpu};
use super::sides::Sides;
use super::sph::GpuField;
use crate::adaptive::grid::{subdivisions, CoarseGrid, FINE_PER_COARSE};
use crate::adaptive::levels::{edge_point, LevelArrays};
use crate::error::{Error, Result};
use crate::mc::case_table;
use crate::progress::Progress;
use glam::DVec3;
use rayon::prelude::*;

/// The SPH kernels, the level kernels and crack filling (`gpu::cracks`): one module, one
/// binding layout.
pub(super) fn level_source() -> (&'static str, &'static str) {
    kernel_source!("level.wgsl", "level.wgsl", "cracks.wgsl")
}

const SCAN: (&str, &str) = ("scan.wgsl", include_str!("shaders/scan.wgsl"));

/// `Level` of level.wgsl (crack filling reads the grid, `iso` and `count` from it too).
#[repr(C)]
#[derive(Clone, Copy, Default)]
pub(super) struct LevelUniform {
    pub fine: f32,
    pub iso: f32,
    pub k: u32,
    pub step: u32,
    pub shift: u32,
    pub steps: u32,
    pub cells_x: u32,
    pub cells_y: u32,
    pub count: u32,
    pub normals: u32,
    pub unit: f32,
    pub margin: f32,
}

/// `Scan` of scan.wgsl.
#[repr(C)]
#[derive(Clone, Copy)]
struct ScanUniform {
    count: u32,
    pad: [u32; 3],
}

/// The case table as level.wgsl reads it: triangle counts, cut-edge bits, then 15 local
/// edges per case.
fn table_words() -> Vec<u32> {
    let table = case_table();
    let mut words = vec![0u32; 512 + 256 * 15];
    for case in 0..256 {
        words[case] = table.triangles[case].len() as u32;
        words[256 + case] = table.edges_cut[case] as u32;
        for (t, tri) in table.triangles[case].iter().enumerate() {
            for (j, &e) in tri.iter().enumerate() {
                words[512 + 15 * case + 3 * t + j] = e as u32;
            }
        }
    }
    words
}

/// A level's arrays on the device, as its kernels left them, for `gpu::cracks` to bind.
pub struct LevelBuffers {
    /// The level's coarse cells, ascending (`LevelArrays::cells`).
    pub cells: wgpu::Buffer,
    pub cells_len: usize,
    /// f32 node values, cell by cell (`LevelArrays::values`).
    pub values: wgpu::Buffer,
    /// E as the bisection read it: per edge its key's two words and the end values
    /// (`LevelArrays::edges` in the first two words).
    pub edges: wgpu::Buffer,
    pub edges_len: usize,
    cases: wgpu::Buffer,
    node_count: usize,
    sub_count: usize,
}

/// What [`build_level`] gives: the host arrays the assembly needs (without node values
/// and cases) and the device buffers (None for a level without cells).
pub struct GpuLevel {
    pub arrays: LevelArrays,
    pub buffers: Option<LevelBuffers>,
}

impl GpuLevel {
    /// Reads the node values (widened to f64) and sub-cell cases back into `arrays`, which
    /// then equal `adaptive::levels::build_level`'s in every field.
    pub fn read_values(&mut self, gpu: &Gpu) -> Result<()> {
        if let Some(b) = &self.buffers {
            self.arrays.values = gpu
                .read::<f32>(&b.values, b.node_count)?
                .into_iter()
                .map(f64::from)
                .collect();
            self.arrays.cases = gpu
                .read::<u32>(&b.cases, b.sub_count)?
                .into_iter()
                .map(|c| c as u8)
                .collect();
        }
        Ok(())
    }
}

/// Exclusive prefix sum, on the device, of the first `count` words of `data`.
pub fn scan(gpu: &Gpu, data: &wgpu::Buffer, count: u64) -> Result<()> {
    let blocks = count.div_ceil(64);
    let sums = gpu.zeroed::<u32>("block sums", blocks as usize)?;
    let uniform = gpu.uniform(
        "scan",
        &ScanUniform {
            count: u32::try_from(count).map_err(gpu_error)?,
            pad: [0; 3],
        },
    );
    let bindings = [(0, data), (1, &sums), (2, &uniform)];
    gpu.dispatch(SCAN, "scan_blocks", &bindings, count)?;
    if blocks > 1 {
        scan(gpu, &sums, blocks)?;
        gpu.dispatch(SCAN, "add_sums", &bindings, count)?;
    }
    Ok(())
}

/// The arrays of `level` with every per-node and per-cell step on the GPU (see the module
/// table), and the device buffers crack filling binds. Nodes within rounding of the
/// isovalue take the CPU's side through `sides` (shared by the levels of one
/// extraction); crack filling must compare with `sides.iso32`.
#[allow(clippy::too_many_arguments)]
pub fn build_level(
    gpu: &Gpu,
    field: &GpuField,
    grid: &CoarseGrid,
    levels: &[u8],
    level: u8,
    sides: &mut Sides,
    iterations: u32,
    normals: bool,
    progress: &mut Progress,
) -> Result<GpuLevel> {
    let k = subdivisions(level);
    let step = FINE_PER_COARSE / k;
    let n = (k + 1) as u64;
    let cells: Vec<u32> = (0..levels.len() as u32)
        .filter(|&i| levels[i as usize] == level)
        .collect();
    let mut out = LevelArrays {
        level,
        cells,
        // The scan's extra entry, there with no cells too (as on the CPU).
        triangle_offsets: vec![0],
        ..LevelArrays::default()
    };
    if out.cells.is_empty() {
        return Ok(GpuLevel {
            arrays: out,
            buffers: None,
        });
    }
    let steps = iterations + (3 - level as u32);
    // Lattice coordinates must stay exact in f32 (see level.wgsl).
    let largest = grid.cells.iter().max().copied().unwrap_or(0) as u64 * FINE_PER_COARSE as u64;
    if largest << iterations >= 1 << 24 {
        return Err(Error::InvalidParameter {
            name: "backend",
            message: format!(
                "the GPU back end needs {largest} finest nodes × 2^{iterations} bisection units below 2^24 along each axis; use fewer bisection iterations, a larger grid factor or the CPU"
            ),
        });
    }
    let mut uniform = LevelUniform {
        fine: grid.fine as f32,
        iso: sides.iso32,
        k,
        step,
        shift: iterations,
        steps,
        cells_x: grid.cells[0],
        cells_y: grid.cells[1],
        count: 0,
        normals: normals as u32,
        unit: (grid.fine / (1u64 << iterations) as f64) as f32,
        margin: sides.margin,
    };
    let settled_before = sides.settled();
    let source = level_source();
    let node_count = out.cells.len() as u64 * n * n * n;
    let sub_count = out.cells.len() as u64 * (k as u64).pow(3);
    let count = |c: u64| u32::try_from(c).map_err(gpu_error);

    // Values at the nodes, settled.
    let cells_buf = gpu.upload("cells", &out.cells);
    let values = gpu.zeroed::<f32>("values", node_count as usize)?;
    uniform.count = count(node_count)?;
    let u = gpu.uniform("level", &uniform);
    let [f0, f1, f2] = field.bindings();
    sides.settle(gpu, |sides, pending, first| {
        let settled = [
            (3, &u),
            (4, &cells_buf),
            (5, &values),
            (23, sides.table()),
            (24, pending),
        ];
        if first {
            let bindings = [
                f0, f1, f2, settled[0], settled[1], settled[2], settled[3], settled[4],
            ];
            gpu.dispatch(source, "node_values", &bindings, node_count)
        } else {
            gpu.dispatch(source, "settle_values", &settled, node_count)
        }
    })?;
    progress.report(0.4)?;

    // Cases and counts; one extra zero entry so the scans end with the totals.
    let cases = gpu.zeroed::<u32>("cases", sub_count as usize)?;
    let tri_offsets = gpu.zeroed::<u32>("triangle offsets", sub_count as usize + 1)?;
    let edge_offsets = gpu.zeroed::<u32>("edge offsets", sub_count as usize + 1)?;
    let table = gpu.upload("case table", &table_words());
    uniform.count = count(sub_count)?;
    let u = gpu.uniform("level", &uniform);
    gpu.dispatch(
        source,
        "cell_cases",
        &[
            (3, &u),
            (5, &values),
            (6, &cases),
            (7, &tri_offsets),
            (8, &edge_offsets),
            (9, &table),
        ],
        sub_count,
    )?;
    scan(gpu, &tri_offsets, sub_count + 1)?;
    scan(gpu, &edge_offsets, sub_count + 1)?;
    let tri_total = gpu.read::<u32>(&tri_offsets, sub_count as usize + 1)?;
    let edge_total = *gpu
        .read::<u32>(&edge_offsets, sub_count as usize + 1)?
        .last()
        .expect("the scan has its extra entry");
    let triangles_total = *tri_total.last().expect("the scan has its extra entry");

    // Cut edges and triangles at their offsets.
    let edges_out = gpu.zeroed::<[u32; 4]>("cut edges", edge_total as usize)?;
    let tris_out = gpu.zeroed::<[u32; 2]>("triangles", 3 * triangles_total as usize)?;
    gpu.dispatch(
        source,
        "emit",
        &[
            (3, &u),
            (4, &cells_buf),
            (5, &values),
            (6, &cases),
            (7, &tri_offsets),
            (8, &edge_offsets),
            (9, &table),
            (10, &edges_out),
            (11, &tris_out),
        ],
        sub_count,
    )?;
    let mut cut: Vec<[u32; 4]> = gpu.read(&edges_out, edge_total as usize)?;
    let tri_keys: Vec<[u32; 2]> = gpu.read(&tris_out, 3 * triangles_total as usize)?;
    let key = |w: [u32; 2]| w[0] as u64 | (w[1] as u64) << 32;
    cut.par_sort_unstable_by_key(|e| key([e[0], e[1]]));
    cut.dedup_by_key(|e| key([e[0], e[1]]));
    progress.report(0.7)?;

    // Bisection of E.
    let bisect_in = gpu.upload("edges", &cut);
    let bisect_out = gpu.zeroed::<[f32; 4]>("edge points", 2 * cut.len())?;
    uniform.count = count(cut.len() as u64)?;
    let u = gpu.uniform("level", &uniform);
    sides.settle(gpu, |sides, pending, _| {
        let bindings = [
            f0,
            f1,
            f2,
            (3, &u),
            (12, &bisect_in),
            (13, &bisect_out),
            (23, sides.table()),
            (24, pending),
        ];
        gpu.dispatch(source, "bisect", &bindings, cut.len() as u64)
    })?;
    let bisected: Vec<[f32; 4]> = gpu.read(&bisect_out, 2 * cut.len())?;
    let iso64 = sides.iso;
    out.edges = cut.iter().map(|e| key([e[0], e[1]])).collect();
    let sides = &*sides;
    let (points, from_cpu): (Vec<_>, Vec<u64>) = out
        .edges
        .par_iter()
        .enumerate()
        .map(|(i, &key)| {
            let [lo, flo, fhi, _] = bisected[2 * i];
            let [nx, ny, nz, _] = bisected[2 * i + 1];
            let start_inside = f32::from_bits(cut[i][2]) > sides.iso32;
            let ends = (flo as f64, fhi as f64);
            let (lo, ends, evaluations) =
                sides.last_interval(key, iterations, lo as i64, ends, start_inside);
            let point = edge_point(grid, key, iterations, lo, ends, iso64, |_| {
                DVec3::new(nx as f64, ny as f64, nz as f64)
            });
            (point, evaluations)
        })
        .unzip();
    out.points = points;
    let edges = &out.edges;
    out.triangles = tri_keys
        .par_chunks(3)
        .map(|t| -> [u32; 3] {
            std::array::from_fn(|j| {
                edges
                    .binary_search(&key(t[j]))
                    .expect("every cut edge of an active sub-cell is in E") as u32
            })
        })
        .collect();
    out.triangle_offsets = tri_total;
    out.evaluations = node_count
        + cut.len() as u64 * (steps as u64 + normals as u64)
        + (sides.settled() - settled_before) as u64
        + from_cpu.iter().sum::<u64>();
    progress.report(1.0)?;
    let buffers = LevelBuffers {
        cells: cells_buf,
        cells_len: out.cells.len(),
        values,
        edges: bisect_in,
        edges_len: cut.len(),
        cases,
        node_count: node_count as usize,
        sub_count: sub_count as usize,
    };
    Ok(GpuLevel {
        arrays: out,
        buffers: Some(buffers),
    })
}

// SAFETY: plain `repr(C)` structs of 4-byte scalars without padding; any bits are valid.
unsafe impl bytemuck::Zeroable for LevelUniform {}
unsafe impl bytemuck::Pod for LevelUniform {}
unsafe impl bytemuck::Zeroable for ScanUniform {}
unsafe impl bytemuck::Pod for ScanUniform {}
