"""isobar: exact isosurfaces of SPH particle data and high-order finite elements.

A thin ctypes layer over the isobar core (libisobar.so, Rust) with numpy arrays in and
out; numpy is the only dependency (``isobar.pyvista`` adapts to pyvista when it is
installed)::

    import isobar
    particles = isobar.Particles.read("frame.vtk")            # or Particles.from_arrays(xyz, h=h)
    surface = isobar.extract(particles, 0.6, h=0.05, grid_factor=0.375)
    surface.points, surface.normals, surface.triangles, surface.attributes, surface.stats
    surface.write("surface.vtp")

Errors raise :class:`isobar.Error` subclasses carrying the core's message and status.
"""

from __future__ import annotations

from ctypes import byref as _byref
from ctypes import c_char_p as _c_char_p

from ._version import __version__
from ._lib import ABI_VERSION
from ._lib import check as _check
from ._lib import lib as _lib_handle
from ._lib import path as library_path
from .errors import (
    Cancelled,
    Error,
    FormatError,
    InternalError,
    InvalidArgumentError,
    InvalidInputError,
    IoError,
    IsobarWarning,
    OverBudgetError,
    Status,
    quiet_warnings,
)
from .adaptive import extract_adaptive
from .fe import FeMesh, Samples, sample_fe
from .particles import Particles
from .slider import Slider, SliderLodMesh, SliderUpdate
from .sph import default_params, extract
from .surface import Surface

#: Kernel names accepted by :func:`extract`.
KERNELS = ("cubic", "wendland", "quintic", "quadratic")


def core_version() -> str:
    """Version of the loaded core library (``isobar_version()``), e.g. "0.1.0"."""
    return _lib_handle.isobar_version().decode()


def abi_version() -> int:
    """C ABI version of the loaded core library (equals :data:`ABI_VERSION`)."""
    return int(_lib_handle.isobar_abi_version())


def auto_backend_note() -> str | None:
    """Why ``backend="auto"`` runs on the CPU on this machine, or None when it picks a GPU.

    The same text the ``isobar`` CLI prints after "backend auto: running on the CPU ("
    (no GPU adapter, only a software rasteriser such as lavapipe, or a core built without
    GPU support), for a host to show its user. The first call opens the GPU device once.
    """
    note = _c_char_p()
    _check(_lib_handle.isobar_auto_backend_note(_byref(note)))
    text = (note.value or b"").decode("utf-8", "replace")
    return text or None


__all__ = [
    "__version__",
    "ABI_VERSION",
    "KERNELS",
    "Cancelled",
    "FeMesh",
    "Error",
    "FormatError",
    "InternalError",
    "InvalidArgumentError",
    "InvalidInputError",
    "IoError",
    "IsobarWarning",
    "OverBudgetError",
    "Particles",
    "Samples",
    "Slider",
    "SliderLodMesh",
    "SliderUpdate",
    "Status",
    "Surface",
    "abi_version",
    "auto_backend_note",
    "core_version",
    "default_params",
    "extract",
    "extract_adaptive",
    "library_path",
    "quiet_warnings",
    "sample_fe",
]


def __getattr__(name):
    """Imports the optional ``isobar.pyvista`` adaptor on first access."""
    if name == "pyvista":
        import importlib

        return importlib.import_module(".pyvista", __name__)
    raise AttributeError(f"module 'isobar' has no attribute '{name}'")
