//! Crack filling on the GPU (`shaders/cracks.wgsl`), giving the same fill triangles, in
//! the same order, as `adaptive::cracks::fill`: one invocation per transition face counts
//! its triangles, the counts are scanned on the device (`level::scan`), and a second pass
//! writes each face's triangles at its offset. The pattern table is the generated
//! `adaptive::crack_table`, uploaded as it is.
//!
//! The fine levels' node values and cut-edge keys are uploaded from their `LevelArrays`:
//! the GPU's values are f32 widened to f64, so narrowing them back is exact and the
//! kernel's sign tests see the values `gpu::level` computed.

use super::device::{gpu_error, Gpu};
use super::level::{level_source, scan, LevelUniform};
use crate::adaptive::crack_table::CRACK_PATTERNS;
use crate::adaptive::cracks::TransitionFace;
use crate::adaptive::grid::CoarseGrid;
use crate::adaptive::levels::LevelArrays;
use crate::error::Result;

/// `FineLevel` of cracks.wgsl: where one fine level lies in the concatenated arrays.
#[repr(C)]
#[derive(Clone, Copy, Default)]
struct FineLevel {
    cells_start: u32,
    cells_len: u32,
    values_start: u32,
    edges_start: u32,
    edges_len: u32,
    pad: [u32; 3],
}

/// A fill vertex the kernel could not find (`MISSING` in cracks.wgsl).
const MISSING: u32 = u32::MAX;

/// Fill triangles of `faces` as (level, index into that level's E) triples, equal to
/// `adaptive::cracks::fill(grid, levels, arrays, faces, iso)` with `arrays` the three
/// levels in order. `iso` is the f32 isovalue the level kernels compared with.
pub fn fill(
    gpu: &Gpu,
    grid: &CoarseGrid,
    levels: &[u8],
    arrays: &[LevelArrays],
    faces: &[TransitionFace],
    iso: f32,
) -> Result<Vec<[(u8, u32); 3]>> {
    if faces.is_empty() {
        return Ok(Vec::new());
    }
    let count = |c: usize| u32::try_from(c).map_err(gpu_error);
    // Levels 2 and 3 (the fine side of every transition face), one after the other.
    let mut ranges = [FineLevel::default(); 2];
    let (mut cells, mut values, mut edges) = (Vec::new(), Vec::new(), Vec::new());
    for (range, a) in ranges.iter_mut().zip(&arrays[1..3]) {
        *range = FineLevel {
            cells_start: count(cells.len())?,
            cells_len: count(a.cells.len())?,
            values_start: count(values.len())?,
            edges_start: count(edges.len())?,
            edges_len: count(a.edges.len())?,
            pad: [0; 3],
        };
        cells.extend_from_slice(&a.cells);
        values.extend(a.values.iter().map(|&v| v as f32));
        edges.extend(a.edges.iter().map(|&k| [k as u32, (k >> 32) as u32]));
    }
    let patterns: Vec<u32> = CRACK_PATTERNS.iter().flatten().map(|&b| b as u32).collect();
    let face_words: Vec<[u32; 2]> = faces
        .iter()
        .map(|f| Ok([count(f.cell)?, f.axis as u32]))
        .collect::<Result<_>>()?;
    let level_words: Vec<u32> = levels.iter().map(|&l| l as u32).collect();
    let uniform = gpu.uniform(
        "cracks",
        &LevelUniform {
            iso,
            cells_x: grid.cells[0],
            cells_y: grid.cells[1],
            count: count(faces.len())?,
            ..LevelUniform::default()
        },
    );
    let fine = gpu.uniform("fine levels", &ranges);
    let faces_buf = gpu.upload("transition faces", &face_words);
    let levels_buf = gpu.upload("cell levels", &level_words);
    let cells_buf = gpu.upload("fine cells", &cells);
    let values_buf = gpu.upload("fine values", &values);
    let edges_buf = gpu.upload("fine edges", &edges);
    let patterns_buf = gpu.upload("crack patterns", &patterns);
    // One extra zero entry so the scan ends with the total.
    let counts = gpu.zeroed::<u32>("fill counts", faces.len() + 1)?;
    let bindings = [
        (3, &uniform),
        (14, &fine),
        (15, &faces_buf),
        (16, &levels_buf),
        (17, &cells_buf),
        (18, &values_buf),
        (19, &edges_buf),
        (20, &patterns_buf),
        (21, &counts),
    ];
    // The counting pass names `fills` too (it shares the face walk with the writing one).
    let unused = gpu.zeroed::<[u32; 4]>("no fills yet", 1)?;
    let source = level_source();
    let threads = faces.len() as u64;
    gpu.dispatch(
        source,
        "count_fills",
        &[&bindings[..], &[(22, &unused)]].concat(),
        threads,
    )?;
    scan(gpu, &counts, threads + 1)?;
    let total = gpu.read::<u32>(&counts, faces.len() + 1)?[faces.len()] as usize;
    let fills = gpu.zeroed::<[u32; 4]>("fills", total)?;
    gpu.dispatch(
        source,
        "emit_fills",
        &[&bindings[..], &[(22, &fills)]].concat(),
        threads,
    )?;
    gpu.read::<[u32; 4]>(&fills, total)?
        .into_iter()
        .map(|[level, a, b, c]| {
            if [level, a, b, c].contains(&MISSING) {
                return Err(gpu_error(
                    "crack filling met a face whose fine cell or cut edge is not in its level's arrays",
                ));
            }
            Ok([a, b, c].map(|e| (level as u8, e)))
        })
        .collect()
}

// SAFETY: a plain `repr(C)` struct of 4-byte scalars without padding; any bits are valid.
unsafe impl bytemuck::Zeroable for FineLevel {}
unsafe impl bytemuck::Pod for FineLevel {}
