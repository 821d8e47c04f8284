"""Bad inputs in a pvbatch process (run by test_paraview.py): each case must print an
error through vtkErrorMacro (stderr), give an empty output, and the process must exit 0.
Prints `EMPTY <case>` for each case whose output is empty. Argument: a scratch folder."""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness as h  # noqa: E402

from paraview import servermanager as sm  # noqa: E402
from paraview.simple import LegacyVTKReader, LoadPlugin, XMLPolyDataReader  # noqa: E402
from vtkmodules.vtkCommonCore import vtkPoints  # noqa: E402
from vtkmodules.vtkCommonDataModel import vtkPolyData  # noqa: E402
from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter  # noqa: E402

LoadPlugin(h.PLUGIN, remote=False, ns=globals())
SPHIsosurface = globals()["SPHIsosurfaceMarchingCorrectors"]
tmp = sys.argv[1] if len(sys.argv) > 1 else h.tmpdir()


def report(case, proxy):
    out = sm.Fetch(proxy)
    if out.GetNumberOfPoints() == 0 and out.GetNumberOfCells() == 0:
        print(f"EMPTY {case}", flush=True)
    else:
        print(f"NOT EMPTY {case}: {out.GetNumberOfCells()} cells", flush=True)


frame = LegacyVTKReader(FileNames=[h.FRAME_26])

f = SPHIsosurface(Input=frame, SmoothingLength=h.H, FieldMode="Point array")
f.InputArray = ["POINTS", "pressure"]
report("missing-array", f)

# Particles with a NaN coordinate, written and read back as a .vtp.
pd = vtkPolyData()
pts = vtkPoints()
pts.SetDataTypeToDouble()
for p in ((0.0, 0.0, 0.0), (0.01, 0.0, 0.0), (float("nan"), 0.0, 0.0), (0.0, 0.02, 0.0)):
    pts.InsertNextPoint(p)
pd.SetPoints(pts)
path = os.path.join(tmp, "nan_particles.vtp")
w = vtkXMLPolyDataWriter()
w.SetFileName(path)
w.SetInputData(pd)
w.Write()
g = SPHIsosurface(Input=XMLPolyDataReader(FileName=[path]), SmoothingLength=h.H)
report("nan-positions", g)

k = SPHIsosurface(Input=frame, SmoothingLength=0.0)
report("no-smoothing-length", k)
