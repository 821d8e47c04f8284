"""High-order FE isosurfaces on real gmsh meshes above order 3, made at test time.

gmsh (PyPI) builds curved meshes of a cylinder in fourth-order hexahedra (gmsh type 93,
125 nodes) and in gmsh's incomplete second-order hexahedra and prisms (types 17 and 18, 20
and 15 nodes: serendipity cells), and of a ball in fourth- and fifth-order tetrahedra
(types 30 and 31, 35 and 56 nodes), sets the field p at every node from an analytic function, and writes .msh 4.1,
ASCII and binary. isobar reads them (the Python package and the command line `isobar fe`)
and samples p = ISO. Every check is against gmsh's own evaluation, not isobar's:

- at each sample's (element, reference point): gmsh's Lagrange basis
  (getBasisFunctions, gmsh's node order) over the element's node coordinates must give
  the sample's position to 1e-10 and over its node values the isovalue to the tolerance;
  on a subset, gmsh's getJacobian gives the same position, det J > 0, and the sample's
  normal is the field gradient J^-T (GradLagrange basis over the values), normalised;
- the other way round, random reference points of random elements mapped by gmsh, then
  located and evaluated by isobar's probe (world point -> cell -> Newton inversion):
  the same element and the same value to 1e-10;
- every element the isosurface cuts (by gmsh's field on a reference lattice) holds
  samples.

A node permutation that differs from gmsh's either inverts a cell (isobar refuses the
file) or moves points and values far beyond these tolerances; so does a node coordinate
or value read 1e-6 off.

VTK's hexahedron is [0, 1]^3, gmsh's [-1, 1]^3; the tetrahedra share the unit simplex
(as in scripts/make_gmsh_fixture.py).
"""

import subprocess
import sys

import gmsh
import numpy as np
import pytest
import pyvista as pv

import isobar
from conftest import REPO

# The committed fixtures' builder (scripts/make_gmsh_fixture.py): the same curved ball and
# cylinder, here of higher order.
sys.path.insert(0, str(REPO / "scripts"))
import make_gmsh_fixture  # noqa: E402

# Each mesh: the fixture builder's kind and order, the elements' family and gmsh type
# (checked against gmsh below), the isovalue and the particle spacing.
MESHES = {
    "cylinder_hex4": dict(kind="hex", order=4, family="Hexahedron", gmsh_type=93, iso=0.7, spacing=0.08),
    "ball_tet4": dict(kind="ball", order=4, family="Tetrahedron", gmsh_type=30, iso=0.4, spacing=0.08),
    "ball_tet5": dict(kind="ball", order=5, family="Tetrahedron", gmsh_type=31, iso=0.4, spacing=0.08),
    # Mesh.SecondOrderIncomplete: gmsh's serendipity cells, which isobar reads as VTK's
    # 20-node hexahedron and 15-node wedge and completes with the face and body nodes.
    "cylinder_hex20": dict(kind="hex", order=2, family="Hexahedron", gmsh_type=17, iso=0.7, spacing=0.08,
                           serendipity=True),
    "cylinder_prism15": dict(kind="prism", order=2, family="Prism", gmsh_type=18, iso=0.7, spacing=0.08,
                             serendipity=True),
}


def field(x):
    """p at (n, 3) points: not a polynomial, so the element's interpolant is what is tested."""
    x = np.asarray(x, dtype=np.float64)
    return (x * x).sum(axis=1) + 0.3 * x[:, 0] * x[:, 2] - 0.2 * x[:, 1] + 0.1 * np.sin(2.0 * x[:, 2])


def to_gmsh_ref(family, u):
    """VTK reference coordinates (n, 3) -> gmsh's (hexahedron [-1, 1]³, prism w in [-1, 1])."""
    if family == "Hexahedron":
        return 2.0 * u - 1.0
    if family == "Prism":
        return np.column_stack([u[:, 0], u[:, 1], 2.0 * u[:, 2] - 1.0])
    return u


class GmshMesh:
    """A gmsh model of one element type with the field at its nodes, kept in the gmsh
    session so that gmsh can evaluate it later."""

    def __init__(self, name, kind, order, family, gmsh_type, iso, spacing, serendipity=False):
        self.name, self.family, self.order = name, family, order
        self.iso, self.spacing = iso, spacing
        types, tags, nodes = gmsh.model.mesh.getElements(3)
        assert list(types) == [gmsh_type], (name, list(types))
        props = gmsh.model.mesh.getElementProperties(gmsh_type)
        assert props[0].split()[0] == family and props[2] == order, props
        self.type = gmsh_type
        self.n = props[3]
        self.tags = np.asarray(tags[0], dtype=np.int64)
        self.nodes = np.asarray(nodes[0], dtype=np.int64).reshape(len(self.tags), self.n)
        node_tags, coords, _ = gmsh.model.mesh.getNodes()
        node_tags = np.asarray(node_tags, dtype=np.int64)
        self.coords = np.full((node_tags.max() + 1, 3), np.nan)
        self.coords[node_tags] = np.reshape(coords, (-1, 3))
        self.values = field(self.coords)
        self.node_tags = node_tags

    def basis(self, xi, kind="Lagrange"):
        """gmsh's basis functions (m, nodes) or their reference gradients (m, nodes, 3)
        at gmsh reference points xi (m, 3), in gmsh's node order."""
        _ncomp, values, _norient = gmsh.model.mesh.getBasisFunctions(self.type, xi.ravel().tolist(), kind)
        return np.reshape(values, (len(xi), self.n) if kind == "Lagrange" else (len(xi), self.n, 3))

    def evaluate(self, cells, ref):
        """gmsh's world position and field at VTK reference points `ref` (m, 3) of
        elements `cells` (indices among the volume elements, file order): gmsh's Lagrange
        basis over the element's node coordinates and values."""
        cells = np.asarray(cells, dtype=np.int64)
        phi = self.basis(to_gmsh_ref(self.family, np.asarray(ref, dtype=np.float64)))
        nodes = self.nodes[cells]
        x = np.einsum("mk,mkd->md", phi, self.coords[nodes])
        f = np.einsum("mk,mk->m", phi, self.values[nodes])
        return x, f

    def jacobian_and_gradient(self, cells, ref):
        """gmsh's own map (getJacobian: position, det J) and the world gradient of the
        field (J^-T times the GradLagrange basis over the nodal values) at `ref` of
        `cells`. gmsh evaluates a fourth-order hexahedron's basis gradients in about
        5 ms a point, so callers pass a subset."""
        cells = np.asarray(cells, dtype=np.int64)
        m = len(cells)
        xi = to_gmsh_ref(self.family, np.asarray(ref, dtype=np.float64))
        x, det = np.empty((m, 3)), np.empty(m)
        # gmsh lists each Jacobian column by column (dx/du, dy/du, dz/du, dx/dv, ...):
        # reshaped to 3 x 3 row-major it is J transposed, row j = dx/dxi_j.
        jt = np.empty((m, 3, 3))
        for c in np.unique(cells):
            at = np.flatnonzero(cells == c)
            jac, d, coord = gmsh.model.mesh.getJacobian(int(self.tags[c]), xi[at].ravel().tolist())
            x[at], det[at], jt[at] = np.reshape(coord, (-1, 3)), d, np.reshape(jac, (-1, 3, 3))
        grad_ref = np.einsum("mkj,mk->mj", self.basis(xi, "GradLagrange"), self.values[self.nodes[cells]])
        # grad_ref = J^T grad_x.
        grad_x = np.linalg.solve(jt, grad_ref[:, :, None])[:, :, 0]
        return x, det, grad_x

    def lattice(self, n=8):
        """Points of an n-lattice of VTK's reference cell."""
        g = np.arange(n + 1) / n
        u = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
        if self.family == "Tetrahedron":
            u = u[u.sum(axis=1) <= 1 + 1e-12]
        elif self.family == "Prism":
            u = u[u[:, 0] + u[:, 1] <= 1 + 1e-12]
        return u

    def lattice_values(self, u):
        """gmsh's field (elements, points) and world positions (elements, points, 3) at
        VTK reference points u of every element."""
        phi = self.basis(to_gmsh_ref(self.family, u))
        f = self.values[self.nodes] @ phi.T
        x = np.einsum("pk,ekd->epd", phi, self.coords[self.nodes])
        return f, x


def write(mesh, path, binary):
    """The mesh and p (one time step) as .msh 4.1, as gmsh writes them."""
    tags = mesh.node_tags.tolist()
    view = gmsh.view.add("p")
    model = gmsh.model.getCurrent()
    gmsh.view.addHomogeneousModelData(view, 0, model, "NodeData", tags, mesh.values[mesh.node_tags].tolist())
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.option.setNumber("Mesh.Binary", int(binary))
    gmsh.write(str(path))
    gmsh.option.setNumber("PostProcessing.SaveMesh", 0)
    gmsh.view.write(view, str(path), append=True)
    gmsh.view.remove(view)
    gmsh.option.setNumber("Mesh.Binary", 0)


@pytest.fixture(scope="module")
def gmsh_session():
    # interruptible=False: leave Ctrl-C to pytest.
    gmsh.initialize(interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    yield
    gmsh.finalize()


@pytest.fixture(scope="module", params=list(MESHES))
def gmsh_mesh(request, gmsh_session, tmp_path_factory):
    """(GmshMesh, {"ascii": path, "binary": path}). The builder replaces gmsh's model, so
    one mesh lives at a time: pytest runs every test of one mesh before building the next."""
    name = request.param
    spec = MESHES[name]
    make_gmsh_fixture.build(spec["kind"], spec["order"], spec.get("serendipity", False))
    mesh = GmshMesh(name, **spec)
    out = tmp_path_factory.mktemp(name)
    paths = {}
    for fmt in ("ascii", "binary"):
        paths[fmt] = out / f"{name}_{fmt}.msh"
        write(mesh, paths[fmt], fmt == "binary")
    return mesh, paths


def test_the_files_hold_binary_data_and_the_asked_element_types(gmsh_mesh):
    mesh, paths = gmsh_mesh
    ascii_text = paths["ascii"].read_bytes()
    binary = paths["binary"].read_bytes()
    assert b"\n4.1 0 8\n" in ascii_text and b"\n4.1 1 8\n" in binary
    # The element block header names the type: "<dim> <entity> <type> <count>".
    assert f" {mesh.type} {len(mesh.tags)}\n".encode() in ascii_text
    # The binary file's node values are binary too (gmsh writes the view that way).
    assert not binary[binary.rindex(b"$NodeData") :].isascii()


@pytest.mark.parametrize("fmt", ["ascii", "binary"])
def test_isobar_reads_gmsh_cells_and_evaluates_them_as_gmsh_does(gmsh_mesh, fmt):
    mesh, paths = gmsh_mesh
    fe = isobar.FeMesh.read(paths[fmt])
    assert fe.n_cells == len(mesh.tags)
    used = np.unique(mesh.nodes)
    assert fe.n_points == len(used)
    # The ASCII file rounds to 16 significant digits.
    np.testing.assert_allclose(np.sort(fe.arrays["p"]), np.sort(mesh.values[used]), rtol=1e-15, atol=0)

    # Random reference points well inside random elements, mapped by gmsh; isobar locates
    # each world point (bins, Newton on its own map) and interpolates: same element, same
    # value. The map is checked through the inversion: a wrong node order would put the
    # point elsewhere or give another value.
    rng = np.random.default_rng(4)
    m = 400
    cells = rng.integers(0, len(mesh.tags), m)
    if mesh.family == "Hexahedron":
        ref = rng.uniform(0.05, 0.95, (m, 3))
    else:
        bary = rng.dirichlet(np.ones(4), m) * 0.9 + 0.025
        ref = bary[:, 1:]
    x, f = mesh.evaluate(cells, ref)
    values, found = fe.probe(x, "p")
    assert (found == cells).all(), np.flatnonzero(found != cells)[:10]
    np.testing.assert_allclose(values, f, rtol=0, atol=1e-10)
    # The elements are curved: the corners' linear map misses gmsh's points.
    assert curvature(mesh, cells, ref, x) > 1e-3


def curvature(mesh, cells, ref, x):
    """The largest distance between gmsh's points and the elements' corners' linear map."""
    linear_type = gmsh.model.mesh.getElementType(mesh.family, 1)
    corners = gmsh.model.mesh.getElementProperties(linear_type)[3]
    local = to_gmsh_ref(mesh.family, ref).ravel().tolist()
    _ncomp, basis, _norient = gmsh.model.mesh.getBasisFunctions(linear_type, local, "Lagrange")
    phi = np.reshape(basis, (len(cells), corners))
    # gmsh lists the corners first in every order.
    linear = np.einsum("mk,mkd->md", phi, mesh.coords[mesh.nodes[cells, :corners]])
    return float(np.linalg.norm(linear - x, axis=1).max())


def check_samples(mesh, points, normals, cells, ref, iso, tolerance):
    """Every sample: gmsh's map at its (element, reference point) is the sample and
    gmsh's field there is within `tolerance` of `iso`. On a subset (gmsh's gradients are
    slow): gmsh's getJacobian gives the same point, det J > 0, and the sample's normal is
    gmsh's field gradient normalised (to the float32 the normals are stored in)."""
    assert len(points) > 0
    assert cells.min() >= 0 and cells.max() < len(mesh.tags)
    x, f = mesh.evaluate(cells, ref)
    np.testing.assert_allclose(points, x, rtol=0, atol=1e-10)
    worst = float(np.abs(f - iso).max())
    assert worst <= tolerance * (1 + 1e-6), worst
    some = np.linspace(0, len(points) - 1, min(len(points), 120)).astype(np.int64)
    xj, det, grad = mesh.jacobian_and_gradient(cells[some], ref[some])
    assert (det > 0).all()
    np.testing.assert_allclose(points[some], xj, rtol=0, atol=1e-10)
    unit = grad / np.linalg.norm(grad, axis=1)[:, None]
    np.testing.assert_allclose(normals[some], unit, rtol=0, atol=1e-6)


def check_cut_cells_hold_samples(mesh, points, cells, iso, spacing, sliver):
    """Every element whose gmsh field crosses `iso` on a reference lattice holds samples.
    As in rust-core/tests/fe_real_solution.rs, an element where the surface only clips a
    corner (fewer than `sliver` of its lattice points on one side, a patch far smaller
    than the spacing) may hold none if a sample lies within `spacing` of that corner: the
    neighbours' samples cover it. At most a tenth of the cut elements may be such."""
    f, x = mesh.lattice_values(mesh.lattice())
    above, below = f > iso + 1e-9, f < iso - 1e-9
    cut = np.flatnonzero(above.any(axis=1) & below.any(axis=1))
    held = set(cells.tolist())
    slivers = []
    for c in cut:
        if c in held:
            continue
        fewer = above[c] if above[c].sum() < below[c].sum() else below[c]
        share = fewer.sum() / f.shape[1]
        near = np.linalg.norm(points[:, None, :] - x[c, fewer][None], axis=2).min()
        assert share < sliver and near <= spacing, (mesh.name, int(c), share, near)
        slivers.append(int(c))
    assert len(cut) >= 10, (mesh.name, len(cut))
    assert 10 * len(slivers) <= len(cut), (mesh.name, slivers, len(cut))
    return len(cut), slivers


def test_samples_of_the_package_lie_on_gmsh_isosurface_and_cover_every_cut_element(gmsh_mesh):
    mesh, paths = gmsh_mesh
    fe = isobar.FeMesh.read(paths["ascii"])
    tolerance = 1e-6
    samples = isobar.sample_fe(fe, "p", mesh.iso, spacing=mesh.spacing, tolerance=tolerance)
    assert len(samples) > 200, samples.stats
    assert samples.stats["max_residual"] <= tolerance
    cells = samples.arrays["Element"].astype(np.int64)
    check_samples(mesh, samples.points, samples.normals, cells, samples.arrays["Reference"], mesh.iso, tolerance)
    check_cut_cells_hold_samples(mesh, samples.points, cells, mesh.iso, mesh.spacing, sliver=0.02)


def test_the_command_line_samples_binary_files_on_gmsh_isosurface(gmsh_mesh, cli, tmp_path):
    mesh, paths = gmsh_mesh
    out = tmp_path / f"{mesh.name}.vtp"
    run = subprocess.run(
        [str(cli), "fe", str(paths["binary"]), "--field", "p", "--iso", repr(mesh.iso),
         "--spacing", repr(mesh.spacing), "--quiet", "-o", str(out)],
        capture_output=True, text=True, timeout=120,
    )
    assert run.returncode == 0, run.stderr
    cloud = pv.read(out)
    # The .vtp keeps the core's f64 positions.
    points = np.asarray(cloud.points)
    assert points.dtype == np.float64 and len(points) > 200, run.stdout
    cells = np.asarray(cloud.point_data["Element"]).astype(np.int64)
    normals = np.asarray(cloud.point_data["Normals"])
    check_samples(mesh, points, normals, cells, np.asarray(cloud.point_data["Reference"]), mesh.iso, 1e-6)
    check_cut_cells_hold_samples(mesh, points, cells, mesh.iso, mesh.spacing, sliver=0.02)
    # The package on the same file, same parameters: the same samples.
    fe = isobar.FeMesh.read(paths["binary"])
    samples = isobar.sample_fe(fe, "p", mesh.iso, spacing=mesh.spacing)
    np.testing.assert_array_equal(samples.points, points)


def test_prisms_above_order_2_are_refused_by_type(gmsh_session, tmp_path):
    """gmsh 4.15 makes and writes cubic prisms (type 90, 40 nodes) but cannot describe
    them: getElementProperties(90) raises "FaceClosureFull not implemented for prisms of
    order 3" (so may setOrder(3), after making them), and gmsh has no reference nodes,
    basis or Jacobians for them, so no node order can be derived from gmsh
    (rust-core/src/io/gmsh/order.rs stops at order 2) and nothing could check one. isobar
    refuses such a file naming the file, the type and that reason, with gmsh's own error.
    (Last in the file: it replaces gmsh's model, which pytest has finished with by then.)"""
    make_gmsh_fixture.build("prism", 2)
    try:
        gmsh.model.mesh.setOrder(3)
    except Exception as e:  # raised from a straight-sided mesh, not after setOrder(2)
        assert "prisms of order 3" in str(e)
    types, _tags, nodes = gmsh.model.mesh.getElements(3)
    assert list(types) == [90] and len(nodes[0]) % 40 == 0
    with pytest.raises(Exception, match="prisms of order 3"):
        gmsh.model.mesh.getElementProperties(90)
    path = tmp_path / "prism3.msh"
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.write(str(path))
    with pytest.raises(isobar.FormatError) as refused:
        isobar.FeMesh.read(path)
    message = str(refused.value)
    for part in ["prism3.msh", "element type 90 (prisms of order 3)",
                 "no node-ordering definition for prisms above order 2",
                 "FaceClosureFull not implemented for prisms of order 3"]:
        assert part in message, message
