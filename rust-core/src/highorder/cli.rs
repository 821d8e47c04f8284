//! `isobar fe`: sample an isosurface of a high-order FE field in a VTU file and write the
//! oriented points (the subcommand body; `bin/isobar.rs` only dispatches here).

use super::{sample, Params, Stats};
use crate::error::{Error, Result};
use crate::progress::Progress;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `isobar fe`.
#[derive(clap::Args, Debug)]
#[command(allow_negative_numbers = true)]
pub struct FeArgs {
    /// A .vtu with Lagrange hexahedra, tetrahedra or wedges (VTK types 72, 71, 73).
    pub input: PathBuf,
    /// The scalar point array to contour.
    #[arg(long)]
    pub field: String,
    /// The isovalue C.
    #[arg(long)]
    pub iso: f64,
    /// Output point samples (.vtp: vertices with Normals, Radius, Element, Reference,
    /// Curvature, Energy).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Particle spacing s on flat parts, world units (default: 1/40 of the bounding-box diagonal).
    #[arg(long, default_value_t = 0.0)]
    pub spacing: f64,
    /// Curvature adaptivity ρ (0: uniform spacing).
    #[arg(long, default_value_t = 0.0)]
    pub rho: f64,
    /// ε_T: every sample has |F − C| at most this.
    #[arg(long, default_value_t = 1e-6)]
    pub tolerance: f64,
    /// Coarse-to-fine levels (each halves the spacing).
    #[arg(long, default_value_t = 2)]
    pub levels: usize,
    /// Seed of the split/delete random bias.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print no progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Runs `isobar fe`: read, sample, write, print statistics.
pub fn run(args: &FeArgs) -> Result<()> {
    let t = Instant::now();
    let mesh = crate::io::read_fe_mesh(&args.input)?;
    let read_s = t.elapsed().as_secs_f64();
    let params = Params {
        iso: args.iso,
        spacing: args.spacing,
        rho: args.rho,
        tolerance: args.tolerance,
        levels: args.levels,
        seed: args.seed,
        ..Params::default()
    };
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(1000)
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {percent:>3}% {msg}")
            .map_err(|e| Error::InvalidInput(format!("progress bar: {e}")))?,
    );
    let mut report = |f: f64, phase: &str| {
        bar.set_position((f * 1000.0) as u64);
        bar.set_message(phase.to_string());
        true
    };
    let mut progress = Progress::new(&mut report);
    let t = Instant::now();
    let result = sample(&mesh, &args.field, &params, &mut progress);
    bar.finish_and_clear();
    let (samples, stats) = result?;
    let sample_s = t.elapsed().as_secs_f64();
    crate::io::write_samples(&args.output, &samples)?;
    print_stats(&stats, mesh.cell_count(), read_s, sample_s);
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
