"""One surface reconstruction per process, so each gets its own peak-RSS measurement.

    python workers.py {splashsurf,vtk} POSITIONS.npy MESH.npz RESULT.json \
        --radius R --cube C --iso ISO

Writes the mesh (vertices float64, triangles int64) to MESH.npz and the timings to
RESULT.json. `extract_s` covers the reconstruction only: after the positions are in
memory, before the mesh is copied out.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def rss_mib() -> float:
    """Current resident set size of this process (VmRSS), in MiB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def run_splashsurf(points: np.ndarray, radius: float, cube: float, iso: float):
    import pysplashsurf

    # pysplashsurf 0.14.1's docstring says absolute units, but smoothing_length and
    # cube_size are multiplied by particle_radius (an absolute 0.75 r gives cells of
    # 0.75 r^2): pass multiples of r. rest_density cancels out of m / rho_j.
    t0 = time.perf_counter()
    recon = pysplashsurf.reconstruct_surface(
        points,
        particle_radius=radius,
        rest_density=1000.0,
        smoothing_length=2.0,
        cube_size=cube,
        iso_surface_threshold=iso,
        multi_threading=True,
    )
    extract_s = time.perf_counter() - t0
    mesh = recon.mesh
    phases = {"cell_size": recon.grid.cell_size}
    return np.asarray(mesh.vertices), np.asarray(mesh.triangles), extract_s, phases


def run_vtk(points: np.ndarray, radius: float, cube: float, iso: float):
    from vtkmodules.vtkCommonCore import vtkSMPTools

    # PyPI's wheel defaults to the Sequential backend; STDThread uses every core, as the
    # other methods do.
    vtkSMPTools.SetBackend("STDThread")
    h = 2.0 * radius
    source = _polydata(points)
    t0 = time.perf_counter()
    _set_sph_volumes(source, h)
    t1 = time.perf_counter()
    image = _sample_sum_of_weights(source, points, h, cube * radius)
    t2 = time.perf_counter()
    vertices, triangles = _flying_edges(image, iso)
    t3 = time.perf_counter()
    phases = {
        "densities_s": t1 - t0,
        "resample_s": t2 - t1,
        "flying_edges_s": t3 - t2,
        "grid_points": image.GetNumberOfPoints(),
        "smp_threads": vtkSMPTools.GetEstimatedNumberOfThreads(),
    }
    return vertices, triangles, t3 - t0, phases


def _polydata(points: np.ndarray):
    from vtkmodules.util.numpy_support import numpy_to_vtk
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkPolyData

    pts = vtkPoints()
    pts.SetData(numpy_to_vtk(points, deep=True))
    poly = vtkPolyData()
    poly.SetPoints(pts)
    return poly


def _sph_interpolator(probe, source, h: float):
    """vtkSPHInterpolator with the cubic kernel of smoothing length h (support 2h)."""
    from vtkmodules.vtkFiltersPoints import vtkSPHCubicKernel, vtkSPHInterpolator

    kernel = vtkSPHCubicKernel()
    # SpatialStep is h; the cubic kernel's CutoffFactor is fixed at 2, so the support is
    # 2h = 4r, and NormFactor = 1/(pi h^3), the normalisation the evaluator uses.
    kernel.SetSpatialStep(h)
    interp = vtkSPHInterpolator()
    interp.SetInputData(probe)
    interp.SetSourceData(source)
    interp.SetKernel(kernel)
    # The Shepard sum is sum_j V_j W(x - x_j): with V_j = 1/rho_j it is exactly S(x).
    interp.ComputeShepardSumOn()
    interp.SetShepardSumArrayName("S")
    interp.ShepardNormalizationOff()
    return interp


def _set_sph_volumes(source, h: float) -> None:
    """Adds mass and density arrays whose ratio is V_j = 1 / sum_k W(x_j - x_k)."""
    from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy

    # Without mass/density arrays the kernel uses the volume h^3, so the Shepard sum at
    # a particle is h^3 sum_k W; mass = h^3 and density = that sum give 1 / sum_k W.
    interp = _sph_interpolator(source, source, h)
    interp.Update()
    density = vtk_to_numpy(interp.GetOutput().GetPointData().GetArray("S")).astype(
        np.float64
    )
    for name, values in (("density", density), ("mass", np.full(len(density), h**3))):
        array = numpy_to_vtk(values, deep=True)
        array.SetName(name)
        source.GetPointData().AddArray(array)


def _sample_sum_of_weights(source, points: np.ndarray, h: float, cell: float):
    """S(x) on an image of spacing `cell` covering the particles plus the support."""
    from vtkmodules.vtkCommonDataModel import vtkImageData

    pad = 2.0 * h + cell
    lo = points.min(axis=0) - pad
    dims = np.ceil((points.max(axis=0) + pad - lo) / cell).astype(int) + 1
    image = vtkImageData()
    image.SetOrigin(*lo)
    image.SetSpacing(cell, cell, cell)
    image.SetDimensions(*(int(d) for d in dims))
    interp = _sph_interpolator(image, source, h)
    interp.SetMassArrayName("mass")
    interp.SetDensityArrayName("density")
    # Only the Shepard sum is wanted; interpolating mass and density would cost time.
    interp.AddExcludedArray("mass")
    interp.AddExcludedArray("density")
    interp.Update()
    return interp.GetOutput()


def _flying_edges(image, iso: float):
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkCommonDataModel import vtkDataObject
    from vtkmodules.vtkFiltersCore import vtkFlyingEdges3D

    fe = vtkFlyingEdges3D()
    fe.SetInputData(image)
    fe.SetInputArrayToProcess(0, 0, 0, vtkDataObject.FIELD_ASSOCIATION_POINTS, "S")
    fe.SetValue(0, iso)
    fe.ComputeNormalsOff()
    fe.ComputeGradientsOff()
    fe.ComputeScalarsOff()
    fe.Update()
    out = fe.GetOutput()
    if out.GetNumberOfPoints() == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    vertices = vtk_to_numpy(out.GetPoints().GetData()).astype(np.float64)
    triangles = vtk_to_numpy(out.GetPolys().GetConnectivityArray()).reshape(-1, 3)
    return vertices, triangles


METHODS = {"splashsurf": run_splashsurf, "vtk": run_vtk}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("method", choices=sorted(METHODS))
    parser.add_argument("positions", type=Path)
    parser.add_argument("mesh", type=Path)
    parser.add_argument("result", type=Path)
    parser.add_argument("--radius", type=float, required=True)
    parser.add_argument("--cube", type=float, required=True)
    parser.add_argument("--iso", type=float, required=True)
    args = parser.parse_args()

    t0 = time.perf_counter()
    points = np.load(args.positions)
    read_s = time.perf_counter() - t0
    # Interpreter, numpy and the positions: the floor under this process's peak RSS.
    baseline_mib = rss_mib()
    vertices, triangles, extract_s, phases = METHODS[args.method](
        points, args.radius, args.cube, args.iso
    )
    np.savez(args.mesh, vertices=vertices, triangles=triangles.astype(np.int64))
    result = {
        "read_s": read_s,
        "extract_s": extract_s,
        "baseline_rss_mib": baseline_mib,
        "phases": phases,
    }
    args.result.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
