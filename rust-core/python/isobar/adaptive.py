"""Adaptive crack-free SPH surfaces on 3-level grids (far fewer triangles than uniform
marching cubes at the finest level; splashes kept at the finest level)."""

from __future__ import annotations

from ctypes import byref, sizeof
from typing import Iterable, Optional, Tuple, Union

import numpy as np

from ._lib import BACKENDS, AdaptiveParams, AdaptiveStats, backend_name, check, lib
from .errors import InvalidArgumentError
from .particles import Particles
from .sph import ProgressCallback, _run, _sph_params
from .surface import Surface


def default_params() -> AdaptiveParams:
    """The core's default ``IsobarAdaptiveParams`` (with ``struct_size`` set)."""
    params = AdaptiveParams()
    check(lib.isobar_adaptive_params_default(byref(params)))
    return params


def extract_adaptive(
    particles: Union[Particles, np.ndarray],
    iso: float,
    field: Optional[str] = None,
    kernel: Union[str, int] = "cubic",
    h: Optional[float] = None,
    h_array: Optional[str] = None,
    h_scale: float = 1.0,
    grid_factor: float = 0.5,
    normals: bool = True,
    attributes: Union[str, Iterable[str]] = (),
    volume_array: Optional[str] = None,
    density_array: Optional[str] = None,
    mass: Optional[float] = None,
    mass_array: Optional[str] = None,
    shepard: bool = False,
    memory_budget: Optional[int] = None,
    splash_threshold: Optional[int] = None,
    splash_dilation: Optional[int] = None,
    max_error: Optional[float] = None,
    bisection_iterations: Optional[int] = None,
    progress: Optional[ProgressCallback] = None,
    backend: str = "auto",
) -> Tuple[Surface, dict]:
    """Extracts the adaptive surface of the particles' SPH field at one isovalue.

    The field options are those of :func:`isobar.extract`; `grid_factor` sets the finest
    (level-3) cell in units of the smallest h, coarse cells being four times larger.

    Args:
        attributes: particle array names to interpolate onto the vertices, as
            :func:`isobar.extract` does (normalised by the sum of weights).
        splash_threshold: coarse cells holding 1..=N particles become level 3 (the
            paper's rule is 1; core default 0, none: the error criterion alone decides).
        splash_dilation: layers of neighbour cells raised to level 3 around each splash
            cell (core default 1; 0 is the paper's criterion alone).
        max_error: error criterion, added to the splash one: each cell at the surface
            takes the lowest level whose surface lies within this many finest cells of
            the finest level's there (core default in
            ``default_params().max_error``; 0 turns it off).
        bisection_iterations: halvings n on level-3 edges (n+1 on level 2, n+2 on level 1),
            0 to 16; 0 places level-3 points linearly between the finest nodes, as
            uniform marching cubes does (faster; coarser edges still coincide).
        backend: "cpu", "gpu" (wgpu; raises "no GPU adapter: ..." without one) or "auto"
            (a hardware GPU when there is one, else the CPU: a software adapter such
            as lavapipe is slower than the CPU path); ``stats["backend"]`` says
            which ran.

    Returns:
        (:class:`Surface`, stats) where stats holds ``cells_per_level``,
        ``triangles_per_level``, ``transition_faces``, ``crack_triangles``, ``vertices``,
        ``triangles``, ``field_evaluations``, ``array_bytes``, ``seconds_total`` and ``backend`` ("cpu" or "gpu").
    """
    if np.ndim(iso) != 0:
        raise InvalidArgumentError(
            f"extract_adaptive takes one isovalue at a time, got {np.size(iso)}; call it once per isovalue"
        )
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {sorted(BACKENDS)}, got {backend!r}")
    if not isinstance(particles, Particles):
        particles = Particles.from_arrays(particles)
    params, keep = _sph_params(particles, float(iso), field, kernel, h, h_array, h_scale,
                               grid_factor, True, 1e-6, None, normals, attributes, volume_array,
                               density_array, mass, mass_array, shepard, memory_budget,
                               False, None, None)
    adaptive = default_params()
    if splash_threshold is not None:
        adaptive.splash_threshold = int(splash_threshold)
    if splash_dilation is not None:
        adaptive.splash_dilation = int(splash_dilation)
    if max_error is not None:
        adaptive.max_error = float(max_error)
    if bisection_iterations is not None:
        adaptive.bisection_iterations = int(bisection_iterations)
    adaptive.backend = BACKENDS[backend]
    stats = AdaptiveStats()
    stats.struct_size = sizeof(AdaptiveStats)
    with particles._in_use() as source:
        surface = _run(
            lambda callback, handle: lib.isobar_adaptive_extract(
                source, byref(params), byref(adaptive), callback, None,
                byref(handle), byref(stats)
            ),
            progress,
            normals,
        )
    del keep
    info = {name: getattr(stats, name) for name, _ in AdaptiveStats._fields_ if name != "struct_size"}
    info["cells_per_level"] = list(stats.cells_per_level)
    info["triangles_per_level"] = list(stats.triangles_per_level)
    info["backend"] = backend_name(stats.backend)
    return surface, info


__all__ = ["extract_adaptive", "default_params"]
