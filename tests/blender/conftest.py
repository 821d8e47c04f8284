"""Fixtures of the Blender add-on tests: bpy (PyPI, headless), the packaged extension
installed the way a user installs it, and small particle sequences made from the
SPlisHSPlasH double dam break frames in shared/data.

Run them with tests/blender/run.sh (venv, bpy==5.0.1, build.sh, pytest).
"""

import os
import shutil
import sys
import tempfile
from pathlib import Path

# Blender's user folders (extensions, config) go to a temporary folder, not ~/.config;
# this must be set before bpy is imported.
_USER = tempfile.mkdtemp(prefix="isobar-blender-user-")
os.environ["BLENDER_USER_RESOURCES"] = _USER
os.environ.pop("ISOBAR_LIBRARY", None)  # use the library inside the installed extension

import bpy  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
DATA = Path(os.environ.get("ISOBAR_TEST_DATA", REPO.parent / "shared" / "data")) / "splashsurf"
FRAME_01 = DATA / "double_dam_break_frame_01_4732_particles.vtk"
FRAME_26 = DATA / "double_dam_break_frame_26_4732_particles.vtk"
ZIP = Path(os.environ.get("ISOBAR_BLENDER_ZIP", REPO / "target" / "blender" / "isobar_fluid-0.1.0.zip"))

EXTENSION_ID = "isobar_fluid"
MODULE = f"bl_ext.user_default.{EXTENSION_ID}"

#: The parameters of the issue's demo: particle radius 0.025, h = 0.05, free surface
#: (SumOfWeights) at 0.6, grid factor 0.375.
H = 0.05
ISO = 0.6
GRID_FACTOR = 0.375


def pytest_report_header(config):
    return f"bpy {bpy.app.version_string}, numpy {np.__version__}, extension zip {ZIP}, user resources {_USER}"


@pytest.fixture(scope="session")
def addon():
    """Installs and enables the packaged extension (zip) as a user does; returns the
    add-on's package module."""
    if not ZIP.is_file():
        pytest.fail(f"extension zip not found: {ZIP} (run blender-addon/build.sh)")
    for path in (FRAME_01, FRAME_26):
        if not path.is_file():
            pytest.skip(f"test data not found: {path}")
    bpy.ops.wm.read_homefile(use_empty=True)
    result = bpy.ops.extensions.package_install_files(filepath=str(ZIP), repo="user_default", enable_on_install=True)
    assert result == {"FINISHED"}
    assert MODULE in bpy.context.preferences.addons, "the extension is installed but not enabled"
    yield sys.modules[MODULE]
    shutil.rmtree(_USER, ignore_errors=True)


@pytest.fixture(scope="session")
def isobar(addon):
    """The isobar package the extension bundles (its wheel, installed by Blender)."""
    import isobar as module

    return module


@pytest.fixture
def scene(addon):
    """An empty scene (the add-on stays enabled)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    return bpy.context.scene


@pytest.fixture(scope="session")
def pxr(addon):
    """USD's Python module for reading exports: the copy bpy ships (in its own Python's
    site-packages, which the PyPI bpy module leaves off sys.path), else usd-core (run.sh
    installs it when bpy ships none)."""
    version = f"python{sys.version_info.major}.{sys.version_info.minor}"
    local = bpy.utils.resource_path("LOCAL")
    for folder in (
        os.path.join(local, "python", "lib", version, "site-packages"),  # Linux, macOS
        os.path.join(local, "python", "lib", "site-packages"),  # Windows
    ):
        if os.path.isdir(os.path.join(folder, "pxr")) and folder not in sys.path:
            sys.path.append(folder)
    module = pytest.importorskip("pxr", reason="no USD Python module (bpy ships none and usd-core is not installed)")
    from pxr import Usd  # noqa: F401

    return module


def make_sequence(folder: Path, sources, pattern="frame_{:04d}.vtk", start=1):
    """Copies `sources` to folder/frame_0001.vtk, frame_0002.vtk, ...; returns the paths."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, src in enumerate(sources):
        path = folder / pattern.format(start + i)
        shutil.copyfile(src, path)
        paths.append(path)
    return paths


def import_sequence(path, **kwargs):
    """Imports the sequence of `path` with the demo parameters (`kwargs` override them) as
    the Import operator does; returns the new fluid surface."""
    params = dict(h=H, iso=ISO, grid_factor=GRID_FACTOR)
    params.update(kwargs)
    assert bpy.ops.isobar.import_sequence(filepath=str(path), **params) == {"FINISHED"}
    obj = bpy.context.active_object
    assert obj.isobar.enabled
    return obj


@pytest.fixture
def demo_sequence(tmp_path):
    """frame_0001.vtk (dam break frame 1), frame_0002.vtk (frame 26), frame_0003.vtk (frame 1)."""
    return make_sequence(tmp_path / "sim", [FRAME_01, FRAME_26, FRAME_01])


def reference(isobar, path, iso=ISO, **kwargs):
    """The core's own surface of a particle file, with the demo parameters."""
    params = dict(h=H, grid_factor=GRID_FACTOR)
    params.update(kwargs)
    return isobar.extract(isobar.Particles.read(str(path)), iso, **params)


def mesh_arrays(obj):
    """(points (n,3) f32, triangles (m,3) i32) of an object's mesh."""
    mesh = obj.data
    points = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", points)
    loops = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", loops)
    return points.reshape(-1, 3), loops.reshape(-1, 3)


def attribute(obj, name):
    attr = obj.data.attributes[name]
    n = len(attr.data)
    if attr.data_type == "FLOAT":
        out = np.empty(n, np.float32)
        attr.data.foreach_get("value", out)
        return out
    out = np.empty(n * 3, np.float32)
    attr.data.foreach_get("vector", out)
    return out.reshape(n, 3)


def assert_mesh_equals(obj, surface):
    """The mesh is the core's surface: same counts, same triangles, positions equal in
    float32 (Blender stores float32)."""
    points, triangles = mesh_arrays(obj)
    assert points.shape == surface.points.shape, (points.shape, surface.points.shape)
    assert triangles.shape == surface.triangles.shape, (triangles.shape, surface.triangles.shape)
    np.testing.assert_array_equal(triangles, surface.triangles.astype(np.int32))
    np.testing.assert_array_equal(points, surface.points.astype(np.float32))
