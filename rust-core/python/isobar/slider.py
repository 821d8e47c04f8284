"""Isovalue sliding on regular volumes (ISOSLIDER): build a store once, then move the
isovalue and get the updated surface, at a cost that follows what changed (about a
millisecond for a small step on a smooth 256³ volume; tens of milliseconds on a noisy one,
where a step moves many edges)::

    isobar.Slider.build("ct.vti", "ct.isoslider")          # or Slider.build_array(volume, ...)
    slider = isobar.Slider("ct.isoslider")
    update = slider.set_isovalue(420.0)
    update.points, update.normals, update.triangles         # numpy arrays
    update.added, update.removed, update.moved, update.seconds
    slider.lod_error_bound = 0.01                            # level of detail (0: off)
    lod = slider.lod_mesh()                                  # lod.points, lod.normals, lod.triangles

The store is memory-mapped: the volume stays mostly on disk.
"""

from __future__ import annotations

import functools
import threading
import weakref
from ctypes import POINTER, byref, c_double, c_float, c_size_t, c_uint32, c_uint64
from typing import Optional

import numpy as np

from ._lib import PROGRESS_FN, SliderChange, SliderHandle, check, encode, lib
from .errors import InvalidArgumentError, issue
from .sph import ProgressCallback, _call
from .surface import _copy

_NO_PROGRESS = PROGRESS_FN()


def _budget(memory_budget) -> int:
    """A build's memory budget in bytes (0: the core's default), checked before the call."""
    if isinstance(memory_budget, bool) or not isinstance(memory_budget, int) or not 0 <= memory_budget < 2**64:
        raise InvalidArgumentError(f"memory_budget must be an integer number of bytes >= 0, got {memory_budget!r}")
    return memory_budget


def _wired(invoke, progress: Optional[ProgressCallback]) -> None:
    """Runs ``invoke(callback)`` (a build, an update) with sph's progress/cancel/Ctrl-C
    wiring. Neither has a result handle: nothing to free when a Ctrl-C comes after the
    core has finished (the store it wrote is complete, the update applied, so they stay)."""
    _call(lambda callback, _handle: invoke(callback), progress, None, lambda _handle: None)


def _one_at_a_time(method):
    """Runs a Slider method under the slider's lock: the core's slider is one mutable
    state, so calls from several threads take turns (two updates at once corrupted it),
    and close waits for a call in progress."""

    @functools.wraps(method)
    def locked(self, *args, **kwargs):
        with self._lock:
            return method(self, *args, **kwargs)

    return locked


def _triple(values, name: str) -> list:
    """Three floats (x, y, z), or InvalidArgumentError naming `name`: ctypes would pad two
    with a zero and fail on four with a bare IndexError."""
    try:
        if isinstance(values, (str, bytes)):
            raise TypeError(values)
        out = [float(v) for v in values]
    except (TypeError, ValueError):
        raise InvalidArgumentError(f"{name} must be three numbers (x, y, z), got {values!r}") from None
    if len(out) != 3:
        raise InvalidArgumentError(f"{name} must be three numbers (x, y, z), got {len(out)}: {values!r}")
    return out


def _issue_build_warnings() -> None:
    """Issues what the last build warned about (values wider than float32 that the store
    holds coarsely), from the caller of the public build method."""
    text = lib.isobar_last_warnings()
    issue([line for line in (text or b"").decode("utf-8", "replace").split("\n") if line], stacklevel=3)


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


class SliderLodMesh:
    """The level-of-detail surface (:meth:`Slider.lod_mesh`): merged cells where the field
    is close to trilinear, watertight where they meet finer ones; every vertex lies on the
    exact surface. At error bound 0 it is the exact mesh (vertices in another order).

    Attributes:
        error_bound: the bound it was made with (fraction of the value range).
        points: (n, 3) float32 vertex positions.
        normals: (n, 3) float32 unit normals, pointing to decreasing values.
        triangles: (m, 3) uint32 vertex indices, oriented like the exact mesh's.
    """

    __slots__ = ("error_bound", "points", "normals", "triangles")

    def __repr__(self) -> str:
        return (
            f"SliderLodMesh(error_bound={self.error_bound}, {len(self.points)} points, "
            f"{len(self.triangles)} triangles)"
        )


class Slider:
    """A memory-mapped slider store and the isosurface at the current isovalue.

    `lod_error_bound` (fraction of the value range, 0 = off) and `lod_max_level` (merge
    levels, 0 = the core's default 3) set the level of detail of :meth:`lod_mesh`; the
    exact arrays of :meth:`set_isovalue` do not depend on them.
    """

    __slots__ = ("_handle", "_finalizer", "_lock", "path", "__weakref__")

    def __init__(self, path, lod_error_bound: float = 0.0, lod_max_level: int = 0) -> None:
        self._lock = threading.RLock()
        handle = POINTER(SliderHandle)()
        check(lib.isobar_slider_open(encode(path, "store path"), byref(handle)))
        self._handle = handle
        self._finalizer = weakref.finalize(self, lib.isobar_slider_free, handle)
        self.path = str(path)
        if lod_error_bound or lod_max_level:
            self.set_lod(lod_error_bound, lod_max_level)

    @staticmethod
    def build(
        volume_path,
        store_path,
        array: Optional[str] = None,
        threshold: float = 0.0,
        max_levels: int = 0,
        memory_budget: int = 0,
        progress: Optional[ProgressCallback] = None,
    ) -> None:
        """Precomputes a store from a .vti, .nrrd or .npy volume (defaults for 0 parameters).

        ``memory_budget`` is the bytes the build may hold besides the volume; beyond about
        29 bytes a node it sorts the values on disk, beside the store (same store); the
        skip-list levels' open blocks stay in memory and grow with the surface (noisy
        volumes need more), and a budget too small for them is refused.

        ``progress`` is ``callable(fraction, phase)``, called on this thread between chunks
        of work; return None or True to go on, False to cancel (raises
        :class:`isobar.Cancelled`). An exception raised in it cancels the build and is
        re-raised here; Ctrl-C cancels too and raises KeyboardInterrupt. The store is
        written last and renamed into place whole: a build stopped before then leaves no
        store and no temporary file, and an earlier store at `store_path` as it was.
        """
        volume = encode(volume_path, "volume path")
        name = None if array is None else encode(array, "array")
        store = encode(store_path, "store path")
        budget = _budget(memory_budget)
        _wired(
            lambda callback: lib.isobar_slider_build_file(
                volume, name, store, float(threshold), int(max_levels), budget, callback, None
            ),
            progress,
        )
        _issue_build_warnings()

    @staticmethod
    def build_array(
        values: np.ndarray,
        store_path,
        origin=(0.0, 0.0, 0.0),
        spacing=(1.0, 1.0, 1.0),
        threshold: float = 0.0,
        max_levels: int = 0,
        memory_budget: int = 0,
        progress: Optional[ProgressCallback] = None,
    ) -> None:
        """Precomputes a store from a 3-D array indexed ``[z, y, x]`` (x fastest); the
        other parameters (``progress`` included) as :meth:`build`'s.

        The store holds float32. Types it holds exactly (float32 and narrower, 8- and
        16-bit integers) go as float32; wider ones (float64, 32- and 64-bit integers) go
        as float64, and the core narrows them: a finite value beyond float32's range
        raises :class:`InvalidInputError` naming the node, and a value range float32
        resolves coarsely (an offset far from zero) issues an :class:`IsobarWarning`."""
        o = (c_double * 3)(*_triple(origin, "origin"))
        s = (c_double * 3)(*_triple(spacing, "spacing"))
        values = np.asarray(values)
        if values.ndim != 3:
            raise InvalidArgumentError(f"values must be a 3-D array [z, y, x], got shape {values.shape}")
        # Types float32 holds exactly go as float32; wider ones (float64, 32- and 64-bit
        # integers) as float64, which the core narrows, saying what that loses.
        exact = values.dtype.kind in "biuf" and values.dtype.itemsize <= (4 if values.dtype.kind == "f" else 2)
        wide = not exact
        data = np.ascontiguousarray(values, dtype=np.float64 if wide else np.float32)
        nz, ny, nx = data.shape
        dims = (c_size_t * 3)(nx, ny, nz)
        store = encode(store_path, "store path")
        budget = _budget(memory_budget)
        build = lib.isobar_slider_build_f64 if wide else lib.isobar_slider_build_f32
        pointer = POINTER(np.ctypeslib.ctypes.c_double if wide else np.ctypeslib.ctypes.c_float)
        _wired(
            lambda callback: build(
                data.ctypes.data_as(pointer),
                dims,
                o,
                s,
                store,
                float(threshold),
                int(max_levels),
                budget,
                callback,
                None,
            ),
            progress,
        )
        _issue_build_warnings()

    def _live(self):
        if not self._finalizer.alive:
            raise InvalidArgumentError("this slider was closed")
        return self._handle

    @property
    @_one_at_a_time
    def value_range(self) -> tuple:
        """(min, max) of the volume's values."""
        lo, hi = c_double(), c_double()
        check(lib.isobar_slider_value_range(self._live(), byref(lo), byref(hi)))
        return lo.value, hi.value

    @property
    @_one_at_a_time
    def stats(self) -> dict:
        """Updates applied so far and their total time in seconds."""
        n, t = c_uint64(), c_double()
        check(lib.isobar_slider_stats(self._live(), byref(n), byref(t)))
        return {"updates": n.value, "seconds": t.value}

    @_one_at_a_time
    def set_isovalue(self, iso: float, progress: Optional[ProgressCallback] = None) -> SliderUpdate:
        """Moves the surface to `iso` and returns the new arrays and the change.

        `progress(fraction, phase)`, when given, is called during long walks (a jump
        across much of the value range on a large volume); returning False, or Ctrl-C,
        cancels the update with :class:`isobar.Cancelled` and the surface stays at the
        previous isovalue. Without it the call carries no callback: small steps, the
        slider's usual work, cost only the update itself.
        """
        h = self._live()
        change = SliderChange()
        invoke = lambda callback: lib.isobar_slider_set_isovalue(h, float(iso), callback, None, byref(change))  # noqa: E731
        if progress is None:
            check(invoke(_NO_PROGRESS))
        else:
            _wired(invoke, progress)
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

    @_one_at_a_time
    def set_lod(self, error_bound: float, max_level: int = 0) -> None:
        """Sets the level of detail of :meth:`lod_mesh`: `error_bound` in [0, 1) is the
        largest deviation of a merged cell from the samples it replaces, as a fraction of
        the value range (0: off; 0.001 is the paper's bound); `max_level` the most merge
        levels (0: default 3, at most 6). Raises InvalidArgumentError out of range."""
        if isinstance(max_level, bool) or int(max_level) != max_level or not 0 <= max_level <= 2**32 - 1:
            raise InvalidArgumentError(f"lod max_level must be an integer >= 0, got {max_level!r}")
        check(lib.isobar_slider_set_lod(self._live(), float(error_bound), int(max_level)))

    @_one_at_a_time
    def _lod(self) -> tuple:
        bound, level = c_double(), c_uint32()
        check(lib.isobar_slider_get_lod(self._live(), byref(bound), byref(level)))
        return bound.value, level.value

    @property
    def lod_error_bound(self) -> float:
        """Level-of-detail error bound, a fraction of the value range (0: off)."""
        return self._lod()[0]

    @lod_error_bound.setter
    def lod_error_bound(self, value: float) -> None:
        self.set_lod(value, self._lod()[1])

    @property
    def lod_max_level(self) -> int:
        """Most level-of-detail merge levels (a level-L cell spans 2^L lattice cells)."""
        return self._lod()[1]

    @lod_max_level.setter
    def lod_max_level(self, value: int) -> None:
        self.set_lod(self._lod()[0], value)

    @_one_at_a_time
    def lod_mesh(self) -> SliderLodMesh:
        """The level-of-detail mesh of the current surface at :attr:`lod_error_bound`
        (computed by the core on the first call after an update, O(surface))."""
        h = self._live()
        nv, nt = c_size_t(), c_size_t()
        p, n, t = POINTER(c_float)(), POINTER(c_float)(), POINTER(c_uint32)()
        check(lib.isobar_slider_lod_mesh(h, byref(nv), byref(nt), byref(p), byref(n), byref(t)))
        m = SliderLodMesh()
        m.error_bound = self._lod()[0]
        m.points = _copy(p, 3 * nv.value, np.float32).reshape(nv.value, 3)
        m.normals = _copy(n, 3 * nv.value, np.float32).reshape(nv.value, 3)
        m.triangles = _copy(t, 3 * nt.value, np.uint32).reshape(nt.value, 3)
        return m

    @_one_at_a_time
    def close(self) -> None:
        """Frees the core's state and unmaps the store (also done on garbage collection)."""
        self._finalizer()

    def __enter__(self) -> "Slider":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Slider({self.path!r})"
