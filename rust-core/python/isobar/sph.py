"""SPH isosurfaces by Marching Correctors (or the full-grid baseline)."""

from __future__ import annotations

import contextlib
import math
import numbers
import signal
import threading
from ctypes import POINTER, byref, c_char_p, c_double
from typing import Callable, Iterable, Optional, Sequence, Tuple, Union

import numpy as np

from ._lib import BACKENDS, KERNELS, PROGRESS_FN, SphParams, SurfaceHandle, check, encode, lib
from .errors import InvalidArgumentError, Status, issue
from .particles import Particles
from .surface import Surface

#: Arrays taken as per-particle smoothing lengths when neither `h` nor `h_array` is given
#: (as the command line does).
DEFAULT_H_ARRAYS = ("h", "smoothing_length", "hsml")

ProgressCallback = Callable[[float, str], Optional[bool]]


def default_params() -> SphParams:
    """The core's default ``IsobarSphParams`` (with ``struct_size`` set)."""
    params = SphParams()
    check(lib.isobar_sph_params_default(byref(params)))
    return params


def is_sum_of_weights(field: Optional[str]) -> bool:
    """True when `field` names the free-surface field (None, "" or "SumOfWeights")."""
    return field is None or field == "" or field.lower() in ("sumofweights", "sum-of-weights")


def _flag(value) -> int:
    return 1 if value else 0


def _name(value, what: str) -> Optional[bytes]:
    return None if value is None else encode(value, what)


def _kernel(kernel: Union[str, int]) -> int:
    if isinstance(kernel, str):
        try:
            return KERNELS[kernel.lower()]
        except KeyError:
            raise InvalidArgumentError(
                f"unknown kernel '{kernel}'; choose one of {', '.join(KERNELS)}"
            ) from None
    return int(kernel)


def extract(
    particles: Union[Particles, np.ndarray],
    iso: Union[float, Sequence[float]],
    field: Optional[str] = None,
    kernel: Union[str, int] = "cubic",
    h: Optional[float] = None,
    h_array: Optional[str] = None,
    h_scale: float = 1.0,
    grid_factor: float = 0.5,
    correct: bool = True,
    tolerance: float = 1e-6,
    trim: Union[str, None, bool, Tuple[float, float]] = "auto",
    normals: bool = True,
    attributes: Union[str, Iterable[str]] = (),
    volume_array: Optional[str] = None,
    density_array: Optional[str] = None,
    mass: Optional[float] = None,
    mass_array: Optional[str] = None,
    shepard: bool = False,
    memory_budget: Optional[int] = None,
    full_grid: bool = False,
    lattice: Optional[Tuple[float, float, float, float]] = None,
    clip: Optional[Tuple[Sequence[float], Sequence[float]]] = None,
    progress: Optional[ProgressCallback] = None,
    backend: str = "cpu",
) -> Surface:
    """Extracts isosurfaces of the particles' SPH field; every vertex lies on the level set
    of the SPH interpolant to `tolerance` (relative), unless `correct` is False.

    Args:
        particles: a :class:`Particles` set (or an (n, 3) position array).
        iso: one isovalue or a sequence of them (one surface holding all, with an
            ``Isovalue`` attribute per vertex).
        field: particle array to contour: ``"NAME"``, ``"NAME:mag"`` (a vector's
            magnitude), ``"NAME:K"`` (component K); None or ``"SumOfWeights"`` for the
            free surface (sum of V_j W_j).
        kernel: ``"cubic"`` (support 2h), ``"wendland"``, ``"quintic"`` (3h),
            ``"quadratic"``.
        h: constant smoothing length. With neither `h` nor `h_array`, the first of the
            arrays ``h``, ``smoothing_length``, ``hsml`` present is used.
        h_array: name of a per-particle smoothing length array.
        h_scale: multiplies every smoothing length (0.75, 0.5 for quick previews).
        grid_factor: virtual cell size in units of the smallest h.
        correct: True to move vertices onto the level set; False for a linear preview.
        tolerance: relative tolerance of the correction.
        trim: free-surface trimming thresholds (node, vertex) on the sum of weights; None
            or False for none; True for the core's defaults (0.1, 0.5); ``"auto"`` (the
            default) trims with the defaults except for the SumOfWeights field, as the
            command line does.
        normals: compute unit vertex normals from the field gradient.
        attributes: particle array names to interpolate onto the vertices.
        volume_array: per-particle volume array (m/rho); wins over `density_array`.
        density_array: density array; volumes = mass / density (needs `mass` or
            `mass_array`). Without either, volumes come from densities computed from the
            particles (splashsurf's convention).
        mass: constant particle mass (> 0).
        mass_array: per-particle mass array.
        shepard: divide the field by the sum of weights.
        memory_budget: bytes (a whole number; the CLI's --memory-budget is in GiB) that
            extent-sized structures may use (default: the core's, 4 GiB).
        full_grid: resample onto a full grid and run marching cubes (the baseline).
        lattice: (x, y, z, cell): put the virtual grid on nodes x + i·cell, ... instead of
            grid_factor × smallest h, so separately extracted pieces share their nodes.
        clip: ((x0, y0, z0), (x1, y1, z1)): keep only the surface in cells whose lowest
            corner lies in this half-open box; particles outside still shape the field.
        progress: ``callable(fraction, phase)`` called on this thread between chunks of
            work; return None or True to go on, False to cancel. An exception raised in
            it cancels the extraction and is re-raised here.
        backend: where the seed cells' neighbour search runs: "cpu", "gpu" (wgpu; raises
            "no GPU adapter: ..." without one) or "auto" (a hardware GPU when there is
            one, else the CPU). Every back end gives the same surface;
            ``surface.stats["backend"]`` says which ran. `full_grid` refuses "gpu".

    Returns:
        A :class:`Surface` (numpy arrays).

    Raises:
        isobar.InvalidArgumentError: a parameter out of range.
        isobar.InvalidInputError: data that cannot form a field (NaN position, h <= 0, no
            particles, a missing array); the message names the particle or array.
        isobar.OverBudgetError: the work would exceed `memory_budget`.
        isobar.Cancelled: `progress` returned False.
    """
    if not isinstance(particles, Particles):
        particles = Particles.from_arrays(particles)
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {sorted(BACKENDS)}, got {backend!r}")
    params, keep = _sph_params(particles, iso, field, kernel, h, h_array, h_scale, grid_factor,
                               correct, tolerance, trim, normals, attributes, volume_array,
                               density_array, mass, mass_array, shepard, memory_budget,
                               full_grid, lattice, clip)
    params.backend = BACKENDS[backend]
    with particles._in_use() as source:
        surface = _run(
            lambda callback, handle: lib.isobar_sph_extract(
                source, byref(params), callback, None, byref(handle)
            ),
            progress,
            normals,
        )
    del keep
    return surface


def _sph_params(particles, iso, field, kernel, h, h_array, h_scale, grid_factor, correct,
                tolerance, trim, normals, attributes, volume_array, density_array, mass,
                mass_array, shepard, memory_budget, full_grid, lattice, clip):
    """``IsobarSphParams`` for :func:`extract`'s arguments, and the objects it points into
    (keep them alive until the call returns)."""
    particles._check_open()

    params = default_params()
    params.kernel = _kernel(kernel)
    keep = []  # bytes and arrays the struct points into, alive until the call returns

    # Smoothing length, as the command line resolves it.
    if h is not None and h_array is not None:
        raise InvalidArgumentError("give either h or h_array, not both")
    if h is None and h_array is None:
        names = particles.names
        h_array = next((n for n in DEFAULT_H_ARRAYS if n in names), None)
        if h_array is None:
            raise InvalidArgumentError(
                f"the data has no smoothing-length array (arrays: {', '.join(names) or 'none'}); "
                "pass h=VALUE or h_array=NAME"
            )
    if h_array is not None:
        params.h_array = _name(h_array, "h_array")
    else:
        params.h = float(h)
    params.h_scale = float(h_scale)
    params.field = _name(field, "field")
    params.volume_array = _name(volume_array, "volume_array")
    params.density_array = _name(density_array, "density_array")
    params.mass_array = _name(mass_array, "mass_array")
    if mass is not None:
        # The C ABI reads mass <= 0 as "not given"; refuse it instead of ignoring it.
        if not (float(mass) > 0 and math.isfinite(float(mass))):
            raise InvalidArgumentError(f"parameter 'mass': must be positive and finite, got {mass}")
        params.mass = float(mass)
    params.shepard = _flag(shepard)
    params.correct = _flag(correct)

    isovalues = np.ascontiguousarray(np.atleast_1d(np.asarray(iso, dtype=np.float64)).ravel())
    keep.append(isovalues)
    params.isovalues = isovalues.ctypes.data_as(POINTER(c_double))
    params.isovalue_count = isovalues.size

    params.grid_factor = float(grid_factor)
    params.tolerance = float(tolerance)
    if isinstance(trim, str):
        if trim != "auto":
            raise InvalidArgumentError(f"trim must be 'auto', None, a bool or (node, vertex), got '{trim}'")
        params.trim = 0 if is_sum_of_weights(field) else 1
    elif trim is None or trim is False:
        params.trim = 0
    elif trim is True:
        params.trim = 1
    else:
        node, vertex = trim
        params.trim, params.trim_node, params.trim_vertex = 1, float(node), float(vertex)
    params.normals = _flag(normals)

    if isinstance(attributes, (str, bytes)):
        attributes = [attributes]
    names = [encode(a, "attribute name") for a in attributes]
    if names:
        name_array = (c_char_p * len(names))(*names)
        keep.append(name_array)
        params.attributes = name_array
        params.attribute_count = len(names)

    if memory_budget is not None:
        # Bytes, as in Slider.build: a fraction (0.25 meant as GiB, the CLI's unit) must not
        # be truncated to a budget of 0.
        if not (isinstance(memory_budget, numbers.Integral) and not isinstance(memory_budget, bool)
                and 0 < memory_budget < 2**64):
            raise InvalidArgumentError(
                f"parameter 'memory_budget': must be a positive whole number of bytes "
                f"(4 GiB: 4 << 30), got {memory_budget!r}")
        params.memory_budget = int(memory_budget)
    params.full_grid = _flag(full_grid)
    if lattice is not None:
        x, y, z, cell = (float(v) for v in lattice)
        params.fixed_lattice = 1
        params.lattice_origin[:] = (x, y, z)
        params.lattice_cell_size = cell
    if clip is not None:
        lo, hi = clip
        params.clip = 1
        params.clip_min[:] = tuple(float(v) for v in lo)
        params.clip_max[:] = tuple(float(v) for v in hi)

    return params, keep


def _run(invoke, progress: Optional[ProgressCallback], normals: bool) -> Surface:
    """Calls ``invoke(callback, handle)`` (a core extraction writing a surface handle) with
    the progress/cancel/Ctrl-C wiring, and wraps the result."""
    handle = _call(invoke, progress, POINTER(SurfaceHandle)(), lib.isobar_surface_free)
    surface = Surface._from_handle(handle, normals_requested=bool(normals))
    issue(surface.warnings, stacklevel=3)  # the line that called extract(_adaptive)
    return surface


def _call(invoke, progress: Optional[ProgressCallback], handle, free):
    """Calls ``invoke(callback, handle)`` (a core call writing a result handle) with the
    progress/cancel/Ctrl-C wiring; returns the filled handle or raises (an exception of
    the callback, KeyboardInterrupt, or the core's error), freeing a result nobody gets."""
    # The callback runs on this thread. It is always installed, so that Ctrl-C (a
    # KeyboardInterrupt raised while it runs) cancels the call too.
    raised: list = []

    interrupted: list = []

    def report(_user, fraction, phase):
        if raised or interrupted:
            return 1
        try:
            if progress is None:
                return 0
            answer = progress(float(fraction), phase.decode("utf-8", "replace") if phase else "")
            return 0 if answer is None or answer else 1
        except BaseException as e:  # noqa: BLE001 - every exception must stop here, not in C
            raised.append(e)
            return 1

    callback = PROGRESS_FN(report)
    with _sigint_cancels(interrupted):
        status = invoke(callback, handle)
    if interrupted and not raised:
        raised.append(KeyboardInterrupt())
    if raised:
        if status == 0:
            free(handle)
        exc = raised[0]
        raised.clear()
        raise exc
    if status == Status.OK:
        return handle
    check(status)
    raise AssertionError("unreachable")  # check raises for every non-zero status


@contextlib.contextmanager
def _sigint_cancels(interrupted: list):
    """While the core runs, Ctrl-C only sets a flag that the progress callback turns into
    a cancel; the caller then raises KeyboardInterrupt. Python would otherwise raise it at
    an arbitrary point inside the ctypes callback, where it cannot be caught cleanly.
    Only where Python's own handler is installed (not inside Blender or another host that
    manages signals itself), and only on the main thread."""
    previous = None
    if threading.current_thread() is threading.main_thread():
        try:
            if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
                previous = signal.signal(signal.SIGINT, lambda *_: interrupted.append(True))
        except (ValueError, OSError):
            previous = None
    try:
        yield
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


__all__ = ["extract", "default_params", "DEFAULT_H_ARRAYS"]
