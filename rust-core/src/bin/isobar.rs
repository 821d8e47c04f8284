//! The `isobar` command line: SPH isosurfaces from particle files, and the demo.

use clap::{Args, Parser, Subcommand};
use glam::DVec3;
use isobar::correctors::{self, Extraction, Lattice, Params, Stats, Trim};
use isobar::field::kernel::Kernel;
use isobar::field::particles::ParticleData;
use isobar::field::sph::{Mass, Quantity, SmoothingLength, SphField, SphSettings, Volumes};
use isobar::field::DEFAULT_MEMORY_BUDGET;
use isobar::gpu::Backend;
use isobar::{baseline, io, terminal, Error, Result};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

/// The demo frame: a SPlisHSPlasH dam break (see rust-core/data/README.md).
const DEMO_FRAME: &[u8] = include_bytes!("../../data/demo_dam_break.npz");

#[derive(Parser)]
#[command(
    name = "isobar",
    version,
    about = "Exact isosurfaces of SPH particle data"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Extract isosurfaces of an SPH field by Marching Correctors.
    Sph(Box<SphArgs>),
    /// Adaptive crack-free surface on a 3-level grid (one isovalue; the SPH options as for `sph`).
    Adaptive {
        #[command(flatten)]
        common: Box<FieldArgs>,
        #[command(flatten)]
        adaptive: isobar::adaptive::cli::AdaptiveArgs,
    },
    /// Extract the free surface of the embedded dam-break frame (46,656 SPlisHSPlasH
    /// particles), its velocity, pressure and density carried onto the vertices.
    Demo {
        /// Where to write the surface (.ply, .obj or .vtp).
        #[arg(short, long, default_value = "isobar_demo.ply")]
        output: PathBuf,
        /// Print no progress bar.
        #[arg(long)]
        quiet: bool,
    },
    /// Sample an isosurface of high-order finite elements (Lagrange cells in a .vtu) with a
    /// particle system; writes oriented points with radii.
    Fe(Box<isobar::highorder::cli::FeArgs>),
    /// List the particles and arrays of a file.
    Info { input: PathBuf },
    /// Precompute an isovalue-slider store from a volume (.vti, .nrrd, .npy, .raw).
    SlideBuild(Box<isobar::slider::cli::BuildArgs>),
    /// Slide the isosurface of a store: keys move the isovalue (or isovalues on stdin).
    Slide(isobar::slider::cli::SlideArgs),
}

/// The options `sph` and `adaptive` share: the particles, their SPH field, the output.
#[derive(Args)]
#[command(allow_negative_numbers = true)]
struct FieldArgs {
    /// Particle file (.vtk .vtp .vtu .ply .bgeo .csv .xyz .npy .npz) or a numbered sequence
    /// ('frame_####.vtk', or one file of it with an output pattern holding '#'; with a plain
    /// output, one file is that file alone).
    input: String,
    /// Field: an array name, 'NAME:mag' for a vector's magnitude, 'NAME:K' for component K,
    /// or SumOfWeights for the free surface.
    #[arg(long, default_value = "SumOfWeights")]
    field: String,
    /// Isovalue(s), comma separated.
    #[arg(
        long,
        value_delimiter = ',',
        required = true,
        allow_hyphen_values = true
    )]
    iso: Vec<f64>,
    /// Kernel: cubic, wendland, quintic, quadratic.
    #[arg(long, default_value = "cubic")]
    kernel: Kernel,
    /// Constant smoothing length h.
    #[arg(long)]
    h: Option<f64>,
    /// Per-particle smoothing length array (default: 'h', 'smoothing_length' or 'hsml' if present).
    #[arg(long)]
    h_array: Option<String>,
    /// Multiplies every smoothing length (previews: 0.75, 0.5).
    #[arg(long, default_value_t = 1.0)]
    h_scale: f64,
    /// Virtual cell size in units of the smallest h.
    #[arg(long, default_value_t = 0.5)]
    grid_factor: f64,
    /// Per-particle volume array (m/ρ).
    #[arg(long)]
    volume_array: Option<String>,
    /// Density array; volumes = mass / density (needs --mass or --mass-array).
    #[arg(long)]
    density_array: Option<String>,
    /// Constant particle mass.
    #[arg(long)]
    mass: Option<f64>,
    /// Per-particle mass array.
    #[arg(long)]
    mass_array: Option<String>,
    /// Normalise the field by the sum of weights (Shepard).
    #[arg(long)]
    shepard: bool,
    /// No vertex normals.
    #[arg(long)]
    no_normals: bool,
    /// Particle arrays to interpolate onto the surface, comma separated.
    #[arg(long, value_delimiter = ',')]
    attributes: Vec<String>,
    /// Memory budget in GiB for extent-sized structures.
    #[arg(long, default_value_t = (DEFAULT_MEMORY_BUDGET >> 30) as f64)]
    memory_budget: f64,
    /// Where the work runs: cpu, gpu (wgpu; an error naming why when there is no GPU
    /// adapter) or auto (a hardware GPU when there is one, else the CPU, saying why).
    /// `sph` runs the seed cells' neighbour search there (same surface on every back end;
    /// --full-grid is CPU only); `adaptive` the per-level grids and crack filling. The
    /// statistics say which ran.
    #[arg(long, default_value = "cpu")]
    backend: String,
    /// Write the statistics as JSON here.
    #[arg(long)]
    stats_json: Option<PathBuf>,
    /// Print no progress bar and no table.
    #[arg(long)]
    quiet: bool,
    /// Output mesh (.ply .obj .vtp); for sequences a pattern with '#' for the frame number.
    #[arg(short, long)]
    output: PathBuf,
}

/// Marching Correctors' own options (`adaptive` has none of them: its help lists only
/// what it takes).
#[derive(Args)]
#[command(allow_negative_numbers = true)]
struct CorrectorsArgs {
    /// Preview: linear interpolation, no correction, face normals.
    #[arg(long)]
    preview: bool,
    /// Relative tolerance of the correction.
    #[arg(long, default_value_t = 1e-6)]
    tolerance: f64,
    /// Trimming thresholds on the sum of weights: NODE,VERTEX (default 0.1,0.5; off for
    /// the SumOfWeights field).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    trim: Option<Vec<f64>>,
    /// No trimming at free surfaces.
    #[arg(long, conflicts_with = "trim")]
    no_trim: bool,
    /// Put the virtual grid on a fixed lattice X,Y,Z,CELL (nodes at origin + integer
    /// multiples of CELL; replaces --grid-factor), so separately extracted pieces line up.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    lattice: Option<Vec<f64>>,
    /// Keep only the surface in cells whose lowest corner lies in [X0,Y0,Z0, X1,Y1,Z1);
    /// particles outside still shape the field (a halo).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    clip: Option<Vec<f64>>,
    /// Resample onto the full grid and run plain marching cubes (the baseline).
    #[arg(long)]
    full_grid: bool,
}

#[derive(Args)]
struct SphArgs {
    #[command(flatten)]
    common: FieldArgs,
    #[command(flatten)]
    correctors: CorrectorsArgs,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    terminal::catch_interrupts();
    if matches!(cli.command, Command::Sph(_) | Command::Demo { .. }) {
        isobar::heap::reuse_freed_memory();
    }
    let result = match cli.command {
        Command::Sph(args) => run_sph(&args),
        Command::Adaptive { common, adaptive } => run_adaptive(&common, &adaptive),
        Command::Demo { output, quiet } => run_demo(&output, quiet),
        Command::Info { input } => run_info(&input),
        Command::SlideBuild(args) => isobar::slider::cli::run_build(&args),
        Command::Slide(args) => isobar::slider::cli::run_slide(&args),
        Command::Fe(args) => isobar::highorder::cli::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(Error::Cancelled) if terminal::interrupted() => {
            eprintln!("isobar: interrupted; no file was left half-written");
            terminal::interrupted_exit_code()
        }
        Err(e) => {
            eprintln!("isobar: error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn settings_from(args: &FieldArgs, data: &ParticleData) -> Result<SphSettings> {
    let smoothing_length = match (args.h, &args.h_array) {
        (Some(h), None) => SmoothingLength::Constant(h),
        (None, Some(name)) => SmoothingLength::Array(name.clone()),
        (Some(_), Some(_)) => {
            return Err(Error::InvalidParameter {
                name: "h",
                message: "give either --h or --h-array, not both".into(),
            })
        }
        (None, None) => ["h", "smoothing_length", "hsml"]
            .iter()
            .find(|n| data.attribute(n).is_some())
            .map(|n| SmoothingLength::Array(n.to_string()))
            .ok_or_else(|| Error::InvalidParameter {
                name: "h",
                message: format!(
                    "the data has no smoothing-length array (arrays: {}); pass --h VALUE or --h-array NAME",
                    data.attribute_names()
                ),
            })?,
    };
    let mass = match (args.mass, &args.mass_array) {
        (Some(m), _) => Some(Mass::Constant(m)),
        (None, Some(name)) => Some(Mass::Array(name.clone())),
        (None, None) => None,
    };
    let volumes = match (&args.volume_array, &args.density_array) {
        (Some(v), _) => Volumes::Array(v.clone()),
        (None, Some(rho)) => Volumes::MassDensity {
            mass: mass.ok_or_else(|| Error::InvalidParameter {
                name: "density-array",
                message: "volumes from density need a mass: pass --mass VALUE or --mass-array NAME"
                    .into(),
            })?,
            density: rho.clone(),
        },
        (None, None) => Volumes::Computed { mass },
    };
    if args.memory_budget.is_nan() || args.memory_budget <= 0.0 {
        return Err(Error::InvalidParameter {
            name: "memory-budget",
            message: format!("must be positive, got {}", args.memory_budget),
        });
    }
    let settings = SphSettings {
        kernel: args.kernel,
        smoothing_length,
        h_scale: args.h_scale,
        volumes,
        quantity: Quantity::parse(&args.field),
        shepard: args.shepard,
        memory_budget: (args.memory_budget * (1u64 << 30) as f64) as u64,
    };
    Ok(settings)
}

/// Checks that a comma-separated option has exactly `n` values.
fn exactly(values: &Option<Vec<f64>>, n: usize, name: &'static str, form: &str) -> Result<()> {
    match values {
        Some(v) if v.len() != n => Err(Error::InvalidParameter {
            name,
            message: format!(
                "takes {n} comma-separated numbers ({form}), got {}",
                v.len()
            ),
        }),
        _ => Ok(()),
    }
}

fn params_from(args: &SphArgs, quantity: &Quantity) -> Result<Params> {
    let (common, own) = (&args.common, &args.correctors);
    exactly(&own.trim, 2, "trim", "NODE,VERTEX")?;
    exactly(&own.lattice, 4, "lattice", "X,Y,Z,CELL")?;
    exactly(&own.clip, 6, "clip", "X0,Y0,Z0,X1,Y1,Z1")?;
    let trim = if own.no_trim {
        None
    } else if let Some(t) = &own.trim {
        Some(Trim {
            node: t[0],
            vertex: t[1],
        })
    } else if *quantity == Quantity::SumOfWeights {
        // Trimming a free surface against its own field would cut it away.
        None
    } else {
        Some(Trim::default())
    };
    Ok(Params {
        memory_budget: (common.memory_budget * (1u64 << 30) as f64) as u64,
        isovalues: common.iso.clone(),
        grid_factor: common.grid_factor,
        correct: !own.preview,
        tolerance: own.tolerance,
        trim,
        normals: !common.no_normals,
        attributes: common.attributes.clone(),
        lattice: own.lattice.as_ref().map(|l| Lattice {
            origin: DVec3::new(l[0], l[1], l[2]),
            cell_size: l[3],
        }),
        clip: own
            .clip
            .as_ref()
            .map(|c| (DVec3::new(c[0], c[1], c[2]), DVec3::new(c[3], c[4], c[5]))),
        backend: Backend::parse(&common.backend)?,
    })
}

/// When `--backend auto` will run on the CPU, a line saying why (unless quiet).
fn say_backend(args: &FieldArgs) -> Result<()> {
    if Backend::parse(&args.backend)? == Backend::Auto && !args.quiet {
        if let Some(why) = isobar::gpu::auto_fallback_reason() {
            eprintln!("backend auto: running on the CPU ({why})");
        }
    }
    Ok(())
}

fn run_sph(args: &SphArgs) -> Result<()> {
    let common = &args.common;
    say_backend(common)?;
    let frames = io::frames_for(&common.input, &common.output, common.stats_json.as_deref())?;
    io::check_frame_outputs(
        &frames,
        &common.output,
        common.stats_json.as_deref(),
        io::check_mesh_output,
    )?;
    for path in &frames {
        let output = io::frame_output(&common.output, path);
        let t = Instant::now();
        let data = io::read_particles(path)?;
        let read_s = t.elapsed().as_secs_f64();
        let settings = settings_from(common, &data).map_err(|e| e.in_file(path))?;
        let params = params_from(args, &settings.quantity)?;
        let full_grid = args.correctors.full_grid;
        let (extraction, build_s) = extract(&data, &settings, &params, full_grid, common.quiet)
            .map_err(|e| e.in_file(path))?;
        io::write_mesh(&output, &extraction.mesh)?;
        io::print_warnings(path, &extraction.stats.warnings);
        if !common.quiet {
            print_stats(path, &data, &extraction.stats, read_s, build_s);
            println!("surface written to {}", output.display());
        }
        if let Some(json) = &common.stats_json {
            let json = io::frame_output(json, path);
            write_stats_json(&json, &data, &extraction.stats, read_s, build_s)?;
        }
    }
    Ok(())
}

fn run_adaptive(field: &FieldArgs, adaptive: &isobar::adaptive::cli::AdaptiveArgs) -> Result<()> {
    let common = isobar::adaptive::cli::Common {
        input: &field.input,
        output: &field.output,
        iso: &field.iso,
        grid_factor: field.grid_factor,
        normals: !field.no_normals,
        attributes: &field.attributes,
        memory_budget: (field.memory_budget * (1u64 << 30) as f64) as u64,
        quiet: field.quiet,
        stats_json: field.stats_json.as_deref(),
        backend: Backend::parse(&field.backend)?,
    };
    say_backend(field)?;
    isobar::adaptive::cli::run(adaptive, &common, &|data| settings_from(field, data))
}

fn run_demo(output: &Path, quiet: bool) -> Result<()> {
    let data = io::read_particles_from_bytes(DEMO_FRAME, "npz", "embedded demo frame")?;
    let settings = SphSettings {
        smoothing_length: SmoothingLength::Array("h".into()),
        ..SphSettings::default()
    };
    let params = Params {
        isovalues: vec![0.6],
        grid_factor: 0.375,
        trim: None,
        attributes: demo_attributes(&data),
        ..Params::default()
    };
    let (extraction, build_s) = extract(&data, &settings, &params, false, quiet)?;
    io::write_mesh(output, &extraction.mesh)?;
    if !quiet {
        print_stats(
            Path::new("embedded dam-break frame"),
            &data,
            &extraction.stats,
            0.0,
            build_s,
        );
    }
    let abs = std::fs::canonicalize(output).unwrap_or_else(|_| output.to_path_buf());
    println!(
        "free surface of {} particles: {} triangles written to {}",
        data.len(),
        extraction.mesh.triangles.len(),
        abs.display()
    );
    Ok(())
}

fn demo_attributes(data: &ParticleData) -> Vec<String> {
    ["velocity", "pressure", "density"]
        .iter()
        .filter(|n| data.attribute(n).is_some())
        .map(|n| n.to_string())
        .collect()
}

/// Prints `text` to stdout; a closed pipe (`isobar info f | head`) is not an error.
fn emit(text: &str) {
    use std::io::Write;
    let _ = std::io::stdout().lock().write_all(text.as_bytes());
}

fn run_info(input: &Path) -> Result<()> {
    use std::fmt::Write;
    let data = io::read_particles(input)?;
    let (lo, hi) = isobar::field::neighbours::bounds(&data.positions);
    let mut text = String::new();
    let _ = writeln!(text, "{}: {} particles", input.display(), data.len());
    let _ = writeln!(text, "bounds: {:?} .. {:?}", lo.to_array(), hi.to_array());
    for a in &data.attributes {
        let (mn, mx) = a
            .data
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                (l.min(v), h.max(v))
            });
        let _ = writeln!(
            text,
            "  {:<24} {} component(s), range {mn} .. {mx}",
            a.name, a.components
        );
    }
    emit(&text);
    Ok(())
}

/// Builds the field and extracts, with a terminal progress bar.
fn extract(
    data: &ParticleData,
    settings: &SphSettings,
    params: &Params,
    full_grid: bool,
    quiet: bool,
) -> Result<(Extraction, f64)> {
    terminal::with_progress(quiet, |progress| {
        progress.window(0.0, 0.1);
        let t = Instant::now();
        let field = SphField::build(data, settings, progress)?;
        let build_s = t.elapsed().as_secs_f64();
        progress.window(0.1, 1.0);
        let result = if full_grid {
            baseline::extract(&field, data, params, progress)
        } else {
            correctors::extract(&field, data, params, progress)
        };
        Ok((result?, build_s))
    })
}

fn stats_rows(
    data: &ParticleData,
    s: &Stats,
    read_s: f64,
    build_s: f64,
) -> Vec<(&'static str, String)> {
    vec![
        ("particles", data.len().to_string()),
        ("backend", s.backend.name().to_string()),
        ("virtual cells", s.virtual_cells.to_string()),
        ("seed cells", s.seed_cells.to_string()),
        ("non-intersected seeds", s.non_intersected_seeds.to_string()),
        (
            "discarded cells (node threshold)",
            s.discarded_cells.to_string(),
        ),
        ("cells used", s.cells_used.to_string()),
        ("vertices", s.vertices.to_string()),
        ("triangles", s.triangles.to_string()),
        ("field evaluations", s.field_evaluations.to_string()),
        ("node evaluations", s.node_evaluations.to_string()),
        ("cache hit ratio", format!("{:.4}", s.cache_hit_ratio)),
        ("correction mean", format!("{:.3e}", s.correction_mean)),
        ("correction max", format!("{:.3e}", s.correction_max)),
        ("correction stdev", format!("{:.3e}", s.correction_stdev)),
        ("unconverged vertices", s.unconverged_vertices.to_string()),
        ("trim cut points", s.trim_cut_points.to_string()),
        ("time: read (s)", format!("{read_s:.3}")),
        ("time: field build (s)", format!("{build_s:.3}")),
        ("time: seed cells (s)", format!("{:.3}", s.timings.seeds)),
        ("time: tracking (s)", format!("{:.3}", s.timings.tracking)),
        ("time: vertices (s)", format!("{:.3}", s.timings.vertices)),
        ("time: trimming (s)", format!("{:.3}", s.timings.trimming)),
        (
            "time: attributes (s)",
            format!("{:.3}", s.timings.attributes),
        ),
        (
            "time: extraction total (s)",
            format!("{:.3}", s.timings.total),
        ),
    ]
}

fn print_stats(source: &Path, data: &ParticleData, s: &Stats, read_s: f64, build_s: f64) {
    let mut text = format!("{}\n", source.display());
    for (k, v) in stats_rows(data, s, read_s, build_s) {
        text += &format!("  {k:<34} {v:>14}\n");
    }
    emit(&text);
}

fn write_stats_json(
    path: &Path,
    data: &ParticleData,
    s: &Stats,
    read_s: f64,
    build_s: f64,
) -> Result<()> {
    let body: Vec<String> = stats_rows(data, s, read_s, build_s)
        .into_iter()
        .map(|(k, v)| {
            let key = k.replace([' ', ':', '(', ')'], "_").replace("__", "_");
            let key = key.trim_matches('_').to_string();
            let value = if v.parse::<f64>().is_ok() {
                v
            } else {
                format!("\"{v}\"")
            };
            format!("  \"{key}\": {value}")
        })
        .collect();
    let text = format!("{{\n{}\n}}\n", body.join(",\n"));
    std::fs::write(path, text).map_err(|e| Error::io(path, e))
}
