//! Crack filling on the GPU (`shaders/cracks.wgsl`), giving the same fill triangles, in
//! the same order, as `adaptive::cracks::fill`: one invocation per transition face counts
//! its triangles, the counts are scanned on the device (`level::scan`), and a second pass
//! writes each face's triangles at its offset. The pattern table is the generated
//! `adaptive::crack_table`, uploaded as it is.
//!
//! The fine side of a face is level 2 or 3. Its cells, node values and cut-edge keys are
//! the buffers `gpu::level` computed them in ([`LevelBuffers`]), bound as they are: no
//! readback, no upload, and the kernel's sign tests see exactly the values the level's
//! own cases came from. Each pass runs once per fine level, over the faces whose fine
//! side it is, so one binding layout (within the default eight storage buffers) serves
//! both levels; the counts of both land in one array, scanned once.

use super::device::{gpu_error, Gpu};
use super::level::{level_source, scan, LevelBuffers, LevelUniform};
use crate::adaptive::crack_table::CRACK_PATTERNS;
use crate::adaptive::cracks::TransitionFace;
use crate::adaptive::grid::CoarseGrid;
use crate::error::Result;

/// `Fine` of cracks.wgsl: the fine level a pass handles.
#[repr(C)]
#[derive(Clone, Copy, Default)]
struct Fine {
    /// The coarse side's level (1 or 2): faces whose lower level this is.
    coarse: u32,
    cells_len: u32,
    edges_len: u32,
    pad: u32,
}

/// A fill vertex the kernel could not find (`MISSING` in cracks.wgsl).
const MISSING: u32 = u32::MAX;

/// Fill triangles of `faces` as (level, index into that level's E) triples, equal to
/// `adaptive::cracks::fill(grid, levels, arrays, faces, iso, progress)`. `fine` holds the device
/// buffers of levels 2 and 3 (None for a level without cells) as `gpu::level` left them;
/// `iso` is the f32 isovalue the level kernels compared with.
pub fn fill(
    gpu: &Gpu,
    grid: &CoarseGrid,
    levels: &[u8],
    fine: [Option<&LevelBuffers>; 2],
    faces: &[TransitionFace],
    iso: f32,
) -> Result<Vec<[(u8, u32); 3]>> {
    if faces.is_empty() {
        return Ok(Vec::new());
    }
    let count = |c: usize| u32::try_from(c).map_err(gpu_error);
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
    let faces_buf = gpu.upload("transition faces", &face_words);
    let levels_buf = gpu.upload("cell levels", &level_words);
    let patterns_buf = gpu.upload("crack patterns", &patterns);
    // One extra zero entry so the scan ends with the total.
    let counts = gpu.zeroed::<u32>("fill counts", faces.len() + 1)?;
    // The fine levels that exist, with their pass uniforms.
    let passes: Vec<(&LevelBuffers, wgpu::Buffer)> = fine
        .iter()
        .zip(1u32..)
        .filter_map(|(b, coarse)| b.map(|b| (b, coarse)))
        .map(|(b, coarse)| {
            let u = Fine {
                coarse,
                cells_len: count(b.cells_len)?,
                edges_len: count(b.edges_len)?,
                pad: 0,
            };
            Ok((b, gpu.uniform("fine level", &u)))
        })
        .collect::<Result<_>>()?;
    let source = level_source();
    let threads = faces.len() as u64;
    let run = |entry, out: &wgpu::Buffer| -> Result<()> {
        for (b, u) in &passes {
            gpu.dispatch(
                source,
                entry,
                &[
                    (3, &uniform),
                    (4, &b.cells),
                    (5, &b.values),
                    (12, &b.edges),
                    (14, u),
                    (15, &faces_buf),
                    (16, &levels_buf),
                    (20, &patterns_buf),
                    (21, &counts),
                    (22, out),
                ],
                threads,
            )?;
        }
        Ok(())
    };
    // The counting pass names `fills` too (it shares the face walk with the writing one).
    run("count_fills", &gpu.zeroed::<[u32; 4]>("no fills yet", 1)?)?;
    scan(gpu, &counts, threads + 1)?;
    let total = gpu.read_at::<u32>(&counts, faces.len(), 1)?[0] as usize;
    let fills = gpu.zeroed::<[u32; 4]>("fills", total)?;
    run("emit_fills", &fills)?;
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
unsafe impl bytemuck::Zeroable for Fine {}
unsafe impl bytemuck::Pod for Fine {}
