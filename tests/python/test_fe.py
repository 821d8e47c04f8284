"""isobar.sample_fe: high-order FE isosurfaces through the C ABI, fed the way pyvista and
VTK users hold Lagrange cells, checked against an analytic surface and against VTK's own
evaluation of the same cells."""

import os

import numpy as np
import pytest
import pyvista as pv
import vtk

import isobar
import isobar.pyvista

FIXTURE = os.path.join(os.path.dirname(__file__), "..", "..", "rust-core", "data", "fe", "mixed_lagrange.vtu")

# The teardrop of the paper's Fig. 7: the sphere |y| = R mapped by the quadratic
# x = (y.x w, y.y w, y.z), w = A + B y.z. Order-2 cells reproduce both the map and the field
# |y|² exactly, so the discrete isosurface is the analytic one.
A, B, R = 0.6, 0.45, 0.8


def teardrop_grid(blocks=2, order=2):
    """Lagrange hexahedra from VTK's own vtkCellTypeSource (VTK's node order by
    construction), over [-1, 1]³ in y, mapped to the teardrop, with f = |y|²."""
    src = vtk.vtkCellTypeSource()
    src.SetCellType(vtk.VTK_LAGRANGE_HEXAHEDRON)
    src.SetCellOrder(order)
    src.SetBlocksDimensions(blocks, blocks, blocks)
    src.Update()
    grid = pv.wrap(src.GetOutput())
    y = np.asarray(grid.points, dtype=np.float64) / blocks * 2.0 - 1.0
    w = A + B * y[:, 2]
    grid.points = np.stack([y[:, 0] * w, y[:, 1] * w, y[:, 2]], axis=1)
    grid.point_data["f"] = (y * y).sum(axis=1)
    return grid


def teardrop_field(x):
    w = A + B * x[:, 2]
    y = np.stack([x[:, 0] / w, x[:, 1] / w, x[:, 2]], axis=1)
    return (y * y).sum(axis=1) - R * R


def test_samples_lie_on_the_analytic_teardrop_with_outward_normals():
    grid = teardrop_grid()
    assert set(np.unique(grid.celltypes)) == {vtk.VTK_LAGRANGE_HEXAHEDRON}
    mesh = isobar.pyvista.fe_mesh_from_dataset(grid)
    assert (mesh.n_cells, mesh.n_points) == (8, grid.n_points)
    samples = isobar.sample_fe(mesh, "f", R * R, spacing=0.1, tolerance=1e-7)
    assert len(samples) > 100
    assert np.abs(teardrop_field(samples.points)).max() <= 1e-7 * (1 + 1e-9)
    assert samples.stats["max_residual"] <= 1e-7
    assert samples.stats["particles"] == len(samples)
    # Unit normals pointing out of the teardrop (f grows outwards): a small step along the
    # normal raises the analytic field.
    assert np.allclose(np.linalg.norm(samples.normals, axis=1), 1.0, atol=1e-5)
    assert (teardrop_field(samples.points + 1e-4 * samples.normals) > 0).all()
    # Reference coordinates in the unit cube of a valid cell.
    ref = samples.arrays["Reference"]
    assert ref.shape == (len(samples), 3) and ref.min() >= -1e-9 and ref.max() <= 1 + 1e-9
    cells = samples.arrays["Element"]
    assert cells.min() >= 0 and cells.max() < mesh.n_cells
    assert (samples.radii > 0).all()
    assert samples.warnings == []
    # An isovalue beyond the field on the mesh: no sample, and a warning saying so.
    with pytest.warns(isobar.IsobarWarning, match=r"no surface at isovalue 1000") as caught:
        none = isobar.sample_fe(mesh, "f", 1000.0, spacing=0.1)
    assert len(none) == 0 and none.warnings == [str(w.message) for w in caught]
    assert caught[0].filename == __file__


def test_the_pyvista_adaptor_and_the_file_round_trip_give_the_same_samples(tmp_path):
    grid = teardrop_grid()
    cloud = isobar.pyvista.samples_from_unstructured_grid(grid, "f", R * R, spacing=0.15)
    assert isinstance(cloud, pv.PolyData) and cloud.n_points > 50
    assert cloud.point_data.active_normals_name == "Normals"
    assert {"Radius", "Element", "Reference", "Curvature", "Energy"} <= set(cloud.point_data.keys())
    # The same cells through a .vtu file and the core's reader: identical samples.
    path = tmp_path / "teardrop.vtu"
    grid.save(path)
    samples = isobar.sample_fe(isobar.FeMesh.read(path), "f", R * R, spacing=0.15)
    np.testing.assert_array_equal(samples.points, np.asarray(cloud.points))
    out = tmp_path / "samples.vtp"
    samples.write(out)
    back = pv.read(out)
    np.testing.assert_allclose(np.asarray(back.points), samples.points, rtol=0, atol=1e-12)
    np.testing.assert_allclose(back.point_data["Radius"], samples.radii)


def vtk_misses(grid, samples, values, iso):
    """The largest distances, over the samples, between VTK's own evaluation of each
    sample's cell at its reference coordinates (vtkCell.EvaluateLocation) and the sample:
    (world position, |interpolated values − iso|)."""
    degrees = grid.cell_data.get("HigherOrderDegrees")
    worst_x = worst_f = 0.0
    for c, u, x in zip(samples.arrays["Element"].astype(int), samples.arrays["Reference"], samples.points):
        cell = grid.GetCell(int(c))
        # VTK's GetCell does not apply HigherOrderDegrees (anisotropic orders); set them.
        if degrees is not None:
            d = np.asarray(degrees[c]).astype(int)
            if grid.celltypes[c] == vtk.VTK_LAGRANGE_HEXAHEDRON:
                cell.SetOrder(*map(int, d))
            elif grid.celltypes[c] == vtk.VTK_LAGRANGE_WEDGE:
                cell.SetOrder(*map(int, d), cell.GetNumberOfPoints())
        weights = [0.0] * cell.GetNumberOfPoints()
        where = [0.0, 0.0, 0.0]
        cell.EvaluateLocation(vtk.reference(0), list(map(float, u)), where, weights)
        ids = [cell.GetPointId(k) for k in range(cell.GetNumberOfPoints())]
        worst_x = max(worst_x, float(np.abs(np.array(where) - x).max()))
        worst_f = max(worst_f, abs(float(np.dot(weights, values[ids])) - iso))
    return worst_x, worst_f


def test_vtk_evaluates_the_same_point_and_value_at_every_sample_of_mixed_cells():
    """The committed fixture mixes a quadratic hexahedron, a cubic tetrahedron and a wedge
    (VTK-written, with HigherOrderDegrees). Each sample carries its cell and reference
    coordinates; VTK's own Lagrange basis there (vtkCell.EvaluateLocation) must give the
    sample's world position and, interpolating the point data, the isovalue."""
    grid = pv.read(FIXTURE)
    p_all = np.asarray(grid.point_data["p"])
    iso = float(np.median(p_all))
    samples = isobar.sample_fe(isobar.FeMesh.read(FIXTURE), "p", iso, tolerance=1e-8)
    assert len(samples) > 50
    cells = samples.arrays["Element"].astype(int)
    assert len(np.unique(cells)) >= 2, "the surface crosses several cells"
    worst_x, worst_f = vtk_misses(grid, samples, p_all, iso)
    assert worst_x <= 1e-9, worst_x
    assert worst_f <= 1e-8 * (1 + 1e-6), worst_f


def test_boundary_cells_beside_the_volume_are_left_out_with_a_warning():
    """A grid converted from a mesher keeps its boundary groups: vertex, line and surface
    cells among the volume cells. They are left out with a warning; the samples are the
    volume cells' own, and each sample's Element counts the cells as given, so VTK's
    evaluation of that cell of the mixed grid lands on the sample."""
    grid = teardrop_grid(blocks=2)
    offsets, conn = grid.cell_offsets, np.asarray(grid.cell_connectivity)
    hexes = [conn[offsets[c]:offsets[c + 1]] for c in range(grid.n_cells)]
    cells, types = [], []
    for c, nodes in enumerate(hexes):
        cells.append(nodes)
        types.append(vtk.VTK_LAGRANGE_HEXAHEDRON)
        if c == 0:
            cells += [nodes[:1], nodes[:4], nodes[:2]]
            types += [vtk.VTK_VERTEX, vtk.VTK_QUAD, vtk.VTK_LINE]
    legacy = np.concatenate([np.concatenate([[len(n)], n]) for n in cells]).astype(np.int64)
    mixed = pv.UnstructuredGrid(legacy, np.array(types, dtype=np.uint8), np.asarray(grid.points))
    mixed.point_data["f"] = grid.point_data["f"]
    whole = isobar.sample_fe(isobar.pyvista.fe_mesh_from_dataset(grid), "f", R * R, spacing=0.15)
    mesh = isobar.pyvista.fe_mesh_from_dataset(mixed)
    assert mesh.n_cells == grid.n_cells
    with pytest.warns(isobar.IsobarWarning, match=r"3 vertex, line and surface cell\(s\) left out"):
        samples = isobar.sample_fe(mesh, "f", R * R, spacing=0.15)
    np.testing.assert_array_equal(samples.points, whole.points)
    element = samples.arrays["Element"].astype(int)
    assert set(np.unique(element).tolist()) - {0} <= set(range(4, mixed.n_cells))
    worst_x, worst_f = vtk_misses(mixed, samples, np.asarray(mixed.point_data["f"]), R * R)
    assert worst_x <= 1e-9 and worst_f <= 1e-6 * (1 + 1e-6), (worst_x, worst_f)


def test_a_delaunay_mesh_is_sampled_without_copies():
    """pyvista's delaunay_3d of random points: slivers where the walk across faces fails
    (an inversion, or more crossings than it follows). Such a point is found in the whole
    mesh, not taken for one leaving it: held in its cell, a move left copies of particles
    (12 exact duplicates among 7,549 samples here before, 878 deletions against 113)."""
    rng = np.random.default_rng(1)
    grid = pv.PolyData(rng.uniform(-1, 1, (20000, 3))).delaunay_3d()
    grid.point_data["f"] = (np.asarray(grid.points) ** 2).sum(axis=1)
    spacing = 0.03
    samples = isobar.sample_fe(isobar.pyvista.fe_mesh_from_dataset(grid), "f", 0.5, spacing=spacing)
    # Linear tets: the field is |x|² interpolated, within h² of it; checked by VTK below.
    worst_x, worst_f = vtk_misses(grid, samples, np.asarray(grid.point_data["f"]), 0.5)
    assert worst_x <= 1e-9 and worst_f <= 1e-6 * (1 + 1e-6), (worst_x, worst_f)
    points = samples.points
    nearest = np.full(len(points), np.inf)
    for i in range(0, len(points), 64):
        d = np.linalg.norm(points[i:i + 64, None, :] - points[None, :, :], axis=2)
        d[np.arange(d.shape[0]), np.arange(i, i + d.shape[0])] = np.inf
        nearest[i:i + 64] = d.min(axis=1)
    assert nearest.min() > 0.4 * spacing, nearest.min() / spacing
    # A relaxed packing: about as many samples as a hexagonal one of the sphere's area.
    ideal = 4 * np.pi * 0.5 / (np.sqrt(0.75) * spacing**2)
    assert 0.9 * ideal < len(samples) < 1.2 * ideal, (len(samples), ideal)


def test_a_nan_in_the_field_leaves_out_its_cells_with_a_warning():
    """Solvers write NaN into masked regions: the cells touching one are left out, and the
    rest of the surface is sampled (the NaN at a corner of the box: its one cell, [0.5, 1]³
    in y, is outside the sphere |y| = 0.8; a projection that would pass through it is
    dropped there, so the samples need not equal the unmasked ones)."""
    grid = teardrop_grid(blocks=4)
    whole = isobar.sample_fe(isobar.pyvista.fe_mesh_from_dataset(grid), "f", R * R, spacing=0.15)
    f = np.asarray(grid.point_data["f"], dtype=np.float64).copy()
    corner = int(np.argmax(f))
    f[corner] = np.nan
    grid.point_data["f"] = f
    mesh = isobar.pyvista.fe_mesh_from_dataset(grid)
    with pytest.warns(isobar.IsobarWarning, match=rf"1 non-finite value \(the first at point {corner}\).*left out"):
        masked = isobar.sample_fe(mesh, "f", R * R, spacing=0.15)
    assert abs(len(masked) - len(whole)) <= 0.05 * len(whole), (len(masked), len(whole))
    np.testing.assert_allclose(teardrop_field(masked.points), 0, atol=2e-6)
    offsets, conn = grid.cell_offsets, np.asarray(grid.cell_connectivity)
    touching = {c for c in range(grid.n_cells) if corner in conn[offsets[c]:offsets[c + 1]]}
    assert len(touching) == 1 and not touching & set(masked.arrays["Element"].astype(int).tolist())


def test_bad_meshes_fields_and_cancellation_raise_clear_errors():
    grid = teardrop_grid(blocks=1)
    mesh = isobar.pyvista.fe_mesh_from_dataset(grid)
    with pytest.raises(isobar.InvalidInputError, match="nope"):
        isobar.sample_fe(mesh, "nope", 0.5)
    # Mirroring x turns every Jacobian negative: a mesh mirrored as a whole is read (the
    # samples lie on the mirrored teardrop), one cell mirrored among upright ones is named.
    points = np.asarray(grid.points).copy()
    points[:, 0] *= -1
    mirrored = isobar.FeMesh.from_arrays(points, grid.celltypes, grid.cell_offsets, grid.cell_connectivity)
    mirrored.add_array("f", np.asarray(grid.point_data["f"], dtype=np.float64))
    samples = isobar.sample_fe(mirrored, "f", R * R, spacing=0.15)
    assert len(samples) > 20
    np.testing.assert_allclose(teardrop_field(samples.points * [-1, 1, 1]), 0, atol=2e-6)
    conn = np.asarray(grid.cell_connectivity)
    both = np.concatenate([np.asarray(grid.points), points + [10.0, 0.0, 0.0]])
    offsets = np.concatenate([grid.cell_offsets, grid.cell_offsets[1:] + len(conn)])
    types = np.concatenate([grid.celltypes, grid.celltypes])
    with pytest.raises(isobar.InvalidInputError, match="cell 1 .* is inverted.*mirrored throughout, while cell 0"):
        isobar.FeMesh.from_arrays(both, types, offsets, np.concatenate([conn, conn + grid.n_points]))
    conn = np.asarray(grid.cell_connectivity).copy()
    conn[2] = 10_000
    with pytest.raises(isobar.InvalidInputError, match="10000"):
        isobar.FeMesh.from_arrays(grid.points, grid.celltypes, grid.cell_offsets, conn)
    with pytest.raises(isobar.InvalidArgumentError, match="offsets"):
        isobar.FeMesh.from_arrays(grid.points, grid.celltypes, grid.cell_offsets[:-1], grid.cell_connectivity)
    with pytest.raises(isobar.IoError):
        isobar.FeMesh.read("/nonexistent/mesh.vtu")
    # 2**32 + 1 levels used to reach the core as 1.
    with pytest.raises(isobar.InvalidArgumentError, match="'levels'"):
        isobar.sample_fe(mesh, "f", R * R, levels=2**32 + 1)
    seen = []
    with pytest.raises(isobar.Cancelled):
        isobar.sample_fe(mesh, "f", R * R, spacing=0.05, progress=lambda f, phase: seen.append(phase) or False)
    assert seen


def quadratic(y):
    """A field in the order-2 space of the teardrop cells (y is affine in each cell's
    reference coordinates), not symmetric under swapping axes."""
    return 0.7 + y[:, 0] + 2.0 * y[:, 1] - 0.5 * y[:, 2] + y[:, 0] * y[:, 2] + 0.3 * y[:, 1] ** 2


def teardrop_map(y):
    w = A + B * y[:, 2]
    return np.stack([y[:, 0] * w, y[:, 1] * w, y[:, 2]], axis=1)


def teardrop_inverse(x):
    w = A + B * x[:, 2]
    return np.stack([x[:, 0] / w, x[:, 1] / w, x[:, 2]], axis=1)


def test_probe_inverts_curved_cells_and_reproduces_a_quadratic_field():
    # VTK's own Lagrange hexahedra (order 2), curved by the teardrop map.
    grid = teardrop_grid(blocks=2, order=2)
    y_nodes = teardrop_inverse(np.asarray(grid.points, dtype=np.float64))
    mesh = isobar.pyvista.fe_mesh_from_dataset(grid, arrays=[])
    mesh.add_array("q", quadratic(y_nodes))
    rng = np.random.default_rng(7)
    y = rng.uniform(-0.999, 0.999, size=(2000, 3))
    x = teardrop_map(y)
    values, cells = mesh.probe(x)
    assert values.dtype == np.float64 and cells.dtype == np.int64 and values.shape == (2000,)
    # The analytic field at each world point, through the closed-form inverse of the map.
    np.testing.assert_allclose(values, quadratic(teardrop_inverse(x)), rtol=0, atol=1e-10)
    assert cells.min() >= 0 and cells.max() < mesh.n_cells
    # Points of one grid octant lie in one cell, different octants in different cells.
    octant = ((y > 0) * [1, 2, 4]).sum(axis=1)
    away = np.abs(y).min(axis=1) > 1e-3
    pairs = set(zip(octant[away].tolist(), cells[away].tolist()))
    assert len(pairs) == 8 and len({c for _, c in pairs}) == 8

    # Outside the mesh: cell -1 and NaN; the inside point among them keeps its value.
    outside = teardrop_map(np.array([[1.2, 0.1, 0.0], [0.0, -1.1, 0.5], [0.2, 0.3, -1.05], [0.25, -0.5, 0.75]]))
    outside = np.vstack([outside[:3], [[10.0, -3.0, 4.0]], outside[3:]])
    values, cells = mesh.probe(outside, "q")
    assert (cells[:4] == -1).all() and np.isnan(values[:4]).all()
    assert cells[4] >= 0 and abs(values[4] - quadratic(np.array([[0.25, -0.5, 0.75]]))[0]) <= 1e-10
    # One point as a (3,) array.
    v, c = mesh.probe(teardrop_map(np.array([[0.5, 0.5, 0.5]]))[0])
    assert v.shape == (1,) and abs(v[0] - quadratic(np.array([[0.5, 0.5, 0.5]]))[0]) <= 1e-10


def test_probe_names_a_nan_point_and_an_unknown_field():
    grid = teardrop_grid(blocks=1, order=2)
    mesh = isobar.pyvista.fe_mesh_from_dataset(grid, arrays=["f"])
    points = np.array([[0.1, 0.2, 0.3], [0.0, 0.0, 0.0], [0.4, np.nan, 0.0]])
    with pytest.raises(isobar.InvalidArgumentError, match=r"point 2 .*NaN"):
        mesh.probe(points, "f")
    with pytest.raises(isobar.InvalidInputError, match="'nope'"):
        mesh.probe(points[:2], "nope")
    with pytest.raises(isobar.InvalidArgumentError, match="shape"):
        mesh.probe(np.zeros((4, 2)), "f")
    # With one scalar array the field may be left out; with two it must be named.
    assert mesh.probe(points[:2])[1].min() >= 0
    mesh.add_array("g", np.zeros(mesh.n_points))
    with pytest.raises(isobar.InvalidArgumentError, match="name the field"):
        mesh.probe(points[:2])


def test_a_component_of_a_vector_array_is_sampled_and_probed_like_a_scalar_array():
    grid = teardrop_grid(blocks=1)
    f = np.asarray(grid.point_data["f"], dtype=np.float64)
    mesh = isobar.pyvista.fe_mesh_from_dataset(grid, arrays=["f"])
    mesh.add_array("v", np.stack([-f, f, np.zeros_like(f)], axis=1))
    scalar = isobar.sample_fe(mesh, "f", R * R, spacing=0.15)
    component = isobar.sample_fe(mesh, "v:1", R * R, spacing=0.15)
    assert len(scalar) > 20
    np.testing.assert_array_equal(component.points, scalar.points)
    x = scalar.points[:10]
    np.testing.assert_array_equal(mesh.probe(x, "v:0")[0], -mesh.probe(x, "f")[0])
    with pytest.raises(isobar.InvalidInputError, match="component 3"):
        isobar.sample_fe(mesh, "v:3", R * R)
    with pytest.raises(isobar.InvalidInputError, match="magnitude"):
        isobar.sample_fe(mesh, "v:mag", R * R)
    # The pyvista adaptor reads the array a component names.
    grid.point_data["v"] = np.stack([-f, f, np.zeros_like(f)], axis=1)
    cloud = isobar.pyvista.samples_from_unstructured_grid(grid, "v:1", R * R, spacing=0.15)
    np.testing.assert_array_equal(np.asarray(cloud.points), scalar.points)


def test_a_cell_array_named_as_the_field_is_refused_with_the_remedy():
    grid = teardrop_grid(blocks=1)
    grid.cell_data["c"] = np.arange(grid.n_cells, dtype=np.float64)
    with pytest.raises(isobar.InvalidArgumentError, match=r"'c' is a cell array.*cell_data_to_point_data"):
        isobar.pyvista.samples_from_unstructured_grid(grid, "c", 0.5)
    # An array that is nowhere: the message lists the point arrays the grid has.
    with pytest.raises(isobar.InvalidInputError, match=r"no point array named 'nope'.*point arrays: .*\bf\b"):
        isobar.pyvista.samples_from_unstructured_grid(grid, "nope", 0.5)


@pytest.mark.parametrize(
    "cell_type",
    [
        vtk.VTK_TETRA,
        vtk.VTK_HEXAHEDRON,
        vtk.VTK_WEDGE,
        vtk.VTK_QUADRATIC_TETRA,
        vtk.VTK_QUADRATIC_HEXAHEDRON,
        vtk.VTK_QUADRATIC_WEDGE,
        vtk.VTK_TRIQUADRATIC_HEXAHEDRON,
    ],
)
def test_linear_and_quadratic_cells_are_sampled_where_vtk_interpolates_them(cell_type):
    """VTK's classic cells (what delaunay_3d, gmsh and most solvers give) read as Lagrange
    cells: every sample's cell and reference coordinates, put into VTK's own basis of the
    original cell (vtkCell.EvaluateLocation), give the sample's world point and the
    isovalue. The 20-node hexahedron and 15-node wedge are serendipity cells whose missing
    face and body nodes the core makes; the teardrop map curves the quadratic cells."""
    src = vtk.vtkCellTypeSource()
    src.SetCellType(cell_type)
    src.SetBlocksDimensions(3, 3, 3)
    src.Update()
    grid = pv.wrap(src.GetOutput())
    assert set(np.unique(grid.celltypes)) == {cell_type}
    y = np.asarray(grid.points, dtype=np.float64) / 3 * 2.0 - 1.0
    w = A + B * y[:, 2]
    grid.points = np.stack([y[:, 0] * w, y[:, 1] * w, y[:, 2]], axis=1)
    f_all = (y * y).sum(axis=1) + 0.3 * y[:, 0] * y[:, 1]
    grid.point_data["f"] = f_all
    mesh = isobar.pyvista.fe_mesh_from_dataset(grid)
    # The host sees its own points, whatever the core made for serendipity cells.
    assert (mesh.n_cells, mesh.n_points) == (grid.n_cells, grid.n_points)
    np.testing.assert_array_equal(mesh.arrays["f"], f_all)
    iso = 0.5
    samples = isobar.sample_fe(mesh, "f", iso, spacing=0.08, tolerance=1e-9)
    assert len(samples) > 100
    worst_x, worst_f = vtk_misses(grid, samples, f_all, iso)
    assert worst_x <= 1e-9, worst_x
    assert worst_f <= 1e-9 * (1 + 1e-6), worst_f


def test_image_data_is_sampled_through_its_voxels():
    """A pyvista ImageData (VTK voxels once cast, x-fastest corner order) of the sphere
    field |x|²: trilinear voxels hold it only at their corners, so the samples lie where
    VTK's own trilinear interpolation of the voxels gives the isovalue."""
    image = pv.ImageData(dimensions=(9, 9, 9), spacing=(0.25, 0.25, 0.25), origin=(-1, -1, -1))
    image.point_data["r2"] = (np.asarray(image.points) ** 2).sum(axis=1)
    cloud = isobar.pyvista.samples_from_unstructured_grid(image, "r2", 0.5, spacing=0.1, tolerance=1e-9)
    assert cloud.n_points > 100
    probed = pv.PolyData(np.asarray(cloud.points)).sample(image)
    np.testing.assert_allclose(probed.point_data["r2"], 0.5, rtol=0, atol=1e-7)
    # Trilinear interpolation of x² + y² + z² overestimates it by (x−x0)(x1−x) ≤ h²/4 per
    # axis: the samples lie inside the sphere r² = 0.5 by at most 3h²/4 in r² (h = 0.25).
    r2 = (np.asarray(cloud.points) ** 2).sum(axis=1)
    assert (r2 <= 0.5 + 1e-9).all() and (r2 >= 0.5 - 3 * 0.25**2 / 4 - 1e-9).all()


def test_an_explicit_structured_grid_is_sampled_as_its_hexahedra():
    image = pv.ImageData(dimensions=(7, 7, 7), spacing=(1 / 3, 1 / 3, 1 / 3), origin=(-1, -1, -1))
    explicit = image.cast_to_structured_grid().cast_to_explicit_structured_grid()
    explicit.point_data["r2"] = (np.asarray(explicit.points) ** 2).sum(axis=1)
    cloud = isobar.pyvista.samples_from_unstructured_grid(explicit, "r2", 0.5, spacing=0.1, tolerance=1e-9)
    assert cloud.n_points > 100
    # Trilinear interpolation of x² between x0 and x1 is x² + (x − x0)(x1 − x): summed
    # over the axes, that is the field of the hexahedra at every sample (vtkProbeFilter's
    # values at points on this grid's cell faces were off by up to 4e-4).
    h = 1 / 3
    x = np.asarray(cloud.points)
    x0 = -1 + h * np.clip(np.floor((x + 1) / h), 0, 5)
    trilinear = (x * x + (x - x0) * (x0 + h - x)).sum(axis=1)
    np.testing.assert_allclose(trilinear, 0.5, rtol=0, atol=1e-8)


def test_connectivity_that_is_not_whole_numbers_is_refused():
    grid = teardrop_grid(blocks=1)
    conn = np.asarray(grid.cell_connectivity, dtype=np.float64) + 0.5
    with pytest.raises(isobar.InvalidArgumentError, match=r"connectivity\[0\] is 0.5, not a whole number"):
        isobar.FeMesh.from_arrays(grid.points, grid.celltypes, grid.cell_offsets, conn)
    with pytest.raises(isobar.InvalidArgumentError, match=r"cell_types\[0\] is 300"):
        isobar.FeMesh.from_arrays(grid.points, [300], grid.cell_offsets, grid.cell_connectivity)
    with pytest.raises(isobar.InvalidArgumentError, match=r"degrees\[0\] is -1, outside 0\.\.4294967295"):
        isobar.FeMesh.from_arrays(grid.points, grid.celltypes, grid.cell_offsets, grid.cell_connectivity,
                                  degrees=[[-1, 2, 2]])
    # A pyramid is named as one.
    points = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], dtype=float)
    with pytest.raises(isobar.InvalidInputError, match=r"cell 0 has VTK type 14 \(a pyramid\)"):
        isobar.FeMesh.from_arrays(points, [vtk.VTK_PYRAMID], [0, 5], np.arange(5))
