"""Small curved high-order meshes made by gmsh, with a field as $NodeData, for the .msh
reader's tests (rust-core/data/fe/gmsh/):

  ball_tet3.msh          unit ball, third-order tetrahedra (type 29), ASCII
  ball_tet3_binary.msh   the same mesh and field, binary
  ball_tet3.vtu          the same cells through VTK's own Lagrange node order
  cylinder_hex2.msh/.vtu cylinder (radius 1, height 1.2), second-order hexahedra (type 12;
                         cubic ones of this coarse disk come out inverted, gmsh agrees)
  cylinder_hex3.msh/.vtu the cylinder in third-order hexahedra (type 92): a finer disk
                         (size 0.4) and 3 layers, so that curving the boundary keeps every
                         cell valid
  cylinder_prism2.msh/.vtu the cylinder in second-order prisms (type 13)
  *_probes.txt           gmsh's own evaluation (first 24 elements): `cell r s t x y z p` per line, cell = index
                         among the volume elements in file order, (r, s, t) in VTK's
                         reference domain, x from gmsh's getJacobians, p from gmsh's
                         Lagrange basis (getBasisFunctions) over the element's node values

The field is `p` = |x|^2 + 0.3 x z - 0.2 y + 0.1 sin(2 z), written as time step 1; time
step 0 holds p = 0 everywhere so a reader taking the wrong step fails the tests.
The .vtu files map gmsh's nodes onto VTK's order by matching gmsh's reference node
coordinates (getElementProperties) with VTK's (GetParametricCoords), so they do not
depend on isobar's own table.

    python -m venv /tmp/fe2venv && /tmp/fe2venv/bin/pip install gmsh vtk
    /tmp/fe2venv/bin/python scripts/make_gmsh_fixture.py rust-core/data/fe/gmsh
"""

import math
import os
import sys

import gmsh

PROBES = {
    4: [(0.1, 0.2, 0.3), (0.25, 0.25, 0.25), (0.6, 0.1, 0.05)],
    5: [(-0.5, 0.3, 0.7), (0.0, 0.0, 0.0), (0.9, -0.8, -0.2)],
    6: [(0.2, 0.3, -0.4), (0.5, 0.1, 0.8), (0.1, 0.7, 0.0)],
}


# Disk mesh size and layers along the axis of each cylinder. ("hex", 4) is not a committed
# fixture: tests/python/test_fe_gmsh.py builds it (and the balls of order 4 and 5) at test
# time with `build`.
CYLINDER = {("hex", 2): (0.7, 2), ("hex", 3): (0.4, 3), ("hex", 4): (0.4, 3), ("prism", 2): (0.7, 2)}


def field(x, y, z):
    return x * x + y * y + z * z + 0.3 * x * z - 0.2 * y + 0.1 * math.sin(2.0 * z)


def to_vtk_ref(family, u, v, w):
    if family == 5:  # hexahedron [-1,1]^3 -> [0,1]^3
        return ((u + 1) / 2, (v + 1) / 2, (w + 1) / 2)
    if family == 6:  # prism w in [-1,1] -> t in [0,1]
        return (u, v, (w + 1) / 2)
    return (u, v, w)


def build(kind, order, serendipity=False):
    """Replaces gmsh's models by a curved mesh of order `order`: "ball" (tetrahedra), "hex"
    or "prism" (a cylinder); every cell valid. `serendipity`: gmsh's incomplete
    second-order cells (20-node hexahedra, 15-node prisms)."""
    gmsh.clear()
    gmsh.model.add(kind)
    gmsh.option.setNumber("Mesh.SecondOrderIncomplete", int(serendipity))
    if kind == "ball":
        gmsh.model.occ.addSphere(0, 0, 0, 1)
        gmsh.model.occ.synchronize()
        gmsh.model.mesh.setSize(gmsh.model.getEntities(0), 0.9)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.6)
    else:
        disk = gmsh.model.occ.addDisk(0, 0, 0, 1, 1)
        gmsh.model.occ.synchronize()
        if kind == "hex":
            gmsh.model.mesh.setRecombine(2, disk)
        size, layers = CYLINDER[(kind, order)]
        gmsh.model.mesh.setSize(gmsh.model.getEntities(0), size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.4)
        gmsh.model.occ.extrude([(2, disk)], 0, 0, 1.2, numElements=[layers], recombine=True)
        gmsh.model.occ.synchronize()
        if kind == "hex":
            gmsh.model.mesh.setRecombine(2, disk)
    gmsh.model.mesh.generate(3)
    gmsh.model.mesh.setOrder(order)
    # Curving a coarse boundary can invert cells next to it (a 0.7 disk mesh in cubic
    # hexahedra does): every cell is checked (det J > 0 at its nodes) before writing.
    for ty in gmsh.model.mesh.getElementTypes(3):
        local = gmsh.model.mesh.getElementProperties(ty)[4]
        _j, det, _x = gmsh.model.mesh.getJacobians(ty, local)
        assert min(det) > 0, (kind, ty, min(det))


def node_values():
    tags, coords, _ = gmsh.model.mesh.getNodes()
    values = [field(*coords[3 * k : 3 * k + 3]) for k in range(len(tags))]
    return list(tags), values


def write(out, stem):
    tags, values = node_values()
    view = gmsh.view.add("p")
    gmsh.view.addHomogeneousModelData(view, 0, gmsh.model.getCurrent(), "NodeData", tags, [0.0] * len(tags), time=0.0)
    gmsh.view.addHomogeneousModelData(view, 1, gmsh.model.getCurrent(), "NodeData", tags, values, time=1.0)
    value_of = dict(zip(tags, values))
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    for binary, suffix in [(0, ""), (1, "_binary")]:
        if binary and not stem.startswith("ball"):
            continue
        gmsh.option.setNumber("Mesh.Binary", binary)
        path = os.path.join(out, stem + suffix + ".msh")
        gmsh.write(path)
        gmsh.option.setNumber("PostProcessing.SaveMesh", 0)
        gmsh.view.write(view, path, append=True)
    gmsh.view.remove(view)
    gmsh.option.setNumber("Mesh.Binary", 0)
    types, elem_tags, elem_nodes = gmsh.model.mesh.getElements(3)
    assert len(types) == 1, types
    ty = types[0]
    _name, _dim, _order, n, local, _prim = gmsh.model.mesh.getElementProperties(ty)
    family = _prim_family(ty)
    elems = list(elem_tags[0])
    nodes = list(elem_nodes[0])
    pts = PROBES[family]
    flat = [c for p in pts for c in p]
    _jac, _det, xs = gmsh.model.mesh.getJacobians(ty, flat)
    _ncomp, basis, _norient = gmsh.model.mesh.getBasisFunctions(ty, flat, "Lagrange")
    with open(os.path.join(out, stem + "_probes.txt"), "w") as f:
        f.write("# cell r s t x y z p (gmsh's own evaluation; see scripts/make_gmsh_fixture.py)\n")
        for e in range(min(len(elems), 24)):
            enodes = nodes[e * n : (e + 1) * n]
            for q, p in enumerate(pts):
                x = xs[3 * (e * len(pts) + q) : 3 * (e * len(pts) + q) + 3]
                phi = basis[q * n : (q + 1) * n]
                val = sum(phi[k] * value_of[enodes[k]] for k in range(n))
                r = to_vtk_ref(family, *p)
                f.write(" ".join([str(e)] + [repr(float(v)) for v in (*r, *x, val)]) + "\n")
    write_vtu(os.path.join(out, stem + ".vtu"), ty, family, n, local, elems, nodes, value_of)


def _prim_family(ty):
    """4, 5 or 6: the linear gmsh type of the element's family."""
    name = gmsh.model.mesh.getElementProperties(ty)[0]
    return {"Tetrahedron": 4, "Hexahedron": 5, "Prism": 6}[name.split()[0]]


def write_vtu(path, ty, family, n, local, elems, nodes, value_of):
    import vtk

    cell = {4: vtk.vtkLagrangeTetra, 5: vtk.vtkLagrangeHexahedron, 6: vtk.vtkLagrangeWedge}[family]()
    order = gmsh.model.mesh.getElementProperties(ty)[2]
    cell.GetPointIds().SetNumberOfIds(n)
    cell.GetPoints().SetNumberOfPoints(n)
    if family == 5:
        cell.SetOrder(order, order, order)
    elif family == 6:
        cell.SetOrder(order, order, order, n)
    for i in range(n):
        cell.GetPointIds().SetId(i, i)
    cell.Initialize()
    pc = cell.GetParametricCoords()
    vtk_pts = [tuple(pc[3 * i : 3 * i + 3]) for i in range(n)]
    # gmsh node k -> VTK node perm[k], by reference coordinates.
    perm = []
    for k in range(n):
        r = to_vtk_ref(family, *local[3 * k : 3 * k + 3])
        best = min(range(n), key=lambda i: sum((a - b) ** 2 for a, b in zip(r, vtk_pts[i])))
        assert sum((a - b) ** 2 for a, b in zip(r, vtk_pts[best])) < 1e-18, (k, r)
        perm.append(best)
    assert sorted(perm) == list(range(n))
    used = sorted(set(nodes))
    index = {t: i for i, t in enumerate(used)}
    grid = vtk.vtkUnstructuredGrid()
    points = vtk.vtkPoints()
    points.SetDataTypeToDouble()
    p = vtk.vtkDoubleArray()
    p.SetName("p")
    for t in used:
        c, _pc, _dim, _tag = gmsh.model.mesh.getNode(t)
        # Rounded as the ASCII .msh writes them (16 significant digits), so the VTU
        # holds exactly the ASCII file's numbers.
        points.InsertNextPoint(*(float(f"{v:.16g}") for v in c[:3]))
        p.InsertNextValue(float(f"{value_of[t]:.16g}"))
    grid.SetPoints(points)
    grid.GetPointData().AddArray(p)
    vtk_type = {4: 71, 5: 72, 6: 73}[family]
    for e in range(len(elems)):
        ids = [0] * n
        for k in range(n):
            ids[perm[k]] = index[nodes[e * n + k]]
        grid.InsertNextCell(vtk_type, n, ids)
    w = vtk.vtkXMLUnstructuredGridWriter()
    w.SetFileName(path)
    w.SetInputData(grid)
    w.SetDataModeToAppended()
    w.SetCompressorTypeToZLib()
    w.Write()


def main(out):
    os.makedirs(out, exist_ok=True)
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    stems = [("ball", 3, "ball_tet3"), ("hex", 2, "cylinder_hex2"), ("hex", 3, "cylinder_hex3"),
             ("prism", 2, "cylinder_prism2")]
    for kind, order, stem in stems:
        build(kind, order)
        write(out, stem)
    gmsh.finalize()


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "rust-core/data/fe/gmsh")
