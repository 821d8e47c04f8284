"""Writing a :class:`FrameMesh` into a Blender mesh, in place, with numpy and foreach_set
(no per-vertex Python loops)."""

from __future__ import annotations

import bpy
import numpy as np

from .extraction import FrameMesh

# Attribute type and foreach key by component count.
_TYPES = {1: ("FLOAT", "value"), 2: ("FLOAT2", "vector"), 3: ("FLOAT_VECTOR", "vector"), 4: ("FLOAT_COLOR", "color")}


def write_object(obj, frame: FrameMesh) -> None:
    """Writes `frame` into `obj`'s mesh, first giving `obj` a mesh of its own when another
    surface the add-on writes shares it (a linked duplicate, Alt+D): each shows the surface
    of its own settings, and a shared mesh would show whichever was written last in both.
    A plain object sharing the mesh on purpose (Ctrl+L, the fluid shown twice) keeps it."""
    data = obj.data
    if data.users > 1 + int(data.use_fake_user) and any(
        o != obj and o.data == data and _writes_its_mesh(o) for o in bpy.data.objects
    ):
        obj.data = data.copy()
    write(obj.data, frame)


def _writes_its_mesh(obj) -> bool:
    """True for a fluid surface or a volume slider (objects whose mesh the add-on writes)."""
    return any(getattr(getattr(obj, group, None), "enabled", False) for group in ("isobar", "isobar_slider"))


def write(mesh: "bpy.types.Mesh", frame: FrameMesh) -> None:
    """Replaces the geometry of `mesh` with `frame`: vertices, triangles (smooth shaded),
    the SPH normals as custom normals and the point attributes. Materials stay."""
    points = np.ascontiguousarray(frame.points, dtype=np.float32).reshape(-1, 3)
    triangles = np.ascontiguousarray(frame.triangles, dtype=np.int32).reshape(-1, 3)
    n, m = points.shape[0], triangles.shape[0]
    if m and (triangles.min() < 0 or triangles.max() >= n):
        raise ValueError(f"triangle index out of range (mesh of {n} vertices)")

    mesh.clear_geometry()
    if n:
        mesh.vertices.add(n)
        mesh.vertices.foreach_set("co", points.ravel())
    if m:
        mesh.loops.add(3 * m)
        mesh.loops.foreach_set("vertex_index", triangles.ravel())
        mesh.polygons.add(m)
        # Face sizes follow from the offsets (loop_total is read-only since 4.0).
        mesh.polygons.foreach_set("loop_start", np.arange(0, 3 * m, 3, dtype=np.int32))
    mesh.update(calc_edges=True)

    if m:
        _shade_smooth(mesh, m)
    if frame.normals is not None and n and m:
        set_vertex_normals(mesh, frame.normals)
    for name, values in frame.attributes.items():
        write_attribute(mesh, name, values, n)
    mesh.update()


def _shade_smooth(mesh, m: int) -> None:
    if hasattr(mesh, "shade_smooth"):
        mesh.shade_smooth()
    else:  # Blender < 4.1
        mesh.polygons.foreach_set("use_smooth", np.ones(m, dtype=bool))


def set_vertex_normals(mesh, normals: np.ndarray) -> None:
    """Custom normals from per-vertex normals: a point-domain 'custom_normal' attribute
    where Blender reads one (free normals, 4.5+), else normals_split_custom_set_from_vertices."""
    normals = np.ascontiguousarray(normals, dtype=np.float32).reshape(-1, 3)
    attr = None
    existing = mesh.attributes.get("custom_normal")
    if existing is not None:
        mesh.attributes.remove(existing)
    try:
        attr = mesh.attributes.new("custom_normal", "FLOAT_VECTOR", "POINT")
        attr.data.foreach_set("vector", normals.ravel())
        if mesh.has_custom_normals:
            return
    except (RuntimeError, TypeError, AttributeError):
        pass
    if attr is not None:
        attr = mesh.attributes.get("custom_normal")
        if attr is not None:
            mesh.attributes.remove(attr)
    mesh.normals_split_custom_set_from_vertices(normals)


def write_attribute(mesh, name: str, values: np.ndarray, n: int) -> None:
    """Writes a point attribute: (n,) FLOAT, (n, 2) FLOAT2, (n, 3) FLOAT_VECTOR, (n, 4)
    FLOAT_COLOR; other component counts as one FLOAT attribute per component (name_0 ...)."""
    values = np.asarray(values, dtype=np.float32)
    if values.shape[0] != n:
        raise ValueError(f"attribute '{name}' has {values.shape[0]} values for {n} vertices")
    # Components from the shape, not reshape(n, -1): that cannot infer them for n = 0 (a
    # surface that is empty at this isovalue still carries its attributes).
    k = int(np.prod(values.shape[1:], dtype=np.int64))
    values = values.reshape(n, k)
    if k in _TYPES:
        _write_one(mesh, name, values, k)
    else:
        for i in range(k):
            _write_one(mesh, f"{name}_{i}", values[:, i : i + 1], 1)


def _write_one(mesh, name: str, values: np.ndarray, k: int) -> None:
    data_type, key = _TYPES[k]
    old = mesh.attributes.get(name)
    if old is not None:
        mesh.attributes.remove(old)
    attr = mesh.attributes.new(name, data_type, "POINT")
    attr.data.foreach_set(key, np.ascontiguousarray(values, dtype=np.float32).ravel())


def read_points(mesh) -> np.ndarray:
    """(n, 3) float32 vertex positions."""
    out = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", out)
    return out.reshape(-1, 3)


def read_triangles(mesh) -> np.ndarray:
    """(m, 3) int32 vertex indices of a triangle mesh."""
    out = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", out)
    return out.reshape(-1, 3)


def read_attribute(mesh, name: str) -> np.ndarray:
    """A point attribute as float32, (n,) or (n, k)."""
    attr = mesh.attributes[name]
    n = len(attr.data)
    for data_type, key in _TYPES.values():
        if attr.data_type == data_type:
            k = {"FLOAT": 1, "FLOAT2": 2, "FLOAT_VECTOR": 3, "FLOAT_COLOR": 4}[data_type]
            out = np.empty(n * k, dtype=np.float32)
            attr.data.foreach_get(key, out)
            return out if k == 1 else out.reshape(n, k)
    raise TypeError(f"attribute '{name}' is {attr.data_type}, not a float type")


__all__ = ["read_attribute", "read_points", "read_triangles", "set_vertex_normals", "write", "write_attribute"]
