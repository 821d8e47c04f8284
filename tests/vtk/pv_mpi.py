"""The filter in a data-parallel pvbatch run (run by test_paraview.py with mpiexec -n 1
and -n 2): the particles are redistributed over the ranks first, so every rank holds a
piece; the fetched surface (all pieces appended) is written to the .vtp named by argv[1].
Prints the particles per rank and the triangles per rank."""

import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness as h  # noqa: E402

from paraview import servermanager as sm  # noqa: E402
from paraview.simple import LegacyVTKReader, LoadPlugin, ProcessIdScalars, RedistributeDataSet  # noqa: E402
from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter  # noqa: E402

LoadPlugin(h.PLUGIN, remote=False, ns=globals())
SPHIsosurface = globals()["SPHIsosurfaceMarchingCorrectors"]
out_path = sys.argv[1]
ranks = sm.vtkProcessModule.GetProcessModule().GetNumberOfLocalPartitions()

reader = LegacyVTKReader(FileNames=[h.FRAME_26])
pieces = RedistributeDataSet(Input=reader)
per_rank = [sm.Fetch(pieces, p).GetNumberOfPoints() for p in range(ranks)]
print("particles per rank:", json.dumps(per_rank), flush=True)

f = SPHIsosurface(Input=pieces, SmoothingLength=h.H, GridFactor=h.GRID_FACTOR, Isovalues=[h.ISO])
surface = sm.Fetch(f)
tris_per_rank = [sm.Fetch(f, p).GetNumberOfCells() for p in range(ranks)]
assert sum(tris_per_rank) == surface.GetNumberOfCells(), (tris_per_rank, surface.GetNumberOfCells())
ids = sm.Fetch(ProcessIdScalars(Input=f))
pid = ids.GetPointData().GetArray("ProcessId")
owners = np.unique([pid.GetValue(i) for i in range(0, pid.GetNumberOfTuples(), 97)])
w = vtkXMLPolyDataWriter()
w.SetFileName(out_path)
w.SetInputData(surface)
w.SetDataModeToBinary()
w.Write()
print(f"{ranks} rank(s): triangles per rank {tris_per_rank}, vertices made on ranks "
      f"{owners.tolist()}, total {surface.GetNumberOfCells()}", flush=True)

# A bad setting under MPI: every rank reports, none waits for another (no deadlock), the
# output is empty everywhere.
bad = SPHIsosurface(Input=pieces, SmoothingLength=h.H, FieldMode="Point array")
bad.InputArray = ["POINTS", "pressure"]
empty = sm.Fetch(bad)
print(f"bad input: {empty.GetNumberOfCells()} cells", flush=True)
