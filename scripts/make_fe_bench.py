"""The FE benchmark's problems (bench/fe/), written by VTK as Lagrange hexahedra (appended,
zlib):

fig11     18 x 18 x 18 = 5,832 curved third-order hexahedra (the paper's CFD mesh has 5,736
          third-order elements) with a smooth pressure-like field "p" whose level 0 spans
          many elements.
teardrop  the paper's Fig. 3/9 data: a sphere |y| = 0.8 mapped through 2 x 2 x 2 quadratic
          elements by x = (y1 w, y2 w, y3), w = 0.6 + 0.45 y3 (the teardrop of
          rust-core/src/highorder/tests.rs); field "f" = |y|^2, level 0.64.

    python scripts/make_fe_bench.py fig11 target/bench/fe_fig11.vtu
    isobar fe target/bench/fe_fig11.vtu --field p --iso 0 --spacing 0.043 -o samples.vtp
"""

import math
import os
import sys

import vtk

def swirl(x, y, z):
    # Curved: a gentle swirl of the box [0, 2]^3.
    return (x + 0.05 * math.sin(2 * y), y + 0.05 * math.sin(2 * z), z + 0.05 * math.sin(2 * x))


def pressure(x, y, z):
    return math.sin(2.1 * x) * math.cos(1.7 * y) + 0.6 * math.sin(1.3 * z + 0.4) - 0.2


def teardrop(x, y, z):
    # Reference coordinates in [0, 2]^3 -> y in [-1, 1]^3 -> the quadratic map.
    y = (x - 1.0, y - 1.0, z - 1.0)
    w = 0.6 + 0.45 * y[2]
    return (y[0] * w, y[1] * w, y[2]), y[0] ** 2 + y[1] ** 2 + y[2] ** 2


CASES = {
    # name: (cells per axis, order, field name, world and value of a lattice point in [0, 2]^3)
    "fig11": (18, 3, "p", lambda x, y, z: (swirl(x, y, z), pressure(*swirl(x, y, z)))),
    "teardrop": (2, 2, "f", teardrop),
}


def main(case, path):
    N, P, name, at = CASES[case]
    side = N * P + 1
    pts = vtk.vtkPoints()
    pts.SetDataTypeToDouble()
    p = vtk.vtkDoubleArray()
    p.SetName(name)
    for k in range(side):
        for j in range(side):
            for i in range(side):
                w, v = at(2.0 * i / (side - 1), 2.0 * j / (side - 1), 2.0 * k / (side - 1))
                pts.InsertNextPoint(*w)
                p.InsertNextValue(v)
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
    w.SetFileName(path + ".part")
    w.SetInputData(grid)
    w.SetDataModeToAppended()
    w.SetCompressorTypeToZLib()
    if not w.Write():
        sys.exit(f"make_fe_bench.py: VTK could not write {path}")
    os.replace(path + ".part", path)


if __name__ == "__main__":
    if len(sys.argv) != 3 or sys.argv[1] not in CASES:
        sys.exit(f"usage: make_fe_bench.py {{{'|'.join(CASES)}}} OUT.vtu")
    main(sys.argv[1], sys.argv[2])
