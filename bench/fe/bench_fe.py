"""The high-order FE benchmark of issue #7: time and forward evaluations of `isobar fe` on
the paper's problems, and accuracy against VTK's own contouring of the same Lagrange cells,
in one run.

    python bench/fe/bench_fe.py [--isobar target/release/isobar] [--out bench/fe/results.md]

Rows:
  - isobar samples: the particle system (`isobar fe`), at spacings that give about the
    paper's particle counts (Fig. 9: 1,280 / 3,232 / 8,647 on the teardrop, rho = 8;
    Fig. 11: 5,000 on 5,832 third-order hexahedra);
  - isobar mc: the paper's baseline (`--method mc`: world grid, numerical inversion per
    node, Newton along edges) at the same spacing;
  - VTK contour: vtkContourFilter on the same vtkUnstructuredGrid (VTK linearises each
    Lagrange cell), timed in this process.
Two accuracy columns give max |F - C| at each method's points by two evaluators that do
not share code: VTK's vtkProbeFilter (its own cell location, inversion and Lagrange basis)
and isobar's probe (`FeMesh.probe`, the C ABI's isobar_fe_probe: binned cell search,
Newton on each cell's mapping, the core's Lagrange basis, loaded from
target/release/libisobar.so). So VTK's contour vertices are graded by an evaluator that
is not VTK, and isobar's samples by one that is not the particle system (which never
inverts a world point). isobar mc locates its grid nodes and edge points with the same
cell search and Newton inverse as the probe, so for that row the isobar probe column
is not independent of the method; the VTK column is. isobar's own figure (its stats line)
is reported beside them. Every run is a process of its
own, started by bench/measure.py (wall, CPU, peak RSS).
"""

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time

import numpy as np
import vtk
from vtk.util.numpy_support import vtk_to_numpy

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
# The isobar package from the source tree; it loads target/release/libisobar.so.
sys.path.insert(0, os.path.join(ROOT, "rust-core", "python"))
import isobar  # noqa: E402

# name, file made by scripts/make_fe_bench.py, field, isovalue, [(label, isobar fe options)]
CASES = [
    ("teardrop (Fig. 9)", "teardrop", "f", 0.64, [
        ("Fig. 9a: 1,280", ["--spacing", "0.08", "--rho", "8"]),
        ("Fig. 9b: 3,232", ["--spacing", "0.05", "--rho", "8"]),
        ("Fig. 9c: 8,647", ["--spacing", "0.028", "--rho", "8"]),
    ]),
    ("5,832 cubic hexahedra (Fig. 11)", "fig11", "p", 0.0, [
        ("Fig. 11b: 5,000", ["--spacing", "0.043"]),
    ]),
]

STATS = re.compile(r"(\d+) samples on \d+ cells .*?(\d+) forward evaluations.*max \|F - C\| = (\S+);")
MC_STATS = re.compile(r"(\d+) vertices.*?(\d+) (?:forward )?evaluations.*?max \|F - C\| = (\S+);")


def measure(cmd, timeout=600):
    with tempfile.NamedTemporaryFile(suffix=".json") as f:
        p = subprocess.run([sys.executable, "-I", "-S", os.path.join(ROOT, "bench", "measure.py"),
                            f.name, str(timeout)] + cmd, capture_output=True, text=True)
        m = json.load(f) if p.returncode == 0 else {}
        if m.get("exit_code") != 0:
            raise SystemExit(f"{' '.join(cmd)} failed:\n{p.stdout}{p.stderr}")
    return m, p.stdout + p.stderr


def read(path, reader):
    r = reader()
    r.SetFileName(path)
    r.Update()
    return r.GetOutput()


def vtk_residual(grid, points, field, iso):
    """max |F - C| at `points` by vtkProbeFilter, and how many VTK could locate."""
    pf = vtk.vtkProbeFilter()
    pf.SetSourceData(grid)
    pf.SetInputData(points)
    pf.Update()
    out = pf.GetOutput()
    vals = vtk_to_numpy(out.GetPointData().GetArray(field))
    ok = vtk_to_numpy(out.GetPointData().GetArray(pf.GetValidPointMaskArrayName())).astype(bool)
    if not ok.any():
        return float("nan"), 0, len(ok)
    return float(abs(vals[ok] - iso).max()), int(ok.sum()), len(ok)


def isobar_residual(mesh, points, field, iso):
    """max |F - C| at `points` by isobar's probe, and how many it located."""
    if points.GetNumberOfPoints() == 0:
        return float("nan"), 0, 0
    xyz = vtk_to_numpy(points.GetPoints().GetData()).astype(np.float64)
    vals, cells = mesh.probe(xyz, field)
    ok = cells >= 0
    if not ok.any():
        return float("nan"), 0, len(ok)
    return float(abs(vals[ok] - iso).max()), int(ok.sum()), len(ok)


def residual_cells(grid, mesh, points, field, iso):
    """The two grader columns of one row."""
    cols = []
    for probe, located, total in (vtk_residual(grid, points, field, iso),
                                  isobar_residual(mesh, points, field, iso)):
        cols.append(f"{probe:.1e} ({located}/{total})")
    return " | ".join(cols)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--isobar", default=os.path.join(ROOT, "target", "release", "isobar"))
    ap.add_argument("--data", default=os.path.join(ROOT, "target", "bench"))
    ap.add_argument("--out", default=os.path.join(HERE, "results.md"))
    args = ap.parse_args()
    os.makedirs(args.data, exist_ok=True)
    work = tempfile.mkdtemp(prefix="bench_fe_")
    load_start = os.getloadavg()
    lines = [
        f"# isobar fe vs VTK contouring of Lagrange cells",
        "",
        f"{platform.node()}: {os.cpu_count()} cores, load average "
        f"{' '.join(f'{x:.2f}' for x in load_start)} at start, VTK {vtk.vtkVersion.GetVTKVersion()}",
        "",
        "| problem | method | points | forward evals | wall s | CPU s | peak RSS MB "
        "| max abs(F-C) by VTK probe (located) | max abs(F-C) by isobar probe (located) "
        "| max abs(F-C) isobar's own |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for title, case, field, iso, runs in CASES:
        vtu = os.path.join(args.data, f"fe_{case}.vtu")
        if not os.path.exists(vtu):
            subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "make_fe_bench.py"),
                            case, vtu], check=True)
        grid = read(vtu, vtk.vtkXMLUnstructuredGridReader)
        grid.GetPointData().SetActiveScalars(field)
        mesh = isobar.FeMesh.read(vtu)
        for label, opts in runs:
            for method in ("samples", "mc"):
                out = os.path.join(work, f"{case}_{method}.vtp")
                m, log = measure([args.isobar, "fe", vtu, "--field", field, "--iso", str(iso),
                                  "--method", method, "-o", out] + opts)
                pat = STATS if method == "samples" else MC_STATS
                s = pat.search(log)
                if not s:
                    raise SystemExit(f"no stats line in:\n{log}")
                n, evals, own = s.groups()
                graded = residual_cells(grid, mesh, read(out, vtk.vtkXMLPolyDataReader), field, iso)
                lines.append(
                    f"| {title} | isobar {method} ({label}, `{' '.join(opts)}`) | {int(n):,} | "
                    f"{int(evals):,} | {m['wall_s']:.2f} | {m['cpu_s']:.2f} | {m['peak_rss_kib'] / 1024:.0f} | "
                    f"{graded} | {float(own):.1e} |")
                print(lines[-1], flush=True)
        t = time.perf_counter()
        c = vtk.vtkContourFilter()
        c.SetInputData(grid)
        c.SetValue(0, iso)
        c.Update()
        wall = time.perf_counter() - t
        contour = c.GetOutput()
        graded = residual_cells(grid, mesh, contour, field, iso)
        lines.append(
            f"| {title} | VTK vtkContourFilter (in-process) | {contour.GetNumberOfPoints():,} | - | "
            f"{wall:.2f} | - | - | {graded} | - |")
        print(lines[-1], flush=True)
    start, end = load_start[0], os.getloadavg()[0]
    lines += ["", f"Load average (1 min) {start:.2f} at start, {end:.2f} at the end, on "
              f"{os.cpu_count()} cores."]
    # Only the load at the start says whether other jobs shared the CPUs: by the end the
    # 1-minute average mostly counts the benchmark's own threads.
    if start > 0.5 * (os.cpu_count() or 1):
        # Other jobs shared the CPUs: the counts and accuracies hold, the times do not.
        lines += ["The machine was loaded (shared with other jobs): wall and CPU times are "
                  "inflated; points, forward evaluations and residuals do not depend on load."]
    # The command as run: niceness and a library other than target/release's change what ran.
    prefix = []
    if os.environ.get("ISOBAR_LIBRARY"):
        prefix.append(f"ISOBAR_LIBRARY={os.environ['ISOBAR_LIBRARY']}")
    if os.nice(0):
        prefix.append(f"nice -n {os.nice(0)}")
    cmd = prefix + [os.path.relpath(sys.executable, ROOT)] + sys.argv
    lines += ["", f"Command: `{' '.join(cmd)}`", ""]
    with open(args.out + ".part", "w") as f:
        f.write("\n".join(lines))
    os.replace(args.out + ".part", args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
