"""The ``isobar-usd`` command line.

    isobar-usd sph 'frames/frame_####.vtk' --iso 0.6 --h 0.05 --grid-factor 0.375 -o fluid.usd
    isobar-usd sph 'frames/frame_####.vtk' ... -o fluid.usd --frames 10-20 --no-stitch
    isobar-usd stitch fluid.usd
    isobar-usd check fluid.usd
    isobar-usd fe solution.vtu --field p --iso 0 -o surface.usd
"""

from __future__ import annotations

import argparse
import signal
import sys
from typing import List, Optional


def _floats(text: str) -> List[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a comma separated list of numbers") from None
    if not values:
        raise argparse.ArgumentTypeError("give at least one number")
    return values


def _names(text: str) -> List[str]:
    return [v.strip() for v in text.split(",") if v.strip()]


def _parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = argparse.ArgumentParser(
        prog="isobar-usd",
        description="Write isobar's SPH isosurfaces as USD stages (time-sampled UsdGeomMesh, value clips).",
    )
    parser.add_argument("--version", action="version", version=f"isobar-usd {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="{sph,fe,stitch,check}")

    sph = sub.add_parser(
        "sph",
        help="extract SPH isosurfaces from particle files and write a USD stage",
        description="Extract isosurfaces of an SPH field by Marching Correctors (the isobar core) and write them "
        "as a USD stage: one frame, or a numbered sequence as one layer per frame joined by value clips.",
    )
    sph.add_argument("input", help="particle file or numbered sequence ('frame_####.vtk', '{}', '%%04d', or one frame of it)")
    sph.add_argument("-o", "--output", required=True, help="root USD file (.usd .usda .usdc)")
    g = sph.add_argument_group("extraction (as `isobar sph`)")
    g.add_argument("--field", help="array name, 'NAME:mag', 'NAME:K', or SumOfWeights (default) for the free surface")
    g.add_argument("--iso", required=True, type=_floats, help="isovalue(s), comma separated")
    g.add_argument("--kernel", default="cubic", choices=["cubic", "wendland", "quintic", "quadratic"], help="SPH kernel (default cubic)")
    smoothing = g.add_mutually_exclusive_group()
    smoothing.add_argument("--h", type=float, help="constant smoothing length")
    smoothing.add_argument("--h-array", help="per-particle smoothing length array (default: 'h', 'smoothing_length' or 'hsml' if present)")
    g.add_argument("--h-scale", type=float, default=1.0, help="multiplies every smoothing length (previews: 0.75, 0.5)")
    g.add_argument("--grid-factor", type=float, default=0.5, help="virtual cell size in units of the smallest h (default 0.5)")
    g.add_argument("--preview", action="store_true", help="linear interpolation, no correction")
    g.add_argument("--tolerance", type=float, default=1e-6, help="relative tolerance of the correction")
    g.add_argument("--trim", nargs="+", metavar="NODE,VERTEX", help="trimming thresholds on the sum of weights (default 0.1,0.5; off for SumOfWeights)")
    g.add_argument("--no-trim", action="store_true", help="no trimming at free surfaces")
    g.add_argument("--volume-array", help="per-particle volume array (m/rho)")
    g.add_argument("--density-array", help="density array; volumes = mass / density (needs --mass or --mass-array)")
    g.add_argument("--mass", type=float, help="constant particle mass")
    g.add_argument("--mass-array", help="per-particle mass array")
    g.add_argument("--shepard", action="store_true", help="normalise the field by the sum of weights")
    g.add_argument("--attributes", type=_names, default=[], help="particle arrays to interpolate onto the surface (written as vertex primvars), comma separated")
    g.add_argument("--no-normals", action="store_true", help="no vertex normals")
    g.add_argument("--full-grid", action="store_true", help="resample onto the full grid and run plain marching cubes (the baseline)")
    g.add_argument("--memory-budget", type=float, help="memory budget in GiB for extent-sized structures (default: the core's, 4)")
    g.add_argument("--method", choices=["correctors", "adaptive"], default="correctors",
                   help="correctors (default): Marching Correctors, vertices on the level set; adaptive: crack-free "
                   "3-level grid, far fewer triangles, one isovalue (both carry --attributes and velocities)")
    g.add_argument("--backend", choices=["cpu", "gpu", "auto"],
                   help="where the GPU-capable steps run (correctors: the seed cells' neighbour search; adaptive: the "
                   "grids): cpu, gpu (wgpu; an error without an adapter) or auto (a hardware GPU when there is one); "
                   "default: the core's (correctors cpu, adaptive auto)")
    g.add_argument("--splash-threshold", type=int, help="adaptive: coarse cells holding 1..N particles are refined to the finest level (the paper's rule: 1; core default 0, none)")
    g.add_argument("--max-error", type=float, help="adaptive: each cell at the surface takes the lowest level whose surface lies "
                   "within this many finest cells of the finest level's there "
                   "(0: off, the splash criterion alone; default: the core's)")
    g.add_argument("--bisection-iterations", type=int,
                   help="adaptive: halvings of a finest-level edge when placing its surface point, one more per "
                   "coarser level (0..16; 0: linear between the finest nodes, as marching cubes; default: the core's, 5)")

    u = sph.add_argument_group("USD")
    u.add_argument("--frames", help="write only these frame numbers: 10-20, 1-5,9, 100- (the other frames of the stage stay)")
    u.add_argument("--jobs", "-j", type=int, default=1, help="processes writing frames in parallel (0: one per core)")
    u.add_argument("--layout", choices=["auto", "clips", "flat"], default="auto",
                   help="clips: one layer per frame joined by value clips; flat: every frame in one file "
                   "(all in memory); auto (default): flat for one frame, clips otherwise")
    u.add_argument("--no-stitch", action="store_true", help="write and commit the frame layers only; run `isobar-usd stitch` afterwards")
    u.add_argument("--keep-going", action="store_true",
                   help="skip a frame that cannot be read or extracted (named on stderr, exit status 1) and write the "
                        "others; without it one bad frame stops the run and nothing is written")
    u.add_argument("--fps", type=float, default=24.0, help="timeCodesPerSecond and framesPerSecond (default 24); time code = frame number")
    u.add_argument("--meters-per-unit", type=float, default=1.0, help="metersPerUnit: the unit the positions are already in (default 1: metres); a label, the data is not scaled")
    u.add_argument("--up-axis", choices=["Y", "Z", "y", "z"], default="Y", help="upAxis (default Y: USD's fallback, SPlisHSPlasH/Houdini; Z for Blender); the data is not rotated")
    u.add_argument("--prim", default="Fluid", help="name of the root prim (defaultPrim, default Fluid)")
    u.add_argument("--mesh", default="Surface", help="name of the Mesh prim under it (default Surface)")
    u.add_argument("--velocities", default="auto", metavar="NAME",
                   help="particle array interpolated into the mesh's velocities (motion blur); default: 'velocity' when present")
    u.add_argument("--no-velocities", action="store_true", help="write no velocities")
    u.add_argument("--primvars", type=_names, help="attributes written as vertex primvars (default: all of --attributes, plus Isovalue for several isovalues)")
    u.add_argument("--check", action="store_true", help="check the written stage (validators, per-frame topology)")
    u.add_argument("--quiet", "-q", action="store_true", help="print nothing but errors")

    _add_fe(sub)

    st = sub.add_parser("stitch", help="rewrite a sequence's root layer and manifest from its frame layers",
                        description="Rewrite the root layer and clip manifest of a sequence from the frame layers in its clips folder "
                        "(after `isobar-usd sph ... --no-stitch` runs).")
    st.add_argument("output", help="the sequence's root USD file")
    st.add_argument("--fps", type=float, help="override the frames' fps")
    st.add_argument("--quiet", "-q", action="store_true")

    ck = sub.add_parser("check", help="check a USD stage: usd-core's validators and per-frame mesh checks",
                        description="Run usd-core's validators and check every mesh at every time sample (topology, normal, "
                        "velocity and primvar counts, extent). Exit status 1 when there is an error.")
    ck.add_argument("path")
    ck.add_argument("--no-validators", action="store_true", help="skip usd-core's validators")
    ck.add_argument("--max-frames", type=int, help="check at most this many time samples per mesh")
    ck.add_argument("--quiet", "-q", action="store_true")
    return parser


def _trim(args):
    if args.no_trim:
        return None
    if args.trim is None:
        return "auto"
    values = [v for part in args.trim for v in part.split(",") if v.strip()]
    try:
        node, vertex = (float(v) for v in values)
    except ValueError:
        raise SystemExit(f"isobar-usd: error: --trim takes NODE,VERTEX (two numbers), got {' '.join(args.trim)}")
    return (node, vertex)


def _extract_options(args) -> dict:
    options = dict(
        field=args.field,
        kernel=args.kernel,
        h_scale=args.h_scale,
        grid_factor=args.grid_factor,
        correct=not args.preview,
        tolerance=args.tolerance,
        trim=_trim(args),
        normals=not args.no_normals,
        attributes=args.attributes,
        shepard=args.shepard,
        full_grid=args.full_grid,
    )
    for name in ("h", "h_array", "volume_array", "density_array", "mass", "mass_array"):
        value = getattr(args, name)
        if value is not None:
            options[name] = value
    if args.memory_budget is not None:
        options["memory_budget"] = int(args.memory_budget * 2**30)
    if args.method != "correctors":
        options["method"] = args.method
    if args.splash_threshold is not None:
        options["splash_threshold"] = args.splash_threshold
    if args.max_error is not None:
        options["max_error"] = args.max_error
    if args.bisection_iterations is not None:
        options["bisection_iterations"] = args.bisection_iterations
    if args.backend is not None:
        # Both methods take it: isobar.extract(backend=) and isobar.extract_adaptive(backend=).
        options["backend"] = args.backend
    return options


def _add_fe(sub) -> None:
    fe = sub.add_parser(
        "fe",
        help="sample the isosurface of a high-order FE field and write it as USD Points",
        description="Sample the isosurface of a scalar field on Lagrange cells (a .vtu) with isobar's particle "
        "system and write the samples as a UsdGeomPoints with normals, widths and primvars.",
    )
    fe.add_argument("input", help=".vtu of Lagrange tetrahedra, hexahedra or wedges, or a Gmsh .msh (v4.1) with high-order elements and $NodeData")
    fe.add_argument("-o", "--output", required=True, help="USD file (.usd .usda .usdc)")
    fe.add_argument("--field", required=True, help="scalar point array to contour")
    fe.add_argument("--iso", required=True, type=float, help="the isovalue")
    fe.add_argument("--spacing", type=float, default=0.0, help="sample spacing on flat parts (default: 1/40 of the diagonal)")
    fe.add_argument("--rho", type=float, default=0.0, help="curvature adaptivity (default 0: uniform)")
    fe.add_argument("--tolerance", type=float, help="every sample within this of the isovalue (core default 1e-6)")
    fe.add_argument("--meters-per-unit", type=float, default=1.0, help="stage metersPerUnit: the unit the positions are already in (default 1); a label, the data is not scaled")
    fe.add_argument("--up-axis", default="Y", choices=["Y", "Z", "y", "z"], help="stage upAxis (default Y)")
    fe.add_argument("--prim", default="FE", help="root prim name (default FE)")
    fe.add_argument("--points", default="Samples", help="Points prim name (default Samples)")
    fe.add_argument("--check", action="store_true", help="check the written stage")
    fe.add_argument("--quiet", "-q", action="store_true", help="print nothing but errors")


def _run_fe(args) -> int:
    from . import check, write_fe_samples

    path, samples = write_fe_samples(
        args.input,
        args.output,
        args.field,
        args.iso,
        spacing=args.spacing,
        rho=args.rho,
        tolerance=args.tolerance,
        meters_per_unit=args.meters_per_unit,
        up_axis=args.up_axis.upper(),
        prim=args.prim,
        points=args.points,
    )
    if not args.quiet:
        st = samples.stats
        print(f"wrote {path}: {len(samples):,} samples, max |F - C| {st['max_residual']:.2e}, {st['evaluations']:,} evaluations")
        # Named by the input, as an error is; the library keeps Python's copy quiet.
        for text in samples.warnings:
            print(f"isobar-usd: warning: {args.input}: {text}", file=sys.stderr, flush=True)
    if args.check:
        return _report_problems(check(path), args.quiet)
    return 0


def _run_sph(args) -> int:
    from . import check, write_sequence

    def progress(p):
        if not args.quiet:
            of = f"/{p.total}" if p.total else ""
            print(
                f"[{p.done}{of}] frame {p.frame} ({p.source}): {p.points:,} points, {p.triangles:,} triangles, {p.seconds:.2f} s",
                file=sys.stderr,
                flush=True,
            )
            # Named as an error names its frame; the library keeps Python's copy quiet.
            for text in p.warnings:
                print(f"isobar-usd: warning: frame {p.frame} ({p.source}): {text}", file=sys.stderr, flush=True)

    options = _extract_options(args)
    if not args.quiet:
        from .sequence import auto_backend_note

        note = auto_backend_note(options)
        if note:  # the isobar CLI's line, word for word
            print(f"backend auto: running on the CPU ({note})", file=sys.stderr, flush=True)
    result = write_sequence(
        args.input,
        args.output,
        args.iso,
        frames=args.frames,
        jobs=args.jobs,
        layout=args.layout,
        stitch=not args.no_stitch,
        fps=args.fps,
        meters_per_unit=args.meters_per_unit,
        up_axis=args.up_axis.upper(),
        prim=args.prim,
        mesh=args.mesh,
        velocities=None if args.no_velocities else args.velocities,
        primvars="auto" if args.primvars is None else args.primvars,
        progress=progress,
        keep_going=args.keep_going,
        **options,
    )
    for note in result.notes:  # a warning: printed even with --quiet
        print(f"isobar-usd: warning: {note}", file=sys.stderr, flush=True)
    for frame, why in result.failed.items():  # skipped by --keep-going
        print(f"isobar-usd: error: {why} (skipped)", file=sys.stderr, flush=True)
    if not args.quiet:
        span = f"{result.frames[0]}..{result.frames[-1]}" if result.frames else "-"
        where = f", frame layers in {result.clips}" if result.clips else ""
        if result.layout == "clips" and args.no_stitch:
            print(f"committed {len(result.written)} frame layer(s) to {result.clips}; run `isobar-usd stitch {result.output}`")
        else:
            print(f"wrote {result.output}: {len(result.frames)} frame(s) ({span}), {result.layout} layout{where}, {result.seconds:.1f} s")
    status = 1 if result.failed else 0
    if result.failed and not args.quiet:
        print(f"{len(result.failed)} frame(s) skipped: {', '.join(map(str, result.failed))}", file=sys.stderr)
    if args.check and not (result.layout == "clips" and args.no_stitch):
        return max(status, _report_problems(check(result.output), args.quiet))
    return status


def _report_problems(problems, quiet: bool) -> int:
    errors = [p for p in problems if p.severity == "error"]
    for p in problems:
        if p.severity != "info" or not quiet:
            print(p, file=sys.stderr if p.severity == "error" else sys.stdout)
    if not quiet:
        print(f"check: {len(errors)} error(s), {len(problems) - len(errors)} other finding(s)")
    return 1 if errors else 0


def main(argv: Optional[List[str]] = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        import isobar

        from . import Error, check, stitch
    except ImportError as e:
        print(f"isobar-usd: error: {e}", file=sys.stderr)
        return 1

    from .sequence import _STOP, request_stop

    def stop(signum, frame):
        # SIGTERM (a farm's time limit, `kill`) and a first Ctrl-C stop the write at the next
        # safe point: staged files are removed, the previous stage stays. (Raising here
        # could land inside the core's ctypes callback, where Python only prints it.)
        if signum == signal.SIGINT and _STOP.is_set():
            raise KeyboardInterrupt  # a second Ctrl-C: at once
        request_stop()

    _STOP.clear()
    previous = {s: signal.signal(s, stop) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        if args.command == "sph":
            return _run_sph(args)
        if args.command == "fe":
            return _run_fe(args)
        if args.command == "stitch":
            result = stitch(args.output, fps=args.fps)
            for note in result.notes:
                print(f"isobar-usd: warning: {note}", file=sys.stderr, flush=True)
            if not args.quiet:
                print(f"stitched {result.output}: {len(result.frames)} frame(s) ({result.frames[0]}..{result.frames[-1]})")
            return 0
        if args.command == "check":
            return _report_problems(check(args.path, validators=not args.no_validators, max_frames=args.max_frames), args.quiet)
    except KeyboardInterrupt:
        print("isobar-usd: interrupted; the previous files were left as they were", file=sys.stderr)
        return 130
    except (Error, isobar.Error) as e:
        if _STOP.is_set():
            print("isobar-usd: interrupted; the previous files were left as they were", file=sys.stderr)
            return 130
        # The isobar package words some hints for Python callers.
        message = str(e).replace("pass h=VALUE or h_array=NAME", "pass --h VALUE or --h-array NAME")
        print(f"isobar-usd: error: {message}", file=sys.stderr)
        return 1
    except OSError as e:  # a write that fails after the checks (disk full, a folder made read-only meanwhile)
        if _STOP.is_set():
            print("isobar-usd: interrupted; the previous files were left as they were", file=sys.stderr)
            return 130
        print(f"isobar-usd: error: {e}", file=sys.stderr)
        return 1
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    parser.error(f"unknown command {args.command}")
    return 2


if __name__ == "__main__":
    sys.exit(main())
