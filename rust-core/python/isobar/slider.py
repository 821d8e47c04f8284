"""Isovalue sliding on regular volumes (ISOSLIDER): build a store once, then move the
isovalue and get the updated surface in milliseconds::

    isobar.Slider.build("ct.vti", "ct.isoslider")          # or Slider.build_array(volume, ...)
    slider = isobar.Slider("ct.isoslider")
    update = slider.set_isovalue(420.0)
    update.points, update.normals, update.triangles         # numpy arrays
    update.added, update.removed, update.moved, update.seconds

The store is memory-mapped: the volume stays mostly on disk.
"""

from __future__ import annotations

import weakref
from ctypes import POINTER, byref, c_double, c_size_t, c_uint32, c_uint64
from typing import Optional

import numpy as np

from ._lib import PROGRESS_FN, SliderChange, SliderHandle, check, encode, lib
from .errors import InvalidArgumentError
from .surface import _copy

_NO_PROGRESS = PROGRESS_FN()


class SliderUpdate:
    """The surface after :meth:`Slider.set_isovalue`, and what changed.

    Attributes:
        isovalue: the isovalue now shown.
        points: (n, 3) float32 vertex positions (V).
        normals: (n, 3) float32 unit normals (N), pointing to decreasing values.
        triangles: (m, 3) uint32 vertex indices (I).
        added: (a, 3) uint32 triangles added, in the new vertex numbering.
        removed: (r, 3) uint32 triangles removed, in the previous vertex numbering.
        moved: (k, 2) uint32 (before, after) indices of vertices that changed index.
        edges_added, edges_removed: active-edge changes.
        seconds: wall time of the update in the core.
    """

    __slots__ = (
        "isovalue",
        "points",
        "normals",
        "triangles",
        "added",
        "removed",
        "moved",
        "edges_added",
        "edges_removed",
        "seconds",
    )

    def __repr__(self) -> str:
        return (
            f"SliderUpdate(isovalue={self.isovalue}, {len(self.points)} points, "
            f"{len(self.triangles)} triangles, +{len(self.added)} -{len(self.removed)}, "
            f"{self.seconds * 1e3:.3f} ms)"
        )


class Slider:
    """A memory-mapped slider store and the isosurface at the current isovalue."""

    __slots__ = ("_handle", "_finalizer", "path", "__weakref__")

    def __init__(self, path) -> None:
        handle = POINTER(SliderHandle)()
        check(lib.isobar_slider_open(encode(path, "store path"), byref(handle)))
        self._handle = handle
        self._finalizer = weakref.finalize(self, lib.isobar_slider_free, handle)
        self.path = str(path)

    @staticmethod
    def build(volume_path, store_path, array: Optional[str] = None, threshold: float = 0.0, max_levels: int = 0) -> None:
        """Precomputes a store from a .vti, .nrrd or .npy volume (defaults for 0 parameters)."""
        check(
            lib.isobar_slider_build_file(
                encode(volume_path, "volume path"),
                None if array is None else encode(array, "array"),
                encode(store_path, "store path"),
                float(threshold),
                int(max_levels),
                _NO_PROGRESS,
                None,
            )
        )

    @staticmethod
    def build_array(
        values: np.ndarray,
        store_path,
        origin=(0.0, 0.0, 0.0),
        spacing=(1.0, 1.0, 1.0),
        threshold: float = 0.0,
        max_levels: int = 0,
    ) -> None:
        """Precomputes a store from a 3-D array indexed ``[z, y, x]`` (x fastest)."""
        values = np.asarray(values)
        if values.ndim != 3:
            raise InvalidArgumentError(f"values must be a 3-D array [z, y, x], got shape {values.shape}")
        data = np.ascontiguousarray(values, dtype=np.float32)
        nz, ny, nx = data.shape
        dims = (c_size_t * 3)(nx, ny, nz)
        o = (c_double * 3)(*[float(v) for v in origin])
        s = (c_double * 3)(*[float(v) for v in spacing])
        check(
            lib.isobar_slider_build_f32(
                data.ctypes.data_as(POINTER(np.ctypeslib.ctypes.c_float)),
                dims,
                o,
                s,
                encode(store_path, "store path"),
                float(threshold),
                int(max_levels),
                _NO_PROGRESS,
                None,
            )
        )

    def _live(self):
        if not self._finalizer.alive:
            raise InvalidArgumentError("this slider was closed")
        return self._handle

    @property
    def value_range(self) -> tuple:
        """(min, max) of the volume's values."""
        lo, hi = c_double(), c_double()
        check(lib.isobar_slider_value_range(self._live(), byref(lo), byref(hi)))
        return lo.value, hi.value

    @property
    def stats(self) -> dict:
        """Updates applied so far and their total time in seconds."""
        n, t = c_uint64(), c_double()
        check(lib.isobar_slider_stats(self._live(), byref(n), byref(t)))
        return {"updates": n.value, "seconds": t.value}

    def set_isovalue(self, iso: float) -> SliderUpdate:
        """Moves the surface to `iso` and returns the new arrays and the change."""
        h = self._live()
        change = SliderChange()
        check(lib.isobar_slider_set_isovalue(h, float(iso), _NO_PROGRESS, None, byref(change)))
        n = lib.isobar_slider_vertex_count(h)
        m = lib.isobar_slider_triangle_count(h)
        u = SliderUpdate()
        u.isovalue = change.isovalue
        u.points = _copy(lib.isobar_slider_positions(h), 3 * n, np.float32).reshape(n, 3)
        u.normals = _copy(lib.isobar_slider_normals(h), 3 * n, np.float32).reshape(n, 3)
        u.triangles = _copy(lib.isobar_slider_triangles(h), 3 * m, np.uint32).reshape(m, 3)
        lists = []
        for which in (0, 1):
            count, data = c_size_t(), POINTER(c_uint32)()
            check(lib.isobar_slider_change_triangles(h, which, byref(count), byref(data)))
            lists.append(_copy(data, 3 * count.value, np.uint32).reshape(count.value, 3))
        u.added, u.removed = lists
        count, data = c_size_t(), POINTER(c_uint32)()
        check(lib.isobar_slider_change_moved(h, byref(count), byref(data)))
        u.moved = _copy(data, 2 * count.value, np.uint32).reshape(count.value, 2)
        u.edges_added = change.edges_added
        u.edges_removed = change.edges_removed
        u.seconds = change.seconds
        return u

    def close(self) -> None:
        """Frees the core's state and unmaps the store (also done on garbage collection)."""
        self._finalizer()

    def __enter__(self) -> "Slider":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Slider({self.path!r})"
