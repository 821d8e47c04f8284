"""Isosurfaces of high-order finite elements as Blender point clouds: no UI here.

A .vtu of Lagrange cells (or a Gmsh .msh v4 with high-order elements and $NodeData) is read once per object into an ``isobar.FeMesh`` (the core checks
and links the cells then); each isovalue or spacing change samples the isosurface again on
that mesh and replaces the object's point cloud: points on the exact level set of the
elements' polynomials, with ``radius`` (the disk each point stands for, which Cycles and
EEVEE render), ``normal``, ``element``, ``curvature`` and ``reference`` attributes.
"""

from __future__ import annotations

import os
from typing import Dict, List, Tuple

import bpy
import numpy as np

from .extraction import isobar_module

#: Extensions of the FE files the core reads.
FE_EXTENSIONS = (".vtu", ".msh")

# Meshes by object (session_uid) with the file each was read from: reading and checking
# the cells is the slow part that an isovalue change must not repeat.
_OPEN: Dict[int, Tuple[str, object]] = {}


def mesh_for(obj, path: str):
    """The object's FE mesh read from `path` (read on first use or after a change)."""
    opened = _OPEN.get(obj.session_uid)
    if opened is not None and opened[0] == path:
        return opened[1]
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no such finite-element file: {path}")
    mesh = isobar_module().FeMesh.read(path)
    _OPEN[obj.session_uid] = (path, mesh)
    return mesh


def close(obj) -> None:
    _OPEN.pop(obj.session_uid, None)


def close_all() -> None:
    _OPEN.clear()


def scalar_fields(mesh) -> List[Tuple[str, float, float, float]]:
    """(name, min, max, median) of each scalar point array of `mesh`."""
    return [
        (name, float(v.min()), float(v.max()), float(np.median(v)))
        for name, v in mesh.arrays.items()
        if v.ndim == 1 and v.size
    ]


def point_cloud(name: str, samples) -> "bpy.types.PointCloud":
    """A new PointCloud datablock holding `samples` and their attributes.

    bpy has no call that sizes a point cloud, so the points go into a temporary mesh that
    Blender's own Convert to Point Cloud turns into one (attributes carried over)."""
    n = len(samples)
    mesh = bpy.data.meshes.new(name)
    if n:
        mesh.vertices.add(n)
        mesh.vertices.foreach_set("co", np.ascontiguousarray(samples.points, dtype=np.float32).ravel())
    columns = {
        "radius": ("FLOAT", "value", samples.radii),
        "normal": ("FLOAT_VECTOR", "vector", samples.normals),
        "element": ("INT", "value", samples.arrays["Element"].astype(np.int32)),
        "curvature": ("FLOAT", "value", samples.arrays["Curvature"]),
        "reference": ("FLOAT_VECTOR", "vector", samples.arrays["Reference"]),
    }
    for attr, (kind, key, values) in columns.items():
        a = mesh.attributes.new(attr, kind, "POINT")
        if n:
            dtype = np.int32 if kind == "INT" else np.float32
            a.data.foreach_set(key, np.ascontiguousarray(values, dtype=dtype).ravel())
    mesh.update()
    carrier = bpy.data.objects.new(name, mesh)
    scene = bpy.context.scene
    scene.collection.objects.link(carrier)
    try:
        with bpy.context.temp_override(
            active_object=carrier, object=carrier, selected_objects=[carrier], selected_editable_objects=[carrier]
        ):
            result = bpy.ops.object.convert(target="POINTCLOUD")
        if "FINISHED" not in result or carrier.type != "POINTCLOUD":
            raise RuntimeError(f"Blender could not convert the samples to a point cloud ({result})")
        cloud = carrier.data
        cloud.name = name
        return cloud
    finally:
        bpy.data.objects.remove(carrier)
        if mesh.users == 0:
            bpy.data.meshes.remove(mesh)


def resample(obj, path: str, field: str, iso: float, spacing: float, rho: float, progress=None):
    """Samples the isosurface again on the object's mesh and swaps its point cloud (the
    materials stay). Returns the isobar.Samples; what the sampling warns about (an
    isovalue the field never crosses) is in its ``warnings`` and nowhere else: the caller
    shows them, so Python's copy would print each twice."""
    isobar = isobar_module()
    with isobar.quiet_warnings():
        samples = isobar.sample_fe(
            mesh_for(obj, path), field, float(iso), spacing=float(spacing), rho=float(rho), progress=progress
        )
    old = obj.data
    name = old.name if old is not None else obj.name
    cloud = point_cloud(name, samples)
    if old is not None:
        for material in old.materials:
            cloud.materials.append(material)
    obj.data = cloud
    if old is not None and old.users == 0:
        bpy.data.pointclouds.remove(old)
        cloud.name = name  # it was made beside the old one (name.001): one name for good
    return samples


__all__ = ["FE_EXTENSIONS", "close", "close_all", "mesh_for", "point_cloud", "resample", "scalar_fields"]
