"""One frame's triangle mesh in the arrays USD stores: float32 points, normals,
velocities and primvars, int32 topology, the float32 extent."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, Iterable, List, Mapping, Optional, Tuple, Union

import numpy as np

from .errors import InputError

#: Surface attributes the core always adds; "auto" primvars leave them out.
CORE_ATTRIBUTES = ("SumOfWeights", "Isovalue")

#: Particle array used for ``velocities`` when ``velocities="auto"``.
VELOCITY_ARRAY = "velocity"

_FLT_MAX = float(np.finfo(np.float32).max)
#: USD's empty extent (what UsdGeom.PointBased.ComputeExtent gives for no points).
EMPTY_EXTENT = np.array([[_FLT_MAX] * 3, [-_FLT_MAX] * 3], dtype=np.float32)


@dataclass
class FrameMesh:
    """A triangle mesh ready for USD.

    Attributes:
        points: (n, 3) float32.
        indices: (3m,) int32 face vertex indices (triangles, the core's winding:
            counter-clockwise seen from where the normals point, USD's ``rightHanded``).
        counts: (m,) int32, all 3.
        normals: (n, 3) float32 or None.
        velocities: (n, 3) float32 (units per second) or None.
        primvars: USD primvar name -> float32 (n,) or (n, k) values.
        extent: (2, 3) float32 [min, max] (USD's empty extent for no points).
        warnings: what the extraction warned about although it succeeded (the
            surface's ``warnings``: an isovalue the field never crosses, a kernel wider
            than the particles); not written to USD.
    """

    points: np.ndarray
    indices: np.ndarray
    counts: np.ndarray
    normals: Optional[np.ndarray] = None
    velocities: Optional[np.ndarray] = None
    primvars: Dict[str, np.ndarray] = field(default_factory=dict)
    extent: np.ndarray = field(default_factory=lambda: EMPTY_EXTENT.copy())
    warnings: List[str] = field(default_factory=list)

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_triangles(self) -> int:
        return int(self.counts.shape[0])

    def nbytes(self) -> int:
        arrays = [self.points, self.indices, self.counts, self.normals, self.velocities, *self.primvars.values()]
        return int(sum(a.nbytes for a in arrays if a is not None))


def _get(source: Any, *names: str):
    """The first of `names` present in a mapping or as an attribute."""
    for name in names:
        if isinstance(source, Mapping):
            if name in source and source[name] is not None:
                return source[name]
        elif getattr(source, name, None) is not None:
            return getattr(source, name)
    return None


def primvar_name(name: str) -> str:
    """A valid USD primvar base name for an array name ("velocity:x" -> "velocity_x")."""
    from pxr import Tf

    return Tf.MakeValidIdentifier(str(name)) if name else "_"


def _vectors(values, n: int, what: str) -> np.ndarray:
    arr = np.asarray(values)
    if arr.ndim != 2 or arr.shape != (n, 3):
        raise InputError(f"{what} must have shape ({n}, 3), got {arr.shape}")
    if not np.issubdtype(arr.dtype, np.number):
        raise InputError(f"{what} must be numbers, got dtype {arr.dtype}")
    out = np.ascontiguousarray(arr, dtype=np.float32)
    if out.size and not np.isfinite(out).all():
        raise InputError(f"{what} holds a NaN or infinite value (or one beyond float32's range)")
    return out


def _per_vertex(values, n: int, what: str) -> np.ndarray:
    arr = np.asarray(values)
    if arr.ndim == 0 or arr.shape[0] != n:
        raise InputError(f"{what} must have one value per point ({n}), got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.number):
        raise InputError(f"{what} must be numbers, got dtype {arr.dtype}")
    arr = arr.reshape(n, -1) if arr.ndim > 2 else arr
    if arr.ndim == 2 and arr.shape[1] == 1:
        arr = arr[:, 0]
    return np.ascontiguousarray(arr, dtype=np.float32)


def extent_of(points: np.ndarray) -> np.ndarray:
    """[min, max] of float32 points, as UsdGeom.PointBased.ComputeExtent gives it."""
    if points.shape[0] == 0:
        return EMPTY_EXTENT.copy()
    return np.stack([points.min(axis=0), points.max(axis=0)]).astype(np.float32)


def to_mesh(
    source: Any,
    primvars: Union[str, None, Iterable[str]] = "auto",
    velocities: Union[str, None, bool, np.ndarray] = "auto",
) -> FrameMesh:
    """Converts an extracted surface into a :class:`FrameMesh`.

    Args:
        source: an :class:`isobar.Surface`; a mapping (or object) with ``points`` (n, 3),
            ``triangles`` (m, 3) (or ``faceVertexIndices``), optional ``normals`` (n, 3),
            ``velocities`` (n, 3), ``attributes`` (name -> (n,) or (n, k)) and
            ``warnings`` (a list of str, as an isobar.Surface has); or a tuple
            ``(points, triangles[, normals[, attributes]])``.
        primvars: attribute names to write as vertex primvars; ``"auto"`` for every
            attribute except the core's own (``SumOfWeights``, ``Isovalue``) and the one
            used for velocities; None or ``()`` for none.
        velocities: ``"auto"`` (a ``velocities`` array, else the 3-component attribute
            ``velocity`` when there is one), an attribute name, an (n, 3) array, or
            None/False for none.

    Raises:
        InputError: missing or misshapen arrays, an index out of range, a named attribute
            that is not there.
    """
    if isinstance(source, tuple):
        parts = dict(zip(("points", "triangles", "normals", "attributes"), source))
        source = parts
    points_in = _get(source, "points")
    triangles_in = _get(source, "triangles", "faceVertexIndices", "faces")
    if points_in is None:
        raise InputError("the frame has no points array")
    if triangles_in is None:
        raise InputError("the frame has no triangles array")
    pts = np.asarray(points_in)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points must have shape (n, 3), got {pts.shape}")
    n = pts.shape[0]
    points = _vectors(pts, n, "points")

    tri = np.asarray(triangles_in)
    if tri.ndim == 1 and tri.size % 3 == 0:
        tri = tri.reshape(-1, 3)
    if tri.ndim != 2 or tri.shape[1] != 3:
        raise InputError(f"triangles must have shape (m, 3), got {tri.shape}")
    if tri.size and not np.issubdtype(tri.dtype, np.integer):
        raise InputError(f"triangles must be integer vertex indices, got dtype {tri.dtype}")
    if tri.size:
        lo, hi = int(tri.min()), int(tri.max())
        if lo < 0 or hi >= n:
            bad = lo if lo < 0 else hi
            raise InputError(f"triangle vertex index {bad} is out of range for {n} points")
    indices = np.ascontiguousarray(tri, dtype=np.int32).reshape(-1)
    counts = np.full(tri.shape[0], 3, dtype=np.int32)

    normals_in = _get(source, "normals")
    normals = _vectors(normals_in, n, "normals") if normals_in is not None else None

    attributes = _get(source, "attributes", "primvars") or {}
    if not isinstance(attributes, Mapping):
        raise InputError("attributes must be a mapping name -> per-point values")

    # Velocities.
    vel = None
    used_for_velocities = None
    if velocities is None or velocities is False:
        pass
    elif isinstance(velocities, str):
        direct = _get(source, "velocities") if velocities == "auto" else None
        if direct is not None:
            vel = _vectors(direct, n, "velocities")
        elif velocities == "auto":
            candidate = attributes.get(VELOCITY_ARRAY)
            if candidate is not None and np.ndim(candidate) == 2 and np.shape(candidate)[1] == 3:
                vel = _vectors(candidate, n, f"attribute '{VELOCITY_ARRAY}'")
                used_for_velocities = VELOCITY_ARRAY
        else:
            if velocities not in attributes:
                raise InputError(
                    f"no attribute '{velocities}' for velocities (attributes: {', '.join(attributes) or 'none'})"
                )
            vel = _vectors(attributes[velocities], n, f"attribute '{velocities}' (velocities)")
            used_for_velocities = velocities
    else:
        vel = _vectors(velocities, n, "velocities")

    # Primvars.
    if primvars is None:
        chosen: List[str] = []
    elif isinstance(primvars, str) and primvars == "auto":
        chosen = [k for k in attributes if k not in CORE_ATTRIBUTES and k != used_for_velocities]
    elif isinstance(primvars, str):
        chosen = [primvars]
    else:
        chosen = list(primvars)
    out: Dict[str, np.ndarray] = {}
    origin: Dict[str, str] = {}
    for name in chosen:
        if name not in attributes:
            raise InputError(f"no attribute '{name}' on the surface (attributes: {', '.join(attributes) or 'none'})")
        usd_name = primvar_name(name)
        if usd_name in out:
            raise InputError(f"attributes '{origin[usd_name]}' and '{name}' both become primvar '{usd_name}'")
        out[usd_name] = _per_vertex(attributes[name], n, f"attribute '{name}'")
        origin[usd_name] = name

    return FrameMesh(
        points=points,
        indices=indices,
        counts=counts,
        normals=normals,
        velocities=vel,
        primvars=out,
        extent=extent_of(points),
        warnings=[str(w) for w in _get(source, "warnings") or ()],
    )


# -- the attribute schema of a frame --------------------------------------------------

#: (attribute name, Sdf value type name, interpolation or "", elementSize or 0)
SchemaEntry = Tuple[str, str, str, int]


def primvar_type(values: np.ndarray) -> Tuple[str, int]:
    """(Sdf type name, elementSize) for per-vertex float32 values."""
    if values.ndim == 1:
        return "float[]", 0
    k = values.shape[1]
    if k in (2, 3, 4):
        return f"float{k}[]", 0
    return "float[]", int(k)


def schema_of(mesh: FrameMesh) -> List[SchemaEntry]:
    """The time-sampled attributes a frame authors, with their types and metadata."""
    entries: List[SchemaEntry] = [
        ("extent", "float3[]", "", 0),
        ("faceVertexCounts", "int[]", "", 0),
        ("faceVertexIndices", "int[]", "", 0),
        ("points", "point3f[]", "", 0),
    ]
    if mesh.normals is not None:
        entries.append(("normals", "normal3f[]", "vertex", 0))
    if mesh.velocities is not None:
        entries.append(("velocities", "vector3f[]", "", 0))
    for name, values in mesh.primvars.items():
        type_name, element_size = primvar_type(values)
        entries.append((f"primvars:{name}", type_name, "vertex", element_size))
    return sorted(entries)


__all__ = ["FrameMesh", "to_mesh", "schema_of", "extent_of", "primvar_name", "EMPTY_EXTENT"]
