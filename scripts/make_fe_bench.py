"""A Fig. 11-sized benchmark problem: 18 x 18 x 18 = 5,832 curved third-order Lagrange
hexahedra (the paper's CFD mesh has 5,736 third-order elements) with a smooth pressure-like
field whose level 0 spans many elements. Written by VTK (appended, zlib).

    /tmp/vtkvenv/bin/python scripts/make_fe_bench.py /tmp/fe_bench.vtu
    isobar fe /tmp/fe_bench.vtu --field p --iso 0 --spacing 0.09 -o /tmp/fe_bench.vtp
"""

import math
import sys

import vtk

N, P = 18, 3


def world(x, y, z):
    # Curved: a gentle swirl of the box [0, 2]^3.
    return (x + 0.05 * math.sin(2 * y), y + 0.05 * math.sin(2 * z), z + 0.05 * math.sin(2 * x))


def pressure(x, y, z):
    return math.sin(2.1 * x) * math.cos(1.7 * y) + 0.6 * math.sin(1.3 * z + 0.4) - 0.2


def main(path):
    side = N * P + 1
    pts = vtk.vtkPoints()
    pts.SetDataTypeToDouble()
    p = vtk.vtkDoubleArray()
    p.SetName("p")
    for k in range(side):
        for j in range(side):
            for i in range(side):
                w = world(2.0 * i / (side - 1), 2.0 * j / (side - 1), 2.0 * k / (side - 1))
                pts.InsertNextPoint(*w)
                p.InsertNextValue(pressure(*w))
    cell = vtk.vtkLagrangeHexahedron()
    n = (P + 1) ** 3
    cell.GetPointIds().SetNumberOfIds(n)
    cell.GetPoints().SetNumberOfPoints(n)
    cell.SetUniformOrderFromNumPoints(n)
    cell.Initialize()
    pc = cell.GetParametricCoords()
    local = [tuple(round(pc[3 * a + d] * P) for d in range(3)) for a in range(n)]
    grid = vtk.vtkUnstructuredGrid()
    grid.SetPoints(pts)
    for c in range(N ** 3):
        a, b, d = c % N, (c // N) % N, c // (N * N)
        ids = [(a * P + l[0]) + side * ((b * P + l[1]) + side * (d * P + l[2])) for l in local]
        grid.InsertNextCell(vtk.VTK_LAGRANGE_HEXAHEDRON, n, ids)
    grid.GetPointData().AddArray(p)
    w = vtk.vtkXMLUnstructuredGridWriter()
    w.SetFileName(path)
    w.SetInputData(grid)
    w.SetDataModeToAppended()
    w.SetCompressorTypeToZLib()
    w.Write()


main(sys.argv[1])
