"""Shared fixtures of the isobar Python tests (run them with tests/python/run.sh)."""

import os
import signal
from pathlib import Path

# PyPI's vtk renders offscreen through EGL without an X server; set before vtk loads.
os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
DATA = Path(os.environ.get("ISOBAR_TEST_DATA", REPO.parent / "shared" / "data"))
DAM_BREAK = DATA / "splashsurf" / "double_dam_break_frame_26_4732_particles.vtk"


@pytest.fixture(scope="session")
def dam_break_path():
    """The SPlisHSPlasH double dam break frame (4,732 particles) from shared/data."""
    if not DAM_BREAK.is_file():
        pytest.skip(f"test data not found: {DAM_BREAK}")
    return DAM_BREAK


@pytest.fixture(scope="session")
def cli():
    """The isobar command line built from the same tree (ISOBAR_CLI or target/release)."""
    path = Path(os.environ.get("ISOBAR_CLI", REPO / "target" / "release" / "isobar"))
    if not path.is_file():
        pytest.fail(f"isobar command line not found at {path}; run `cargo build --release -p isobar`")
    return path


def lattice(n=6, spacing=0.1, origin=(0.0, 0.0, 0.0)):
    """An n x n x n cube of particles, float64 (n^3, 3)."""
    axis = np.arange(n, dtype=np.float64) * spacing
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1) + np.asarray(origin)


def cubic_shape(q):
    """Monaghan's cubic spline shape f(q) (support 2), written out independently."""
    q = np.asarray(q, dtype=np.float64)
    return np.where(q < 1, 1 - 1.5 * q**2 + 0.75 * q**3, np.where(q < 2, 0.25 * (2 - q) ** 3, 0.0))


@pytest.fixture
def python_sigint():
    """Python's own Ctrl-C handler for the test, as an interactive session has it: a test
    run started in the background by a shell without job control inherits an ignored
    SIGINT, under which isobar rightly leaves Ctrl-C alone."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)
