"""Dump VTK's own parametric coordinates of Lagrange hexahedra, tetrahedra and wedges.

The output fixes the node ordering isobar must read (rust-core/data/fe/vtk_lagrange_nodes.txt),
checked by `cargo test --lib field::fe`. Needs PyPI `vtk` (9.x):

    python3 -m venv /tmp/vtkvenv && /tmp/vtkvenv/bin/pip install vtk
    /tmp/vtkvenv/bin/python scripts/dump_vtk_lagrange_order.py > rust-core/data/fe/vtk_lagrange_nodes.txt

Format: one line per cell, `TYPE ORDER NPOINTS` then the 3*NPOINTS parametric coordinates.
"""

import vtk


def nodes_for(cell, npts):
    cell.GetPointIds().SetNumberOfIds(npts)
    cell.GetPoints().SetNumberOfPoints(npts)
    for i in range(npts):
        cell.GetPointIds().SetId(i, i)
        cell.GetPoints().SetPoint(i, 0.0, 0.0, 0.0)
    if hasattr(cell, "SetUniformOrderFromNumPoints"):
        cell.SetUniformOrderFromNumPoints(npts)
    cell.Initialize()
    pc = cell.GetParametricCoords()
    return [pc[i] for i in range(3 * npts)]


def main():
    print(f"# VTK {vtk.vtkVersion.GetVTKVersion()}: TYPE ORDER NPOINTS then parametric coords")
    for p in range(1, 7):
        n = (p + 1) ** 3
        print("hex", p, n, " ".join(f"{v:.17g}" for v in nodes_for(vtk.vtkLagrangeHexahedron(), n)))
    for p in range(1, 7):
        n = (p + 1) * (p + 2) * (p + 3) // 6
        print("tet", p, n, " ".join(f"{v:.17g}" for v in nodes_for(vtk.vtkLagrangeTetra(), n)))
    for p in range(1, 7):
        n = (p + 1) * (p + 2) // 2 * (p + 1)
        print("wedge", p, n, " ".join(f"{v:.17g}" for v in nodes_for(vtk.vtkLagrangeWedge(), n)))


main()
