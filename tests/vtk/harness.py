"""A small test harness shared by the VTK and ParaView tests.

The tests run under Debian's /usr/bin/python3 (Debian VTK 9.1) and under pvbatch
(ParaView's own VTK 9.2), neither of which has pytest; both have numpy. Each test
prints `PASS name` or `FAIL name: why`; tests/vtk/run.sh counts those lines.
Only `vtkmodules` APIs common to VTK 9.1 and 9.2 are used here.
"""

import os
import subprocess
import sys
import tempfile
import traceback

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.abspath(os.path.join(HERE, "..", ".."))
DATA = os.environ.get(
    "ISOBAR_DATA", os.path.abspath(os.path.join(REPO, "..", "shared", "data", "splashsurf"))
)
CLI = os.path.join(REPO, "target", "release", "isobar")
PLUGIN = os.path.join(
    REPO, "vtk-plugin", "build-pv", "lib", "paraview-5.11", "plugins", "IsobarSPH", "IsobarSPH.so"
)
XML = os.path.join(REPO, "vtk-plugin", "paraview", "IsobarSPHIsosurface.xml")
FRAME_01 = os.path.join(DATA, "double_dam_break_frame_01_4732_particles.vtk")
FRAME_26 = os.path.join(DATA, "double_dam_break_frame_26_4732_particles.vtk")
# A real MFEM solution (Poisson, Q3 hexahedra) as VTK Lagrange cells, point array "u".
FE_MFEM = os.path.join(REPO, "rust-core", "data", "fe", "mfem_poisson_q3.vtu")
BUNNY = os.path.join(DATA, "bunny_frame_14_7705_particles.vtk")

# splashsurf's settings for these frames: r = 0.025, h = 2r, cube 0.75r, iso 0.6.
H = 0.05
GRID_FACTOR = 0.375
ISO = 0.6
# A lattice off the data's own grid (Fixed Lattice / the CLI's --lattice).
LATTICE_ORIGIN = (-0.013, 0.002, 0.007)
LATTICE_CELL = 0.01875

_tests = []


def test(fn):
    """Registers a test function."""
    _tests.append(fn)
    return fn


def run_all(only=None):
    """Runs the registered tests; returns the number of failures."""
    failed = 0
    for fn in _tests:
        if only and fn.__name__ not in only:
            continue
        try:
            fn()
        except Exception as e:  # noqa: BLE001 - every failure is reported, none stops the run
            failed += 1
            detail = "".join(traceback.format_exception_only(type(e), e)).strip()
            print(f"FAIL {fn.__name__}: {detail}", flush=True)
            traceback.print_exc(file=sys.stderr)
        else:
            print(f"PASS {fn.__name__}", flush=True)
    return failed


class Errors:
    """Collects the ErrorEvent messages of a VTK object (WarningEvent with `event`)."""

    def __init__(self, obj, event="ErrorEvent"):
        from vtkmodules.util.vtkConstants import VTK_STRING
        from vtkmodules.vtkCommonCore import vtkCommand

        self.messages = []

        def on_event(o, e, data):
            self.messages.append(data)

        on_event.CallDataType = VTK_STRING
        obj.AddObserver(getattr(vtkCommand, event), on_event)


def core_auto_note():
    """The C ABI's isobar_auto_backend_note() from the workspace's libisobar.so (the
    build the plugin links statically): "" when Auto runs on a GPU here."""
    import ctypes

    lib = ctypes.CDLL(os.path.join(REPO, "target", "release", "libisobar.so"))
    lib.isobar_auto_backend_note.restype = ctypes.c_int
    lib.isobar_auto_backend_note.argtypes = [ctypes.POINTER(ctypes.c_char_p)]
    note = ctypes.c_char_p()
    assert lib.isobar_auto_backend_note(ctypes.byref(note)) == 0
    return note.value.decode()


def tmpdir():
    d = os.environ.get("ISOBAR_TEST_TMP")
    if d:
        os.makedirs(d, exist_ok=True)
        return d
    return tempfile.mkdtemp(prefix="isobar-vtk-")


def cli_surface(particles, out, *args):
    """Runs the isobar CLI (the reference) and returns the output path."""
    cmd = [CLI, "sph", particles, "--quiet", "-o", out, *map(str, args)]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    return out


def read_vtp(path):
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    r = vtkXMLPolyDataReader()
    r.SetFileName(path)
    r.Update()
    return r.GetOutput()


def arrays(pd):
    """Points (n, 3) and triangles (m, 3) of a triangle vtkPolyData as numpy arrays."""
    from vtkmodules.util.numpy_support import vtk_to_numpy

    n = pd.GetNumberOfPoints()
    pts = vtk_to_numpy(pd.GetPoints().GetData()).reshape(-1, 3) if n else np.zeros((0, 3))
    polys = pd.GetPolys()
    if polys is None or polys.GetNumberOfCells() == 0:
        return pts, np.zeros((0, 3), dtype=np.int64)
    conn = vtk_to_numpy(polys.GetConnectivityArray()).astype(np.int64)
    offs = vtk_to_numpy(polys.GetOffsetsArray()).astype(np.int64)
    assert np.all(np.diff(offs) == 3), "not all cells are triangles"
    return pts, conn.reshape(-1, 3)


def point_array(pd, name):
    from vtkmodules.util.numpy_support import vtk_to_numpy

    a = pd.GetPointData().GetArray(name)
    assert a is not None, f"no point array {name!r}"
    return vtk_to_numpy(a)


def sorted_rows(a, quantum=0.0):
    """Rows of `a` in lexicographic order. With quantum > 0 the order is that of the rows
    rounded to multiples of `quantum`, so that values equal but for rounding noise (a
    vertex made on two ranks) sort alike; the rows themselves are returned unrounded."""
    a = np.asarray(a, dtype=np.float64).reshape(len(a), -1)
    if len(a) == 0:
        return a
    keys = np.round(a / quantum) if quantum > 0 else a
    return a[np.lexsort(keys.T[::-1])]


def canonical_triangles(pts, tris, quantum=0.0):
    """Each triangle as its three vertex positions in sorted order (9 numbers), rows
    sorted: independent of vertex numbering and triangle order."""
    if len(tris) == 0:
        return np.zeros((0, 9))
    corners = pts[tris].reshape(-1, 3)  # (3m, 3)
    tri_id = np.repeat(np.arange(len(tris)), 3)
    order = np.lexsort((corners[:, 2], corners[:, 1], corners[:, 0], tri_id))
    out = corners[order].reshape(-1, 9)
    return sorted_rows(out, quantum)


def assert_same_surface(a, b, tol=1e-9, what="surface"):
    """Same triangle count, same vertex set and same triangles (after sorting) within
    `tol` (absolute, on coordinates of order 1)."""
    pa, ta = arrays(a)
    pb, tb = arrays(b)
    assert len(ta) == len(tb), f"{what}: {len(ta)} vs {len(tb)} triangles"
    assert len(pa) == len(pb), f"{what}: {len(pa)} vs {len(pb)} vertices"
    q = 10.0 * tol
    dv = np.max(np.abs(sorted_rows(pa, q) - sorted_rows(pb, q))) if len(pa) else 0.0
    assert dv <= tol, f"{what}: vertex sets differ by {dv:.3e}"
    dt = (np.max(np.abs(canonical_triangles(pa, ta, q) - canonical_triangles(pb, tb, q)))
          if len(ta) else 0.0)
    assert dt <= tol, f"{what}: triangles differ by {dt:.3e}"
    return len(ta)


def duplicate_triangles(pd):
    pts, tris = arrays(pd)
    c = canonical_triangles(pts, tris)
    if len(c) < 2:
        return 0
    return int(np.sum(np.all(np.abs(np.diff(c, axis=0)) <= 1e-12, axis=1)))


def assert_same_point_data(a, b, names, tol=1e-9, what="surface"):
    """Each vertex of `a` has a vertex of `b` within `tol` whose arrays `names` agree
    within `tol` relative to each array's largest magnitude (any vertex order)."""
    from vtkmodules.vtkCommonDataModel import vtkStaticPointLocator

    pa, pb = arrays(a)[0], arrays(b)[0]
    assert len(pa) == len(pb), f"{what}: {len(pa)} vs {len(pb)} vertices"
    loc = vtkStaticPointLocator()
    loc.SetDataSet(b)
    loc.BuildLocator()
    match = np.array([loc.FindClosestPoint(p) for p in pa], dtype=np.int64)
    d = np.max(np.abs(pa - pb[match])) if len(pa) else 0.0
    assert d <= tol, f"{what}: vertices {d:.3e} apart"
    assert len(np.unique(match)) == len(pb), f"{what}: vertices matched twice"
    for name in names:
        va = np.asarray(point_array(a, name), dtype=np.float64).reshape(len(pa), -1)
        vb = np.asarray(point_array(b, name), dtype=np.float64).reshape(len(pb), -1)[match]
        scale = max(1.0, float(np.max(np.abs(vb)))) if len(vb) else 1.0
        dv = np.max(np.abs(va - vb)) if len(va) else 0.0
        assert dv <= tol * scale, f"{what}: {name} differs by {dv:.3e}"


def volume(pd):
    from vtkmodules.vtkFiltersCore import vtkMassProperties

    m = vtkMassProperties()
    m.SetInputData(pd)
    m.Update()
    return m.GetVolume()


def open_edges(pd):
    """Boundary plus non-manifold edges (0 for a watertight manifold)."""
    from vtkmodules.vtkFiltersCore import vtkFeatureEdges

    f = vtkFeatureEdges()
    f.SetInputData(pd)
    f.BoundaryEdgesOn()
    f.NonManifoldEdgesOn()
    f.FeatureEdgesOff()
    f.ManifoldEdgesOff()
    f.Update()
    return f.GetOutput().GetNumberOfCells()


def xml_properties():
    """The plugin's XML properties: {name: (element, attributes)}."""
    import xml.etree.ElementTree as ET

    root = ET.parse(XML).getroot()
    proxy = root.find("ProxyGroup/SourceProxy")
    out = {}
    for el in proxy:
        if el.tag.endswith("Property") and el.tag != "InputProperty":
            out[el.get("name")] = (el.tag, dict(el.attrib), el)
    return proxy, out


def trilinear(values, origin, spacing, points):
    """The trilinear interpolant of a volume at `points` (n, 3), evaluated here with numpy
    (independent of the core): `values` is indexed [z, y, x] (VTK's point order, x
    fastest), `origin` and `spacing` are the image's."""
    v = np.asarray(values, dtype=np.float64)
    nz, ny, nx = v.shape
    g = (np.asarray(points, dtype=np.float64) - np.asarray(origin)) / np.asarray(spacing)
    hi = np.array([nx - 2, ny - 2, nz - 2])
    i0 = np.clip(np.floor(g).astype(np.int64), 0, hi)
    t = g - i0
    assert np.all((t > -1e-6) & (t < 1 + 1e-6)), "a point lies outside the volume"
    out = np.zeros(len(g))
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                w = ((t[:, 0] if dx else 1 - t[:, 0]) * (t[:, 1] if dy else 1 - t[:, 1])
                     * (t[:, 2] if dz else 1 - t[:, 2]))
                out += w * v[i0[:, 2] + dz, i0[:, 1] + dy, i0[:, 0] + dx]
    return out


def assert_closed_and_oriented(tris, what="surface"):
    """Every edge is shared by exactly two triangles, traversed once each way (a closed,
    consistently oriented triangle surface), and no triangle repeats a vertex."""
    t = np.asarray(tris, dtype=np.int64)
    assert len(t), f"{what}: no triangles"
    assert np.all((t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 2] != t[:, 0])), (
        f"{what}: degenerate triangle")
    directed = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    _, dcount = np.unique(directed, axis=0, return_counts=True)
    assert dcount.max() == 1, f"{what}: a directed edge is used twice (orientation flips)"
    undirected = np.sort(directed, axis=1)
    _, ucount = np.unique(undirected, axis=0, return_counts=True)
    bad = int(np.sum(ucount != 2))
    assert bad == 0, f"{what}: {bad} edges not in exactly two triangles"
