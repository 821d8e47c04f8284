"""vtkIsobarFESamples (high-order FE isosurface samples) with Debian's VTK 9.1, from
Debian's /usr/bin/python3. Run by tests/vtk/run.sh with PYTHONPATH=vtk-plugin/build-vtk/python.

VTK's own Lagrange cells are the independent evaluator: at each sample's cell and reference
coordinates VTK's basis (vtkCell.EvaluateLocation) must give the sample's position and the
isovalue.
"""

import os
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness as h  # noqa: E402
from harness import Errors, test  # noqa: E402

from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy  # noqa: E402
from vtkmodules.vtkCommonCore import vtkCommand  # noqa: E402
from vtkmodules.vtkCommonDataModel import vtkUnstructuredGrid  # noqa: E402
from vtkmodules.vtkFiltersCore import vtkAppendFilter  # noqa: E402
from vtkmodules.vtkFiltersSources import vtkCellTypeSource  # noqa: E402
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader  # noqa: E402

from isobar_vtk import vtkIsobarFESamples  # noqa: E402

TMP = h.tmpdir()
FIXTURE = os.path.join(h.REPO, "rust-core", "data", "fe", "mixed_lagrange.vtu")
VTK_LAGRANGE_HEXAHEDRON = 72


def fixture():
    r = vtkXMLUnstructuredGridReader()
    r.SetFileName(FIXTURE)
    r.Update()
    return r.GetOutput()


def median_p(grid):
    return float(np.median(vtk_to_numpy(grid.GetPointData().GetArray("p"))))


def samples_filter(grid, iso, **settings):
    f = vtkIsobarFESamples()
    f.SetInputData(grid)
    f.SetInputArrayToProcess(0, 0, 0, 0, "p")
    f.SetIsovalue(iso)
    for k, v in settings.items():
        getattr(f, "Set" + k)(v)
    return f


def vtk_evaluate(grid, cell_ids, reference, name):
    """World points and values of point array `name` that VTK's own Lagrange basis gives
    at each (cell, reference coordinates): vtkCell.EvaluateLocation, no point location."""
    from vtkmodules.vtkCommonCore import reference as ref

    values = vtk_to_numpy(grid.GetPointData().GetArray(name))
    degrees = grid.GetCellData().GetArray("HigherOrderDegrees")
    xs, fs = [], []
    for c, u in zip(cell_ids, reference):
        c = int(c)
        cell = grid.GetCell(c)
        # GetCell does not apply HigherOrderDegrees (anisotropic orders): set them.
        if degrees is not None and grid.GetCellType(c) in (72, 73):
            d = [int(degrees.GetComponent(c, k)) for k in range(3)]
            if grid.GetCellType(c) == 72:
                cell.SetOrder(*d)
            else:
                cell.SetOrder(*d, cell.GetNumberOfPoints())
        weights = [0.0] * cell.GetNumberOfPoints()
        x = [0.0, 0.0, 0.0]
        cell.EvaluateLocation(ref(0), [float(v) for v in u], x, weights)
        ids = [cell.GetPointId(k) for k in range(cell.GetNumberOfPoints())]
        xs.append(x)
        fs.append(float(np.dot(weights, values[ids])))
    return np.array(xs), np.array(fs)


@test
def test_samples_lie_on_vtks_own_interpolation_of_the_cells():
    grid = fixture()
    iso = median_p(grid)
    f = samples_filter(grid, iso, Tolerance=1e-8)
    f.Update()
    assert f.GetErrorMessage() == "", f.GetErrorMessage()
    out = f.GetOutput()
    n = out.GetNumberOfPoints()
    assert n > 50 and out.GetNumberOfVerts() == n
    pts = vtk_to_numpy(out.GetPoints().GetData())
    cells = vtk_to_numpy(out.GetPointData().GetArray("Element"))
    reference = vtk_to_numpy(out.GetPointData().GetArray("Reference"))
    x, value = vtk_evaluate(grid, cells, reference, "p")
    assert np.abs(x - pts).max() <= 1e-9, np.abs(x - pts).max()
    assert np.abs(value - iso).max() <= 1e-8 * (1 + 1e-6), np.abs(value - iso).max()
    assert f.GetLastMaxResidual() <= 1e-8 and f.GetLastEvaluations() > 0
    normals = vtk_to_numpy(out.GetPointData().GetNormals())
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
    for name, k in (("Radius", 1), ("Element", 1), ("Reference", 3), ("Curvature", 1), ("Energy", 1)):
        a = out.GetPointData().GetArray(name)
        assert a is not None and a.GetNumberOfComponents() == k and a.GetNumberOfTuples() == n, name
    cells = vtk_to_numpy(out.GetPointData().GetArray("Element"))
    assert len(np.unique(cells)) >= 2 and cells.max() < grid.GetNumberOfCells()


@test
def test_filter_equals_the_cli_and_isovalue_changes_keep_the_mesh():
    grid = fixture()
    iso = median_p(grid)
    f = samples_filter(grid, iso)
    f.Update()
    ref = os.path.join(TMP, "fe_cli.vtp")
    subprocess.run([h.CLI, "fe", FIXTURE, "--field", "p", "--iso", repr(iso), "-o", ref, "--quiet"],
                   check=True, capture_output=True)
    a = vtk_to_numpy(f.GetOutput().GetPoints().GetData())
    b = vtk_to_numpy(h.read_vtp(ref).GetPoints().GetData())
    assert a.shape == b.shape and np.abs(a - b).max() <= 1e-12
    for k, other in enumerate((iso + 0.3, iso - 0.2)):
        f.SetIsovalue(other)
        f.Update()
        assert f.GetOutput().GetNumberOfPoints() > 20
        assert f.GetNumberOfMeshBuilds() == 1, "an isovalue change rebuilt the core mesh"
    grid.GetPointData().GetArray("p").Modified()
    grid.Modified()
    f.Update()
    assert f.GetNumberOfMeshBuilds() == 2


@test
def test_vtk_cell_type_source_hexahedra_of_order_3():
    """Cells in VTK's own node order from vtkCellTypeSource; f = x² + y² + z² sampled at
    the sphere of radius 1.2 inside the 2×2×2 block, with every sample on it to 1e-6
    (order 3 reproduces the quadratic exactly)."""
    src = vtkCellTypeSource()
    src.SetCellType(VTK_LAGRANGE_HEXAHEDRON)
    src.SetCellOrder(3)
    src.SetBlocksDimensions(2, 2, 2)
    src.Update()
    grid = vtkUnstructuredGrid()
    grid.DeepCopy(src.GetOutput())
    x = vtk_to_numpy(grid.GetPoints().GetData()).astype(np.float64) - 1.0
    grid.GetPoints().SetData(numpy_to_vtk(np.ascontiguousarray(x), deep=1))
    p = numpy_to_vtk((x * x).sum(axis=1), deep=1)
    p.SetName("p")
    grid.GetPointData().AddArray(p)
    f = samples_filter(grid, 0.36, Spacing=0.06, Tolerance=1e-8)
    f.Update()
    assert f.GetErrorMessage() == "", f.GetErrorMessage()
    pts = vtk_to_numpy(f.GetOutput().GetPoints().GetData())
    assert len(pts) > 200
    err = np.abs((pts * pts).sum(axis=1) - 0.36).max()
    assert err <= 1e-6, err


@test
def test_bad_inputs_give_an_error_naming_the_problem_and_empty_output():
    grid = fixture()
    # No point scalars chosen that exist.
    f = vtkIsobarFESamples()
    f.SetInputData(grid)
    f.SetInputArrayToProcess(0, 0, 0, 0, "nope")
    errors = Errors(f)
    f.Update()
    assert f.GetOutput().GetNumberOfPoints() == 0
    assert "the input has no point array 'nope'" in f.GetErrorMessage(), f.GetErrorMessage()
    assert errors.messages
    # A vector: refused, not read as its first component.
    vec = vtkUnstructuredGrid()
    vec.DeepCopy(grid)
    x = vtk_to_numpy(vec.GetPoints().GetData()).astype(np.float64)
    arrow = numpy_to_vtk(x - x.mean(axis=0), deep=1)
    arrow.SetName("arrow")
    vec.GetPointData().AddArray(arrow)
    f = vtkIsobarFESamples()
    f.SetInputData(vec)
    f.SetInputArrayToProcess(0, 0, 0, 0, "arrow")
    Errors(f)
    f.Update()
    assert f.GetOutput().GetNumberOfPoints() == 0
    assert "array 'arrow' has 3 components" in f.GetErrorMessage(), f.GetErrorMessage()
    # Mirrored points: every element mirrored, which is read; after the upright cells, the
    # core names the first mirrored one.
    mirrored = vtkUnstructuredGrid()
    mirrored.DeepCopy(grid)
    x = vtk_to_numpy(mirrored.GetPoints().GetData()).astype(np.float64).copy()
    x[:, 0] = 10.0 - x[:, 0]
    mirrored.GetPoints().SetData(numpy_to_vtk(x, deep=1))
    f = samples_filter(mirrored, median_p(grid))
    Errors(f)
    f.Update()
    assert f.GetOutput().GetNumberOfPoints() > 0, f.GetErrorMessage()
    append = vtkAppendFilter()
    append.AddInputData(grid)
    append.AddInputData(mirrored)
    append.Update()
    f = samples_filter(append.GetOutput(), median_p(grid))
    Errors(f)
    f.Update()
    assert f.GetOutput().GetNumberOfPoints() == 0
    first = f"cell {grid.GetNumberOfCells()} "
    message = f.GetErrorMessage()
    assert first in message and "inverted" in message and "while cell 0 is not" in message, message
    # Pyramids have no Lagrange form the core reads: the message names the cell and its
    # type. Linear hexahedra (read as order-1 Lagrange cells) are sampled.
    for cell_type, error in ((14, "cell 0 has VTK type 14 (a pyramid)"), (12, "")):
        src = vtkCellTypeSource()
        src.SetCellType(cell_type)
        src.SetBlocksDimensions(1, 1, 1)
        src.Update()
        lin = vtkUnstructuredGrid()
        lin.DeepCopy(src.GetOutput())
        p = numpy_to_vtk(np.arange(lin.GetNumberOfPoints(), dtype=np.float64), deep=1)
        p.SetName("p")
        lin.GetPointData().AddArray(p)
        f = samples_filter(lin, 1.5)
        Errors(f)
        f.Update()
        assert error in f.GetErrorMessage(), f.GetErrorMessage()
        assert (f.GetOutput().GetNumberOfPoints() > 0) == (error == ""), cell_type


@test
def test_settings_out_of_range_are_refused_naming_them_not_clamped():
    """VTK's clamping setters turned Spacing -1 into 0 (the default spacing) and a Levels of
    20 into 8, running without a word; each is now an error naming the setting."""
    grid = fixture()
    iso = median_p(grid)
    good = samples_filter(grid, iso)
    good.Update()
    assert good.GetErrorMessage() == "" and good.GetOutput().GetNumberOfPoints() > 20
    for setting, value, expected in (
            ("Spacing", -0.1, "Spacing must be >= 0 (0: 1/40 of the mesh's diagonal), got -0.1"),
            ("CurvatureAdaptivity", -1.0, "Curvature Adaptivity must be >= 0"),
            ("Tolerance", 0.0, "Tolerance must lie in (0, 1)"),
            ("Tolerance", float("nan"), "Tolerance must lie in (0, 1)"),
            ("Levels", 20, "Levels must lie in [0, 8], got 20")):
        f = samples_filter(grid, iso, **{setting: value})
        errors = Errors(f)
        f.Update()
        assert f.GetOutput().GetNumberOfPoints() == 0, setting
        assert expected in f.GetErrorMessage(), (setting, f.GetErrorMessage())
        assert len(errors.messages) == 1, errors.messages


@test
def test_isovalue_beyond_the_field_warns_once_with_empty_output():
    grid = fixture()
    p = vtk_to_numpy(grid.GetPointData().GetArray("p"))
    f = samples_filter(grid, float(p.max()) + 1000.0)
    warnings, errors = Errors(f, "WarningEvent"), Errors(f)
    f.Update()
    assert f.GetErrorMessage() == "" and not errors.messages, errors.messages
    assert f.GetOutput().GetNumberOfPoints() == 0
    assert len(warnings.messages) == 1, warnings.messages
    assert "no surface at isovalue" in warnings.messages[0], warnings.messages
    # A crossed isovalue: samples and no warning.
    f.SetIsovalue(median_p(grid))
    warnings.messages.clear()
    f.Update()
    assert f.GetOutput().GetNumberOfPoints() > 20 and warnings.messages == [], warnings.messages


@test
def test_progress_and_abort():
    grid = fixture()
    f = samples_filter(grid, median_p(grid), Spacing=0.05)
    seen = []
    f.AddObserver(vtkCommand.ProgressEvent, lambda o, e: seen.append(o.GetProgress()))
    f.Update()
    assert len(seen) >= 3 and seen[-1] == 1.0, seen
    g = samples_filter(grid, median_p(grid), Spacing=0.05)

    def abort(o, e):
        if o.GetProgress() > 0.0:
            o.SetAbortExecute(1)

    g.AddObserver(vtkCommand.ProgressEvent, abort)
    g.Update()
    assert g.GetOutput().GetNumberOfPoints() == 0 and g.GetErrorMessage() == "cancelled"


if __name__ == "__main__":
    sys.exit(1 if h.run_all(sys.argv[1:]) else 0)
