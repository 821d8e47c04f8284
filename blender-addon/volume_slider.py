"""Isovalue sliding on volumes (isobar's ISOSLIDER): no UI here.

A volume (.vti, .nrrd, .npy, or a store already built) is pre-encoded once into an
``.isoslider`` store beside it; an object then keeps an open ``isobar.Slider`` on that
store, and each isovalue change asks the core for the changed surface (milliseconds for
small changes) and writes it into the object's mesh in place.
"""

from __future__ import annotations

import os
from typing import Dict, Tuple

import numpy as np

from . import mesh as mesh_io
from .extraction import FrameMesh, isobar_module

#: Extensions of volumes the core reads, and of its stores.
VOLUME_EXTENSIONS = (".vti", ".nrrd", ".npy")
STORE_EXTENSION = ".isoslider"

# Open sliders by object (session_uid), with the store each was opened on: a slider
# holds the run-time state (active edges, triangle lists) that makes the next change
# cheap, so it must outlive one update.
_OPEN: Dict[int, Tuple[str, object]] = {}


def store_path_for(path: str) -> str:
    """The store of `path`: the path itself for a store, else `<volume>.isoslider`."""
    return path if path.endswith(STORE_EXTENSION) else path + STORE_EXTENSION


def ensure_store(path: str) -> str:
    """Builds the store of the volume at `path` unless an up-to-date one exists; returns
    its path. Raises isobar.Error (naming the file) when the volume cannot be read."""
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no such volume file: {path}")
    store = store_path_for(path)
    if store != path and (not os.path.exists(store) or os.path.getmtime(store) < os.path.getmtime(path)):
        isobar_module().Slider.build(path, store)
    return store


def slider_for(obj, store: str):
    """The object's open slider on `store` (opened on first use or after a change)."""
    key = obj.session_uid
    opened = _OPEN.get(key)
    if opened is not None and opened[0] == store:
        return opened[1]
    close(obj)
    slider = isobar_module().Slider(store)
    _OPEN[key] = (store, slider)
    return slider


def close(obj) -> None:
    opened = _OPEN.pop(obj.session_uid, None)
    if opened is not None:
        opened[1].close()


def close_all() -> None:
    for _store, slider in _OPEN.values():
        slider.close()
    _OPEN.clear()


def slide(obj, store: str, isovalue: float):
    """Moves the object's surface to `isovalue` and writes it into its mesh; returns the
    core's update (counts and time)."""
    update = slider_for(obj, store).set_isovalue(float(isovalue))
    frame = FrameMesh(
        points=np.ascontiguousarray(update.points, dtype=np.float32),
        triangles=np.ascontiguousarray(update.triangles, dtype=np.int32),
        normals=np.ascontiguousarray(update.normals, dtype=np.float32),
    )
    mesh_io.write(obj.data, frame)
    return update


__all__ = ["STORE_EXTENSION", "VOLUME_EXTENSIONS", "close", "close_all", "ensure_store", "slide", "slider_for", "store_path_for"]
