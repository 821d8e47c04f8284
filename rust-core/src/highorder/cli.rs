//! `isobar fe`: sample an isosurface of a high-order FE field in a VTU or Gmsh file and
//! write the oriented points, or (`--method mc`) extract it as triangles with the paper's
//! marching-cubes baseline (the subcommand body; `bin/isobar.rs` only dispatches here).

use super::marching::{extract, McParams};
use super::{sample, Params, Stats};
use crate::error::Result;
use crate::terminal::with_progress;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `isobar fe`.
#[derive(clap::Args, Debug)]
#[command(allow_negative_numbers = true)]
pub struct FeArgs {
    /// A .vtu with Lagrange hexahedra, tetrahedra or wedges (VTK types 72, 71, 73) or
    /// VTK's linear and quadratic tetrahedra, hexahedra, voxels and wedges, or a Gmsh .msh
    /// 4.1 with Lagrange tetrahedra, hexahedra or prisms and $NodeData.
    pub input: PathBuf,
    /// The scalar point array to contour, or NAME:K for component K (from 0) of a vector
    /// point array.
    #[arg(long)]
    pub field: String,
    /// The isovalue C.
    #[arg(long)]
    pub iso: f64,
    /// Output: point samples (.vtp: vertices with Normals, Radius, Element, Reference,
    /// Curvature, Energy), or with `--method mc` a triangle mesh (.vtp, .ply, .obj).
    #[arg(short, long)]
    pub output: PathBuf,
    /// samples: the particle system; mc: marching cubes with numerical inversion and
    /// Newton along edges (the paper's baseline).
    #[arg(long, value_enum, default_value_t = Method::Samples)]
    pub method: Method,
    /// Particle spacing s on flat parts, or the grid cell size with `--method mc`, world
    /// units (default: 1/40 of the bounding-box diagonal).
    #[arg(long, default_value_t = 0.0, hide_default_value = true)]
    pub spacing: f64,
    /// Curvature adaptivity ρ (0: uniform spacing).
    #[arg(long, default_value_t = 0.0)]
    pub rho: f64,
    /// ε_T: every sample has |F − C| at most this.
    #[arg(long, default_value_t = 1e-6)]
    pub tolerance: f64,
    /// Coarse-to-fine levels (each halves the spacing; more while the seeds are sparser).
    #[arg(long, default_value_t = 2)]
    pub levels: usize,
    /// Seed of the split/delete random bias.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print no progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// How `isobar fe` extracts the surface.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Oriented point samples from the particle system.
    Samples,
    /// Triangles from marching cubes with numerical inversion (the paper's baseline).
    Mc,
}

/// Runs `isobar fe`: read, sample (or extract), write, print statistics.
pub fn run(args: &FeArgs) -> Result<()> {
    if args.method == Method::Mc {
        crate::io::check_mesh_output(&args.output)?;
    } else {
        crate::io::check_samples_output(&args.output)?;
    }
    let t = Instant::now();
    let mesh = crate::io::read_fe_mesh(&args.input)?;
    let read_s = t.elapsed().as_secs_f64();
    if args.method == Method::Mc {
        return run_mc(args, &mesh, read_s);
    }
    let params = Params {
        iso: args.iso,
        spacing: args.spacing,
        rho: args.rho,
        tolerance: args.tolerance,
        levels: args.levels,
        seed: args.seed,
        ..Params::default()
    };
    let t = Instant::now();
    let (samples, stats) = with_progress(args.quiet, |progress| {
        sample(&mesh, &args.field, &params, progress)
    })?;
    let sample_s = t.elapsed().as_secs_f64();
    crate::io::write_samples(&args.output, &samples)?;
    crate::io::print_warnings(&args.input, &stats.warnings);
    print_stats(&stats, mesh.cell_count(), read_s, sample_s);
    Ok(())
}

fn run_mc(args: &FeArgs, mesh: &crate::field::fe::FeMesh, read_s: f64) -> Result<()> {
    let params = McParams {
        iso: args.iso,
        spacing: args.spacing,
        tolerance: args.tolerance,
        ..McParams::default()
    };
    let t = Instant::now();
    let (surface, s) = with_progress(args.quiet, |progress| {
        extract(mesh, &args.field, &params, progress)
    })?;
    let extract_s = t.elapsed().as_secs_f64();
    // The baseline keeps no warnings of its own; the mesh's is the one it can have.
    crate::io::print_warnings(&args.input, mesh.left_out_warning().as_slice());
    crate::io::write_mesh(&args.output, &surface)?;
    println!(
        "{} vertices, {} triangles on {} cells (grid spacing {:.4}, {} nodes, {} inside): {} active cells, {} forward evaluations, {} unresolved edges; max |F - C| = {:.2e}; read {:.3} s, extracted {:.3} s (nodes {:.3} s, edges {:.3} s)",
        s.vertices,
        s.triangles,
        mesh.cell_count(),
        s.spacing,
        s.nodes,
        s.nodes_inside,
        s.active_cells,
        s.evaluations,
        s.unresolved_edges,
        s.max_residual,
        read_s,
        extract_s,
        s.node_seconds,
        s.edge_seconds
    );
    Ok(())
}

fn print_stats(s: &Stats, cells: usize, read_s: f64, sample_s: f64) {
    println!(
        "{} samples on {} cells (s = {:.4}): {} seeds, {} sweeps, {} forward evaluations, {} splits, {} deletions; max |F - C| = {:.2e}; read {:.3} s, sampled {:.3} s",
        s.particles,
        cells,
        s.spacing,
        s.seeds,
        s.iterations,
        s.evaluations,
        s.splits,
        s.deletes,
        s.max_residual,
        read_s,
        sample_s
    );
}
