"""The filter in a data-parallel pvbatch run (run by test_paraview.py with mpiexec -n 1,
-n 2 and -n 3). Argument: an output prefix. Writes the fetched surfaces (all pieces
appended, unmerged) as .vtp files:

  PREFIX_auto.vtp   particles split over the ranks by RedistributeDataSet, default
                    settings (the lattice of the single-process grid);
  PREFIX_reader.vtp the reader's output directly (LegacyVTKReader gives rank 0 every
                    particle; the filter redistributes them itself);
  PREFIX_fixed.vtp  Fixed Lattice on, origin LATTICE_ORIGIN, cell LATTICE_CELL;
  PREFIX_frame01.vtp frame 1 (particles on a regular lattice) from the reader;
  PREFIX_varied.vtp per-particle h, quintic kernel, H Scale, a point-array field with
                    Shepard and trimming, carried arrays;
  PREFIX_fe_*.vtp   the FE filter's samples of an MFEM solution: from the reader's one
                    piece, from its cells split over the ranks, beyond the field;

and prints one JSON line per case: `CASE name {"particles": [...], "triangles": [...],
"points": [...], "rank0_piece": {...}}` (per rank: input particles, output triangles and
points; rank 0's slab and the particles it extracted from), then one
`bad ...: N cells` line per bad setting (all must be empty, no rank may hang)."""

import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness as h  # noqa: E402

from paraview import servermanager as sm  # noqa: E402
from paraview.simple import (  # noqa: E402
    Calculator,
    LegacyVTKReader,
    LoadPlugin,
    RedistributeDataSet,
    XMLPolyDataReader,
    XMLUnstructuredGridReader,
)
from vtkmodules.util.numpy_support import vtk_to_numpy  # noqa: E402
from vtkmodules.vtkCommonCore import vtkPoints  # noqa: E402
from vtkmodules.vtkCommonDataModel import vtkPolyData  # noqa: E402
from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter  # noqa: E402

LoadPlugin(h.PLUGIN, remote=False, ns=globals())
SPHIsosurface = globals()["SPHIsosurfaceMarchingCorrectors"]
prefix = sys.argv[1]
ranks = sm.vtkProcessModule.GetProcessModule().GetNumberOfLocalPartitions()

reader = LegacyVTKReader(FileNames=[h.FRAME_26])
pieces = RedistributeDataSet(Input=reader)


def run_case(name, source, **props):
    settings = dict(SmoothingLength=h.H, GridFactor=h.GRID_FACTOR, Isovalues=[h.ISO])
    settings.update(props)
    f = SPHIsosurface(Input=source, **settings)
    surface = sm.Fetch(f)
    per_rank = [sm.Fetch(f, p) for p in range(ranks)]
    # Rank 0's filter, as PrintSelf lists it (the plugin's class has no Python wrapping).
    printed = {}
    for line in str(f.GetClientSideObject()).splitlines():
        key, sep, value = line.strip().partition(":")
        if sep:
            printed[key] = value.strip()
    info = {
        "particles": [sm.Fetch(source, p).GetNumberOfPoints() for p in range(ranks)],
        "triangles": [d.GetNumberOfCells() for d in per_rank],
        "points": [d.GetNumberOfPoints() for d in per_rank],
        "rank0_piece": {"axis": int(printed["PieceAxis"]),
                        "slab": [float(x) for x in printed["PieceBounds"].split()],
                        "particles": int(printed["PieceParticles"])},
    }
    assert sum(info["triangles"]) == surface.GetNumberOfCells(), (info, surface.GetNumberOfCells())
    w = vtkXMLPolyDataWriter()
    w.SetFileName(f"{prefix}_{name}.vtp")
    w.SetInputData(surface)
    w.SetDataModeToBinary()
    w.Write()
    global _last_case
    _last_case = json.dumps(info)
    print(f"CASE {name} {_last_case}", flush=True)


_last_case = "{}"


run_case("auto", pieces)
run_case("reader", reader)
run_case("fixed", pieces, FixedLattice=1, LatticeOrigin=list(h.LATTICE_ORIGIN),
         LatticeCellSize=h.LATTICE_CELL)
# Frame 1: particles still on their initial lattice, many of them exactly on a cut.
run_case("frame01", LegacyVTKReader(FileNames=[h.FRAME_01]))
# Per-particle h (a wider support at some particles), the quintic kernel (support 3h),
# a scaled h, a point-array field with Shepard normalisation and trimming, carried arrays.
varied = Calculator(Input=pieces, ResultArrayName="hvar",
                    Function="0.05*(1+0.1*sin(20*coordsX))")
run_case("varied", varied, SmoothingLength=0.0, SmoothingLengthArray="hvar",
         Kernel="Quintic spline", HScale=0.75, FieldMode="Point array",
         InputArray=["POINTS", "velocity"], Isovalues=[1.5], Shepard=1,
         CarriedArrays=["velocity", "id"])
# The coordinate along the slab axis as the field: its level set a quarter of the way
# along is a plane in one slab only (the other ranks make none of it, which is no news),
# and 1000 is beyond the data everywhere (news: its warning must come).
axis = max(json.loads(_last_case)["rank0_piece"]["axis"], 0)  # one rank cuts no slab
lo, hi = reader.GetDataInformation().GetBounds()[2 * axis: 2 * axis + 2]
plane = round(lo + 0.25 * (hi - lo), 3)
coordinate = Calculator(Input=pieces, ResultArrayName="along", Function="coords" + "XYZ"[axis])
run_case("plane", coordinate, FieldMode="Point array", InputArray=["POINTS", "along"],
         Shepard=1, Isovalues=[plane, 1000.0])
print(f"plane at {plane}", flush=True)

# High-order samples (the FE filter) of a real MFEM solution (Q3 hexahedra): the reader's
# single piece (rank 0 holds every cell, the others none) and the cells split over the
# ranks. Each case prints the samples and the median Radius (which follows the spacing)
# per rank and writes the joined samples.
HighOrderSamples = globals()["HighOrderIsosurfaceSamples"]
fe_reader = XMLUnstructuredGridReader(FileName=[h.FE_MFEM])
fe_range = fe_reader.PointData["u"].GetRange()


def run_fe_case(name, source, iso):
    f = HighOrderSamples(Input=source, Isovalue=iso)
    f.Scalars = ["POINTS", "u"]
    per_rank = [sm.Fetch(f, p) for p in range(ranks)]
    radius = [vtk_to_numpy(d.GetPointData().GetArray("Radius")) for d in per_rank
              if d.GetNumberOfPoints() > 0]
    info = {"cells": [sm.Fetch(source, p).GetNumberOfCells() for p in range(ranks)],
            "samples": [d.GetNumberOfPoints() for d in per_rank],
            "radius_median": float(np.median(np.concatenate(radius))) if radius else None}
    w = vtkXMLPolyDataWriter()
    w.SetFileName(f"{prefix}_{name}.vtp")
    w.SetInputData(sm.Fetch(f))
    w.SetDataModeToBinary()
    w.Write()
    print(f"CASE {name} {json.dumps(info)}", flush=True)


fe_middle = 0.5 * (fe_range[0] + fe_range[1])
run_fe_case("fe_reader", fe_reader, fe_middle)
run_fe_case("fe_split", RedistributeDataSet(Input=fe_reader), fe_middle)
# Beyond the field: no piece has a sample, so this one must be warned about.
run_fe_case("fe_beyond", RedistributeDataSet(Input=fe_reader), fe_range[1] + 1.0)

# A bad setting under MPI: every rank reports, none waits for another (no deadlock), the
# output is empty everywhere.
bad = SPHIsosurface(Input=pieces, SmoothingLength=h.H, FieldMode="Point array")
bad.InputArray = ["POINTS", "pressure"]
empty = sm.Fetch(bad)
print(f"bad input: {empty.GetNumberOfCells()} cells", flush=True)

# A NaN position (on the rank that reads the file): refused before the particles are
# partitioned, on every rank.
pd = vtkPolyData()
pts = vtkPoints()
pts.SetDataTypeToDouble()
for p in ((0.0, 0.0, 0.0), (0.01, 0.0, 0.0), (float("nan"), 0.0, 0.0), (0.0, 0.02, 0.0)):
    pts.InsertNextPoint(p)
pd.SetPoints(pts)
nan_path = f"{prefix}_nan_particles.vtp"
w = vtkXMLPolyDataWriter()
w.SetFileName(nan_path)
w.SetInputData(pd)
w.Write()
nan = SPHIsosurface(Input=XMLPolyDataReader(FileName=[nan_path]), SmoothingLength=h.H)
print(f"bad nan: {sm.Fetch(nan).GetNumberOfCells()} cells", flush=True)

# An error inside the core, after the exchange (over the memory budget on every rank).
tight = SPHIsosurface(Input=pieces, SmoothingLength=h.H, GridFactor=h.GRID_FACTOR,
                      MemoryBudget=1e-6)
print(f"bad budget: {sm.Fetch(tight).GetNumberOfCells()} cells", flush=True)
