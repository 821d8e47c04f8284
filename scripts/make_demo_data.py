#!/usr/bin/env python3
"""Make isobar's embedded demo frame: one frame of a real SPH dam-break simulation.

Solver: SPlisHSPlasH through PyPI ``pysplishsplash`` 2.19.0 (pinned in
``scripts/requirements-demo.txt``), run headless.  Scene: the package's own
``data/Scenes/DamBreakModel.json`` (a 1 m x 1 m x 1 m water column in a 4 m x 3 m x 1.5 m
tank) with three edits: the particle radius (0.0135 m instead of 0.025 m, giving 46,656
fluid particles), the pressure solver (IISPH, ``simulationMethod`` 3, instead of DFSPH,
because IISPH exposes a per-particle ``pressure`` field; DFSPH only exposes
``p / rho^2``), and the exported attributes (``density;velocity;pressure``).  The frame
is taken at t = 1.3 s, when the surge has hit the far wall (x = 2 m) and splashes up it
and back: a thin bulk layer, a tall sheet on the wall, thin films on the side walls,
droplets.

Output (``numpy.savez_compressed``, all float32, SI units, y axis up, gravity -9.81 y):

* ``positions`` (N,3) m, ``velocity`` (N,3) m/s
* ``pressure`` (N,) Pa — IISPH's ``pressure`` field times the rest density (IISPH stores
  p/rho0 in m^2/s^2; checked: a fluid at rest gives d(raw)/d(depth) ~ g)
* ``density`` (N,) kg/m^3 — the solver's SPH density (fluid + boundary contribution)
* ``h`` (N,) m — smoothing length for a cubic spline with support 2h: SPlisHSPlasH's
  support radius is 4 r, so h = 2 r (asserted against ``Simulation.getSupportRadius()``)
* ``mass`` (N,) kg — ``FluidModel.getMass`` = rho0 (2r)^3 (asserted)

Particles are the fluid particles only (this scene's walls are a volume map, not
particles), ordered by their SPlisHSPlasH particle id.  The arrays come from the file the
solver's own VTK exporter wrote at the chosen time; they are checked bit-for-bit against
the solver's in-memory buffers of the same step.

Determinism: SPlisHSPlasH runs its loops with OpenMP; IISPH sums the density error with
``omp atomic``, so with more than one thread the iteration counts, and hence the frame,
differ from run to run (measured: two 2-thread runs of the coarse scene differ by 7 cm
in positions after 0.5 s; the flow is chaotic).  The default ``--threads 1`` gave
bit-identical files in repeated runs with the same pysplishsplash version; ``--threads 0``
(all cores) is faster but not reproducible.  The committed .npz is the reference.

Run time: 5 min 17 s with the default options (one thread) on the idle 2-core dev
machine. Output: 1.3 MB, and a second run gave a byte-identical file.

Usage::

    python3.11 -m venv /work/venv-demo
    /work/venv-demo/bin/pip install -r scripts/requirements-demo.txt
    /work/venv-demo/bin/python scripts/make_demo_data.py --out rust-core/data/demo_dam_break.npz

Options: ``--scene`` (a scene name shipped with pysplishsplash or a JSON path),
``--time`` (s), ``--radius`` (m), ``--method`` (iisph|dfsph), ``--threads``,
``--preview-fps`` (also keep the VTK frames at this rate, for choosing a time),
``--workdir``/``--keep-workdir``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from splishsplash_common import (  # noqa: E402
    METHODS,
    PRESSURE_FIELD,
    PYSPLISHSPLASH_VERSION,
    absolutize_scene_paths,
    import_pysplishsplash,
    pressure_to_pascal,
    read_splishsplash_vtk,
    resolve_scene,
    write_scene,
)

DEFAULT_SCENE = "DamBreakModel"
DEFAULT_TIME = 1.3
DEFAULT_RADIUS = 0.0135


def build_scene(args) -> dict:
    src = resolve_scene(args.scene)
    with open(src) as f:
        scene = json.load(f)
    absolutize_scene_paths(scene, os.path.dirname(src))
    cfg = scene.setdefault("Configuration", {})
    cfg["particleRadius"] = args.radius
    cfg["simulationMethod"] = METHODS[args.method]
    attrs = ["density", "velocity"]
    if args.method in PRESSURE_FIELD:
        attrs.append(PRESSURE_FIELD[args.method][0])
    cfg["particleAttributes"] = ";".join(attrs)
    # Stop/export are driven from here, not from the scene.
    for k in ("stopAt", "pauseAt", "enablePartioExport", "enableVTKExport", "dataExportFPS"):
        cfg.pop(k, None)
    return scene


def simulate(args, sph, scene_path: str, workdir: str) -> dict:
    """Run to args.time; return the exporter's frame plus what the solver knows in memory."""
    base = sph.Exec.SimulatorBase()
    base.init(useGui=False, outputDir=workdir, sceneFile=scene_path)
    # Export at t=first step (frame 1) and at the first step with t >= T (frame 2), or at
    # the preview rate (then the frame at T is the first one written at t >= T).
    fps = args.preview_fps if args.preview_fps else 1.0 / args.time
    base.setValueFloat(base.DATA_EXPORT_FPS, fps)
    base.setValueFloat(base.STOP_AT, args.time + 0.05)
    base.activateExporter("VTK Exporter", True)
    vtk_dir = os.path.join(workdir, "vtk")

    st = {"steps": 0, "t0": time.time(), "last_report": time.time()}

    def on_step():
        sim = sph.Simulation.getCurrent()
        tm = sph.TimeManager.getCurrent()
        fm = sim.getFluidModel(0)
        st["steps"] += 1
        t = tm.getTime()
        if st["steps"] == 1:
            n = fm.numActiveParticles()
            st["n0"] = n
            st["mass"] = np.array([fm.getMass(i) for i in range(n)], dtype=np.float64)
            st["density0"] = fm.getDensity0()
            st["particle_radius"] = sim.getParticleRadius()
            st["support_radius"] = sim.getSupportRadius()
            st["kernel"] = sim.getValueInt(sim.KERNEL_METHOD)
            st["kernel_cubic"] = (sim.ENUM_KERNEL_CUBIC, sim.ENUM_KERNEL_PRECOMPUTED_CUBIC)
            st["n_fluid_models"] = sim.numberOfFluidModels()
            st["fields"] = [fm.getField(i).name for i in range(fm.numberOfFields())]
        if time.time() - st["last_report"] > 15:
            st["last_report"] = time.time()
            print(f"  t = {t:.4f} s, dt = {tm.getTimeStepSize():.5f} s, steps = {st['steps']}, "
                  f"wall = {time.time() - st['t0']:.0f} s", flush=True)
        frames = sorted(
            (int(f.rsplit("_", 1)[1][:-4]), f) for f in os.listdir(vtk_dir) if f.endswith(".vtk")
        )
        wrote_now = len(frames) > st.get("nframes", 0)
        st["nframes"] = len(frames)
        if "frame" not in st and wrote_now and t >= args.time * (1 - 1e-6):
            # The exporter wrote a frame in this very step (it runs before this callback):
            # snapshot the solver's in-memory buffers of the same state for the check.
            n = fm.numActiveParticles()
            mem = {}
            for name in ["position", "velocity", "density"] + (
                [PRESSURE_FIELD[args.method][0]] if args.method in PRESSURE_FIELD else []
            ):
                buf = np.array(fm.getFieldBuffer(name), copy=True)
                mem[name] = buf[:n]
            mem["id"] = np.array([fm.getParticleId(i) for i in range(n)], dtype=np.uint32)
            st["frame"] = os.path.join(vtk_dir, frames[-1][1])
            st["frame_time"] = t
            st["mem"] = mem
            st["steps_at_frame"] = st["steps"]
            # Stop at the next step (the check is "stopAt < time").
            base.setValueFloat(base.STOP_AT, t * 0.5)

    base.setTimeStepCB(on_step)
    base.run()
    st["wall"] = time.time() - st["t0"]
    if "frame" not in st:
        raise SystemExit("simulation ended before the requested time")
    return st


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="output .npz path")
    ap.add_argument("--scene", default=DEFAULT_SCENE,
                    help="scene shipped with pysplishsplash (name) or a scene JSON path")
    ap.add_argument("--time", type=float, default=DEFAULT_TIME, help="simulated time of the frame (s)")
    ap.add_argument("--radius", type=float, default=DEFAULT_RADIUS, help="particle radius r (m)")
    ap.add_argument("--method", choices=["iisph", "dfsph"], default="iisph",
                    help="pressure solver (dfsph exports no pressure field)")
    ap.add_argument("--threads", type=int, default=1,
                    help="OpenMP threads (default 1: bit-for-bit reproducible; 0 = all cores, "
                         "faster but not reproducible)")
    ap.add_argument("--preview-fps", type=float, default=None,
                    help="also export VTK frames at this rate (kept in the workdir)")
    ap.add_argument("--workdir", default=None, help="solver output folder (default: a temp dir)")
    ap.add_argument("--keep-workdir", action="store_true")
    args = ap.parse_args(argv)
    if args.preview_fps:
        args.keep_workdir = True

    sph = import_pysplishsplash(args.threads or None)
    from importlib.metadata import version

    got = version("pysplishsplash")
    if got != PYSPLISHSPLASH_VERSION:
        print(f"warning: pysplishsplash {got} installed, the reference data used "
              f"{PYSPLISHSPLASH_VERSION}", file=sys.stderr)

    own_workdir = args.workdir is None
    workdir = args.workdir or tempfile.mkdtemp(prefix="isobar-demo-")
    scene = build_scene(args)
    scene_path = write_scene(scene, workdir)
    print(f"scene: {resolve_scene(args.scene)} -> {scene_path}")
    print(f"  particleRadius={args.radius} simulationMethod={args.method} "
          f"particleAttributes={scene['Configuration']['particleAttributes']}")

    st = simulate(args, sph, scene_path, workdir)

    # --- read the exporter's frame and check it against the solver's memory ----------
    vtk = read_splishsplash_vtk(st["frame"])
    mem = st["mem"]
    n = len(vtk["id"])
    if st["n_fluid_models"] != 1:
        raise SystemExit("expected exactly one fluid model")
    if n != st["n0"] or n != len(mem["id"]):
        raise SystemExit(f"particle count changed: {st['n0']} -> {n}")
    checks = {"position": "position", "velocity": "velocity", "density": "density"}
    if args.method in PRESSURE_FIELD:
        pf = PRESSURE_FIELD[args.method][0]
        checks[pf.replace(" ", "_")] = pf
    if not np.array_equal(vtk["id"], mem["id"]):
        raise SystemExit("VTK ids differ from the solver's ids")
    for vk, mk in checks.items():
        if not np.array_equal(vtk[vk], mem[mk].astype(vtk[vk].dtype)):
            raise SystemExit(f"VTK field {vk} differs from the solver's buffer {mk}")

    r = float(st["particle_radius"])
    rho0 = float(st["density0"])
    support = float(st["support_radius"])
    if not np.isclose(support, 4 * r, rtol=1e-6):
        raise SystemExit(f"support radius {support} != 4 r = {4 * r}")
    h = support / 2.0
    mass = st["mass"]
    if not np.allclose(mass, rho0 * (2 * r) ** 3, rtol=1e-5):
        raise SystemExit(f"masses {mass.min()}..{mass.max()} != rho0 (2r)^3 = {rho0 * (2 * r) ** 3}")

    order = np.argsort(vtk["id"], kind="stable")
    out = {
        "positions": vtk["position"][order].astype(np.float32),
        "velocity": vtk["velocity"][order].astype(np.float32),
    }
    if args.method in PRESSURE_FIELD:
        raw = vtk[PRESSURE_FIELD[args.method][0]][order]
        out["pressure"] = pressure_to_pascal(args.method, raw, rho0)
    else:
        print("note: this solver exposes no 'pressure' field; only density is exported",
              file=sys.stderr)
    out["density"] = vtk["density"][order].astype(np.float32)
    out["h"] = np.full(n, h, dtype=np.float32)
    out["mass"] = mass[: n].astype(np.float32)  # all equal (asserted above)

    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    np.savez_compressed(args.out, **out)

    speed = np.linalg.norm(out["velocity"], axis=1)
    print(f"frame: {os.path.basename(st['frame'])} at t = {st['frame_time']:.5f} s after "
          f"{st['steps_at_frame']} steps; simulation wall time {st['wall']:.1f} s")
    print(f"kernel method {st['kernel']} (cubic={st['kernel_cubic'][0]}, "
          f"precomputed cubic={st['kernel_cubic'][1]}); fields: {st['fields']}")
    print(f"N = {n}, r = {r:g} m, h = {h:g} m (support {support:g} m), rho0 = {rho0:g} kg/m^3, "
          f"mass = {float(mass[0]):g} kg")
    for k, v in out.items():
        a = speed if k == "velocity" else v
        label = "|velocity|" if k == "velocity" else k
        if k == "positions":
            print(f"  positions min {v.min(axis=0)} max {v.max(axis=0)}")
            continue
        print(f"  {label:10s} min {a.min():.6g} max {a.max():.6g} mean {a.mean():.6g} "
              f"median {np.median(a):.6g}")
    if "pressure" in out:
        p = out["pressure"]
        print(f"  pressure > 0 for {np.count_nonzero(p > 0)} of {n}; "
              f"percentiles 50/75/90/99: {np.percentile(p, [50, 75, 90, 99])}")
    print(f"wrote {args.out} ({os.path.getsize(args.out)} bytes)")

    if args.keep_workdir or not own_workdir:
        print(f"solver output kept in {workdir}")
    else:
        shutil.rmtree(workdir, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
