"""Write a small VTU with curved Lagrange cells through VTK itself, and VTK's own
evaluation of world position and field at reference points of each cell.

rust-core/data/fe/mixed_lagrange.vtu: a hexahedron of order 2 (with HigherOrderDegrees
2,2,3 so it is order 3 along t), a tetrahedron of order 3 and a wedge of order 2, curved,
written by vtkXMLUnstructuredGridWriter (appended, zlib). Point array `p`.
rust-core/data/fe/mixed_lagrange_probes.txt: `cell r s t x y z p` as VTK evaluates them.

    /tmp/vtkvenv/bin/python scripts/make_fe_fixture.py rust-core/data/fe
"""

import math
import sys

import vtk


def bend(x, y, z):
    return (x + 0.08 * math.sin(2.0 * y), y + 0.06 * x * z, z + 0.05 * math.cos(x + y))


def field(x, y, z):
    return x * x - 0.5 * y + math.sin(z) + 0.3 * x * y * z


def main(out):
    grid = vtk.vtkUnstructuredGrid()
    pts = vtk.vtkPoints()
    pts.SetDataTypeToDouble()
    grid.SetPoints(pts)
    p = vtk.vtkDoubleArray()
    p.SetName("p")
    degrees = vtk.vtkIntArray()
    degrees.SetName("HigherOrderDegrees")
    degrees.SetNumberOfComponents(3)
    cells = []
    specs = [
        (vtk.vtkLagrangeHexahedron(), (2, 2, 3), (0.0, 0.0, 0.0)),
        (vtk.vtkLagrangeTetra(), (3, 3, 3), (2.0, 0.0, 0.0)),
        (vtk.vtkLagrangeWedge(), (2, 2, 2), (0.0, 2.0, 0.0)),
    ]
    for cell, order, shift in specs:
        if isinstance(cell, vtk.vtkLagrangeTetra):
            n = (order[0] + 1) * (order[0] + 2) * (order[0] + 3) // 6
        elif isinstance(cell, vtk.vtkLagrangeWedge):
            n = (order[0] + 1) * (order[0] + 2) // 2 * (order[2] + 1)
        else:
            n = (order[0] + 1) * (order[1] + 1) * (order[2] + 1)
        cell.GetPointIds().SetNumberOfIds(n)
        cell.GetPoints().SetNumberOfPoints(n)
        if hasattr(cell, "SetOrder"):
            try:
                cell.SetOrder(order[0], order[1], order[2], n)  # wedge
            except TypeError:
                cell.SetOrder(order[0], order[1], order[2])  # hexahedron
        for i in range(n):
            cell.GetPointIds().SetId(i, i)
        cell.Initialize()
        pc = cell.GetParametricCoords()
        ids = []
        for i in range(n):
            w = bend(pc[3 * i] + shift[0], pc[3 * i + 1] + shift[1], pc[3 * i + 2] + shift[2])
            cell.GetPoints().SetPoint(i, *w)
            ids.append(pts.InsertNextPoint(*w))
            p.InsertNextValue(field(*w))
        cells.append((cell, ids))
        grid.InsertNextCell(cell.GetCellType(), len(ids), ids)
        degrees.InsertNextTuple3(*order)
    grid.GetPointData().AddArray(p)
    grid.GetCellData().AddArray(degrees)
    w = vtk.vtkXMLUnstructuredGridWriter()
    w.SetFileName(f"{out}/mixed_lagrange.vtu")
    w.SetInputData(grid)
    w.SetDataModeToAppended()
    w.SetCompressorTypeToZLib()
    w.Write()

    probes = [(0.2, 0.3, 0.1), (0.1, 0.6, 0.25), (0.5, 0.2, 0.7), (0.25, 0.25, 0.25)]
    with open(f"{out}/mixed_lagrange_probes.txt", "w") as f:
        f.write(f"# VTK {vtk.vtkVersion.GetVTKVersion()} EvaluateLocation: cell r s t x y z p\n")
        # The cells as built (grid.GetCell would not know the hexahedron's anisotropic order).
        for c, (cell, ids) in enumerate(cells):
            for pc in probes:
                x = [0.0, 0.0, 0.0]
                weights = [0.0] * cell.GetNumberOfPoints()
                sub = vtk.reference(0)
                cell.EvaluateLocation(sub, pc, x, weights)
                val = sum(wt * p.GetValue(ids[i]) for i, wt in enumerate(weights))
                f.write(" ".join(f"{v:.17g}" for v in (c, *pc, *x, val)) + "\n")


main(sys.argv[1])
