//! The `isobar adaptive` subcommand's body: the binary parses the SPH field options
//! shared with `isobar sph` and hands them here with these adaptive ones.

use super::{extract, extract_sph, extract_sph_carrying, grid_for, Extraction, Params, Stats};
use crate::correctors;
use crate::error::{Error, Result};
use crate::field::particles::ParticleData;
use crate::field::sph::carried::Carried;
use crate::field::sph::{SphField, SphSettings};
use crate::gpu::Backend;
use crate::io;
use crate::terminal::with_progress;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// Options of `isobar adaptive` beyond the SPH field's.
#[derive(clap::Args, Clone, Debug)]
pub struct AdaptiveArgs {
    /// Splash criterion: coarse cells holding 1..=N particles become level 3 (the paper's
    /// rule is 1; 0, the default, leaves the levels to the error criterion, which at
    /// finest cells of 0.375–0.5 h gives far fewer triangles within the same distance).
    #[arg(long, default_value_t = Params::default().splash_threshold)]
    pub splash_threshold: u32,
    /// Layers of neighbour cells raised to level 3 around each splash cell (0 = the
    /// paper's criterion alone).
    #[arg(long, default_value_t = Params::default().splash_dilation)]
    pub splash_dilation: u32,
    /// Error criterion: each cell at the surface takes the lowest level whose surface lies
    /// within this many finest cells of the finest level's there (0 = off, the splash
    /// criterion alone).
    #[arg(long, default_value_t = Params::default().max_error)]
    pub max_error: f64,
    /// Turn off the hidden-surface rule (cells rise until their sub-cell corners see the
    /// side of the isovalue the field at each of their particles is on).
    #[arg(long)]
    pub no_hidden_surfaces: bool,
    /// Bisection halvings n on level-3 edges (n+1 on level 2, n+2 on level 1); 0: linear
    /// between the finest nodes, as uniform marching cubes.
    #[arg(long, default_value_t = Params::default().bisection_iterations)]
    pub bisection_iterations: u32,
    /// Also run uniform marching cubes at the finest level (the full-grid baseline and the
    /// adaptive code with every cell at level 3) and print time, triangles, memory and
    /// the Hausdorff distance; both back ends (cpu, gpu) are timed too.
    #[arg(long)]
    pub compare: bool,
}

/// What the binary passes from its shared SPH options.
pub struct Common<'a> {
    pub input: &'a str,
    pub output: &'a Path,
    pub iso: &'a [f64],
    pub grid_factor: f64,
    pub normals: bool,
    /// Particle arrays to carry onto the vertices.
    pub attributes: &'a [String],
    pub memory_budget: u64,
    pub quiet: bool,
    pub stats_json: Option<&'a Path>,
    /// `--backend`: where the per-level work and crack filling run.
    pub backend: Backend,
}

/// Runs the subcommand on every frame of `common.input`.
pub fn run(
    args: &AdaptiveArgs,
    common: &Common,
    settings: &dyn Fn(&ParticleData) -> Result<SphSettings>,
) -> Result<()> {
    let [isovalue] = common.iso else {
        return Err(Error::InvalidParameter {
            name: "iso",
            message: format!(
                "the adaptive surface takes one isovalue, got {}",
                common.iso.len()
            ),
        });
    };
    let params = Params {
        isovalue: *isovalue,
        grid_factor: common.grid_factor,
        splash_threshold: args.splash_threshold,
        splash_dilation: args.splash_dilation,
        max_error: args.max_error,
        hidden_surfaces: !args.no_hidden_surfaces,
        bisection_iterations: args.bisection_iterations,
        normals: common.normals,
        memory_budget: common.memory_budget,
        backend: common.backend,
    };
    params.validate()?;
    let frames = io::frames_for(common.input, common.output, common.stats_json)?;
    io::check_frame_outputs(
        &frames,
        common.output,
        common.stats_json,
        io::check_mesh_output,
    )?;
    for path in &frames {
        let output = io::frame_output(common.output, path);
        let data = io::read_particles(path)?;
        let (field, build_s, out) = with_progress(common.quiet, |progress| {
            progress.window(0.0, 0.1);
            let t = Instant::now();
            let field = settings(&data)
                .and_then(|s| SphField::build(&data, &s, progress))
                .map_err(|e| e.in_file(path))?;
            // A missing array is refused before the surface is made.
            let carried =
                Carried::new(&field, &data, common.attributes).map_err(|e| e.in_file(path))?;
            let build_s = t.elapsed().as_secs_f64();
            let out = extract_sph_carrying(&field, &carried, &params, (0.1, 1.0), progress)?;
            Ok((field, build_s, out))
        })?;
        io::write_mesh(&output, &out.mesh)?;
        io::print_warnings(path, &out.stats.warnings);
        let mut rows = rows(&data, &out.stats, build_s);
        if args.compare {
            rows.extend(compare(&field, &params, &out)?);
            rows.extend(compare_backends(&field, &params)?);
        }
        if !common.quiet {
            let mut text = format!("{}\n", path.display());
            for (k, v) in &rows {
                let _ = writeln!(text, "  {k:<40} {v:>14}");
            }
            let _ = writeln!(text, "surface written to {}", output.display());
            print!("{text}");
        }
        if let Some(json) = common.stats_json {
            let json = io::frame_output(json, path);
            write_json(&json, &rows)?;
        }
    }
    Ok(())
}

fn rows(data: &ParticleData, s: &Stats, build_s: f64) -> Vec<(String, String)> {
    let mut r: Vec<(String, String)> = vec![
        ("particles".into(), data.len().to_string()),
        ("backend".into(), s.backend.name().to_string()),
        ("coarse cells".into(), s.coarse_cells.to_string()),
    ];
    for l in 0..3 {
        r.push((
            format!("level {} cells", l + 1),
            s.cells_per_level[l].to_string(),
        ));
        r.push((
            format!("level {} triangles", l + 1),
            s.triangles_per_level[l].to_string(),
        ));
    }
    r.extend([
        (
            "error criterion: cells to level 2".into(),
            s.error_raised[0].to_string(),
        ),
        (
            "error criterion: cells to level 3".into(),
            s.error_raised[1].to_string(),
        ),
        (
            "hidden-surface rule: cells raised".into(),
            s.hidden_raised.to_string(),
        ),
        ("transition faces".into(), s.transition_faces.to_string()),
        ("crack triangles".into(), s.crack_triangles.to_string()),
        ("vertices".into(), s.vertices.to_string()),
        ("triangles".into(), s.triangles.to_string()),
        ("field evaluations".into(), s.field_evaluations.to_string()),
        ("array bytes".into(), s.array_bytes.to_string()),
        ("time: field build (s)".into(), format!("{build_s:.3}")),
        (
            "time: levels (s)".into(),
            format!("{:.3}", s.timings.levels),
        ),
        (
            "time: level surfaces (s)".into(),
            format!("{:.3}", s.timings.surfaces),
        ),
        (
            "time: crack filling (s)".into(),
            format!("{:.3}", s.timings.cracks),
        ),
        (
            "time: assembly (s)".into(),
            format!("{:.3}", s.timings.assembly),
        ),
        (
            "time: attributes (s)".into(),
            format!("{:.3}", s.timings.attributes),
        ),
        (
            "time: adaptive total (s)".into(),
            format!("{:.3}", s.timings.total),
        ),
    ]);
    r
}

/// Uniform marching cubes at the finest level, two ways: the full-grid baseline (linear
/// edge points, the usual route) and this extractor with every cell at level 3.
fn compare(
    field: &SphField,
    params: &Params,
    adaptive: &Extraction,
) -> Result<Vec<(String, String)>> {
    let grid = grid_for(field, params)?;
    let t = Instant::now();
    // The comparisons run without a bar of their own, but an interrupt still stops them.
    let uniform = with_progress(true, |p| {
        extract(field, &grid, &vec![3u8; grid.cell_count()], params, p)
    })?;
    let uniform_s = t.elapsed().as_secs_f64();
    let baseline_params = correctors::Params {
        isovalues: vec![params.isovalue],
        grid_factor: params.grid_factor,
        correct: false,
        trim: None,
        normals: params.normals,
        memory_budget: params.memory_budget,
        ..correctors::Params::default()
    };
    let t = Instant::now();
    let empty = ParticleData::default();
    let baseline = with_progress(true, |p| {
        crate::baseline::extract(field, &empty, &baseline_params, p)
    })?;
    let baseline_s = t.elapsed().as_secs_f64();
    let fine = grid.fine;
    let d = crate::mesh::hausdorff::hausdorff(&adaptive.mesh, &uniform.mesh, 8.0 * fine);
    let baseline_nodes = baseline.stats.node_evaluations;
    let ratio = |n: u64| n as f64 / adaptive.mesh.triangles.len().max(1) as f64;
    Ok(vec![
        ("finest cell".into(), format!("{fine:.4e}")),
        (
            "uniform L3: triangles".into(),
            uniform.stats.triangles.to_string(),
        ),
        (
            "uniform L3: triangles / adaptive".into(),
            format!("{:.2}", ratio(uniform.stats.triangles)),
        ),
        (
            "uniform L3: array bytes".into(),
            uniform.stats.array_bytes.to_string(),
        ),
        ("uniform L3: time (s)".into(), format!("{uniform_s:.3}")),
        (
            "full-grid MC: triangles".into(),
            baseline.stats.triangles.to_string(),
        ),
        (
            "full-grid MC: triangles / adaptive".into(),
            format!("{:.2}", ratio(baseline.stats.triangles)),
        ),
        (
            "full-grid MC: grid bytes".into(),
            (baseline_nodes * 16).to_string(),
        ),
        ("full-grid MC: time (s)".into(), format!("{baseline_s:.3}")),
        (
            "Hausdorff to uniform L3 / finest cell".into(),
            format!("{:.4}", d / fine),
        ),
    ])
}

/// The adaptive extraction on each back end with an adapter for it: time, triangles,
/// array bytes, and the largest distance between the two meshes' positions (same
/// vertex order when the triangle sets agree).
fn compare_backends(field: &SphField, params: &Params) -> Result<Vec<(String, String)>> {
    let mut rows = Vec::new();
    let mut meshes = Vec::new();
    for backend in [Backend::Cpu, Backend::Gpu] {
        let name = backend.name();
        if let Err(e) = backend.resolve() {
            rows.push((format!("{name} adaptive"), e.to_string()));
            continue;
        }
        let p = Params {
            backend,
            ..params.clone()
        };
        let t = Instant::now();
        let out = with_progress(true, |progress| extract_sph(field, &p, progress))?;
        let seconds = t.elapsed().as_secs_f64();
        rows.extend([
            (
                format!("{name} adaptive: time (s)"),
                format!("{seconds:.3}"),
            ),
            (
                format!("{name} adaptive: triangles"),
                out.stats.triangles.to_string(),
            ),
            (
                format!("{name} adaptive: array bytes"),
                out.stats.array_bytes.to_string(),
            ),
        ]);
        meshes.push(out.mesh);
    }
    if let [cpu, gpu] = &meshes[..] {
        let same = cpu.triangles == gpu.triangles;
        rows.push(("gpu == cpu triangles".into(), same.to_string()));
        if same {
            let d = cpu
                .positions
                .iter()
                .zip(&gpu.positions)
                .map(|(a, b)| (0..3).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max))
                .fold(0.0, f64::max);
            rows.push((
                "gpu - cpu max position difference".into(),
                format!("{d:.3e}"),
            ));
        }
    }
    Ok(rows)
}

fn write_json(path: &Path, rows: &[(String, String)]) -> Result<()> {
    let body: Vec<String> = rows
        .iter()
        .map(|(k, v)| {
            let key: String = k
                .chars()
                .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
                .collect();
            let key = key
                .split('_')
                .filter(|s| !s.is_empty())
                .collect::<Vec<_>>()
                .join("_");
            let value = if v.parse::<f64>().is_ok_and(f64::is_finite) {
                v.clone()
            } else if v.parse::<f64>().is_ok() {
                "null".to_string()
            } else {
                format!("\"{v}\"")
            };
            format!("  \"{key}\": {value}")
        })
        .collect();
    let text = format!("{{\n{}\n}}\n", body.join(",\n"));
    io::write_atomically(path, |w| std::io::Write::write_all(w, text.as_bytes()))
}
