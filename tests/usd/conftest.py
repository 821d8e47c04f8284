"""Shared fixtures of the USD writer's tests (run them with tests/usd/run.sh)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
DATA = Path(os.environ.get("ISOBAR_TEST_DATA", REPO.parent / "shared" / "data"))
FRAME_01 = DATA / "splashsurf" / "double_dam_break_frame_01_4732_particles.vtk"
FRAME_26 = DATA / "splashsurf" / "double_dam_break_frame_26_4732_particles.vtk"
DEMO = REPO / "rust-core" / "data" / "demo_dam_break.npz"

#: The double dam break's free surface (SPlisHSPlasH, radius 0.025): h = 0.05, sum of
#: weights 0.6, cells of 0.375 h.
DAM = dict(h=0.05, grid_factor=0.375)
ISO = 0.6
CLI_DAM = ["--iso", "0.6", "--h", "0.05", "--grid-factor", "0.375"]


def need(path: Path) -> Path:
    if not path.is_file():
        pytest.skip(f"test data not found: {path}")
    return path


@pytest.fixture(scope="session")
def cli() -> Path:
    """The installed `isobar-usd` console script (beside this interpreter)."""
    path = Path(sys.executable).parent / "isobar-usd"
    if not path.is_file():
        found = shutil.which("isobar-usd")
        if not found:
            pytest.fail("isobar-usd is not installed; run tests/usd/run.sh (pip install ./usd-exporter)")
        path = Path(found)
    return path


def run_cli(cli: Path, *args, cwd=None, check=True) -> subprocess.CompletedProcess:
    proc = subprocess.run([str(cli), *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=600)
    if check and proc.returncode != 0:
        raise AssertionError(f"isobar-usd {' '.join(map(str, args))} failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    return proc


def link_frames(folder: Path, frames: dict) -> Path:
    """Symlinks frame_NNNN.vtk -> source for {number: source}; returns the folder."""
    folder.mkdir(parents=True, exist_ok=True)
    for number, source in frames.items():
        os.symlink(need(source), folder / f"frame_{number:04d}.vtk")
    return folder


@pytest.fixture(scope="session")
def dam_frames(tmp_path_factory) -> Path:
    """frames/frame_0001.vtk and frame_0026.vtk: the two SPlisHSPlasH frames."""
    return link_frames(tmp_path_factory.mktemp("dam") / "frames", {1: FRAME_01, 26: FRAME_26})


@pytest.fixture(scope="session")
def reference():
    """The core's own mesh of a frame file: isobar.extract with the same parameters."""
    import isobar

    cache = {}

    def get(path, iso=ISO, **options):
        key = (str(path), repr(iso), repr(sorted(options.items())))
        if key not in cache:
            opts = {**DAM, **options}
            with isobar.Particles.read(str(path)) as particles:
                cache[key] = isobar.extract(particles, iso, **opts)
                cache[key].release()
        return cache[key]

    return get


def mesh_at(stage, time, path="/Fluid/Surface"):
    """Arrays of the mesh at a time code: points, counts, indices, normals, extent, velocities."""
    from pxr import UsdGeom

    mesh = UsdGeom.Mesh(stage.GetPrimAtPath(path))
    assert mesh, f"no Mesh at {path}"

    def get(attr, dtype):
        value = attr.Get(time)
        return None if value is None else np.asarray(value, dtype=dtype)

    return dict(
        points=get(mesh.GetPointsAttr(), np.float32),
        counts=get(mesh.GetFaceVertexCountsAttr(), np.int32),
        indices=get(mesh.GetFaceVertexIndicesAttr(), np.int32),
        normals=get(mesh.GetNormalsAttr(), np.float32),
        extent=get(mesh.GetExtentAttr(), np.float32),
        velocities=get(mesh.GetVelocitiesAttr(), np.float32),
        mesh=mesh,
    )


def assert_same_mesh(got: dict, surface, velocity: bool = True):
    """The USD samples equal the core's surface (positions as float32, USD's points type)."""
    n = surface.points.shape[0]
    np.testing.assert_array_equal(got["points"], surface.points.astype(np.float32))
    np.testing.assert_array_equal(got["counts"], np.full(surface.triangles.shape[0], 3, np.int32))
    np.testing.assert_array_equal(got["indices"], surface.triangles.astype(np.int32).ravel())
    np.testing.assert_array_equal(got["normals"], surface.normals)
    assert got["normals"].shape == (n, 3)
    if velocity:
        np.testing.assert_array_equal(got["velocities"], surface.attributes["velocity"].astype(np.float32))


def validation_errors(stage):
    """(name, message) of every error usd-core's validators report."""
    from pxr import UsdValidation

    context = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    return [
        (e.GetName(), e.GetMessage())
        for e in context.Validate(stage)
        if e.GetType() == UsdValidation.ValidationErrorType.Error
    ]


def open_stage(path):
    """Opens a stage from disk, reloading layers this process has open already (USD caches
    layers by path, and these tests rewrite files)."""
    from pxr import Sdf, Usd

    folder = Path(path).resolve().parent
    for layer in Sdf.Layer.GetLoadedLayers():
        try:
            real = None if layer.anonymous else layer.realPath
        except Exception:  # noqa: BLE001 - a layer that expired while we looked
            continue
        if real and Path(real).resolve().parent.is_relative_to(folder):
            if Path(real).exists():
                layer.Reload(True)
    stage = Usd.Stage.Open(str(path))
    assert stage is not None, f"USD could not open {path}"
    return stage
