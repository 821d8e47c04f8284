"""Extraction results as numpy arrays."""

from __future__ import annotations

import weakref
from ctypes import POINTER, byref, c_char_p, c_double, c_size_t, sizeof
from typing import Dict, List, Optional

import numpy as np

from ._lib import Stats, backend_name, check, encode, lib
from .errors import InvalidArgumentError


def _copy(ptr, count: int, dtype) -> np.ndarray:
    """A numpy copy of `count` items behind a ctypes pointer (nothing is read for 0)."""
    if count == 0:
        return np.empty(0, dtype=dtype)
    if not ptr:
        raise InvalidArgumentError("the core returned NULL for a non-empty array")
    return np.ctypeslib.as_array(ptr, shape=(count,)).astype(dtype, copy=True)


def _attributes(handle, n: int, count_fn, attribute_fn) -> Dict[str, np.ndarray]:
    """Copies a result handle's named per-point arrays: name -> (n,) or (n, k) float64."""
    attributes = {}
    name = c_char_p()
    components = c_size_t()
    data = POINTER(c_double)()
    for i in range(count_fn(handle)):
        check(attribute_fn(handle, i, byref(name), byref(components), byref(data)))
        k = components.value
        values = _copy(data, n * k, np.float64)
        attributes[name.value.decode("utf-8", "replace")] = values.reshape(n, k) if k != 1 else values
    return attributes


class Surface:
    """A triangle mesh extracted by isobar, with per-vertex data, in numpy arrays.

    Attributes:
        points: (n, 3) float64 vertex positions (on the level set to the tolerance asked).
        normals: (n, 3) float32 unit normals from the field's gradient, pointing to
            decreasing field values (out of the fluid), or None when not computed.
        triangles: (m, 3) uint32 vertex indices, counter-clockwise seen from where the
            normals point.
        attributes: dict name -> float64 array, (n,) or (n, k): ``SumOfWeights``,
            ``Isovalue`` and the interpolated particle arrays that were asked for.
        stats: dict of the extraction statistics (cells, evaluations, corrections,
            seconds per phase, ``backend``: "cpu" or "gpu", where the seed search ran).
        warnings: list of what the extraction warned about although it succeeded (an
            isovalue never crossed, a kernel wider than the particle set); each was also
            issued as an :class:`isobar.IsobarWarning`.

    The arrays belong to numpy. The core's copy of the mesh is kept only for
    :meth:`write`; :meth:`release` (or garbage collection) frees it.
    """

    __slots__ = (
        "points",
        "normals",
        "triangles",
        "attributes",
        "stats",
        "warnings",
        "_handle",
        "_finalizer",
        "__weakref__",
    )

    def __init__(
        self,
        points: np.ndarray,
        triangles: np.ndarray,
        normals: Optional[np.ndarray] = None,
        attributes: Optional[Dict[str, np.ndarray]] = None,
        stats: Optional[Dict[str, float]] = None,
        warnings: Optional[List[str]] = None,
    ):
        """A surface from arrays (no core handle: :meth:`write` is unavailable)."""
        self.points = points
        self.triangles = triangles
        self.normals = normals
        self.attributes = dict(attributes or {})
        self.stats = dict(stats or {})
        self.warnings = list(warnings or [])
        self._handle = None
        self._finalizer = None

    @classmethod
    def _from_handle(cls, handle, normals_requested: bool = True) -> "Surface":
        """Copies everything out of a core surface and takes ownership of the handle."""
        try:
            n = lib.isobar_surface_vertex_count(handle)
            m = lib.isobar_surface_triangle_count(handle)
            points = _copy(lib.isobar_surface_positions(handle), 3 * n, np.float64).reshape(n, 3)
            triangles = _copy(lib.isobar_surface_triangles(handle), 3 * m, np.uint32).reshape(m, 3)
            normals_ptr = lib.isobar_surface_normals(handle)
            if normals_ptr and n:
                normals = _copy(normals_ptr, 3 * n, np.float32).reshape(n, 3)
            elif normals_requested and n == 0:
                normals = np.empty((0, 3), dtype=np.float32)
            else:
                normals = None
            attributes = _attributes(handle, n, lib.isobar_surface_attribute_count, lib.isobar_surface_attribute)
            stats = Stats()
            stats.struct_size = sizeof(Stats)
            check(lib.isobar_surface_stats(handle, byref(stats)))
            stats_dict = {f: getattr(stats, f) for f, _ in Stats._fields_ if f != "struct_size"}
            stats_dict["backend"] = backend_name(stats.backend)
            text = lib.isobar_surface_warnings(handle).decode("utf-8", "replace")
        except BaseException:
            lib.isobar_surface_free(handle)
            raise
        surface = cls(points, triangles, normals, attributes, stats_dict, text.splitlines())
        surface._handle = handle
        surface._finalizer = weakref.finalize(surface, lib.isobar_surface_free, handle)
        return surface

    # -- derived quantities -----------------------------------------------------------

    @property
    def n_points(self) -> int:
        """Number of vertices."""
        return int(self.points.shape[0])

    @property
    def n_triangles(self) -> int:
        """Number of triangles."""
        return int(self.triangles.shape[0])

    def __len__(self) -> int:
        """Number of triangles."""
        return self.n_triangles

    def area(self) -> float:
        """Total triangle area."""
        p = self.points[self.triangles.astype(np.intp)]
        return float(0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum())

    def volume(self) -> float:
        """Signed enclosed volume (divergence theorem); positive for a closed surface whose
        triangles are counter-clockwise seen from outside. Meaningful for closed surfaces."""
        p = self.points[self.triangles.astype(np.intp)]
        return float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0)

    # -- output -----------------------------------------------------------------------

    def write(self, path) -> None:
        """Writes the surface to a .ply, .obj or .vtp file (through the core's writers;
        .vtp keeps float64 positions).

        Raises:
            isobar.InvalidArgumentError: the core copy was released (or never existed).
            isobar.IoError, isobar.FormatError: unwritable path, unknown extension.
        """
        if self._handle is None:
            raise InvalidArgumentError(
                "this Surface has no core copy (released, or built from arrays); write it before release()"
            )
        check(lib.isobar_surface_write(self._handle, encode(path, "path")))

    def release(self) -> None:
        """Frees the core's copy of the mesh now; the numpy arrays stay."""
        if self._finalizer is not None:
            self._finalizer()
        self._handle = None

    def __enter__(self) -> "Surface":
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def __repr__(self) -> str:
        names = ", ".join(self.attributes)
        return f"<isobar.Surface {self.n_points} points, {self.n_triangles} triangles, attributes [{names}]>"


__all__ = ["Surface"]
