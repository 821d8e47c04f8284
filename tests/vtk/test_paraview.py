"""The ParaView plugin in pvbatch (Debian ParaView 5.11), under xvfb-run for the screenshot.

Run by tests/vtk/run.sh:
    PYTHONPATH=<prefix>/usr/lib/python3/dist-packages xvfb-run -a -s "-screen 0 640x480x24" \
        pvbatch tests/vtk/test_paraview.py
The bad-input and MPI cases run pvbatch (and mpiexec) as child processes, so that their
exit status is checked too.
"""

import json
import os
import shutil
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness as h  # noqa: E402
from harness import test  # noqa: E402

from paraview import servermanager as sm  # noqa: E402
from paraview.simple import (  # noqa: E402
    ColorBy,
    CreateView,
    Delete,
    LegacyVTKReader,
    LoadPlugin,
    OpenDataFile,
    ResetCamera,
    SaveScreenshot,
    SetActiveView,
    Show,
)

LoadPlugin(h.PLUGIN, remote=False, ns=globals())
SPHIsosurface = globals()["SPHIsosurfaceMarchingCorrectors"]

TMP = h.tmpdir()
PVBATCH = shutil.which("pvbatch") or "/usr/bin/pvbatch"


def free_surface(source, **props):
    f = SPHIsosurface(Input=source)
    f.SmoothingLength = h.H
    f.GridFactor = h.GRID_FACTOR
    f.Isovalues = [h.ISO]
    for k, v in props.items():
        setattr(f, k, v)
    return f


def output_at(proxy, time=None):
    """The filter's output (builtin session): updated at `time`, copied."""
    if time is None:
        proxy.UpdatePipeline()
    else:
        proxy.UpdatePipeline(time)
    data = proxy.GetClientSideObject().GetOutputDataObject(0)
    copy = data.NewInstance()
    copy.DeepCopy(data)
    return copy


def settings(proxy):
    """The VTK object's settings as its PrintSelf lists them ({name: text})."""
    text = str(proxy.GetClientSideObject())
    out = {}
    for line in text.splitlines():
        key, sep, value = line.strip().partition(":")
        if sep:
            out[key] = value.strip()
    return out


def cli_reference(frame, name):
    return h.read_vtp(h.cli_surface(frame, os.path.join(TMP, name), "--iso", h.ISO, "--h", h.H,
                                    "--grid-factor", h.GRID_FACTOR))


@test
def test_plugin_filter_matches_core_on_a_real_frame():
    r = LegacyVTKReader(FileNames=[h.FRAME_26])
    f = free_surface(r)
    out = sm.Fetch(f)
    assert out.GetPoints().GetDataType() == 11, "points are not doubles"
    n = h.assert_same_surface(out, cli_reference(h.FRAME_26, "ref26.vtp"), 1e-12, "frame 26")
    assert n > 100000, n
    for name in ("Normals", "SumOfWeights"):
        assert out.GetPointData().GetArray(name) is not None, name
    assert h.open_edges(out) == 0
    info = f.GetDataInformation()
    assert info.GetNumberOfCells() == n


@test
def test_screenshot_is_not_blank():
    r = LegacyVTKReader(FileNames=[h.FRAME_26])
    f = free_surface(r)
    view = CreateView("RenderView")
    view.ViewSize = [640, 480]
    view.OrientationAxesVisibility = 0
    SetActiveView(view)
    d = Show(f, view)
    ColorBy(d, ("POINTS", "Normals", "Z"))
    view.CameraPosition = [4.0, 3.0, 5.0]
    view.CameraFocalPoint = [0.0, 0.3, 0.0]
    view.CameraViewUp = [0.0, 1.0, 0.0]
    ResetCamera(view)
    png = os.path.join(TMP, "isobar_frame26.png")
    SaveScreenshot(png, view, ImageResolution=[640, 480])
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOImage import vtkPNGReader

    reader = vtkPNGReader()
    reader.SetFileName(png)
    reader.Update()
    img = reader.GetOutput()
    pixels = vtk_to_numpy(img.GetPointData().GetScalars())[:, :3].astype(int)
    background = pixels[0]
    covered = np.mean(np.any(pixels != background, axis=1))
    colours = len(np.unique(pixels, axis=0))
    assert covered > 0.05, f"only {covered:.1%} of the image is not background"
    assert colours > 50, f"only {colours} colours: flat image"
    print(f"  screenshot {png}: {covered:.0%} covered, {colours} colours", flush=True)
    # Release the GL context now: torn down at exit, Xvfb's GLX reports GLXBadContext.
    Delete(view)
    del view


# A value for every XML property, and how the VTK object prints it back.
ROUND_TRIP = {
    "FieldMode": ("Point array", "1"),
    "InputArray": (["POINTS", "velocity"], "velocity"),
    "FieldComponent": (2, "2"),
    "Isovalues": ([0.25, 0.75, 1.5], "0.25 0.75 1.5"),
    "SmoothingLength": (0.0625, "0.0625"),
    "SmoothingLengthArray": ("id", "id"),
    "Kernel": ("Wendland C2", "1"),
    "VolumeArray": ("id", "id"),
    "DensityArray": ("id", "id"),
    "MassArray": ("id", "id"),
    "Mass": (0.125, "0.125"),
    "GridFactor": (0.4375, "0.4375"),
    "Method": ("Adaptive", "1"),
    "SplashThreshold": (3, "3"),
    "MaxError": (0.375, "0.375"),
    "BisectionIterations": (0, "0"),
    "Backend": ("Auto", "2"),
    "Correct": (0, "0"),
    "ComputeNormals": (0, "0"),
    "CarriedArrays": (["velocity", "id"], "id velocity"),
    "HScale": (0.75, "0.75"),
    "Tolerance": (1e-5, "1.0000000000000001e-05"),
    "Trim": (0, "0"),
    "TrimNode": (0.2, "0.20000000000000001"),
    "TrimVertex": (0.375, "0.375"),
    "Shepard": (1, "1"),
    "MemoryBudget": (2.5, "2.5"),
    "FullGrid": (1, "1"),
    "FixedLattice": (1, "1"),
    "LatticeOrigin": ([0.5, -0.25, 0.125], "0.5 -0.25 0.125"),
    "LatticeCellSize": (0.03125, "0.03125"),
}


@test
def test_every_xml_property_exists_and_round_trips():
    _, props = h.xml_properties()
    settable = {n for n, (_t, a, _e) in props.items() if a.get("information_only") != "1"}
    assert settable == set(ROUND_TRIP), (
        f"XML and test disagree: {sorted(settable ^ set(ROUND_TRIP))}")
    r = LegacyVTKReader(FileNames=[h.FRAME_26])
    f = SPHIsosurface(Input=r)
    listed = set(f.ListProperties())
    missing = (settable | {"ErrorMessage", "Input"}) - listed
    assert not missing, f"not exposed to Python: {missing}"
    for name, (value, _printed) in ROUND_TRIP.items():
        setattr(f, name, value)
        got = f.GetPropertyValue(name)
        if isinstance(value, list):
            got_list = list(got)
            if name == "CarriedArrays":
                assert sorted(got_list) == sorted(value), (name, got_list)
            elif name == "InputArray":
                assert got_list[-1] == value[-1], (name, got_list)
            else:
                assert got_list == value, (name, got_list)
        else:
            assert got == value or str(got) == str(value), (name, got, value)
    f.UpdateVTKObjects()
    s = settings(f)
    for name, (_value, printed) in ROUND_TRIP.items():
        got = s.get(name)
        if name == "CarriedArrays":
            got = " ".join(sorted(got.split()))
        assert got == printed, f"{name}: the VTK object has {got!r}, expected {printed!r}"


@test
def test_volume_slider_in_paraview_slides_without_rebuilding():
    from paraview.simple import Wavelet

    IsovalueSlider = globals()["IsovalueSlider"]
    source = Wavelet(WholeExtent=[-12, 12, -12, 12, -12, 12])
    f = IsovalueSlider(Input=source)
    f.Scalars = ["POINTS", "RTData"]
    counts = []
    for iso in (150.0, 160.0, 150.5, 200.0):
        f.Isovalue = iso
        out = sm.Fetch(f)
        assert out.GetNumberOfCells() > 100, iso
        f.UpdatePropertyInformation()
        counts.append((f.GetPropertyValue("NumberOfStoreBuilds"), f.GetPropertyValue("NumberOfUpdates")))
    assert counts == [(1, 1), (1, 2), (1, 3), (1, 4)], counts
    assert f.SMProxy.GetHints().FindNestedElementByName("ShowInMenu").GetAttribute("category") == "isobar"
    Delete(f)


def wavelet_slider(ext=16, iso=200.0):
    """A Wavelet (extent -ext..ext, not starting at 0), its RTData as a [z, y, x] array with
    the image's first point and spacing, and an Isovalue Slider on it at `iso` (closed
    there)."""
    from paraview.simple import Wavelet
    from vtkmodules.util.numpy_support import vtk_to_numpy

    source = Wavelet(WholeExtent=[-ext, ext] * 3)
    image = sm.Fetch(source)
    n = 2 * ext + 1
    values = vtk_to_numpy(image.GetPointData().GetArray("RTData")).reshape(n, n, n)
    f = globals()["IsovalueSlider"](Input=source)
    f.Scalars = ["POINTS", "RTData"]
    f.Isovalue = iso
    return source, f, values, image.GetPoint(0), image.GetSpacing()


@test
def test_volume_slider_in_paraview_sits_where_contour_does():
    from paraview.simple import Contour

    source, f, _values, _first, _spacing = wavelet_slider()
    c = Contour(Input=source, ContourBy=["POINTS", "RTData"], Isosurfaces=[200.0])
    p, t = h.arrays(sm.Fetch(f))
    q, _ = h.arrays(sm.Fetch(c))
    assert len(t) > 1000 and len(p) == len(q), (len(p), len(q))
    # ParaView's Contour puts one vertex per cut edge by linear interpolation, as the
    # slider does: the same points, in the image's own coordinates (its extent starts at
    # -16, not 0).
    for a, b in ((p, q), (q, p)):
        d = np.array([np.min(np.linalg.norm(b - x, axis=1)) for x in a])
        assert d.max() <= 1e-4, d.max()
    Delete(c)
    Delete(f)


@test
def test_volume_slider_level_of_detail_in_paraview():
    iso = 200.0
    _source, f, values, first, spacing = wavelet_slider(iso=iso)
    value_range = float(values.max() - values.min())
    assert "LodErrorBound" in f.ListProperties() and "LodMaxLevel" in f.ListProperties()
    assert f.LodErrorBound == 0.0 and f.LodMaxLevel == 0
    exact = sm.Fetch(f)
    _, exact_tris = h.arrays(exact)
    h.assert_closed_and_oriented(exact_tris, "exact")
    counts = []
    for bound in (0.02, 0.05, 0.1):
        f.LodErrorBound = bound
        out = sm.Fetch(f)
        points, tris = h.arrays(out)
        h.assert_closed_and_oriented(tris, f"bound {bound}")
        off = np.abs(h.trilinear(values, first, spacing, points) - iso)
        assert off.max() <= bound * value_range and off.max() <= 1e-5 * value_range, (bound, off.max())
        counts.append(len(tris))
        f.UpdatePropertyInformation()
        # Only the level of detail ran again: no new store, no slide.
        assert (f.GetPropertyValue("NumberOfStoreBuilds"), f.GetPropertyValue("NumberOfUpdates")) == (1, 1)
    assert len(exact_tris) > counts[0] > counts[1] > counts[2], (len(exact_tris), counts)
    f.LodErrorBound = 0.0
    h.assert_same_surface(sm.Fetch(f), exact, tol=0.0, what="bound 0")
    Delete(f)


@test
def test_fe_samples_in_paraview_equal_the_cli_and_keep_the_mesh_across_isovalues():
    from paraview.simple import XMLUnstructuredGridReader

    HighOrderSamples = globals()["HighOrderIsosurfaceSamples"]
    fixture = os.path.join(h.REPO, "rust-core", "data", "fe", "mixed_lagrange.vtu")
    reader = XMLUnstructuredGridReader(FileName=[fixture])
    f = HighOrderSamples(Input=reader)
    f.Scalars = ["POINTS", "p"]
    iso = float(np.median(h.point_array(output_at(reader), "p")))
    f.Isovalue = iso
    out = output_at(f)
    ref = os.path.join(TMP, "fe_pv_cli.vtp")
    subprocess.run([h.CLI, "fe", fixture, "--field", "p", "--iso", repr(iso), "-o", ref, "--quiet"],
                   check=True, capture_output=True)
    a, _ = h.arrays(out)
    b, _ = h.arrays(h.read_vtp(ref))
    assert len(a) > 20 and a.shape == b.shape, (a.shape, b.shape)
    assert np.abs(a - b).max() <= 1e-12, np.abs(a - b).max()
    for name in ("Normals", "Radius", "Element", "Reference", "Curvature", "Energy"):
        assert out.GetPointData().GetArray(name) is not None, name
    for other in (iso - 0.2, iso + 0.3):
        f.Isovalue = other
        assert output_at(f).GetNumberOfPoints() > 10
    f.UpdatePropertyInformation()
    assert f.GetPropertyValue("NumberOfMeshBuilds") == 1, f.GetPropertyValue("NumberOfMeshBuilds")
    hints = f.SMProxy.GetHints()
    assert hints.FindNestedElementByName("Representation").GetAttribute("type") == "Point Gaussian"
    assert hints.FindNestedElementByName("ShowInMenu").GetAttribute("category") == "isobar"
    Delete(f)


@test
def test_fe_samples_of_quadratic_hexahedra_equal_the_cli():
    """VTK's 20-node (serendipity) hexahedra, as solvers write them, curved: ParaView's
    High-Order Isosurface Samples reads them as the CLI reads the same .vtu, and VTK's own
    basis of each original cell puts every sample on the isovalue."""
    from paraview.simple import XMLUnstructuredGridReader
    from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy
    from vtkmodules.vtkCommonCore import reference
    from vtkmodules.vtkCommonDataModel import VTK_QUADRATIC_HEXAHEDRON
    from vtkmodules.vtkFiltersSources import vtkCellTypeSource
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridWriter

    src = vtkCellTypeSource()
    src.SetCellType(VTK_QUADRATIC_HEXAHEDRON)
    src.SetBlocksDimensions(2, 2, 2)
    src.Update()
    grid = src.GetOutput()
    y = vtk_to_numpy(grid.GetPoints().GetData()).astype(np.float64) - 1.0
    x = np.stack([y[:, 0] * (0.6 + 0.45 * y[:, 2]), y[:, 1] * (0.6 + 0.45 * y[:, 2]), y[:, 2]], axis=1)
    grid.GetPoints().SetData(numpy_to_vtk(x, deep=1))
    f = (y * y).sum(axis=1)
    arr = numpy_to_vtk(f, deep=1)
    arr.SetName("f")
    grid.GetPointData().AddArray(arr)
    path = os.path.join(TMP, "quadratic_hex.vtu")
    w = vtkXMLUnstructuredGridWriter()
    w.SetFileName(path)
    w.SetInputData(grid)
    assert w.Write() == 1
    reader = XMLUnstructuredGridReader(FileName=[path])
    samples = globals()["HighOrderIsosurfaceSamples"](Input=reader)
    samples.Scalars = ["POINTS", "f"]
    samples.Isovalue = 0.5
    samples.Tolerance = 1e-9
    out = output_at(samples)
    ref = os.path.join(TMP, "quadratic_hex_cli.vtp")
    subprocess.run([h.CLI, "fe", path, "--field", "f", "--iso", "0.5", "--tolerance", "1e-9", "-o", ref,
                    "--quiet"], check=True, capture_output=True)
    a, _ = h.arrays(out)
    b, _ = h.arrays(h.read_vtp(ref))
    assert len(a) > 100 and a.shape == b.shape, (a.shape, b.shape)
    assert np.abs(a - b).max() <= 1e-12, np.abs(a - b).max()
    cells = vtk_to_numpy(out.GetPointData().GetArray("Element")).astype(int)
    refs = vtk_to_numpy(out.GetPointData().GetArray("Reference"))
    worst = 0.0
    for c, u in zip(cells, refs):
        cell = grid.GetCell(int(c))
        weights = [0.0] * 20
        cell.EvaluateLocation(reference(0), list(map(float, u)), [0.0, 0.0, 0.0], weights)
        ids = [cell.GetPointId(k) for k in range(20)]
        worst = max(worst, abs(float(np.dot(weights, f[ids])) - 0.5))
    assert worst <= 1e-9 * (1 + 1e-6), worst
    Delete(samples)


@test
def test_filter_is_in_the_isobar_menu_category():
    r = LegacyVTKReader(FileNames=[h.FRAME_26])
    f = SPHIsosurface(Input=r)
    assert f.SMProxy.GetXMLLabel() == "SPH Isosurface (Marching Correctors)"
    assert f.SMProxy.GetVTKClassName() == "vtkIsobarSPHIsosurface"
    menu = f.SMProxy.GetHints().FindNestedElementByName("ShowInMenu")
    assert menu is not None and menu.GetAttribute("category") == "isobar"
    for name in ("HScale", "Tolerance", "Trim", "TrimNode", "TrimVertex", "Shepard",
                 "MemoryBudget", "FullGrid", "FixedLattice", "LatticeOrigin", "LatticeCellSize"):
        assert f.GetProperty(name).SMProperty.GetPanelVisibility() == "advanced", name


@test
def test_error_message_property_and_empty_output_on_bad_input():
    r = LegacyVTKReader(FileNames=[h.FRAME_26])
    f = free_surface(r, FieldMode="Point array")
    f.InputArray = ["POINTS", "pressure"]  # not in the data
    out = output_at(f)
    assert out.GetNumberOfPoints() == 0 and out.GetNumberOfCells() == 0
    f.UpdatePropertyInformation()
    msg = f.GetPropertyValue("ErrorMessage")
    assert "'pressure'" in msg, msg
    # Fixed, it works again.
    f.FieldMode = "Sum of weights (free surface)"
    out = output_at(f)
    assert out.GetNumberOfCells() > 100000
    f.UpdatePropertyInformation()
    assert f.GetPropertyValue("ErrorMessage") == ""


@test
def test_core_warning_in_paraview_and_empty_output_above_the_field():
    # The core's warnings reach ParaView as the VTK object's warnings (Output Messages);
    # an isovalue the field never crosses is no error, and a normal run warns nothing.
    r = LegacyVTKReader(FileNames=[h.FRAME_26])
    f = free_surface(r, Isovalues=[100.0])
    warnings = h.Errors(f.GetClientSideObject(), "WarningEvent")
    out = output_at(f)
    assert out.GetNumberOfPoints() == 0 and out.GetNumberOfCells() == 0
    f.UpdatePropertyInformation()
    assert f.GetPropertyValue("ErrorMessage") == ""
    assert len(warnings.messages) == 1, warnings.messages
    assert "no surface at isovalue 100" in warnings.messages[0], warnings.messages
    f.Isovalues = [h.ISO]
    assert output_at(f).GetNumberOfCells() > 100000
    assert len(warnings.messages) == 1, warnings.messages


@test
def test_bad_inputs_in_a_pvbatch_process():
    """Missing array, NaN positions, no smoothing length: error messages, empty outputs,
    exit status 0."""
    p = subprocess.run(
        [PVBATCH, os.path.join(h.HERE, "pv_bad_input.py"), TMP],
        capture_output=True, text=True, timeout=300, env=clean_env())
    assert p.returncode == 0, f"pvbatch exited {p.returncode}: {p.stderr[-2000:]}"
    lines = p.stdout.splitlines()
    for case in ("missing-array", "nan-positions", "no-smoothing-length"):
        assert f"EMPTY {case}" in lines, f"{case}: {p.stdout[-2000:]}"
    err = p.stderr
    for fragment in ("'pressure'", "smoothing length", "isobar_sph_extract"):
        assert fragment in err, f"stderr lacks {fragment!r}: {err[-3000:]}"


def time_steps(proxy):
    """TIME_STEPS of the filter's output as the pipeline reports them downstream."""
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline as sddp

    proxy.UpdatePipelineInformation()
    algo = proxy.GetClientSideObject()
    algo.UpdateInformation()
    steps = algo.GetOutputInformation(0).Get(sddp.TIME_STEPS())
    return list(steps) if steps is not None else None


def make_series_dir():
    d = os.path.join(TMP, "series")
    os.makedirs(d, exist_ok=True)
    for src, name in ((h.FRAME_01, "frame_01.vtk"), (h.FRAME_26, "frame_26.vtk")):
        dst = os.path.join(d, name)
        if not os.path.exists(dst):
            shutil.copy(src, dst)
    return d


@test
def test_two_frame_series_extracts_frame_by_frame():
    d = make_series_dir()
    refs = [cli_reference(h.FRAME_01, "ref01.vtp"), cli_reference(h.FRAME_26, "ref26.vtp")]
    # A file list (what File > Open of frame_..vtk gives) ...
    r = LegacyVTKReader(FileNames=[os.path.join(d, "frame_01.vtk"), os.path.join(d, "frame_26.vtk")])
    f = free_surface(r)
    assert list(r.TimestepValues) == [0.0, 1.0], r.TimestepValues
    assert time_steps(f) == [0.0, 1.0], time_steps(f)
    counts = []
    for t, ref in zip((0.0, 1.0), refs, strict=True):
        counts.append(h.assert_same_surface(output_at(f, t), ref, 1e-12, f"t={t}"))
    assert counts[0] != counts[1], counts
    # ... and a .vtk.series file with its own times.
    series = os.path.join(d, "frames.vtk.series")
    with open(series, "w") as fh:
        json.dump({"file-series-version": "1.0", "files": [
            {"name": "frame_01.vtk", "time": 0.5}, {"name": "frame_26.vtk", "time": 2.25}]}, fh)
    r2 = OpenDataFile(series)
    assert r2 is not None, "ParaView cannot open the .vtk.series file"
    f2 = free_surface(r2)
    assert time_steps(f2) == [0.5, 2.25], time_steps(f2)
    for t, ref in zip((0.5, 2.25), refs, strict=True):
        h.assert_same_surface(output_at(f2, t), ref, 1e-12, f"series t={t}")
    # Backwards in time works too (nothing cached wrongly).
    h.assert_same_surface(output_at(f2, 0.5), refs[0], 1e-12, "series back to t=0.5")


def clean_env(**extra):
    """This pvbatch is an MPI singleton: its OpenMPI/PMIx variables would make a child
    mpiexec or pvbatch believe it belongs to this job."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("OMPI_", "PMIX_", "OPAL_", "ORTE_"))}
    env.update(extra)
    return env


def run_mpi(ranks):
    """Runs pv_mpi.py under `mpiexec -n ranks` once; returns (prefix, {case: info}, log)."""
    if ranks in _mpi_runs:
        return _mpi_runs[ranks]
    env = clean_env(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
                    OMPI_MCA_rmaps_base_oversubscribe="1")
    prefix = os.path.join(TMP, f"mpi_{ranks}")
    cmd = ["mpiexec", "-n", str(ranks), PVBATCH, os.path.join(h.HERE, "pv_mpi.py"), prefix]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert p.returncode == 0, f"{ranks} ranks: exit {p.returncode}\n{p.stdout[-2000:]}\n{p.stderr[-3000:]}"
    cases = {}
    for ln in p.stdout.splitlines():
        if ln.startswith("CASE "):
            _, name, info = ln.split(" ", 2)
            cases[name] = json.loads(info)
    assert set(cases) == {"auto", "reader", "fixed", "frame01", "varied", "plane",
                          "fe_reader", "fe_split", "fe_beyond"}, p.stdout[-2000:]
    # Each rank warns of the isovalues its slab has no triangle of; only those no rank
    # has reach the user: 1000 (the "plane" case's second isovalue), once per rank, and
    # not the plane, which lies in one slab.
    warned = [ln for ln in p.stderr.splitlines()
              if "vtkIsobarSPHIsosurface" in ln and "no surface at isovalue" in ln]
    assert len(warned) == ranks and all("no surface at isovalue 1000" in ln for ln in warned), (
        f"{ranks} ranks: {warned}")
    # The FE filter likewise: only the isovalue beyond the field, once per rank; and a
    # rank whose piece holds no cell (the reader's one piece) is no error.
    fe_warned = [ln for ln in p.stderr.splitlines()
                 if "vtkIsobarFESamples" in ln and "no surface at isovalue" in ln]
    assert len(fe_warned) == ranks, f"{ranks} ranks: {fe_warned}"
    assert "no volume cell" not in p.stderr and "no cells" not in p.stderr, p.stderr[-3000:]
    assert sum(t > 0 for t in cases["plane"]["triangles"]) >= 1, cases["plane"]
    # Bad settings: empty everywhere, no rank hung (the run ended).
    for bad in ("bad input", "bad nan", "bad budget"):
        assert f"{bad}: 0 cells" in p.stdout, f"{ranks} ranks, {bad}: {p.stdout[-2000:]}"
    assert "non-finite position" in p.stderr, p.stderr[-3000:]
    _mpi_runs[ranks] = (prefix, cases, p.stdout)
    return _mpi_runs[ranks]


_mpi_runs = {}


def merge_points(pd, tol):
    """`pd` with points closer than `tol` (absolute) merged, cells kept as they are."""
    from vtkmodules.vtkFiltersCore import vtkCleanPolyData

    c = vtkCleanPolyData()
    c.SetInputData(pd)
    c.PointMergingOn()
    c.ToleranceIsAbsoluteOn()
    c.SetAbsoluteTolerance(tol)
    c.ConvertPolysToLinesOff()
    c.ConvertLinesToPointsOff()
    c.ConvertStripsToPolysOff()
    c.Update()
    return c.GetOutput()


def check_pieces(ranks, case, reference, arrays=("SumOfWeights",), least=1000):
    """The `ranks`-rank surface of `case` against `reference` (a vtkPolyData): every rank
    made triangles, the pieces together have exactly the reference's triangles (1e-9), no
    duplicates, and merging the vertices that adjacent pieces both made gives the
    reference's vertices, the reference's open edges (none for a closed surface) and its
    point `arrays` (1e-9 relative; Normals are floats: 1e-6)."""
    prefix, cases, _log = run_mpi(ranks)
    info = cases[case]
    assert len(info["triangles"]) == ranks, info
    assert min(info["triangles"]) > least, f"{ranks} ranks, {case}: a rank made no surface: {info}"
    joined = h.read_vtp(f"{prefix}_{case}.vtp")
    ref_points, ref_tris = h.arrays(reference)
    assert joined.GetNumberOfCells() == len(ref_tris), (joined.GetNumberOfCells(), len(ref_tris))
    assert h.duplicate_triangles(joined) == 0, "duplicate triangles"
    # Vertices on a cut are made by both adjacent ranks, from sums over the particles in
    # a different order: equal to the last bits or so, hence a merge tolerance far below
    # any edge length (the merged vertex count must still equal the reference's exactly).
    merged = merge_points(joined, 1e-12)
    assert merged.GetNumberOfPoints() == len(ref_points), (
        f"{merged.GetNumberOfPoints()} merged vertices vs {len(ref_points)}")
    assert h.open_edges(reference) == 0 or case == "varied", "the reference is not closed"
    assert h.open_edges(merged) == h.open_edges(reference), (
        f"seams: {h.open_edges(merged)} open edges in the merged pieces, "
        f"{h.open_edges(reference)} in the reference")
    what = f"{ranks} ranks, {case}"
    h.assert_same_surface(merged, reference, 1e-9, what)
    h.assert_same_point_data(merged, reference, arrays, 1e-9, what)
    h.assert_same_point_data(merged, reference, ["Normals"], 1e-6, what)
    return info


@test
def test_mpi_two_ranks_each_extract_a_piece_of_the_one_rank_surface():
    prefix1, cases1, _ = run_mpi(1)
    assert cases1["auto"]["particles"] == [4732], cases1
    one = h.read_vtp(f"{prefix1}_auto.vtp")
    # One rank is the plain single-process filter: the CLI's surface.
    h.assert_same_surface(one, cli_reference(h.FRAME_26, "ref26.vtp"), 1e-12, "1 rank vs CLI")
    _, cases2, _ = run_mpi(2)
    # RedistributeDataSet really split the particles before the filter ...
    per_rank = cases2["auto"]["particles"]
    assert len(per_rank) == 2 and min(per_rank) > 1000 and sum(per_rank) == 4732, per_rank
    info = check_pieces(2, "auto", one)
    piece = cases2["auto"]["rank0_piece"]
    assert piece["axis"] in (0, 1, 2) and piece["slab"][0] < -1e300 < piece["slab"][1], piece
    assert per_rank[0] < piece["particles"] < 4732, f"rank 0 has no halo or everything: {piece}"
    # ... and from a reader that hands every particle to rank 0 the filter splits them.
    assert cases2["reader"]["particles"] == [4732, 0], cases2["reader"]
    check_pieces(2, "reader", one)
    print(f"  2 ranks: triangles per rank {info['triangles']}, total {sum(info['triangles'])}; "
          f"rank 0: slab {piece['slab']} along axis {piece['axis']}, "
          f"{piece['particles']} particles with its halo", flush=True)


@test
def test_mpi_three_ranks_each_extract_a_piece_of_the_one_rank_surface():
    prefix1, _, _ = run_mpi(1)
    one = h.read_vtp(f"{prefix1}_auto.vtp")
    info = check_pieces(3, "auto", one)
    check_pieces(3, "reader", one)
    # Particles on a regular lattice (frame 1): many lie exactly on a cut.
    one01 = h.read_vtp(f"{prefix1}_frame01.vtp")
    for ranks in (2, 3):
        check_pieces(ranks, "frame01", one01)
    print(f"  3 ranks: triangles per rank {info['triangles']}, total {sum(info['triangles'])}",
          flush=True)


@test
def test_mpi_varied_h_quintic_point_array_field_and_carried_arrays():
    """Per-particle h, quintic kernel (support 3h), H Scale 0.75, velocity magnitude with
    Shepard and trimming (an open surface), carried velocity and id: the halo and the
    lattice follow the settings, the pieces are still the one-rank surface."""
    prefix1, _, _ = run_mpi(1)
    one = h.read_vtp(f"{prefix1}_varied.vtp")
    assert one.GetNumberOfCells() > 5000, one.GetNumberOfCells()
    for ranks in (2, 3):
        check_pieces(ranks, "varied", one, arrays=("SumOfWeights", "velocity", "id"),
                     least=500)


@test
def test_mpi_fe_samples_take_the_whole_meshs_spacing_and_empty_pieces_are_no_error():
    """The FE filter under mpiexec: a rank whose piece holds no cell gives no samples and
    no error, and the default spacing follows the whole mesh's box, not each piece's (from
    a piece's smaller box the pieces were sampled denser than the one-rank surface)."""
    prefix1, cases1, _ = run_mpi(1)
    one = cases1["fe_reader"]
    assert one["samples"][0] > 500, one
    ref_points, _ = h.arrays(h.read_vtp(f"{prefix1}_fe_reader.vtp"))
    for ranks in (2, 3):
        prefix, cases, _ = run_mpi(ranks)
        reader = cases["fe_reader"]
        assert reader["cells"][1:] == [0] * (ranks - 1), reader
        # Rank 0 holds the whole mesh: the one-rank samples, bit for bit.
        points, _ = h.arrays(h.read_vtp(f"{prefix}_fe_reader.vtp"))
        assert np.array_equal(points, ref_points), f"{ranks} ranks: samples differ"
        split = cases["fe_split"]
        assert min(split["cells"]) > 0 and min(split["samples"]) > 0, split
        # A radius reaches its sample's Voronoi cell among the samples of its own piece.
        # Each piece is sampled up to its seam as to a boundary, and its own history of
        # splits settles it a little denser or sparser (6 % on the median with 2 ranks).
        # Spacing taken from a piece's box (1/40 of its diagonal: half a cube's is 13 %
        # shorter, and a third's more) still fails.
        print(f"  {ranks} ranks: radius median {split['radius_median']:.5f}, one rank "
              f"{one['radius_median']:.5f}", flush=True)
        assert abs(split["radius_median"] - one["radius_median"]) <= 0.09 * one["radius_median"], (
            split, one)
        # The seams are sampled from both sides (1.21 times the one-rank count with 2
        # ranks, 1.26 with 3); a piece's own spacing would add 30 % more.
        assert 0.8 < sum(split["samples"]) / one["samples"][0] < 1.4, (split, one)
        assert cases["fe_beyond"]["samples"] == [0] * ranks, cases["fe_beyond"]
        print(f"  {ranks} ranks: split cells {split['cells']}, samples {split['samples']} "
              f"(one rank: {one['samples'][0]})", flush=True)


@test
def test_fixed_lattice_matches_cli_lattice_in_one_and_several_ranks():
    ref = h.read_vtp(h.cli_surface(
        h.FRAME_26, os.path.join(TMP, "ref26_lattice.vtp"), "--iso", h.ISO, "--h", h.H,
        "--lattice", ",".join(str(v) for v in (*h.LATTICE_ORIGIN, h.LATTICE_CELL))))
    # In this process (builtin session, one rank).
    r = LegacyVTKReader(FileNames=[h.FRAME_26])
    f = free_surface(r, FixedLattice=1, LatticeOrigin=list(h.LATTICE_ORIGIN),
                     LatticeCellSize=h.LATTICE_CELL)
    n = h.assert_same_surface(sm.Fetch(f), ref, 1e-12, "Fixed Lattice vs CLI --lattice")
    assert n > 100000, n
    plain = sm.Fetch(free_surface(r))
    assert plain.GetNumberOfCells() != n, "the lattice changed nothing"
    prefix1, _, _ = run_mpi(1)
    h.assert_same_surface(h.read_vtp(f"{prefix1}_fixed.vtp"), ref, 1e-12, "1 rank, fixed")
    for ranks in (2, 3):
        check_pieces(ranks, "fixed", ref)


if __name__ == "__main__":
    sys.exit(1 if h.run_all(sys.argv[1:]) else 0)
