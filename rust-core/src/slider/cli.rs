//! The `slide-build` and `slide` commands: precompute a store from a volume file, then
//! slide its isosurface from the keyboard (or from isovalues read one per line when stdin
//! is not a terminal, so scripts and tests can drive it).

use super::store::{Store, MAGIC};
use super::{build_store, BuildParams, BuildStats, LodParams, Slider};
use crate::error::{Error, Result};
use crate::field::grid::Volume;
use crate::io::{read_volume, RawLayout, RawType, VOLUME_EXTENSIONS};
use glam::DVec3;
use std::io::{BufRead, IsTerminal, Read, Write};
use std::path::{Path, PathBuf};

/// How to read a volume file (shared by `slide-build` and `slide VOLUME`).
#[derive(clap::Args, Debug, Default)]
pub struct VolumeArgs {
    /// Point array of a .vti to use (default: the active scalars, else the first scalar array).
    #[arg(long)]
    pub array: Option<String>,
    /// Nodes per axis of a .raw file, e.g. 256,256,128.
    #[arg(long, value_delimiter = ',')]
    pub raw_dims: Option<Vec<usize>>,
    /// Element type of a .raw file (u8 i8 u16 i16 u32 i32 f32 f64).
    #[arg(long, default_value = "u8")]
    pub raw_type: String,
    /// A .raw file is big-endian.
    #[arg(long)]
    pub raw_big_endian: bool,
    /// Node spacing of a .raw file.
    #[arg(long, value_delimiter = ',')]
    pub raw_spacing: Option<Vec<f64>>,
}

impl VolumeArgs {
    /// Reads `input` as these options say; prints what reading it lost (see
    /// [`crate::field::grid::Narrowing`]).
    pub fn read(&self, input: &Path) -> Result<Volume> {
        let volume = self.read_quietly(input)?;
        crate::io::print_warnings(input, &volume.warnings);
        Ok(volume)
    }

    fn read_quietly(&self, input: &Path) -> Result<Volume> {
        let three = |v: Option<Vec<f64>>, name: &'static str| -> Result<Option<DVec3>> {
            match v.as_deref() {
                None => Ok(None),
                Some([a, b, c]) => Ok(Some(DVec3::new(*a, *b, *c))),
                Some(other) => Err(Error::InvalidParameter {
                    name,
                    message: format!("needs 3 comma-separated values, got {}", other.len()),
                }),
            }
        };
        let dims = three(
            self.raw_dims
                .as_ref()
                .map(|d| d.iter().map(|&v| v as f64).collect()),
            "raw-dims",
        )?;
        let spacing = three(self.raw_spacing.clone(), "raw-spacing")?;
        let raw = match (dims, &self.raw_dims) {
            (Some(_), Some(d)) => Some(RawLayout {
                dims: [d[0], d[1], d[2]],
                ty: self.raw_type.parse::<RawType>()?,
                big_endian: self.raw_big_endian,
                origin: DVec3::ZERO,
                spacing: spacing.unwrap_or(DVec3::ONE),
            }),
            _ => None,
        };
        read_volume(input, self.array.as_deref(), raw)
    }

    /// Whether any option was given (they mean nothing for a store).
    fn given(&self) -> bool {
        self.array.is_some()
            || self.raw_dims.is_some()
            || self.raw_type != "u8"
            || self.raw_big_endian
            || self.raw_spacing.is_some()
    }
}

/// How to build a store (shared by `slide-build` and `slide VOLUME`).
#[derive(clap::Args, Debug)]
pub struct BuildOptions {
    /// Skip-list threshold: a block closes once its redundant edges exceed this fraction
    /// of the active edges.
    #[arg(long, default_value_t = 0.25)]
    pub threshold: f64,
    /// Most skip-list levels above level 0.
    #[arg(long, default_value_t = 12)]
    pub max_levels: usize,
    /// Memory budget of the precomputation in bytes, the volume excluded. Over about 29
    /// bytes a node, the node values are sorted on disk (an external-memory sort, in
    /// unnamed temporary files beside the output) and the skip-list levels spooled there.
    /// The levels' open blocks stay in memory and grow with the surface's extent: a noisy
    /// volume needs more than a smooth one, and a budget below that is refused.
    #[arg(long, default_value_t = crate::field::DEFAULT_MEMORY_BUDGET)]
    pub memory_budget: u64,
}

impl BuildOptions {
    fn params(&self) -> BuildParams {
        BuildParams {
            threshold: self.threshold,
            max_levels: self.max_levels,
            memory_budget: self.memory_budget,
        }
    }
}

/// `isobar slide-build`.
#[derive(clap::Args, Debug)]
pub struct BuildArgs {
    /// Volume file: .vti, .nrrd, .npy (3-D, C order) or .raw (with --raw-dims, --raw-type).
    pub input: PathBuf,
    /// Store to write (default: the input with extension .isoslider).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    #[command(flatten)]
    pub volume: VolumeArgs,
    #[command(flatten)]
    pub build: BuildOptions,
    /// Print no progress.
    #[arg(long)]
    pub quiet: bool,
}

/// `isobar slide`.
#[derive(clap::Args, Debug)]
#[command(allow_negative_numbers = true)]
pub struct SlideArgs {
    /// A store written by `isobar slide-build`, or a volume file (.vti, .nrrd, .npy, .raw
    /// with --raw-dims): its store is built first, or reused when the one at --store holds
    /// this very volume.
    pub input: PathBuf,
    /// Where a volume's store lives (default: the volume with extension .isoslider).
    #[arg(long)]
    pub store: Option<PathBuf>,
    #[command(flatten)]
    pub volume: VolumeArgs,
    #[command(flatten)]
    pub build: BuildOptions,
    /// Starting isovalue (default: the middle of the value range).
    #[arg(long)]
    pub iso: Option<f64>,
    /// Isovalue step of one key press, as a fraction of the value range.
    #[arg(long, default_value_t = 0.001)]
    pub step: f64,
    /// Also build the level-of-detail mesh after each change, merging cells while every
    /// deleted sample stays within this fraction of the value range (the paper uses
    /// 0.001); 0 gives the exact mesh.
    #[arg(long)]
    pub lod: Option<f64>,
}

/// Runs `slide-build`.
pub fn run_build(args: &BuildArgs) -> Result<()> {
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| default_store_path(&args.input));
    super::build::check_store_path(&args.input, &output)?;
    let volume = args.volume.read(&args.input)?;
    let stats = build_with_progress(&volume, &output, &args.build.params(), args.quiet)?;
    let [nx, ny, nz] = volume.lattice.dims;
    let volume_bytes = volume.values.len() * volume.values.value_type().size();
    println!(
        "{}: {nx}×{ny}×{nz} {} volume ({volume_bytes} bytes) -> {} ({} bytes, {:.2}× the volume), {} skip-list levels (blocks {:?}), {}, {:.2} s",
        args.input.display(),
        volume.values.value_type().name(),
        output.display(),
        stats.file_bytes,
        stats.file_bytes as f64 / volume_bytes as f64,
        stats.level_blocks.len(),
        stats.level_blocks,
        match stats.sorted_runs {
            0 => "sorted in memory".to_string(),
            runs => format!("sorted on disk in {runs} run(s) within the memory budget"),
        },
        stats.seconds
    );
    Ok(())
}

/// [`build_store`] with a progress bar on stderr unless `quiet`.
fn build_with_progress(
    volume: &Volume,
    output: &Path,
    params: &BuildParams,
    quiet: bool,
) -> Result<BuildStats> {
    crate::terminal::with_progress(quiet, |progress| {
        build_store(volume, output, params, progress)
    })
}

/// The store `slide` opens for `args.input`: the input itself when it is a store; for a
/// volume, the store at `--store` (default beside the volume) if it holds this volume's
/// lattice and values, else one built there now (replacing a stale one by rename).
fn store_for(args: &SlideArgs) -> Result<Slider> {
    let volume_named = args
        .input
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| VOLUME_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
    // Neither a store nor named as a volume: opening it as a store says what is wrong.
    if is_store(&args.input)? || !volume_named {
        if args.store.is_some() || args.volume.given() {
            return Err(Error::InvalidParameter {
                name: "store",
                message: format!(
                    "{} is a slider store already; --store and the volume options apply to a volume",
                    args.input.display()
                ),
            });
        }
        return Slider::open(&args.input);
    }
    let volume = args.volume.read(&args.input)?;
    let path = args
        .store
        .clone()
        .unwrap_or_else(|| default_store_path(&args.input));
    if path.exists() {
        if !is_store(&path)? {
            // Not ours to replace.
            return Err(Error::format(
                path,
                "exists and is not a slider store; name another path with --store",
            ));
        }
        // A store that fails to open (another version, corrupt) is rebuilt like a stale one.
        if let Ok(store) = Store::open(&path) {
            if store.holds(&volume)? {
                eprintln!(
                    "{}: using its store {}",
                    args.input.display(),
                    path.display()
                );
                drop(volume);
                return Slider::open(&path);
            }
        }
    }
    eprintln!(
        "{}: building its store {}",
        args.input.display(),
        path.display()
    );
    build_with_progress(&volume, &path, &args.build.params(), false)?;
    // The slider reads the store, not the volume: free it before the surface is built.
    drop(volume);
    Slider::open(&path)
}

/// Whether `path` starts with a store's magic (a missing file is an error naming it).
fn is_store(path: &Path) -> Result<bool> {
    let mut head = [0u8; 8];
    let mut file = crate::io::open_regular(path)?;
    let n = file.read(&mut head).map_err(|e| Error::io(path, e))?;
    Ok(n == head.len() && &head == MAGIC)
}

/// Runs `slide`: interactive on a terminal, else one isovalue per input line.
pub fn run_slide(args: &SlideArgs) -> Result<()> {
    // Checked before the store is opened (or built from a volume, which takes a while).
    if !(args.step > 0.0 && args.step <= 1.0) {
        return Err(Error::InvalidParameter {
            name: "step",
            message: format!("a fraction of the value range in (0, 1], got {}", args.step),
        });
    }
    if let Some(iso) = args.iso.filter(|iso| !iso.is_finite()) {
        return Err(Error::InvalidParameter {
            name: "iso",
            message: format!("must be finite, got {iso}"),
        });
    }
    let mut slider = store_for(args)?;
    if let Some(error_bound) = args.lod {
        slider.set_lod(LodParams {
            error_bound,
            ..LodParams::default()
        })?;
    }
    let lod = args.lod.is_some();
    let (lo, hi) = slider.store().value_range();
    let range = (hi - lo).max(f32::MIN_POSITIVE) as f64;
    if std::io::stdin().is_terminal() {
        interactive(&mut slider, args, lo as f64, range)
    } else {
        scripted(&mut slider, lod)
    }
}

/// One line per isovalue read from stdin: iso, triangles, vertices, update time,
/// triangles added and removed, the slider's own memory ([`Slider::held_bytes`]) (and,
/// with `lod`, the LOD mesh's triangles, vertices and build time).
fn scripted(slider: &mut Slider, lod: bool) -> Result<()> {
    let mut stdin = std::io::stdin().lock();
    let mut out = std::io::stdout().lock();
    let mut line = Vec::new();
    for k in 0.. {
        if !next_line(&mut stdin, &mut line)? {
            break;
        }
        let line = String::from_utf8_lossy(&line);
        let text = line.trim();
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        let iso: f64 = text.parse().map_err(|_| Error::InvalidParameter {
            name: "isovalue",
            message: format!("line {}: '{text}' is not a number", k + 1),
        })?;
        let change = slider.set_isovalue(iso)?;
        let (lo, hi) = slider.store().value_range();
        if let Some(why) = outside(iso, lo as f64, hi as f64) {
            eprintln!("isobar: warning: line {}: {why}", k + 1);
        }
        write!(
            out,
            "iso {iso} triangles {} vertices {} update_ms {:.3} added {} removed {} held_mib {:.1}",
            slider.triangle_count(),
            slider.vertex_count(),
            change.seconds * 1e3,
            change.added_triangles.len(),
            change.removed_triangles.len(),
            slider.held_bytes() as f64 / (1u64 << 20) as f64
        )
        .map_err(|e| Error::io("<stdout>", e))?;
        if lod {
            let m = slider.lod_mesh()?;
            write!(
                out,
                " lod_triangles {} lod_vertices {} lod_ms {:.3}",
                m.triangles.len(),
                m.positions.len(),
                m.seconds * 1e3
            )
            .map_err(|e| Error::io("<stdout>", e))?;
        }
        writeln!(out).map_err(|e| Error::io("<stdout>", e))?;
    }
    Ok(())
}

/// Why isovalue `iso` has no surface when it lies outside the values `lo..hi`.
fn outside(iso: f64, lo: f64, hi: f64) -> Option<String> {
    (!(lo..=hi).contains(&iso))
        .then(|| format!("no surface at isovalue {iso}: the values range over {lo} .. {hi}"))
}

/// Reads the next line of `input` into `line`; false at the end of the input. An
/// interrupt ends the command (Cancelled) between lines and while it waits for one:
/// `BufRead::read_line` would retry after the signal and wait on.
fn next_line(input: &mut impl BufRead, line: &mut Vec<u8>) -> Result<bool> {
    line.clear();
    loop {
        if crate::terminal::interrupted() {
            return Err(Error::Cancelled);
        }
        let available = match input.fill_buf() {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(Error::io("<stdin>", e)),
        };
        if available.is_empty() {
            return Ok(!line.is_empty());
        }
        let (taken, ended) = match available.iter().position(|&b| b == b'\n') {
            Some(i) => (i + 1, true),
            None => (available.len(), false),
        };
        line.extend_from_slice(&available[..taken]);
        input.consume(taken);
        if ended {
            return Ok(true);
        }
    }
}

/// Puts the terminal in non-canonical, no-echo mode while alive (through `stty`, so no
/// terminal library is needed), and restores it when dropped.
struct RawTerminal {
    saved: Option<String>,
}

impl RawTerminal {
    fn enter() -> Self {
        let stty = |args: &[&str]| {
            std::process::Command::new("stty")
                .args(args)
                .stdin(std::process::Stdio::inherit())
                .output()
                .ok()
                .filter(|o| o.status.success())
                .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        };
        let saved = stty(&["-g"]);
        if saved.is_some() {
            stty(&["-icanon", "-echo", "min", "1"]);
        }
        RawTerminal { saved }
    }
}

impl Drop for RawTerminal {
    fn drop(&mut self) {
        if let Some(s) = &self.saved {
            let _ = std::process::Command::new("stty")
                .arg(s)
                .stdin(std::process::Stdio::inherit())
                .status();
        }
    }
}

fn interactive(slider: &mut Slider, args: &SlideArgs, lo: f64, range: f64) -> Result<()> {
    let mut iso = args.iso.unwrap_or(lo + 0.5 * range);
    let mut step = args.step * range;
    eprintln!(
        "{}: values {lo} .. {}; keys: up/right/+ raise, down/left/- lower, ]/[ step ×10/÷10, q quits",
        slider.store().path().display(),
        lo + range
    );
    let _raw = RawTerminal::enter();
    let mut stdin = std::io::stdin().lock();
    let mut key = [0u8; 1];
    let mut escape = 0u8;
    loop {
        let change = slider.set_isovalue(iso)?;
        eprint!(
            "\riso {iso:<14.6} step {step:<10.4} triangles {:<10} update {:>8.3} ms",
            slider.triangle_count(),
            change.seconds * 1e3
        );
        if args.lod.is_some() {
            let m = slider.lod_mesh()?;
            eprint!(" lod {:<10} {:>8.3} ms", m.triangles.len(), m.seconds * 1e3);
        }
        eprint!(
            "{}",
            outside(iso, lo, lo + range).map_or("   ", |_| " (outside the values)")
        );
        // A Ctrl-C during the update: the read below would wait for a key first.
        if crate::terminal::interrupted() {
            eprintln!();
            return Ok(());
        }
        loop {
            let read = match stdin.read(&mut key) {
                // Ctrl-C (the terminal keeps sending signals) quits like q, and the
                // terminal's settings are restored on the way out.
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {
                    if crate::terminal::interrupted() {
                        0
                    } else {
                        continue;
                    }
                }
                other => other.map_err(|e| Error::io("<stdin>", e))?,
            };
            if read == 0 {
                eprintln!();
                return Ok(());
            }
            // Arrow keys arrive as ESC [ A..D.
            let k = match (escape, key[0]) {
                (0, 0x1b) => {
                    escape = 1;
                    continue;
                }
                // ESC O A..D in the terminal's application cursor mode.
                (1, b'[' | b'O') => {
                    escape = 2;
                    continue;
                }
                (2, c) => {
                    escape = 0;
                    match c {
                        b'A' | b'C' => b'+',
                        b'B' | b'D' => b'-',
                        _ => continue,
                    }
                }
                (_, c) => {
                    escape = 0;
                    c
                }
            };
            match k {
                // Within a range's width of the values and steps of at most the
                // range: repeated keys never reach an infinite isovalue.
                b'+' | b'=' | b'k' => iso = (iso + step).min(lo + 2.0 * range),
                b'-' | b'_' | b'j' => iso = (iso - step).max(lo - range),
                b']' => step = (step * 10.0).min(range),
                b'[' => step = (step / 10.0).max(range * 1e-12),
                b'q' | b'Q' | 3 | 4 => {
                    eprintln!();
                    return Ok(());
                }
                _ => continue,
            }
            break;
        }
    }
}

/// The default store path for a volume path.
pub fn default_store_path(input: &Path) -> PathBuf {
    input.with_extension("isoslider")
}
