#!/usr/bin/env python3
"""Make a >= 1,000,000-particle SPH frame for benchmarks (not committed).

Writes an .npz with the same arrays as ``rust-core/data/demo_dam_break.npz``
(``positions`` (N,3), ``velocity`` (N,3), ``pressure``, ``density``, ``h``, ``mass``, all
float32, SI units).

Why tiling is the default: a real million-particle solver frame does not reach a
useful state in 10 minutes on 2 cores.
Measured with pysplishsplash 2.19.0, IISPH, 2 threads, on the 2-core dev machine:

* 1,000,000 particles (r = 0.00495 m) simulated to t = 0.1 s took 3 min 19 s. At that
  time the column (which starts 5 cm above the floor in the shipped scene) has just
  landed. Pressure is zero for half the particles, and the water is up to 18 %
  compressed where it hits the floor.
* Going on from there, the time step falls to the 1e-4 s minimum, with about 80 s per
  step. After 15 minutes the run had only reached t = 0.116 s.

The two modes:

``--mode tile`` (default)
    Tiles copies of a real solver frame on a regular grid. The default source is the
    committed demo frame: 46,656 particles of a pysplishsplash IISPH dam break at
    t = 1.3 s. Each copy is shifted by the frame's bounding-box size plus ``--gap``
    (default 0.5 m, checked to be at least the kernel support 2h). So the copies never
    overlap, and no particle lies inside another copy's kernel support. Every copy is
    the same real frame; only the tiling is synthetic. The grid is the smallest
    (nx, ny, nz) with at least ``--min-particles`` particles, grown x first, then z,
    then y. For the demo frame that is 3 x 3 x 3 = 27 copies = 1,259,712 particles,
    spanning x in [-1.98, 10.89], y in [0.01, 9.50], z in [-0.73, 4.66] m. All arrays
    are tiled along with the positions; pressures and densities are those of each copy.
    Measured: 1.5 s wall time (34.4 MB .npz).

``--mode simulate``
    A real frame of one large dam break, made by ``make_demo_data.py``. It uses the
    same scene as the demo (pysplishsplash DamBreakModel, IISPH) at particle radius
    ``--radius`` (default 0.00495 m: 100^3 = 1,000,000 particles), run on all cores to
    ``--time`` (default 0.1 s). Measured: 3 min 20 s in total, 12.3 MB .npz. This is the
    state described above: the column landing on the floor.

Usage::

    /work/venv-demo/bin/python scripts/make_bench_frame.py --out /tmp/bench_1m.npz
    /work/venv-demo/bin/python scripts/make_bench_frame.py --mode simulate --out /tmp/bench_sim.npz
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_SOURCE = os.path.join(HERE, "..", "rust-core", "data", "demo_dam_break.npz")
ARRAYS = ("positions", "velocity", "pressure", "density", "h", "mass")


def grid_for(n_src: int, min_particles: int) -> tuple[int, int, int]:
    nx = ny = nz = 1
    axis = 0
    while nx * ny * nz * n_src < min_particles:
        if axis == 0:
            nx += 1
        elif axis == 1:
            nz += 1
        else:
            ny += 1
        axis = (axis + 1) % 3
    return nx, ny, nz


def tile(src: dict, min_particles: int, gap: float) -> tuple[dict, tuple[int, int, int]]:
    pos = src["positions"].astype(np.float64)
    n = len(pos)
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    step = (hi - lo) + gap
    nx, ny, nz = grid_for(n, min_particles)
    offsets = np.array(
        [(i * step[0], j * step[1], k * step[2]) for j in range(ny) for k in range(nz) for i in range(nx)]
    )
    out = {}
    out["positions"] = (pos[None, :, :] + offsets[:, None, :]).reshape(-1, 3).astype(np.float32)
    for k in ARRAYS:
        if k == "positions" or k not in src:
            continue
        a = src[k]
        out[k] = np.concatenate([a] * len(offsets), axis=0)
    return out, (nx, ny, nz)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="output .npz path")
    ap.add_argument("--mode", choices=["tile", "simulate"], default="tile")
    ap.add_argument("--min-particles", type=int, default=1_000_000)
    ap.add_argument("--source", default=DEFAULT_SOURCE, help="tile mode: the frame to tile")
    ap.add_argument("--gap", type=float, default=0.5, help="tile mode: gap between copies (m)")
    ap.add_argument("--radius", type=float, default=0.00495, help="simulate mode: particle radius (m)")
    ap.add_argument("--time", type=float, default=0.1, help="simulate mode: simulated time (s)")
    ap.add_argument("--threads", type=int, default=0, help="simulate mode: OpenMP threads (0 = all)")
    args = ap.parse_args(argv)

    t0 = time.time()
    if args.mode == "simulate":
        sys.path.insert(0, HERE)
        import make_demo_data

        rc = make_demo_data.main(["--out", args.out, "--radius", str(args.radius),
                                  "--time", str(args.time), "--threads", str(args.threads)])
        n = len(np.load(args.out)["h"])
        if n < args.min_particles:
            print(f"warning: only {n} particles (< {args.min_particles}); lower --radius",
                  file=sys.stderr)
        print(f"simulate mode: {n} particles, {time.time() - t0:.1f} s in total")
        return rc

    with np.load(args.source) as f:
        src = {k: f[k] for k in f.files}
    missing = [k for k in ("positions", "h") if k not in src]
    if missing:
        raise SystemExit(f"{args.source} lacks {missing}")
    support = 2.0 * float(src["h"].max())
    if args.gap < support:
        raise SystemExit(f"--gap {args.gap} is less than the kernel support {support}")
    out, grid = tile(src, args.min_particles, args.gap)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    np.savez_compressed(args.out, **out)
    n = len(out["positions"])
    lo, hi = out["positions"].min(axis=0), out["positions"].max(axis=0)
    print(f"tile mode: {len(src['positions'])} particles x {grid[0]}x{grid[1]}x{grid[2]} copies "
          f"= {n} particles, bounds {lo} .. {hi}")
    print(f"wrote {args.out} ({os.path.getsize(args.out)} bytes) in {time.time() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
