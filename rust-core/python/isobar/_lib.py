"""Loading libisobar.so and declaring every function of its C ABI for ctypes.

The library is looked for, in order:

1. the path in the environment variable ``ISOBAR_LIBRARY``;
2. ``libisobar.so`` inside this package (what ``pip install`` puts there);
3. the source tree's cargo output, ``<repo>/target/release/libisobar.so`` (development),
   or ``$CARGO_TARGET_DIR/release/libisobar.so``.

The ABI version the library reports must equal :data:`ABI_VERSION`, the one this module
was written against. Nothing here is public API; use the functions of the package.
"""

from __future__ import annotations

import ctypes
import numbers
import os
from ctypes import (
    CFUNCTYPE,
    POINTER,
    Structure,
    c_char_p,
    c_double,
    c_float,
    c_int,
    c_int32,
    c_int64,
    c_size_t,
    c_uint32,
    c_uint64,
    c_uint8,
    c_void_p,
)
from pathlib import Path

from .errors import Error, InvalidArgumentError, error_for

#: The ABI version this module declares (ISOBAR_ABI_VERSION in isobar.h).
ABI_VERSION = 1

LIBRARY_NAME = "libisobar.so"

KERNELS = {"cubic": 0, "wendland": 1, "quintic": 2, "quadratic": 3}

#: ``backend`` values of ``IsobarSphParams`` and ``IsobarAdaptiveParams``
#: (ISOBAR_BACKEND_CPU, _GPU, _AUTO).
BACKENDS = {"cpu": 0, "gpu": 1, "auto": 2}


def backend_name(value: int) -> str:
    """The name of an ``ISOBAR_BACKEND_*`` value that ran ("cpu" or "gpu")."""
    return {v: k for k, v in BACKENDS.items()}.get(value, "cpu")


class ParticlesHandle(Structure):
    """Opaque ``IsobarParticles``."""


class SurfaceHandle(Structure):
    """Opaque ``IsobarSurface``."""


class SliderHandle(Structure):
    """Opaque ``IsobarSlider``."""


class SliderChange(Structure):
    """``IsobarSliderChange``."""

    _fields_ = [
        ("isovalue", c_double),
        ("triangles_added", c_uint64),
        ("triangles_removed", c_uint64),
        ("vertices_moved", c_uint64),
        ("edges_added", c_uint64),
        ("edges_removed", c_uint64),
        ("seconds", c_double),
    ]


def _integer_range(kind) -> tuple[int, int]:
    bits = 8 * ctypes.sizeof(kind)
    signed = kind(-1).value == -1
    return (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if signed else (0, 2**bits - 1)


class _Params(Structure):
    """A parameter struct that refuses a value its integer field cannot hold, naming the
    field: ctypes would keep the low bits silently (a kernel of 2**32 became 0, the cubic
    spline; a memory budget of 2**64 became 0, the default; a splash threshold of -1
    became 4294967295)."""

    def __setattr__(self, name, value):
        kind = dict(self._fields_).get(name)
        if kind is not None and issubclass(kind, ctypes._SimpleCData) and kind._type_ in "bBhHiIlLqQnN":
            if not isinstance(value, numbers.Integral):
                raise InvalidArgumentError(f"parameter '{name}': must be an integer, got {value!r}")
            lo, hi = _integer_range(kind)
            if not lo <= int(value) <= hi:
                raise InvalidArgumentError(f"parameter '{name}': {value} is out of range [{lo}, {hi}]")
            value = int(value)
        super().__setattr__(name, value)


class SphParams(_Params):
    """``IsobarSphParams``; fill with ``isobar_sph_params_default``."""

    _fields_ = [
        ("struct_size", c_uint32),
        ("kernel", c_uint32),
        ("h", c_double),
        ("h_array", c_char_p),
        ("h_scale", c_double),
        ("field", c_char_p),
        ("volume_array", c_char_p),
        ("density_array", c_char_p),
        ("mass_array", c_char_p),
        ("mass", c_double),
        ("shepard", c_int32),
        ("correct", c_int32),
        ("isovalues", POINTER(c_double)),
        ("isovalue_count", c_size_t),
        ("grid_factor", c_double),
        ("tolerance", c_double),
        ("trim", c_int32),
        ("trim_node", c_double),
        ("trim_vertex", c_double),
        ("normals", c_int32),
        ("attributes", POINTER(c_char_p)),
        ("attribute_count", c_size_t),
        ("memory_budget", c_uint64),
        ("full_grid", c_int32),
        # after ABI 1: shared lattice and clip box for data-parallel pieces
        ("fixed_lattice", c_int32),
        ("lattice_origin", c_double * 3),
        ("lattice_cell_size", c_double),
        ("clip", c_int32),
        ("clip_min", c_double * 3),
        ("clip_max", c_double * 3),
        # after ABI 2: where the seed search runs (ISOBAR_BACKEND_*)
        ("backend", c_uint32),
    ]


class Stats(Structure):
    """``IsobarStats``; set ``struct_size`` before ``isobar_surface_stats``."""

    _fields_ = [
        ("struct_size", c_uint32),
        ("virtual_cells", c_uint64),
        ("seed_cells", c_uint64),
        ("non_intersected_seeds", c_uint64),
        ("discarded_cells", c_uint64),
        ("cells_used", c_uint64),
        ("vertices", c_uint64),
        ("triangles", c_uint64),
        ("field_evaluations", c_uint64),
        ("node_evaluations", c_uint64),
        ("cache_hit_ratio", c_double),
        ("correction_mean", c_double),
        ("correction_max", c_double),
        ("correction_stdev", c_double),
        ("unconverged_vertices", c_uint64),
        ("trim_cut_points", c_uint64),
        ("seconds_seeds", c_double),
        ("seconds_tracking", c_double),
        ("seconds_vertices", c_double),
        ("seconds_trimming", c_double),
        ("seconds_attributes", c_double),
        ("seconds_total", c_double),
        ("backend", c_uint32),
    ]


class AdaptiveParams(_Params):
    """``IsobarAdaptiveParams``; fill with ``isobar_adaptive_params_default``."""

    _fields_ = [
        ("struct_size", c_uint32),
        ("splash_threshold", c_uint32),
        ("splash_dilation", c_uint32),
        ("bisection_iterations", c_uint32),
        ("backend", c_uint32),
        ("max_error", c_double),
    ]


class AdaptiveStats(Structure):
    """``IsobarAdaptiveStats``; set ``struct_size`` before ``isobar_adaptive_extract``."""

    _fields_ = [
        ("struct_size", c_uint32),
        ("cells_per_level", c_uint64 * 3),
        ("triangles_per_level", c_uint64 * 3),
        ("transition_faces", c_uint64),
        ("crack_triangles", c_uint64),
        ("vertices", c_uint64),
        ("triangles", c_uint64),
        ("field_evaluations", c_uint64),
        ("array_bytes", c_uint64),
        ("seconds_total", c_double),
        ("backend", c_uint32),
    ]


class FeMeshHandle(Structure):
    """Opaque ``IsobarFeMesh``."""


class SamplesHandle(Structure):
    """Opaque ``IsobarSamples``."""


class FeParams(_Params):
    """``IsobarFeParams``; fill with ``isobar_fe_params_default``."""

    _fields_ = [
        ("struct_size", c_uint32),
        ("levels", c_uint32),
        ("iso", c_double),
        ("spacing", c_double),
        ("rho", c_double),
        ("tolerance", c_double),
        ("max_density", c_double),
        ("steady_fraction", c_double),
        ("max_iterations", c_uint32),
        ("neighbour_refresh", c_uint32),
        ("split_rounds", c_uint32),
        ("_reserved", c_uint32),
        ("seed", c_uint64),
    ]


class FeStats(Structure):
    """``IsobarFeStats``; set ``struct_size`` before ``isobar_samples_stats``."""

    _fields_ = [
        ("struct_size", c_uint32),
        ("particles", c_uint64),
        ("seeds", c_uint64),
        ("iterations", c_uint64),
        ("evaluations", c_uint64),
        ("splits", c_uint64),
        ("deletes", c_uint64),
        ("spacing", c_double),
        ("max_residual", c_double),
    ]


#: ``int32_t (*)(void* user, double fraction, const char* phase)``; non-zero cancels.
PROGRESS_FN = CFUNCTYPE(c_int32, c_void_p, c_double, c_char_p)

_Status = c_int  # IsobarStatus: a C enum, int-sized

#: The parameters after the values of isobar_slider_build_f32 and isobar_slider_build_f64.
_BUILD_ARRAY = [
    POINTER(c_size_t),
    POINTER(c_double),
    POINTER(c_double),
    c_char_p,
    c_double,
    c_uint32,
    c_uint64,
    PROGRESS_FN,
    c_void_p,
]

# name: (restype, argtypes)
_PROTOTYPES = {
    "isobar_last_error_message": (c_char_p, []),
    "isobar_abi_version": (c_uint32, []),
    "isobar_version": (c_char_p, []),
    "isobar_auto_backend_note": (_Status, [POINTER(c_char_p)]),
    # particles
    "isobar_particles_create": (_Status, [POINTER(c_double), c_size_t, POINTER(POINTER(ParticlesHandle))]),
    "isobar_particles_create_f32": (_Status, [POINTER(c_float), c_size_t, POINTER(POINTER(ParticlesHandle))]),
    "isobar_particles_add_array": (
        _Status,
        [POINTER(ParticlesHandle), c_char_p, POINTER(c_double), c_size_t, c_size_t],
    ),
    "isobar_particles_add_array_f32": (
        _Status,
        [POINTER(ParticlesHandle), c_char_p, POINTER(c_float), c_size_t, c_size_t],
    ),
    "isobar_particles_read": (_Status, [c_char_p, POINTER(POINTER(ParticlesHandle))]),
    "isobar_particles_count": (c_size_t, [POINTER(ParticlesHandle)]),
    "isobar_particles_array_count": (c_size_t, [POINTER(ParticlesHandle)]),
    "isobar_particles_array_info": (
        _Status,
        [POINTER(ParticlesHandle), c_size_t, POINTER(c_char_p), POINTER(c_size_t)],
    ),
    "isobar_particles_copy_positions": (_Status, [POINTER(ParticlesHandle), POINTER(c_double), c_size_t]),
    "isobar_particles_copy_array": (_Status, [POINTER(ParticlesHandle), c_char_p, POINTER(c_double), c_size_t]),
    "isobar_particles_free": (None, [POINTER(ParticlesHandle)]),
    # sph
    "isobar_sph_params_default": (_Status, [POINTER(SphParams)]),
    "isobar_sph_extract": (
        _Status,
        [POINTER(ParticlesHandle), POINTER(SphParams), PROGRESS_FN, c_void_p, POINTER(POINTER(SurfaceHandle))],
    ),
    # adaptive
    "isobar_adaptive_params_default": (_Status, [POINTER(AdaptiveParams)]),
    "isobar_adaptive_extract": (
        _Status,
        [
            POINTER(ParticlesHandle),
            POINTER(SphParams),
            POINTER(AdaptiveParams),
            PROGRESS_FN,
            c_void_p,
            POINTER(POINTER(SurfaceHandle)),
            POINTER(AdaptiveStats),
        ],
    ),
    # high-order finite elements
    "isobar_fe_params_default": (_Status, [POINTER(FeParams)]),
    "isobar_fe_mesh_create": (
        _Status,
        [
            POINTER(c_double),
            c_size_t,
            POINTER(c_uint8),
            c_size_t,
            POINTER(c_int64),
            POINTER(c_int64),
            c_size_t,
            POINTER(c_uint32),
            POINTER(POINTER(FeMeshHandle)),
        ],
    ),
    "isobar_fe_mesh_read": (_Status, [c_char_p, POINTER(POINTER(FeMeshHandle))]),
    "isobar_fe_mesh_add_array": (
        _Status,
        [POINTER(FeMeshHandle), c_char_p, POINTER(c_double), c_size_t, c_size_t],
    ),
    "isobar_fe_mesh_array_count": (c_size_t, [POINTER(FeMeshHandle)]),
    "isobar_fe_mesh_array": (
        _Status,
        [POINTER(FeMeshHandle), c_size_t, POINTER(c_char_p), POINTER(c_size_t), POINTER(POINTER(c_double))],
    ),
    "isobar_fe_mesh_point_count": (c_size_t, [POINTER(FeMeshHandle)]),
    "isobar_fe_mesh_cell_count": (c_size_t, [POINTER(FeMeshHandle)]),
    "isobar_fe_mesh_free": (None, [POINTER(FeMeshHandle)]),
    "isobar_fe_probe": (
        _Status,
        [
            POINTER(FeMeshHandle),
            c_char_p,
            POINTER(c_double),
            c_size_t,
            POINTER(c_double),
            POINTER(c_int64),
            POINTER(c_double),
        ],
    ),
    "isobar_fe_sample": (
        _Status,
        [
            POINTER(FeMeshHandle),
            c_char_p,
            POINTER(FeParams),
            PROGRESS_FN,
            c_void_p,
            POINTER(POINTER(SamplesHandle)),
        ],
    ),
    "isobar_samples_count": (c_size_t, [POINTER(SamplesHandle)]),
    "isobar_samples_positions": (POINTER(c_double), [POINTER(SamplesHandle)]),
    "isobar_samples_normals": (POINTER(c_float), [POINTER(SamplesHandle)]),
    "isobar_samples_radii": (POINTER(c_double), [POINTER(SamplesHandle)]),
    "isobar_samples_attribute_count": (c_size_t, [POINTER(SamplesHandle)]),
    "isobar_samples_attribute": (
        _Status,
        [POINTER(SamplesHandle), c_size_t, POINTER(c_char_p), POINTER(c_size_t), POINTER(POINTER(c_double))],
    ),
    "isobar_samples_stats": (_Status, [POINTER(SamplesHandle), POINTER(FeStats)]),
    "isobar_samples_warnings": (c_char_p, [POINTER(SamplesHandle)]),
    "isobar_samples_write": (_Status, [POINTER(SamplesHandle), c_char_p]),
    "isobar_samples_free": (None, [POINTER(SamplesHandle)]),
    # surface
    "isobar_surface_vertex_count": (c_size_t, [POINTER(SurfaceHandle)]),
    "isobar_surface_triangle_count": (c_size_t, [POINTER(SurfaceHandle)]),
    "isobar_surface_positions": (POINTER(c_double), [POINTER(SurfaceHandle)]),
    "isobar_surface_normals": (POINTER(c_float), [POINTER(SurfaceHandle)]),
    "isobar_surface_triangles": (POINTER(c_uint32), [POINTER(SurfaceHandle)]),
    "isobar_surface_attribute_count": (c_size_t, [POINTER(SurfaceHandle)]),
    "isobar_surface_attribute": (
        _Status,
        [POINTER(SurfaceHandle), c_size_t, POINTER(c_char_p), POINTER(c_size_t), POINTER(POINTER(c_double))],
    ),
    "isobar_surface_stats": (_Status, [POINTER(SurfaceHandle), POINTER(Stats)]),
    "isobar_surface_warnings": (c_char_p, [POINTER(SurfaceHandle)]),
    "isobar_surface_write": (_Status, [POINTER(SurfaceHandle), c_char_p]),
    "isobar_surface_free": (None, [POINTER(SurfaceHandle)]),
    # slider
    "isobar_slider_build_file": (
        _Status,
        [c_char_p, c_char_p, c_char_p, c_double, c_uint32, c_uint64, PROGRESS_FN, c_void_p],
    ),
    "isobar_slider_build_f32": (_Status, [POINTER(c_float), *_BUILD_ARRAY]),
    "isobar_slider_build_f64": (_Status, [POINTER(c_double), *_BUILD_ARRAY]),
    "isobar_last_warnings": (c_char_p, []),
    "isobar_slider_open": (_Status, [c_char_p, POINTER(POINTER(SliderHandle))]),
    "isobar_slider_set_isovalue": (
        _Status,
        [POINTER(SliderHandle), c_double, PROGRESS_FN, c_void_p, POINTER(SliderChange)],
    ),
    "isobar_slider_vertex_count": (c_size_t, [POINTER(SliderHandle)]),
    "isobar_slider_triangle_count": (c_size_t, [POINTER(SliderHandle)]),
    "isobar_slider_positions": (POINTER(c_float), [POINTER(SliderHandle)]),
    "isobar_slider_normals": (POINTER(c_float), [POINTER(SliderHandle)]),
    "isobar_slider_triangles": (POINTER(c_uint32), [POINTER(SliderHandle)]),
    "isobar_slider_change_triangles": (
        _Status,
        [POINTER(SliderHandle), c_uint32, POINTER(c_size_t), POINTER(POINTER(c_uint32))],
    ),
    "isobar_slider_change_moved": (
        _Status,
        [POINTER(SliderHandle), POINTER(c_size_t), POINTER(POINTER(c_uint32))],
    ),
    "isobar_slider_value_range": (_Status, [POINTER(SliderHandle), POINTER(c_double), POINTER(c_double)]),
    "isobar_slider_stats": (_Status, [POINTER(SliderHandle), POINTER(c_uint64), POINTER(c_double)]),
    "isobar_slider_set_lod": (_Status, [POINTER(SliderHandle), c_double, c_uint32]),
    "isobar_slider_get_lod": (_Status, [POINTER(SliderHandle), POINTER(c_double), POINTER(c_uint32)]),
    "isobar_slider_lod_mesh": (
        _Status,
        [
            POINTER(SliderHandle),
            POINTER(c_size_t),
            POINTER(c_size_t),
            POINTER(POINTER(c_float)),
            POINTER(POINTER(c_float)),
            POINTER(POINTER(c_uint32)),
        ],
    ),
    "isobar_slider_free": (None, [POINTER(SliderHandle)]),
}


def candidates() -> list[Path]:
    """The paths tried, in order, when loading the library."""
    paths = []
    env = os.environ.get("ISOBAR_LIBRARY")
    if env:
        paths.append(Path(env))
    here = Path(__file__).resolve().parent
    paths.append(here / LIBRARY_NAME)
    target = os.environ.get("CARGO_TARGET_DIR")
    if target:
        paths.append(Path(target) / "release" / LIBRARY_NAME)
    # <repo>/rust-core/python/isobar/_lib.py -> <repo>/target/release
    if len(here.parents) >= 3:
        paths.append(here.parents[2] / "target" / "release" / LIBRARY_NAME)
    return paths


def _load() -> ctypes.CDLL:
    env = os.environ.get("ISOBAR_LIBRARY")
    tried = []
    for path in candidates():
        if not path.is_file():
            tried.append(f"{path} (absent)")
            if env and path == Path(env):
                raise ImportError(f"ISOBAR_LIBRARY={env} is not a file")
            continue
        try:
            lib = ctypes.CDLL(str(path))
        except OSError as e:
            if env and path == Path(env):
                raise ImportError(f"cannot load ISOBAR_LIBRARY={env}: {e}") from e
            tried.append(f"{path} ({e})")
            continue
        lib._isobar_path = str(path)
        return lib
    raise ImportError(
        "libisobar.so not found; install the package with `pip install ./rust-core/python`, "
        "build it with `cargo build --release -p isobar`, or set ISOBAR_LIBRARY. Tried: " + "; ".join(tried)
    )


def _declare(lib: ctypes.CDLL) -> None:
    for name, (restype, argtypes) in _PROTOTYPES.items():
        try:
            fn = getattr(lib, name)
        except AttributeError as e:
            raise ImportError(f"{lib._isobar_path} lacks {name}: library and package do not match") from e
        fn.restype = restype
        fn.argtypes = argtypes


lib = _load()
_declare(lib)

_found_abi = lib.isobar_abi_version()
if _found_abi != ABI_VERSION:
    raise ImportError(
        f"{lib._isobar_path} has C ABI version {_found_abi}; this isobar package was written for "
        f"version {ABI_VERSION}. Rebuild and reinstall the package from one source tree."
    )

#: Path of the loaded library.
path = lib._isobar_path


def last_error() -> str:
    """The core's message for the last failed call on this thread."""
    raw = lib.isobar_last_error_message()
    return raw.decode("utf-8", "replace") if raw else ""


def check(status: int) -> None:
    """Raises the :class:`isobar.Error` subclass for a non-zero status."""
    if status != 0:
        raise error_for(status, last_error())


def encode(text, what: str) -> bytes:
    """UTF-8 bytes of a name or path for the C ABI (NUL characters refused)."""
    from .errors import InvalidArgumentError

    value = text if isinstance(text, bytes) else os.fspath(text)
    try:
        data = value if isinstance(value, bytes) else value.encode("utf-8")
    except UnicodeEncodeError as e:
        raise InvalidArgumentError(f"{what} {text!r} is not valid UTF-8") from e
    if b"\0" in data:
        raise InvalidArgumentError(f"{what} {text!r} contains a NUL character")
    return data


__all__ = ["lib", "check", "last_error", "encode", "SphParams", "Stats", "PROGRESS_FN", "KERNELS", "BACKENDS", "backend_name", "Error"]
