"""Benchmark (not a test): the isobar filter against ParaView's own route to an SPH
isosurface — SPH Volume Interpolator onto a grid, then Contour — on the same particles,
in one pvbatch run.

    PYTHONPATH=/opt/isobar/paraview-5.11/usr/lib/python3/dist-packages \
        pvbatch vtk-plugin/bench.py [FRAME.vtk ...] [--json OUT.json]

Field: the free surface of splashsurf's frames, the SPH sum of weights
F(x) = sum_j V_j W(|x - x_j|, h) = 0.6 with V_j = 1 / sum_k W(|x_j - x_k|, h) (cubic
spline, h = 0.05). ParaView gets the same volumes the ParaView way: an SPH Dataset
Interpolator of the particles onto themselves gives sum_k W (its Shepard sum with the
default volume h^3, divided by h^3), a Calculator makes density and mass arrays, and the
SPH Volume Interpolator's Shepard sum on the grid is then F.

Each route runs in its own pvbatch child process (so that peaks are its own), twice: a
first run (pages in code, starts thread pools) and the measured one. Measured: wall time
of the pipeline update, peak resident memory above the level just before it (VmHWM,
reset through /proc/self/clear_refs), triangles, and |F - iso| at the output vertices,
F evaluated independently here with numpy (a cell-grid brute force over all particles
within the kernel support). Threads: whatever each library uses on this machine.
"""

import argparse
import gc
import json
import os
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
DATA = os.path.join(os.path.dirname(REPO), "shared", "data", "splashsurf")
PLUGIN = os.path.join(HERE, "build-pv", "lib", "paraview-5.11", "plugins", "IsobarSPH", "IsobarSPH.so")
H = 0.05
ISO = 0.6
GRID_FACTOR = 0.375  # splashsurf's cube size 0.75 r = 0.375 h

from paraview import servermanager as sm  # noqa: E402
from paraview.simple import (  # noqa: E402
    Calculator,
    Contour,
    Delete,
    LegacyVTKReader,
    LoadPlugin,
    SetActiveSource,
    SPHDatasetInterpolator,
    SPHVolumeInterpolator,
)
from vtkmodules.util.numpy_support import vtk_to_numpy  # noqa: E402

LoadPlugin(PLUGIN, remote=False, ns=globals())
SPHIsosurface = globals()["SPHIsosurfaceMarchingCorrectors"]


# --- the field, independently ----------------------------------------------------------
def cubic(r, h):
    q = r / h
    w = np.where(q < 1.0, 1.0 - 1.5 * q * q + 0.75 * q**3,
                 np.where(q < 2.0, 0.25 * (2.0 - q) ** 3, 0.0))
    return w / (np.pi * h**3)


class Field:
    """Brute force over a cell grid of the kernel support: exact sums, no cutoffs other
    than the kernel's own."""

    def __init__(self, particles, h):
        self.p = np.asarray(particles, dtype=np.float64)
        self.h = h
        self.cell = 2.0 * h
        self.lo = self.p.min(axis=0) - self.cell
        c = np.floor((self.p - self.lo) / self.cell).astype(np.int64)
        self.dims = c.max(axis=0) + 3
        lin = self._lin(c)
        self.order = np.argsort(lin, kind="stable")
        self.sorted = lin[self.order]
        self.volumes = np.ones(len(self.p))
        self.volumes = 1.0 / self.sum(self.p)

    def _lin(self, c):
        return (c[:, 0] * self.dims[1] + c[:, 1]) * self.dims[2] + c[:, 2]

    def sum(self, x, chunk=200000):
        out = np.empty(len(x))
        for s in range(0, len(x), chunk):
            out[s:s + chunk] = self._sum(np.asarray(x[s:s + chunk], dtype=np.float64))
        return out

    def _sum(self, x):
        qc = np.floor((x - self.lo) / self.cell).astype(np.int64)
        f = np.zeros(len(x))
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    nc = qc + (dx, dy, dz)
                    ok = np.all((nc >= 0) & (nc < self.dims), axis=1)
                    lin = self._lin(np.where(ok[:, None], nc, 0))
                    s = np.searchsorted(self.sorted, lin, "left")
                    e = np.searchsorted(self.sorted, lin, "right")
                    n = np.where(ok, e - s, 0)
                    for k in range(int(n.max(initial=0))):
                        m = n > k
                        j = self.order[s[m] + k]
                        r = np.linalg.norm(x[m] - self.p[j], axis=1)
                        f[m] += self.volumes[j] * cubic(r, self.h)
        return f


# --- measuring -------------------------------------------------------------------------
def rss_kib(field="VmRSS"):
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    return 0


def reset_peak():
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def measure(update):
    gc.collect()
    base = rss_kib()
    exact_peak = reset_peak()
    t = time.perf_counter()
    update()
    seconds = time.perf_counter() - t
    peak = rss_kib("VmHWM") - base
    return seconds, peak / 1024.0, exact_peak


def surface_arrays(proxy):
    data = sm.Fetch(proxy)
    pts = vtk_to_numpy(data.GetPoints().GetData()).reshape(-1, 3).astype(np.float64)
    return data, pts


# --- the routes ------------------------------------------------------------------------
def isobar_route(reader, correct):
    SetActiveSource(None)
    f = SPHIsosurface(Input=reader, SmoothingLength=H, GridFactor=GRID_FACTOR, Isovalues=[ISO],
                      Correct=int(correct))
    seconds, mib, exact = measure(f.UpdatePipeline)
    data, pts = surface_arrays(f)
    result = dict(seconds=seconds, peak_mib=mib, peak_exact=exact,
                  triangles=data.GetNumberOfCells(), points=pts)
    Delete(f)
    return result


def paraview_route(reader, bounds, cell):
    pad = 2.0 * H + cell
    lo = np.array(bounds[0::2]) - pad
    size = np.array(bounds[1::2]) + pad - lo
    stages = {}

    # 1. Particle volumes, the ParaView way: Shepard sum of the particles at themselves.
    dens = SPHDatasetInterpolator(Input=reader)
    dens.Source = reader
    # Its cutoff array defaults to the first scalar array ('id' here): per-particle radii
    # of up to thousands of h. The kernel's own cutoff (2h) is what SPH means.
    dens.CutoffArray = "None"
    dens.Kernel = "SPHCubicKernel"
    dens.Kernel.SpatialStep = H
    dens.DensityArray = ""
    dens.MassArray = ""
    dens.ExcludedArrays = ["id", "velocity"]
    dens.ComputeShepardSum = 1
    calc = Calculator(Input=dens)
    calc.ResultArrayName = "rho"
    calc.Function = f'"Shepard Summation" / {H**3!r}'
    calc2 = Calculator(Input=calc)
    calc2.ResultArrayName = "mass"
    calc2.Function = "1"
    # 2. The field on a grid of the same cell size as isobar's virtual grid.
    # With no active source, Source gets its default, the proxy list's BoundedVolumeSource
    # (what the GUI offers); otherwise Python would put the input there too.
    SetActiveSource(None)
    vol = SPHVolumeInterpolator(Input=calc2)
    vol.Source.Origin = lo.tolist()
    vol.Source.Scale = size.tolist()
    vol.Source.RefinementMode = 1  # by cell size
    vol.Source.CellSize = cell
    vol.Kernel = "SPHCubicKernel"
    vol.Kernel.SpatialStep = H
    vol.DensityArray = "rho"
    vol.MassArray = "mass"
    vol.ExcludedArrays = ["id", "velocity", "rho", "mass", "Shepard Summation"]
    vol.ComputeShepardSum = 1
    # 3. Contour.
    con = Contour(Input=vol)
    con.ContourBy = ["POINTS", "Shepard Summation"]
    con.Isosurfaces = [ISO]
    con.ComputeScalars = 0

    def run():
        t = time.perf_counter()
        calc2.UpdatePipeline()
        stages["volumes"] = time.perf_counter() - t
        t = time.perf_counter()
        vol.UpdatePipeline()
        stages["interpolate"] = time.perf_counter() - t
        t = time.perf_counter()
        con.UpdatePipeline()
        stages["contour"] = time.perf_counter() - t

    seconds, mib, exact = measure(run)
    data, pts = surface_arrays(con)
    img = vol.GetDataInformation()
    result = dict(seconds=seconds, peak_mib=mib, peak_exact=exact, stages=stages,
                  triangles=data.GetNumberOfCells(), points=pts,
                  grid_points=img.GetNumberOfPoints())
    # Sanity: the grid holds the same field as ours (a sample of grid points).
    grid = sm.Fetch(vol)
    g = vtk_to_numpy(grid.GetPointData().GetArray("Shepard Summation"))
    idx = np.linspace(0, len(g) - 1, 4000).astype(np.int64)
    gp = np.array([grid.GetPoint(int(i)) for i in idx])
    result["grid_sample"] = (gp, g[idx])
    for proxy in (con, vol, calc2, calc, dens):
        Delete(proxy)
    del grid
    return result


ROUTES = {
    "isobar": ("isobar (Marching Correctors)", lambda rd, b: isobar_route(rd, True)),
    "isobar-preview": ("isobar preview (no correction)", lambda rd, b: isobar_route(rd, False)),
    "paraview": ("ParaView SPH Volume Interpolator + Contour, same cell",
                 lambda rd, b: paraview_route(rd, b, GRID_FACTOR * H)),
    "paraview-coarse": ("ParaView SPH Volume Interpolator + Contour, cell 2x",
                        lambda rd, b: paraview_route(rd, b, 2 * GRID_FACTOR * H)),
}


def child(route, frame, out):
    """One route in this (fresh) process: its peak memory is its own."""
    reader = LegacyVTKReader(FileNames=[frame])
    reader.UpdatePipeline()
    bounds = reader.GetDataInformation().GetBounds()
    # A first run pages in code, starts thread pools and builds caches; the second,
    # measured run starts from that warm state (large buffers went back to the OS).
    warm = ROUTES[route][1](reader, bounds)
    cold_seconds = warm["seconds"]
    del warm
    gc.collect()
    r = ROUTES[route][1](reader, bounds)
    r["cold_seconds"] = cold_seconds
    np.save(out + ".points.npy", r.pop("points"))
    if "grid_sample" in r:
        gp, gv = r.pop("grid_sample")
        np.save(out + ".grid.npy", np.column_stack([gp, gv]))
    with open(out + ".json", "w") as fh:
        json.dump(r, fh)


def run_child(route, frame, tmp):
    import subprocess

    out = os.path.join(tmp, route)
    # pvbatch is an MPI singleton; its OpenMPI variables must not reach the child.
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("OMPI_", "PMIX_", "OPAL_", "ORTE_"))}
    pvbatch = os.environ.get("PVBATCH", "pvbatch")
    p = subprocess.run([pvbatch, os.path.abspath(__file__), "--child", route, frame, out],
                       env=env, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"{route} failed ({p.returncode}):\n{p.stdout[-2000:]}\n{p.stderr[-4000:]}")
    with open(out + ".json") as fh:
        r = json.load(fh)
    r["points"] = np.load(out + ".points.npy")
    if os.path.exists(out + ".grid.npy"):
        g = np.load(out + ".grid.npy")
        r["grid_sample"] = (g[:, :3], g[:, 3])
    return r


def bench(frame, tmp):
    from vtkmodules.vtkIOLegacy import vtkUnstructuredGridReader

    rd = vtkUnstructuredGridReader()
    rd.SetFileName(frame)
    rd.Update()
    pos = vtk_to_numpy(rd.GetOutput().GetPoints().GetData()).reshape(-1, 3).astype(np.float64)
    field = Field(pos, H)
    rows = []
    for route, (label, _fn) in ROUTES.items():
        r = run_child(route, frame, tmp)
        err = np.abs(field.sum(r.pop("points")) - ISO)
        r.update(label=label, max_err=float(err.max()), mean_err=float(err.mean()))
        if "grid_sample" in r:
            gp, gv = r.pop("grid_sample")
            r["grid_field_max_diff"] = float(np.max(np.abs(field.sum(gp) - gv)))
        rows.append(r)
    return dict(frame=os.path.basename(frame), particles=len(pos), rows=rows)


def table(result):
    lines = [f"{result['frame']} ({result['particles']} particles, h = {H}, iso {ISO}, "
             f"cell {GRID_FACTOR} h)", "",
             "| route | time (s) | first run (s) | peak memory (MiB) | triangles "
             "| max abs(F - iso) | mean abs(F - iso) |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for r in result["rows"]:
        lines.append(f"| {r['label']} | {r['seconds']:.3f} | {r['cold_seconds']:.3f} | {r['peak_mib']:.1f} | "
                     f"{r['triangles']} | {r['max_err']:.2e} | {r['mean_err']:.2e} |")
    notes = []
    for r in result["rows"]:
        if "stages" in r:
            s = r["stages"]
            notes.append(f"- {r['label']}: {r['grid_points']} grid points; volumes "
                         f"{s['volumes']:.3f} s, interpolation {s['interpolate']:.3f} s, contour "
                         f"{s['contour']:.3f} s; grid field vs numpy max diff "
                         f"{r['grid_field_max_diff']:.1e}")
    if not all(r["peak_exact"] for r in result["rows"]):
        notes.append("- peak memory: /proc/self/clear_refs not writable, peaks include reading")
    return "\n".join(lines + [""] + notes)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("frames", nargs="*", default=[
        os.path.join(DATA, "double_dam_break_frame_26_4732_particles.vtk"),
        os.path.join(DATA, "bunny_frame_14_7705_particles.vtk")])
    ap.add_argument("--json", help="also write the results here")
    ap.add_argument("--child", nargs=3, metavar=("ROUTE", "FRAME", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(*args.child)
        return
    import tempfile

    tmp = tempfile.mkdtemp(prefix="isobar-bench-")
    results = []
    for frame in args.frames:
        res = bench(frame, tmp)
        results.append(res)
        print(table(res), "\n", flush=True)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)


if __name__ == "__main__":
    main()
