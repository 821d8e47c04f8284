"""Accuracy of `isobar fe` samples against VTK's own contouring of the same Lagrange cells.

VTK evaluates the field (vtkProbeFilter: its own inversion and Lagrange basis) at
(a) the vertices of vtkContourFilter's isosurface of the cells (VTK linearises each cell)
and (b) isobar's samples; prints max and mean |F - C| of both.

    /tmp/vtkvenv/bin/python scripts/fe_accuracy_vs_vtk.py /tmp/fe_bench.vtu /tmp/fe_bench.vtp p 0
"""

import sys
import time

import vtk
from vtk.util.numpy_support import vtk_to_numpy


def probe(grid, points, field, iso):
    pf = vtk.vtkProbeFilter()
    pf.SetSourceData(grid)
    pf.SetInputData(points)
    pf.Update()
    out = pf.GetOutput()
    vals = vtk_to_numpy(out.GetPointData().GetArray(field))
    ok = vtk_to_numpy(out.GetPointData().GetArray(pf.GetValidPointMaskArrayName())).astype(bool)
    err = abs(vals[ok] - iso)
    return err.max(), err.mean(), ok.sum(), len(ok)


def main(vtu, vtp, field, iso):
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(vtu)
    r.Update()
    grid = r.GetOutput()
    grid.GetPointData().SetActiveScalars(field)
    t = time.time()
    c = vtk.vtkContourFilter()
    c.SetInputData(grid)
    c.SetValue(0, iso)
    c.Update()
    contour = c.GetOutput()
    print(f"VTK contour: {contour.GetNumberOfPoints()} vertices in {time.time() - t:.2f} s")
    print("VTK contour vertices: max |F-C| %.2e mean %.2e (%d of %d probed)" % probe(grid, contour, field, iso))
    s = vtk.vtkXMLPolyDataReader()
    s.SetFileName(vtp)
    s.Update()
    print("isobar samples:       max |F-C| %.2e mean %.2e (%d of %d probed)" % probe(grid, s.GetOutput(), field, iso))


main(sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4]))
