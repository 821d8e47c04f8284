"""The VTK module with Debian's VTK 9.1, from Debian's /usr/bin/python3.

Run by tests/vtk/run.sh with PYTHONPATH=vtk-plugin/build-vtk/python.
"""

import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness as h  # noqa: E402
from harness import Errors, test  # noqa: E402

import vtkmodules  # noqa: E402
from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy  # noqa: E402
from vtkmodules.vtkCommonCore import vtkCommand, vtkPoints, vtkUnsignedCharArray, vtkVersion  # noqa: E402
from vtkmodules.vtkCommonDataModel import vtkDataObject, vtkDataSetAttributes, vtkPolyData  # noqa: E402
from vtkmodules.vtkIOLegacy import vtkUnstructuredGridReader  # noqa: E402


from isobar_vtk import vtkIsobarSPHIsosurface  # noqa: E402

TMP = h.tmpdir()


def reader(path):
    r = vtkUnstructuredGridReader()
    r.SetFileName(path)
    r.ReadAllScalarsOn()
    r.ReadAllVectorsOn()
    r.ReadAllFieldsOn()
    r.Update()
    return r


def free_surface_filter(source, **settings):
    f = vtkIsobarSPHIsosurface()
    f.SetInputConnection(source.GetOutputPort())
    f.SetSmoothingLength(h.H)
    f.SetGridFactor(h.GRID_FACTOR)
    f.SetIsovalue(0, h.ISO)
    for k, v in settings.items():
        getattr(f, "Set" + k)(v)
    return f


@test
def test_debian_vtk_9_1():
    v = vtkVersion.GetVTKVersion()
    assert v.startswith("9.1"), f"expected Debian's VTK 9.1, got {v} from {vtkmodules.__file__}"
    assert vtkmodules.__file__.startswith("/usr/lib/python3/dist-packages"), vtkmodules.__file__


@test
def test_free_surface_watertight_and_volume_equals_core():
    for frame in (h.FRAME_26, h.FRAME_01, h.BUNNY):
        f = free_surface_filter(reader(frame))
        f.Update()
        out = f.GetOutput()
        assert f.GetErrorMessage() == "", f.GetErrorMessage()
        assert out.GetNumberOfCells() > 1000, out.GetNumberOfCells()
        assert out.GetPoints().GetDataType() == 11, "points are not doubles"
        assert h.open_edges(out) == 0, f"{frame}: {h.open_edges(out)} boundary/non-manifold edges"
        ref = h.read_vtp(
            h.cli_surface(frame, os.path.join(TMP, "ref.vtp"), "--iso", h.ISO, "--h", h.H,
                          "--grid-factor", h.GRID_FACTOR)
        )
        v, vr = h.volume(out), h.volume(ref)
        assert vr > 0 and abs(v - vr) <= 1e-9 * abs(vr), f"{frame}: volume {v!r} vs core {vr!r}"
        h.assert_same_surface(out, ref, 1e-12, os.path.basename(frame))
        for name in ("Normals", "SumOfWeights"):
            d = np.max(np.abs(np.sort(h.point_array(out, name), axis=0)
                              - np.sort(h.point_array(ref, name), axis=0)))
            assert d <= 1e-6, f"{name} differs by {d}"
        assert out.GetPointData().GetNormals() is not None


@test
def test_adaptive_method_equals_the_cli_and_is_closed():
    import subprocess

    f = free_surface_filter(reader(h.FRAME_26), Method=vtkIsobarSPHIsosurface.ADAPTIVE)
    f.Update()
    out = f.GetOutput()
    assert f.GetErrorMessage() == "", f.GetErrorMessage()
    assert h.open_edges(out) == 0, f"{h.open_edges(out)} boundary/non-manifold edges"
    ref_path = os.path.join(TMP, "adaptive.vtp")
    subprocess.run([h.CLI, "adaptive", h.FRAME_26, "--quiet", "-o", ref_path, "--iso", str(h.ISO),
                    "--h", str(h.H), "--grid-factor", str(h.GRID_FACTOR)], check=True, capture_output=True)
    ref = h.read_vtp(ref_path)
    h.assert_same_surface(out, ref, 1e-12, "adaptive")
    corrected = free_surface_filter(reader(h.FRAME_26))
    corrected.Update()
    assert 0 < out.GetNumberOfCells() < corrected.GetOutput().GetNumberOfCells()
    # Backend GPU (wgpu; lavapipe in CI, installed by the test command): the CLI's GPU
    # surface exactly, and the CPU surface within the f32 tolerance.
    gpu = free_surface_filter(reader(h.FRAME_26), Method=vtkIsobarSPHIsosurface.ADAPTIVE, Backend=1)
    gpu.Update()
    assert gpu.GetErrorMessage() == "", gpu.GetErrorMessage()
    gpu_ref_path = os.path.join(TMP, "adaptive_gpu.vtp")
    subprocess.run([h.CLI, "adaptive", h.FRAME_26, "--quiet", "-o", gpu_ref_path, "--iso", str(h.ISO),
                    "--h", str(h.H), "--grid-factor", str(h.GRID_FACTOR), "--backend", "gpu"],
                   check=True, capture_output=True)
    h.assert_same_surface(gpu.GetOutput(), h.read_vtp(gpu_ref_path), 1e-12, "adaptive gpu")
    assert gpu.GetOutput().GetNumberOfCells() == out.GetNumberOfCells()
    assert h.open_edges(gpu.GetOutput()) == 0
    # One isovalue only: a clear error and an empty output, not a silent first isovalue.
    f.SetIsovalue(1, 0.7)
    errors = Errors(f)
    f.Update()
    assert f.GetOutput().GetNumberOfCells() == 0
    assert any("one isovalue at a time" in m for m in errors.messages), errors.messages


def adaptive_output_equal_to_the_cli(setting, value, option):
    """The adaptive filter's output with `setting` = `value`, after checking it is the
    CLI's surface with `option value` on the same frame and closed."""
    import subprocess

    f = free_surface_filter(reader(h.FRAME_26), Method=vtkIsobarSPHIsosurface.ADAPTIVE, **{setting: value})
    f.Update()
    assert f.GetErrorMessage() == "", f.GetErrorMessage()
    ref_path = os.path.join(TMP, f"adaptive_{setting}_{value}.vtp")
    subprocess.run([h.CLI, "adaptive", h.FRAME_26, "--quiet", "-o", ref_path, "--iso", str(h.ISO),
                    "--h", str(h.H), "--grid-factor", str(h.GRID_FACTOR), option, str(value)],
                   check=True, capture_output=True)
    h.assert_same_surface(f.GetOutput(), h.read_vtp(ref_path), 1e-12, f"{setting} {value}")
    assert h.open_edges(f.GetOutput()) == 0
    return f.GetOutput()


@test
def test_adaptive_max_error_equals_the_cli_option():
    # The error criterion's tolerance reaches the core: each value gives the CLI's
    # surface with the same --max-error, and 0 (off) differs from the default.
    cells = {e: adaptive_output_equal_to_the_cli("MaxError", e, "--max-error").GetNumberOfCells()
             for e in (0.0, 0.1)}
    assert cells[0.1] > cells[0.0], cells
    assert vtkIsobarSPHIsosurface().GetMaxError() > 0


@test
def test_adaptive_bisection_iterations_equal_the_cli_option():
    # The halvings reach the core: 0 and 2 each give the CLI's surface with the same
    # --bisection-iterations (and differ from each other); the default is the core's,
    # and values past 16 are refused (they used to be clamped to 16 without a word).
    points = {}
    for n in (0, 2):
        out = adaptive_output_equal_to_the_cli("BisectionIterations", n, "--bisection-iterations")
        points[n] = np.sort(vtk_to_numpy(out.GetPoints().GetData()), axis=0)
    assert not np.array_equal(points[0], points[2]), "bisection_iterations did not reach the core"
    f = vtkIsobarSPHIsosurface()
    assert f.GetBisectionIterations() == 5
    f = free_surface_filter(reader(h.FRAME_26), Method=vtkIsobarSPHIsosurface.ADAPTIVE,
                            BisectionIterations=40)
    expect_error(f, "Bisection Iterations must lie in [0, 16], got 40")


@test
def test_marching_correctors_backend_gpu_gives_the_cpu_surface():
    # Backend GPU (wgpu; lavapipe in CI) runs the seed cells' neighbour search on the
    # device; the exact tests stay on the CPU, so the surface is the CPU's, bit for bit.
    cpu = free_surface_filter(reader(h.FRAME_26))
    cpu.Update()
    gpu = free_surface_filter(reader(h.FRAME_26), Backend=1)
    gpu.Update()
    assert gpu.GetErrorMessage() == "", gpu.GetErrorMessage()
    a, b = cpu.GetOutput(), gpu.GetOutput()
    assert a.GetNumberOfCells() > 1000
    assert np.array_equal(vtk_to_numpy(a.GetPoints().GetData()), vtk_to_numpy(b.GetPoints().GetData()))
    assert np.array_equal(vtk_to_numpy(a.GetPolys().GetConnectivityArray()),
                          vtk_to_numpy(b.GetPolys().GetConnectivityArray()))
    # The full-grid baseline runs on the CPU only: asking it for the GPU is an error.
    refused = free_surface_filter(reader(h.FRAME_26), Backend=1, FullGrid=1)
    errors = Errors(refused)
    refused.Update()
    assert refused.GetOutput().GetNumberOfCells() == 0
    assert any("CPU only" in m for m in errors.messages), errors.messages


@test
def test_backend_auto_on_the_cpu_says_why_in_a_warning_and_field_data():
    # Auto runs on the CPU without a hardware GPU (lavapipe in CI is software): the filter
    # warns with the CLI's line and leaves the core's reason in the field data; a run that
    # did not ask for Auto carries no note.
    note = h.core_auto_note()
    for method in (vtkIsobarSPHIsosurface.MARCHING_CORRECTORS, vtkIsobarSPHIsosurface.ADAPTIVE):
        f = free_surface_filter(reader(h.FRAME_26), Method=method, Backend=2)
        warnings = Errors(f, "WarningEvent")
        f.Update()
        assert f.GetErrorMessage() == "", f.GetErrorMessage()
        out = f.GetOutput()
        assert out.GetNumberOfCells() > 1000, out.GetNumberOfCells()
        array = out.GetFieldData().GetAbstractArray("IsobarBackendNote")
        if note:
            assert array is not None and array.GetNumberOfValues() == 1, method
            assert array.GetValue(0) == note, (array.GetValue(0), note)
            line = f"backend auto: running on the CPU ({note})"
            assert any(line in m for m in warnings.messages), warnings.messages
        else:
            assert array is None and warnings.messages == [], warnings.messages
    cpu = free_surface_filter(reader(h.FRAME_26), Backend=0)
    cpu.Update()
    assert cpu.GetOutput().GetFieldData().GetAbstractArray("IsobarBackendNote") is None


@test
def test_core_warnings_come_as_one_vtk_warning_a_line():
    # An isovalue above the field's maximum is a valid question with an empty answer: no
    # error, an empty output, and the core's warning (isobar_surface_warnings) as a VTK
    # warning. A normal run warns nothing. Backend CPU: Auto would add its own warning on
    # a machine without a GPU.
    def run(method, *isovalues):
        f = free_surface_filter(reader(h.FRAME_26), Method=method, Backend=0)
        f.SetNumberOfIsovalues(len(isovalues))
        for i, iso in enumerate(isovalues):
            f.SetIsovalue(i, iso)
        warnings = Errors(f, "WarningEvent")
        f.Update()
        assert f.GetErrorMessage() == "", f.GetErrorMessage()
        return f.GetOutput(), warnings.messages

    for method in (vtkIsobarSPHIsosurface.MARCHING_CORRECTORS, vtkIsobarSPHIsosurface.ADAPTIVE):
        out, messages = run(method, 100.0)
        assert out.GetNumberOfPoints() == 0 and out.GetNumberOfCells() == 0, method
        assert len(messages) == 1, messages
        assert "no surface at isovalue 100" in messages[0], messages
        out, messages = run(method, h.ISO)
        assert out.GetNumberOfCells() > 1000, method
        assert messages == [], messages
    # Several lines (Marching Correctors takes several isovalues): one warning each.
    out, messages = run(vtkIsobarSPHIsosurface.MARCHING_CORRECTORS, h.ISO, 100.0, 200.0)
    assert out.GetNumberOfCells() > 1000
    assert len(messages) == 2, messages
    for iso, message in zip((100, 200), messages):
        assert f"no surface at isovalue {iso}" in message, messages


def blobs_image(n=24):
    """Two overlapping Gaussian blobs on an n³ image (origin (1, 2, 3), spacing 0.5)."""
    from vtkmodules.vtkCommonDataModel import vtkImageData

    x = np.linspace(-1.0, 1.0, n)
    z, y, xx = np.meshgrid(x, x, x, indexing="ij")
    values = np.exp(-6 * ((xx - 0.35) ** 2 + y**2 + z**2)) + np.exp(-6 * ((xx + 0.35) ** 2 + y**2 + z**2))
    img = vtkImageData()
    img.SetDimensions(n, n, n)
    img.SetOrigin(1.0, 2.0, 3.0)
    img.SetSpacing(0.5, 0.5, 0.5)
    arr = numpy_to_vtk(values.ravel().astype(np.float32), deep=True)
    arr.SetName("blobs")
    img.GetPointData().SetScalars(arr)
    return img, arr


def nearest_distances(a, b):
    """For each row of a, the distance to the nearest row of b."""
    out = np.empty(len(a))
    for i in range(0, len(a), 512):
        d = np.linalg.norm(a[i:i + 512, None, :] - b[None, :, :], axis=2)
        out[i:i + 512] = d.min(axis=1)
    return out


@test
def test_volume_slider_slides_without_rebuilding_and_matches_flying_edges():
    from isobar_vtk import vtkIsobarVolumeSlider
    from vtkmodules.vtkFiltersCore import vtkFlyingEdges3D

    img, arr = blobs_image()
    f = vtkIsobarVolumeSlider()
    f.SetInputData(img)
    for k, iso in enumerate((0.3, 0.5, 0.31, 0.9, 0.3)):
        f.SetIsovalue(iso)
        f.Update()
        assert f.GetErrorMessage() == "", f.GetErrorMessage()
        out = f.GetOutput()
        assert out.GetNumberOfCells() > 100 and h.open_edges(out) == 0
        assert out.GetPointData().GetNormals() is not None
        # The same vertices as VTK's own marching cubes of the same volume (both put one
        # vertex per cut edge by linear interpolation), to float rounding.
        fe = vtkFlyingEdges3D()
        fe.SetInputData(img)
        fe.SetValue(0, iso)
        fe.Update()
        p, _ = h.arrays(out)
        q, _ = h.arrays(fe.GetOutput())
        assert len(p) == len(q), (iso, len(p), len(q))
        assert nearest_distances(p, q).max() <= 1e-5 and nearest_distances(q, p).max() <= 1e-5, iso
        # One pre-encoding; every isovalue change is a slide, not a start-over.
        assert f.GetNumberOfStoreBuilds() == 1 and f.GetNumberOfUpdates() == k + 1
    # New values rebuild the store.
    arr.SetValue(0, 0.25)
    arr.Modified()
    img.Modified()
    f.Update()
    assert f.GetNumberOfStoreBuilds() == 2


@test
def test_volume_slider_store_build_reports_progress_and_aborts():
    """The store build (seconds for a 256³ volume) ran without progress and could not be
    stopped: now it reports VTK progress, and an abort leaves an empty output with the
    message "cancelled", no store, and the next update builds again."""
    from isobar_vtk import vtkIsobarVolumeSlider

    img, _ = blobs_image()
    f = vtkIsobarVolumeSlider()
    f.SetInputData(img)
    f.SetIsovalue(0.5)
    seen = []
    f.AddObserver(vtkCommand.ProgressEvent, lambda o, e: seen.append(o.GetProgress()))
    f.Update()
    assert f.GetErrorMessage() == "", f.GetErrorMessage()
    assert any(0.0 < p < 1.0 for p in seen) and seen[-1] == 1.0, seen
    assert all(b >= a for a, b in zip(seen, seen[1:], strict=False)), "progress went backwards"

    g = vtkIsobarVolumeSlider()
    g.SetInputData(img)
    g.SetIsovalue(0.5)
    calls = []

    def abort(o, e):
        calls.append(o.GetProgress())
        if o.GetProgress() > 0.0:
            o.SetAbortExecute(1)

    g.AddObserver(vtkCommand.ProgressEvent, abort)
    g.Update()
    assert g.GetErrorMessage() == "cancelled", g.GetErrorMessage()
    assert g.GetOutput().GetNumberOfCells() == 0 and g.GetNumberOfStoreBuilds() == 0
    g.RemoveAllObservers()
    g.SetAbortExecute(0)
    g.Modified()
    g.Update()
    assert g.GetErrorMessage() == "" and g.GetNumberOfStoreBuilds() == 1
    assert g.GetOutput().GetNumberOfCells() == f.GetOutput().GetNumberOfCells()


@test
def test_volume_slider_narrows_doubles_in_the_core_and_says_what_that_loses():
    """The filter cast double scalars to float itself: a pressure of 101325 Pa plus
    small variations moved vertices by half a cell, a finite 1e300 became inf and was
    blamed on the data, and an isovalue outside the values gave an empty output, all
    without a word. Doubles now go to the core, which warns or refuses."""
    from isobar_vtk import vtkIsobarVolumeSlider
    from vtkmodules.vtkFiltersCore import vtkFlyingEdges3D

    img, arr = blobs_image()
    blobs = vtk_to_numpy(arr).astype(np.float64)
    for offset, coarse in ((0.0, False), (101325.0, True)):
        doubles = numpy_to_vtk(offset + 0.02 * blobs, deep=True)
        doubles.SetName("pressure")
        img.GetPointData().SetScalars(doubles)
        f = vtkIsobarVolumeSlider()
        f.SetInputData(img)
        f.SetIsovalue(offset + 0.01)
        warned = Errors(f, "WarningEvent")
        f.Update()
        assert f.GetErrorMessage() == "", f.GetErrorMessage()
        assert f.GetOutput().GetNumberOfCells() > 100
        if coarse:
            assert len(warned.messages) == 1, warned.messages
            assert "array 'pressure': the values are held as float32, in steps of 0.0078125" in warned.messages[0]
        else:
            assert warned.messages == [], warned.messages
            # Exactly representable data: VTK's own marching cubes of the same values.
            fe = vtkFlyingEdges3D()
            fe.SetInputData(img)
            fe.SetValue(0, offset + 0.01)
            fe.Update()
            assert f.GetOutput().GetNumberOfCells() == fe.GetOutput().GetNumberOfCells()
    huge = numpy_to_vtk(blobs, deep=True)
    huge.SetName("huge")
    huge.SetValue(5, 1e300)
    img.GetPointData().SetScalars(huge)
    f = vtkIsobarVolumeSlider()
    f.SetInputData(img)
    f.SetIsovalue(0.5)
    f.Update()
    assert "array 'huge'" in f.GetErrorMessage() and "1e300, beyond the range of float32" in f.GetErrorMessage()
    # An isovalue outside the values: empty, and the filter says why.
    img.GetPointData().SetScalars(arr)
    f = vtkIsobarVolumeSlider()
    f.SetInputData(img)
    f.SetIsovalue(5.0)
    warned = Errors(f, "WarningEvent")
    f.Update()
    assert f.GetOutput().GetNumberOfCells() == 0 and f.GetErrorMessage() == ""
    assert len(warned.messages) == 1 and "no surface at isovalue 5: array 'blobs' ranges over" in warned.messages[0]
    # Memory Budget 0 is the core's default, as the panel says.
    f.SetMemoryBudget(0.0)
    f.SetIsovalue(0.5)
    arr.Modified()
    f.Update()
    assert f.GetErrorMessage() == "" and f.GetOutput().GetNumberOfCells() > 100


@test
def test_volume_slider_within_a_small_memory_budget_gives_the_same_surface():
    from isobar_vtk import vtkIsobarVolumeSlider

    # 48³ nodes: an in-memory pre-encoding needs about 3.2 MB; 2.5 MiB sorts on disk.
    img, _ = blobs_image(48)
    surfaces = []
    for budget in (4.0, 2.5 / 1024):
        f = vtkIsobarVolumeSlider()
        assert f.GetMemoryBudget() == 4.0
        f.SetMemoryBudget(budget)
        f.SetInputData(img)
        f.SetIsovalue(0.5)
        f.Update()
        assert f.GetErrorMessage() == "", f.GetErrorMessage()
        surfaces.append([np.array(a, copy=True) for a in h.arrays(f.GetOutput())])
        # A new budget does not rebuild the store it already built.
        f.SetMemoryBudget(1.0)
        f.SetIsovalue(0.45)
        f.Update()
        assert f.GetNumberOfStoreBuilds() == 1 and f.GetErrorMessage() == ""
    (p, t), (q, u) = surfaces
    assert len(t) > 1000 and np.array_equal(p, q) and np.array_equal(t, u)
    # Too small even for sorting on disk: the filter reports it, ParaView keeps running.
    f = vtkIsobarVolumeSlider()
    f.SetMemoryBudget(1e-6)
    f.SetInputData(img)
    f.SetIsovalue(0.5)
    f.Update()
    assert "memory budget" in f.GetErrorMessage(), f.GetErrorMessage()
    assert f.GetNumberOfStoreBuilds() == 0


@test
def test_volume_slider_level_of_detail_is_closed_on_the_surface_and_coarser():
    from isobar_vtk import vtkIsobarVolumeSlider
    from vtkmodules.vtkCommonDataModel import vtkPolyData

    n, iso = 48, 0.5
    img, arr = blobs_image(n)
    values = vtk_to_numpy(arr).reshape(n, n, n)
    value_range = float(values.max() - values.min())
    f = vtkIsobarVolumeSlider()
    f.SetInputData(img)
    f.SetIsovalue(iso)
    assert f.GetLodErrorBound() == 0.0 and f.GetLodMaxLevel() == 0
    f.Update()
    exact = vtkPolyData()
    exact.DeepCopy(f.GetOutput())
    exact_triangles = exact.GetNumberOfCells()
    assert exact_triangles > 1000 and h.open_edges(exact) == 0

    counts = []
    for bound in (0.01, 0.03, 0.1):
        f.SetLodErrorBound(bound)
        f.Update()
        assert f.GetErrorMessage() == "", f.GetErrorMessage()
        out = f.GetOutput()
        points, triangles = h.arrays(out)
        h.assert_closed_and_oriented(triangles, f"bound {bound}")
        assert h.open_edges(out) == 0, bound
        # Every vertex on the input's trilinear surface (numpy, not the core): within the
        # bound, and in fact to float rounding (the core puts LOD vertices on the surface).
        off = np.abs(h.trilinear(values, img.GetOrigin(), img.GetSpacing(), points) - iso)
        assert off.max() <= bound * value_range, (bound, off.max())
        assert off.max() <= 1e-5 * value_range, (bound, off.max())
        normals = vtk_to_numpy(out.GetPointData().GetNormals())
        assert len(normals) == len(points)
        assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-4), bound
        # Still the same blobs: coarser chords cut a little off the convex surface (5 %
        # at bound 0.1, under 1 % at 0.01), no more.
        assert abs(h.volume(out) - h.volume(exact)) <= max(0.01, bound) * h.volume(exact), bound
        counts.append(len(triangles))
        # A new level of detail neither rebuilds the store nor slides.
        assert f.GetNumberOfStoreBuilds() == 1 and f.GetNumberOfUpdates() == 1, bound
    assert exact_triangles > counts[0] > counts[1] > counts[2], (exact_triangles, counts)

    # Fewer merge levels, less merging.
    f.SetLodMaxLevel(1)
    f.Update()
    assert counts[2] < f.GetOutput().GetNumberOfCells() < exact_triangles
    f.SetLodMaxLevel(0)

    # Bound 0 is the exact surface again, triangle for triangle.
    f.SetLodErrorBound(0.0)
    f.Update()
    h.assert_same_surface(f.GetOutput(), exact, tol=0.0, what="bound 0")
    assert f.GetNumberOfUpdates() == 1

    # Sliding with a level of detail on: the level of detail of the new surface.
    f.SetLodErrorBound(0.03)
    f.SetIsovalue(0.3)
    f.Update()
    points, triangles = h.arrays(f.GetOutput())
    h.assert_closed_and_oriented(triangles, "after a slide")
    off = np.abs(h.trilinear(values, img.GetOrigin(), img.GetSpacing(), points) - 0.3)
    assert off.max() <= 1e-5 * value_range
    assert f.GetNumberOfStoreBuilds() == 1 and f.GetNumberOfUpdates() == 2

    # Bounds the core refuses: an error and an empty output, then a good one recovers.
    for bad in (-0.01, 1.5):
        f.SetLodErrorBound(bad)
        errors = Errors(f)
        f.Update()
        assert f.GetOutput().GetNumberOfCells() == 0, bad
        assert "bound" in f.GetErrorMessage().lower() and errors.messages, (bad, f.GetErrorMessage())
    f.SetLodErrorBound(0.03)
    f.SetLodMaxLevel(7)
    f.Update()
    assert f.GetOutput().GetNumberOfCells() == 0 and "levels" in f.GetErrorMessage(), f.GetErrorMessage()
    f.SetLodMaxLevel(0)
    f.Update()
    assert f.GetErrorMessage() == "" and f.GetOutput().GetNumberOfCells() == len(triangles)


@test
def test_volume_slider_without_scalars_reports_an_error():
    from isobar_vtk import vtkIsobarVolumeSlider
    from vtkmodules.vtkCommonDataModel import vtkImageData

    img = vtkImageData()
    img.SetDimensions(4, 4, 4)
    f = vtkIsobarVolumeSlider()
    f.SetInputData(img)
    errors = Errors(f)
    f.Update()
    assert f.GetOutput().GetNumberOfCells() == 0
    assert "no point scalars" in f.GetErrorMessage() and errors.messages


@test
def test_a_partitioned_dataset_is_one_fluid():
    """A vtkPartitionedDataSet is one dataset in pieces: its partitions' particles make
    one surface (the unsplit frame's), not a closed surface per partition with walls at
    the cuts. A partitioned dataset collection gives a surface per partitioned dataset;
    partitions whose arrays differ are refused, naming the array and the partition."""
    from vtkmodules.vtkCommonDataModel import vtkPartitionedDataSet, vtkPartitionedDataSetCollection, vtkPlane
    from vtkmodules.vtkFiltersPoints import vtkExtractPoints

    frame = reader(h.FRAME_26)
    whole = free_surface_filter(frame)
    whole.Update()
    halves = vtkPartitionedDataSet()
    for i, normal in enumerate(((1, 0, 0), (-1, 0, 0))):
        plane = vtkPlane()
        plane.SetNormal(*normal)
        cut = vtkExtractPoints()
        cut.SetImplicitFunction(plane)
        cut.SetInputConnection(frame.GetOutputPort())
        cut.Update()
        assert 1000 < cut.GetOutput().GetNumberOfPoints() < 4000
        halves.SetPartition(i, cut.GetOutput())
    f = vtkIsobarSPHIsosurface()
    f.SetInputData(halves)
    f.SetSmoothingLength(h.H)
    f.SetGridFactor(h.GRID_FACTOR)
    f.SetIsovalue(0, h.ISO)
    f.Update()
    assert f.GetErrorMessage() == "", f.GetErrorMessage()
    out = f.GetOutputDataObject(0)
    assert out.IsA("vtkPolyData") and h.open_edges(out) == 0
    assert out.GetNumberOfCells() == whole.GetOutput().GetNumberOfCells() > 1000
    # The same vertices, from particles summed in another order: each coordinate's
    # sorted values agree to rounding.
    p, _ = h.arrays(out)
    q, _ = h.arrays(whole.GetOutput())
    assert p.shape == q.shape
    assert np.abs(np.sort(p, axis=0) - np.sort(q, axis=0)).max() <= 1e-9

    collection = vtkPartitionedDataSetCollection()
    collection.SetPartitionedDataSet(0, halves)
    collection.SetPartitionedDataSet(1, halves)
    f.SetInputData(collection)
    f.Update()
    out = f.GetOutputDataObject(0)
    assert out.IsA("vtkPartitionedDataSetCollection")
    leaves = out.NewIterator()
    leaves.InitTraversal()
    cells = []
    while not leaves.IsDoneWithTraversal():
        cells.append(leaves.GetCurrentDataObject().GetNumberOfCells())
        leaves.GoToNextItem()
    assert cells == [whole.GetOutput().GetNumberOfCells()] * 2, cells

    one = halves.GetPartition(1)
    one.GetPointData().RemoveArray("velocity")
    f.GetCarriedArraySelection().EnableArray("velocity")
    f.SetInputData(halves)
    halves.Modified()
    f.Update()
    assert "partition 1: the input has no point array 'velocity'" in f.GetErrorMessage(), f.GetErrorMessage()
    # The same array with other components in another partition: refused, naming both.
    f.GetCarriedArraySelection().DisableArray("velocity")
    for i, components in enumerate((1, 3)):
        part = halves.GetPartition(i)
        extra = numpy_to_vtk(np.zeros((part.GetNumberOfPoints(), components)), deep=True)
        extra.SetName("extra")
        part.GetPointData().AddArray(extra)
    f.GetCarriedArraySelection().EnableArray("extra")
    halves.Modified()
    f.Update()
    assert (
        "point array 'extra' has 3 components in partition 1 but 1 component in the partitions before it"
        in f.GetErrorMessage()
    ), f.GetErrorMessage()


@test
def test_an_error_in_one_block_of_a_multi_block_input_names_the_block():
    """VTK's composite pipeline runs the filter once per block; an error in one block of
    many (a NaN coordinate here) must say which, and leave the other blocks' surfaces."""
    from vtkmodules.vtkCommonDataModel import vtkMultiBlockDataSet, vtkUnstructuredGrid

    good = reader(h.FRAME_26).GetOutput()
    bad = vtkUnstructuredGrid()
    bad.DeepCopy(good)
    bad.GetPoints().SetPoint(7, math.nan, 0.0, 0.0)
    blocks = vtkMultiBlockDataSet()
    for i, block in enumerate((good, bad, good)):
        blocks.SetBlock(i, block)
    f = vtkIsobarSPHIsosurface()
    f.SetInputData(blocks)
    f.SetSmoothingLength(h.H)
    f.SetGridFactor(h.GRID_FACTOR)
    f.SetIsovalue(0, h.ISO)
    errors = Errors(f)
    f.Update()
    assert len(errors.messages) == 1, errors.messages
    assert "block 2 of 3: " in errors.messages[0] and "NaN" in errors.messages[0], errors.messages
    out = f.GetOutputDataObject(0)
    cells = [out.GetBlock(i).GetNumberOfCells() for i in range(3)]
    assert cells[0] == cells[2] > 1000 and cells[1] == 0, cells
    # GetErrorMessage keeps the failing block's error although the last block succeeded
    # (each block's run cleared it before), and lists every failing block, a line each.
    message = f.GetErrorMessage()
    assert message.startswith("block 2 of 3: ") and "NaN" in message and "\n" not in message, message
    for i, block in enumerate((bad, good, bad)):
        blocks.SetBlock(i, block)
    blocks.Modified()
    f.Update()
    lines = f.GetErrorMessage().splitlines()
    assert [line[:14] for line in lines] == ["block 1 of 3: ", "block 3 of 3: "], lines
    assert all("NaN" in line for line in lines), lines
    f.SetInputData(good)
    f.Update()
    assert f.GetErrorMessage() == "" and f.GetOutput().GetNumberOfCells() > 1000
    # The same filter on the bad block alone: no block to name.
    f.SetInputData(bad)
    f.Update()
    assert "NaN" in f.GetErrorMessage() and "block" not in f.GetErrorMessage(), f.GetErrorMessage()


@test
def test_settings_out_of_range_are_refused_naming_them_not_clamped():
    """VTK's clamping setters turned a negative Max Error into 0 (the error criterion off)
    and a negative Smoothing Length beside an h array into 0 (the array used), running
    without a word; each bad value is now an error naming the setting, output empty."""
    from isobar_vtk import vtkIsobarVolumeSlider

    r = reader(h.FRAME_26)
    cases = (
        ("SmoothingLength", -0.02, "Smoothing Length must be >= 0"),
        ("HScale", 0.0, "H Scale must be > 0, got 0"),
        ("Mass", -1.0, "Mass must be >= 0 (0: none)"),
        ("GridFactor", -0.5, "Grid Factor must be > 0"),
        ("SplashThreshold", -3, "Splash Threshold must be >= 0"),
        ("MaxError", -1.0, "Max Error must be >= 0 (0: no error criterion), got -1"),
        ("BisectionIterations", 17, "Bisection Iterations must lie in [0, 16], got 17"),
        ("Tolerance", -1.0, "Tolerance must lie in (0, 1), got -1"),
        ("Tolerance", 1.0, "Tolerance must lie in (0, 1), got 1"),
        ("TrimNode", -0.1, "Trim Node must be >= 0"),
        ("TrimVertex", float("inf"), "Trim Vertex must be >= 0"),
        ("MemoryBudget", 0.0, "Memory Budget must be > 0"),
        ("LatticeCellSize", -1.0, "Lattice Cell Size must be >= 0"),
        ("FieldComponent", -2, "Field Component must be >= -1"),
    )
    for setting, value, expected in cases:
        f = free_surface_filter(r, **{setting: value})
        errors = Errors(f)
        f.Update()
        assert f.GetOutput().GetNumberOfCells() == 0, setting
        assert expected in f.GetErrorMessage(), (setting, f.GetErrorMessage())
        assert len(errors.messages) == 1, errors.messages
    # The same filter, the value put right: it runs again.
    f.SetFieldComponent(-1)
    f.Update()
    assert f.GetErrorMessage() == "" and f.GetOutput().GetNumberOfCells() > 100000
    img, _arr = blobs_image()
    s = vtkIsobarVolumeSlider()
    s.SetInputData(img)
    s.SetIsovalue(0.5)
    for setting, value, expected in (("LodErrorBound", -0.1, "Lod Error Bound must be >= 0"),
                                     ("LodMaxLevel", -1, "Lod Max Level must be >= 0"),
                                     ("MemoryBudget", -1.0, "Memory Budget must be >= 0 (GiB, 0: the core's default)")):
        getattr(s, "Set" + setting)(value)
        errors = Errors(s)
        s.Update()
        assert s.GetOutput().GetNumberOfCells() == 0 and expected in s.GetErrorMessage(), (
            setting, s.GetErrorMessage())
        getattr(s, "Set" + setting)({"LodErrorBound": 0.0, "LodMaxLevel": 0, "MemoryBudget": 4.0}[setting])
    s.Update()
    assert s.GetErrorMessage() == "" and s.GetOutput().GetNumberOfCells() > 1000


@test
def test_volume_slider_refuses_a_cell_array_and_a_vector_naming_them():
    """The core reads one value a point: a cell array (39³ values for 40³ points) used to
    be read past its end into a wrong surface, a vector as its first components."""
    from isobar_vtk import vtkIsobarVolumeSlider
    from vtkmodules.vtkCommonDataModel import vtkImageData

    img = vtkImageData()
    img.SetDimensions(10, 10, 10)
    cells = numpy_to_vtk(np.linspace(0.0, 1.0, 9 ** 3), deep=True)
    cells.SetName("c")
    img.GetCellData().AddArray(cells)
    vectors = numpy_to_vtk(np.random.default_rng(1).random((1000, 3)), deep=True)
    vectors.SetName("v")
    img.GetPointData().AddArray(vectors)
    f = vtkIsobarVolumeSlider()
    f.SetInputData(img)
    f.SetIsovalue(0.5)
    errors = Errors(f)
    for association, name, expected in (
            (vtkDataObject.FIELD_ASSOCIATION_CELLS, "c", "array 'c' is not point data (729 values for 1000 points)"),
            (vtkDataObject.FIELD_ASSOCIATION_POINTS, "v", "array 'v' has 3 components")):
        f.SetInputArrayToProcess(0, 0, 0, association, name)
        f.Update()
        assert f.GetOutput().GetNumberOfCells() == 0, name
        assert expected in f.GetErrorMessage(), f.GetErrorMessage()
    assert len(errors.messages) == 2, errors.messages


@test
def test_volume_slider_places_the_surface_in_the_images_own_coordinates():
    from isobar_vtk import vtkIsobarVolumeSlider
    from vtkmodules.vtkFiltersCore import vtkFlyingEdges3D

    img, _arr = blobs_image()
    f = vtkIsobarVolumeSlider()
    f.SetInputData(img)
    f.SetIsovalue(0.5)
    f.Update()
    at_zero = h.arrays(f.GetOutput())[0]
    # The same image with an extent that starts at (-3, 5, 2): every point moves by that
    # many spacings, and so must the surface (as VTK's own contour's does).
    img.SetExtent(-3, 20, 5, 28, 2, 25)
    img.Modified()
    f.Update()
    moved = h.arrays(f.GetOutput())[0]
    fe = vtkFlyingEdges3D()
    fe.SetInputData(img)
    fe.SetValue(0, 0.5)
    fe.Update()
    q = h.arrays(fe.GetOutput())[0]
    shift = np.array([-3, 5, 2]) * 0.5
    assert np.abs(moved.min(axis=0) - (at_zero.min(axis=0) + shift)).max() <= 1e-5
    assert nearest_distances(moved, q).max() <= 1e-5 and nearest_distances(q, moved).max() <= 1e-5
    # A rotated image is refused, not contoured in the wrong place.
    img.SetDirectionMatrix(0, -1, 0, 1, 0, 0, 0, 0, 1)
    img.Modified()
    f.Update()
    assert f.GetOutput().GetNumberOfCells() == 0 and "direction matrix" in f.GetErrorMessage()


@test
def test_vector_magnitude_component_and_carried_arrays_match_cli():
    r = reader(h.FRAME_26)
    speed = np.linalg.norm(h.point_array(r.GetOutput(), "velocity"), axis=1)
    iso = float(np.percentile(speed, 60))
    for component, field in ((-1, "velocity:mag"), (1, "velocity:1")):
        f = free_surface_filter(r, FieldMode=vtkIsobarSPHIsosurface.POINT_ARRAY,
                                FieldComponent=component)
        iso_c = iso if component < 0 else 0.2
        f.SetIsovalue(0, iso_c)
        f.SetInputArrayToProcess(0, 0, 0, vtkDataObject.FIELD_ASSOCIATION_POINTS, "velocity")
        f.GetCarriedArraySelection().EnableArray("velocity")
        f.GetCarriedArraySelection().EnableArray("id")
        f.Update()
        out = f.GetOutput()
        assert f.GetErrorMessage() == "", f.GetErrorMessage()
        assert f.FieldString("velocity", 3) == field
        ref = h.read_vtp(h.cli_surface(
            h.FRAME_26, os.path.join(TMP, "ref_vel.vtp"), "--field", field, "--iso", iso_c,
            "--h", h.H, "--grid-factor", h.GRID_FACTOR, "--attributes", "velocity,id"))
        n = h.assert_same_surface(out, ref, 1e-12, field)
        assert n > 100, f"{field}: only {n} triangles"
        for name, comps in (("velocity", 3), ("id", 1)):
            a = out.GetPointData().GetArray(name)
            assert a is not None and a.GetNumberOfComponents() == comps, name
            d = np.max(np.abs(h.sorted_rows(h.point_array(out, name))
                              - h.sorted_rows(h.point_array(ref, name))))
            assert d <= 1e-9 * max(1.0, float(np.max(np.abs(h.point_array(ref, name))))), (name, d)


@test
def test_several_isovalues_give_isovalue_array():
    f = free_surface_filter(reader(h.FRAME_26))
    f.SetNumberOfIsovalues(2)
    f.SetIsovalue(0, 0.4)
    f.SetIsovalue(1, 0.6)
    f.Update()
    iso = h.point_array(f.GetOutput(), "Isovalue")
    assert set(np.unique(iso)) == {0.4, 0.6}, np.unique(iso)
    one = free_surface_filter(reader(h.FRAME_26))
    one.Update()
    assert f.GetOutput().GetNumberOfCells() > one.GetOutput().GetNumberOfCells()


@test
def test_polydata_input_and_ghost_points_are_skipped():
    r = reader(h.FRAME_26)
    ug = r.GetOutput()
    base = free_surface_filter(r)
    base.Update()
    # The same particles as vtkPolyData, plus copies of the first 500 marked as ghosts.
    pts = vtk_to_numpy(ug.GetPoints().GetData()).astype(np.float64)
    both = np.vstack([pts, pts[:500]])
    pd = vtkPolyData()
    p = vtkPoints()
    p.SetData(numpy_to_vtk(both, deep=True))
    pd.SetPoints(p)
    ghosts = np.zeros(len(both), dtype=np.uint8)
    ghosts[len(pts):] = vtkDataSetAttributes.DUPLICATEPOINT
    g = numpy_to_vtk(ghosts, deep=True, array_type=vtkUnsignedCharArray().GetDataType())
    g.SetName(vtkDataSetAttributes.GhostArrayName())
    pd.GetPointData().AddArray(g)
    f = vtkIsobarSPHIsosurface()
    f.SetInputData(pd)
    f.SetSmoothingLength(h.H)
    f.SetGridFactor(h.GRID_FACTOR)
    f.Update()
    h.assert_same_surface(f.GetOutput(), base.GetOutput(), 1e-12, "ghosted polydata")


def expect_error(f, fragment):
    errors = Errors(f)
    f.Update()
    out = f.GetOutput()
    assert out.GetNumberOfPoints() == 0 and out.GetNumberOfCells() == 0, "output not empty"
    msg = f.GetErrorMessage()
    assert fragment in msg, f"message {msg!r} lacks {fragment!r}"
    assert errors.messages and fragment in errors.messages[-1], errors.messages
    return msg


@test
def test_bad_inputs_give_error_and_empty_output():
    r = reader(h.FRAME_26)
    # A missing field array.
    f = free_surface_filter(r, FieldMode=vtkIsobarSPHIsosurface.POINT_ARRAY)
    f.SetInputArrayToProcess(0, 0, 0, vtkDataObject.FIELD_ASSOCIATION_POINTS, "pressure")
    expect_error(f, "'pressure'")
    # A missing carried array.
    f = free_surface_filter(r)
    f.GetCarriedArraySelection().EnableArray("nope")
    expect_error(f, "'nope'")
    # No smoothing length at all.
    f = free_surface_filter(r, SmoothingLength=0.0)
    expect_error(f, "smoothing length")
    # NaN positions.
    pd = vtkPolyData()
    pts = vtkPoints()
    pts.SetDataTypeToDouble()
    for p in ((0.0, 0.0, 0.0), (0.01, 0.0, 0.0), (math.nan, 0.0, 0.0), (0.0, 0.02, 0.0)):
        pts.InsertNextPoint(p)
    pd.SetPoints(pts)
    f = vtkIsobarSPHIsosurface()
    f.SetInputData(pd)
    f.SetSmoothingLength(h.H)
    msg = expect_error(f, "isobar_sph_extract")
    assert "nan" in msg.lower() or "finite" in msg.lower(), msg
    # A component that does not exist.
    f = free_surface_filter(r, FieldMode=vtkIsobarSPHIsosurface.POINT_ARRAY, FieldComponent=7)
    f.SetInputArrayToProcess(0, 0, 0, vtkDataObject.FIELD_ASSOCIATION_POINTS, "velocity")
    expect_error(f, "Field Component 7")
    # Settings outside their range are refused by the filter, naming them.
    f = free_surface_filter(r, Tolerance=0.0)
    expect_error(f, "Tolerance must lie in (0, 1), got 0")
    # And a good run afterwards still works.
    f.SetTolerance(1e-6)
    f.Update()
    assert f.GetOutput().GetNumberOfCells() > 1000 and f.GetErrorMessage() == ""


@test
def test_empty_input_gives_empty_output_without_error():
    """An emitter before its first particle: empty, not an error, but said."""
    f = vtkIsobarSPHIsosurface()
    f.SetInputData(vtkPolyData())
    f.SetSmoothingLength(h.H)
    errors = Errors(f)
    warned = Errors(f, "WarningEvent")
    f.Update()
    assert f.GetOutput().GetNumberOfPoints() == 0 and not errors.messages
    assert len(warned.messages) == 1 and "no particles: empty output" in warned.messages[0], warned.messages


@test
def test_adaptive_carries_arrays_as_the_cli_and_says_what_it_ignores():
    """Carried Arrays reach the adaptive surface as `isobar adaptive --attributes` puts
    them; Full Grid belongs to Marching Correctors, and doing nothing is said."""
    import subprocess

    f = free_surface_filter(reader(h.FRAME_26), Method=vtkIsobarSPHIsosurface.ADAPTIVE)
    warned = Errors(f, "WarningEvent")
    f.GetCarriedArraySelection().EnableArray("velocity")
    f.Update()
    assert not [m for m in warned.messages if "ignore" in m], warned.messages
    out = f.GetOutput()
    ref_path = os.path.join(TMP, "adaptive_velocity.vtp")
    subprocess.run([h.CLI, "adaptive", h.FRAME_26, "--quiet", "-o", ref_path, "--iso", str(h.ISO),
                    "--h", str(h.H), "--grid-factor", str(h.GRID_FACTOR), "--attributes", "velocity"],
                   check=True, capture_output=True)
    ref = h.read_vtp(ref_path)
    h.assert_same_surface(out, ref, 1e-12, "adaptive")
    h.assert_same_point_data(out, ref, ["velocity"], 1e-9, "adaptive velocity")
    velocity = vtk_to_numpy(out.GetPointData().GetArray("velocity"))
    assert velocity.shape == (out.GetNumberOfPoints(), 3) and np.abs(velocity).max() > 0.1
    f.SetFullGrid(True)
    f.Update()
    said = [m for m in warned.messages if "ignore" in m]
    assert len(said) == 1 and "Full Grid applies to 'Marching Correctors'" in said[0], warned.messages
    assert f.GetErrorMessage() == "" and f.GetOutput().GetNumberOfCells() > 1000


@test
def test_progress_and_abort():
    f = free_surface_filter(reader(h.FRAME_26))
    seen = []
    f.AddObserver(vtkCommand.ProgressEvent, lambda o, e: seen.append(o.GetProgress()))
    f.Update()
    assert len(seen) >= 5 and seen[-1] == 1.0, seen
    assert all(b >= a for a, b in zip(seen, seen[1:], strict=False)), "progress went backwards"

    g = free_surface_filter(reader(h.FRAME_26), GridFactor=0.2)
    calls = []
    aborted_at = []

    def abort(o, e):
        calls.append(o.GetProgress())
        if o.GetProgress() > 0.0 and not aborted_at:
            aborted_at.append(len(calls))
            o.SetAbortExecute(1)

    g.AddObserver(vtkCommand.ProgressEvent, abort)
    g.Update()
    assert aborted_at, "no progress reported"
    assert g.GetOutput().GetNumberOfCells() == 0, "aborted run has output"
    assert g.GetErrorMessage() == "cancelled", g.GetErrorMessage()
    assert len(calls) == aborted_at[0], f"progress went on after the abort: {calls}"
    # The next update runs again, whole.
    g.SetAbortExecute(0)
    g.Modified()
    g.RemoveAllObservers()
    g.Update()
    assert g.GetOutput().GetNumberOfCells() > 1000


@test
def test_defaults_come_from_the_core_and_match_the_xml():
    _, props = h.xml_properties()
    f = vtkIsobarSPHIsosurface()
    checked = 0
    for name, (tag, attrs, _el) in props.items():
        if attrs.get("information_only") == "1" or "default_values" not in attrs:
            continue
        command = attrs["command"]
        if tag == "StringVectorProperty":
            getter = getattr(f, "Get" + command[3:])
            assert (getter() or "") == attrs["default_values"], (name, getter())
        elif name == "Isovalues":
            assert [f.GetIsovalue(i) for i in range(f.GetNumberOfIsovalues())] == [
                float(x) for x in attrs["default_values"].split()]
        elif int(attrs.get("number_of_elements", "1")) > 1:
            value = list(getattr(f, "Get" + command[3:])())
            assert value == [float(x) for x in attrs["default_values"].split()], (
                name, value, attrs["default_values"])
        else:
            value = getattr(f, "Get" + command[3:])()
            assert math.isclose(float(value), float(attrs["default_values"]), rel_tol=1e-12), (
                name, value, attrs["default_values"])
        checked += 1
    assert checked >= 18, checked
    # Every setter the XML names exists on the class.
    for name, (_tag, attrs, _el) in props.items():
        assert hasattr(f, attrs["command"]), (name, attrs["command"])


@test
def test_fixed_lattice_matches_cli_lattice():
    ref = h.read_vtp(h.cli_surface(
        h.FRAME_26, os.path.join(TMP, "ref_lattice.vtp"), "--iso", h.ISO, "--h", h.H,
        "--lattice", ",".join(str(v) for v in (*h.LATTICE_ORIGIN, h.LATTICE_CELL))))
    f = free_surface_filter(reader(h.FRAME_26), FixedLattice=1,
                            LatticeOrigin=h.LATTICE_ORIGIN, LatticeCellSize=h.LATTICE_CELL)
    f.Update()
    assert f.GetErrorMessage() == "", f.GetErrorMessage()
    assert f.GetPieceAxis() == -1, "a single process cuts nothing"
    n = h.assert_same_surface(f.GetOutput(), ref, 1e-12, "Fixed Lattice vs CLI --lattice")
    assert h.open_edges(f.GetOutput()) == 0
    # Cell size 0: Grid Factor x the smallest h, on the same origin. 0.375 * 0.05 is
    # 0.018750000000000003, one ulp off 0.01875: a lattice equal only to rounding, where a
    # vertex's Newton steps may end at another point within the correction tolerance, so
    # the vertices agree to 1e-9 (cells are 0.019), not to the last bits.
    g = free_surface_filter(reader(h.FRAME_26), FixedLattice=1, LatticeOrigin=h.LATTICE_ORIGIN)
    g.Update()
    h.assert_same_surface(g.GetOutput(), f.GetOutput(), 1e-9, "cell size 0 = 0.375 x 0.05")
    # A lattice whose origin is the data's own first grid node reproduces the default.
    r = reader(h.FRAME_26)
    pts = vtk_to_numpy(r.GetOutput().GetPoints().GetData()).astype(np.float64)
    cell = h.GRID_FACTOR * h.H
    origin = pts.min(axis=0) - (2.0 * h.H + cell)
    d = free_surface_filter(r)
    d.Update()
    k = free_surface_filter(r, FixedLattice=1, LatticeOrigin=tuple(origin), LatticeCellSize=cell)
    k.Update()
    h.assert_same_surface(k.GetOutput(), d.GetOutput(), 1e-12, "lattice of the data's own grid")
    assert n != d.GetOutput().GetNumberOfCells()
    # A bad cell size is an error, not a hang or a crash.
    bad = free_surface_filter(reader(h.FRAME_26), FixedLattice=1, GridFactor=0.0)
    expect_error(bad, "Grid Factor must be > 0, got 0")
    # A cell size the core cannot use (overflowing the lattice) comes through as its error.
    bad = free_surface_filter(reader(h.FRAME_26), FixedLattice=1, LatticeCellSize=1e-300)
    expect_error(bad, "lattice")


@test
def test_time_steps_pass_through():
    """The filter adds no time logic: a temporal source's TIME_STEPS reach its output
    and the requested time goes upstream (ParaView's file series rely on this)."""
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline as sddp
    from vtkmodules.vtkFiltersGeneral import vtkTimeSourceExample

    src = vtkTimeSourceExample()
    src.SetXAmplitude(0.0)
    src.SetYAmplitude(0.0)
    f = vtkIsobarSPHIsosurface()
    f.SetInputConnection(src.GetOutputPort())
    f.SetSmoothingLength(0.5)
    f.UpdateInformation()
    info = f.GetOutputInformation(0)
    steps = info.Get(sddp.TIME_STEPS())
    assert steps is not None and len(steps) == 10, steps
    f.UpdateTimeStep(steps[3])
    assert src.GetOutputInformation(0).Get(sddp.UPDATE_TIME_STEP()) == steps[3]
    assert f.GetOutput().GetInformation().Get(vtkDataObject.DATA_TIME_STEP()) == steps[3]


if __name__ == "__main__":
    sys.exit(1 if h.run_all(sys.argv[1:]) else 0)
