"""Isovalue sliding on volumes (isobar's ISOSLIDER): no UI here.

A volume (.vti, .nrrd, .npy, or a store already built) is pre-encoded once into an
``.isoslider`` store beside it; an object then keeps an open ``isobar.Slider`` on that
store, and each isovalue change asks the core for the changed surface (milliseconds for
small changes) and writes it into the object's mesh in place.

With a level-of-detail error bound above 0 the mesh is the core's level of detail of
that surface instead (fewer triangles where the field is nearly trilinear, still closed,
every vertex on the exact surface); changing only the bound re-runs the level of detail
and does not slide.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np

from . import mesh as mesh_io
from .extraction import FrameMesh, isobar_module

#: Extensions of volumes the core reads, and of its stores.
VOLUME_EXTENSIONS = (".vti", ".nrrd", ".npy")
STORE_EXTENSION = ".isoslider"

# Open sliders by object (session_uid): [store, slider, isovalue it stands at (None
# before the first slide)]. A slider holds the run-time state (active edges, triangle
# lists) that makes the next change cheap, so it must outlive one update.
_OPEN: Dict[int, List[object]] = {}


@dataclass
class Shown:
    """What :func:`show` wrote into the mesh."""

    triangles: int
    #: Core time of the isovalue change (0 when only the level of detail changed).
    seconds: float
    #: Whether the slider moved (False: only the level of detail was redone).
    slid: bool


def store_path_for(path: str) -> str:
    """The store of `path`: the path itself for a store, else `<volume>.isoslider`."""
    return path if path.endswith(STORE_EXTENSION) else path + STORE_EXTENSION


def ensure_store(path: str, memory_budget_gib: float = 0.0, progress=None) -> Tuple[str, List[str]]:
    """Builds the store of the volume at `path` unless an up-to-date one exists; returns
    its path and what the build warned about (values wider than float32, float64 or 32/64-bit
    integers, that the store holds coarsely as float32), for the caller to show. `memory_budget_gib` bounds what the build holds
    besides the volume (0: the core's default; past about 29 bytes a node it sorts on
    disk, beside the store). Raises isobar.Error (naming the file) when the volume cannot
    be read or the budget is too small. `progress` (fraction, phase) sees the build, which
    takes seconds for a 256³ volume."""
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no such volume file: {path}")
    store = store_path_for(path)
    said: List[str] = []
    if store != path and not _store_is_current(store, path):
        budget = int(min(max(memory_budget_gib, 0.0), 1.0e9) * 2**30)
        isobar = isobar_module()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", isobar.IsobarWarning)
            isobar.Slider.build(path, store, memory_budget=budget, progress=progress)
        for w in caught:
            if issubclass(w.category, isobar.IsobarWarning):
                said.append(f"{os.path.basename(path)}: {w.message}")
            else:  # not ours to report: shown as Python would have
                warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    return store, said


def _store_is_current(store: str, volume: str) -> bool:
    """Whether `store` exists, is newer than `volume` and opens: a store an earlier isobar
    wrote in another format version (or a damaged one) is rebuilt like a stale one, not
    shown as an error."""
    if not os.path.exists(store) or os.path.getmtime(store) < os.path.getmtime(volume):
        return False
    isobar = isobar_module()
    try:
        isobar.Slider(store).close()
    except isobar.FormatError:
        return False
    return True


def rebuild_if_stale(obj, volume: str, store: str) -> bool:
    """Rebuilds `store` when the file `volume` was written after it (the object's open
    slider, on the old store, is closed); returns whether it did. Only the dates are
    compared, cheap enough for every isovalue change; a store imported by itself, or
    whose volume is gone, is used as it is."""
    if not volume or volume == store or not os.path.isfile(volume):
        return False
    if os.path.exists(store) and os.path.getmtime(store) >= os.path.getmtime(volume):
        return False
    close(obj)
    for text in ensure_store(volume)[1]:
        print(f"isobar: warning: {text}")
    return True


def slider_for(obj, store: str):
    """The object's open slider on `store` (opened on first use or after a change)."""
    key = obj.session_uid
    opened = _OPEN.get(key)
    if opened is not None and opened[0] == store:
        return opened[1]
    close(obj)
    slider = isobar_module().Slider(store)
    _OPEN[key] = [store, slider, None]
    return slider


def close(obj) -> None:
    opened = _OPEN.pop(obj.session_uid, None)
    if opened is not None:
        opened[1].close()


def close_all() -> None:
    for opened in _OPEN.values():
        opened[1].close()
    _OPEN.clear()


def show(obj, store: str, isovalue: float, lod_error_bound: float = 0.0) -> Shown:
    """Shows the surface of `isovalue` in the object's mesh: the exact surface, or with
    `lod_error_bound` > 0 (a fraction of the value range) the core's level of detail of
    it. Slides only when the isovalue differs from the one the object's slider stands at,
    so a new bound alone re-runs just the level of detail. Raises isobar.Error on a bad
    bound (the mesh is then left as it was)."""
    slider = slider_for(obj, store)
    opened = _OPEN[obj.session_uid]
    iso = float(isovalue)
    update: Optional[object] = None
    if opened[2] != iso:
        opened[2] = None
        update = slider.set_isovalue(iso)
        opened[2] = iso
    bound = float(lod_error_bound)
    if bound > 0.0 or update is None:
        # At bound 0 the core's level of detail is the exact mesh (vertices in another
        # order): the exact surface without a slide.
        slider.set_lod(bound)
        lod = slider.lod_mesh()
        points, triangles, normals = lod.points, lod.triangles, lod.normals
    else:
        points, triangles, normals = update.points, update.triangles, update.normals
    frame = FrameMesh(
        points=np.ascontiguousarray(points, dtype=np.float32),
        triangles=np.ascontiguousarray(triangles, dtype=np.int32),
        normals=np.ascontiguousarray(normals, dtype=np.float32),
    )
    mesh_io.write_object(obj, frame)
    return Shown(
        triangles=int(frame.triangles.shape[0]),
        seconds=float(update.seconds) if update is not None else 0.0,
        slid=update is not None,
    )


__all__ = ["STORE_EXTENSION", "VOLUME_EXTENSIONS", "close", "close_all", "Shown", "ensure_store", "rebuild_if_stale", "show", "slider_for", "store_path_for"]
