"""The bake cache: one .npz file per scene frame (numpy only, no bpy).

Layout of ``<folder>/frame_000012.npz`` (uncompressed, written atomically)::

    points      (n, 3) float32
    triangles   (m, 3) int32
    normals     (n, 3) float32            (absent when none were computed)
    a.<name>    (n,) or (n, k) float32    one per mesh attribute, Blender names
    fingerprint 0-d str                   the parameters and source it was made with
    info        0-d str                   JSON: vertices, triangles, seconds
    warnings    0-d str                   JSON list: the extraction's warnings (absent: none)

A cached frame is used only while its fingerprint equals the current one, so changing a
parameter after baking never shows a stale surface.
"""

from __future__ import annotations

import json
import os
import re
import tempfile
from typing import List, Optional, Tuple

import numpy as np

from .extraction import FrameMesh

_NAME = re.compile(r"frame_(-?\d{6,})\.npz\Z")


def frame_path(folder: str, frame: int) -> str:
    """Path of the cached `frame` in `folder`."""
    sign = "-" if frame < 0 else ""
    return os.path.join(folder, f"frame_{sign}{abs(frame):06d}.npz")


def write(path: str, mesh: FrameMesh, fingerprint: str, owner: str = "") -> None:
    """Writes one frame (to a temporary name first, then renamed: a reader never sees a
    half-written file). `owner` names the .blend file baking it (see :func:`owner`): another
    .blend file with an object of the same name and the same cache folder (two shots side
    by side) then bakes into a folder of its own instead of over these frames, and frees
    only its own."""
    folder = os.path.dirname(path) or "."
    os.makedirs(folder, exist_ok=True)
    arrays = {
        "points": np.ascontiguousarray(mesh.points, dtype=np.float32),
        "triangles": np.ascontiguousarray(mesh.triangles, dtype=np.int32),
        "fingerprint": np.array(fingerprint),
        "owner": np.array(owner),
        "info": np.array(json.dumps(mesh.info)),
    }
    if mesh.warnings:  # shown again when the baked frame plays
        arrays["warnings"] = np.array(json.dumps(mesh.warnings))
    if mesh.normals is not None:
        arrays["normals"] = np.ascontiguousarray(mesh.normals, dtype=np.float32)
    for name, values in mesh.attributes.items():
        arrays["a." + name] = np.ascontiguousarray(values, dtype=np.float32)
    fd, tmp = tempfile.mkstemp(prefix=".frame_", suffix=".npz.tmp", dir=folder)
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def read_fingerprint(path: str) -> Optional[str]:
    """The fingerprint stored in a cached frame, or None when the file is missing or not a
    cache file."""
    try:
        with np.load(path, allow_pickle=False) as data:
            return str(data["fingerprint"][()])
    except (OSError, KeyError, ValueError):
        return None


def read(path: str) -> Tuple[FrameMesh, str]:
    """Reads one cached frame: (mesh, fingerprint).

    Raises:
        OSError: the file cannot be read; ValueError/KeyError: it is not a cache file.
    """
    with np.load(path, allow_pickle=False) as data:
        points = data["points"]
        n = points.shape[0]
        mesh = FrameMesh(
            points=points.reshape(n, 3),
            triangles=data["triangles"].reshape(-1, 3),
            normals=data["normals"].reshape(n, 3) if "normals" in data.files else None,
            attributes={k[2:]: data[k] for k in data.files if k.startswith("a.")},
            info=json.loads(str(data["info"][()])) if "info" in data.files else {},
            warnings=json.loads(str(data["warnings"][()])) if "warnings" in data.files else [],
        )
        fingerprint = str(data["fingerprint"][()])
    return mesh, fingerprint


def frames(folder: str) -> List[int]:
    """Frames cached in `folder`, sorted."""
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    out = []
    for name in names:
        match = _NAME.match(name)
        if match:
            out.append(int(match.group(1)))
    return sorted(out)


def owner(folder: str) -> Optional[str]:
    """The .blend file (its name; '' for an unsaved one) that baked the frames in `folder`,
    as the first frame records it; None when there is none, or it records no owner."""
    for frame in frames(folder):
        try:
            with np.load(frame_path(folder, frame), allow_pickle=False) as data:
                return str(data["owner"][()]) if "owner" in data.files else None
        except (OSError, ValueError):
            continue
    return None


def clear(folder: str) -> int:
    """Deletes the cached frames in `folder` (only files named like cache frames, and the
    folder itself when that leaves it empty); returns how many were deleted."""
    removed = 0
    for frame in frames(folder):
        try:
            os.unlink(frame_path(folder, frame))
            removed += 1
        except OSError:
            pass
    try:
        os.rmdir(folder)
    except OSError:
        pass
    return removed


__all__ = ["clear", "frame_path", "frames", "owner", "read", "read_fingerprint", "write"]
