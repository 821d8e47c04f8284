"""Oriented point samples (isobar's high-order FE isosurfaces) as a UsdGeomPoints.

The samples of ``isobar.sample_fe`` become one Points prim: ``points``, ``normals``,
``widths`` (twice each sample's radius, which reaches the sample's Voronoi cell, so
the disks cover the surface) and the per-sample
arrays as vertex primvars (``Element`` int, ``Curvature`` and ``Energy`` float,
``Reference`` float3), under a root Xform that is the stage's defaultPrim::

    import isobar, isobar_usd
    samples = isobar.sample_fe(isobar.FeMesh.read("solution.vtu"), "p", 0.0)
    isobar_usd.write_points(samples, "surface.usd")
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Union

import numpy as np

from . import _atomic
from .errors import InputError
from .layers import StageSettings, _array, _pxr, _stage_metadata, check_output_path
from .mesh import primvar_name

#: USD type of each array ``isobar.sample_fe`` returns.
_PRIMVAR_TYPES = {"Element": "int[]", "Curvature": "float[]", "Energy": "float[]", "Reference": "float3[]"}


def write_points(
    samples,
    output: Union[str, Path],
    time: Optional[float] = None,
    fps: float = 24.0,
    meters_per_unit: float = 1.0,
    up_axis: str = "Y",
    prim: str = "FE",
    points: str = "Samples",
) -> Path:
    """Writes `samples` (an ``isobar.Samples``) as ``/<prim>/<points>`` to a new stage at
    `output` (through a staging file renamed over it: the old file stays intact on
    failure). With `time`, values are time samples at that time code. Returns the path."""
    Sdf, Usd, UsdGeom, Vt = _pxr()
    output = check_output_path(Path(output))
    settings = StageSettings(fps, meters_per_unit, up_axis, prim, points).checked()
    xyz = np.ascontiguousarray(samples.points, dtype=np.float64).reshape(-1, 3)
    n = xyz.shape[0]
    if not np.isfinite(xyz).all():
        raise InputError("the samples have non-finite positions")
    radii = np.asarray(samples.radii, dtype=np.float64).reshape(-1)
    normals = np.asarray(samples.normals, dtype=np.float32).reshape(-1, 3)
    if radii.shape[0] != n or normals.shape[0] != n:
        raise InputError(f"{n} samples but {radii.shape[0]} radii and {normals.shape[0]} normals")
    when = Usd.TimeCode.Default() if time is None else Usd.TimeCode(float(time))
    stage = Usd.Stage.CreateInMemory()
    start = end = 0.0 if time is None else float(time)
    _stage_metadata(stage, settings, start, end)
    root = UsdGeom.Xform.Define(stage, settings.root_path)
    Usd.ModelAPI(root.GetPrim()).SetKind("component")
    stage.SetDefaultPrim(root.GetPrim())
    geom = UsdGeom.Points.Define(stage, settings.mesh_path)
    point_values = _array(xyz, "point3f[]")
    width_values = _array(2.0 * radii, "float[]")
    geom.CreatePointsAttr().Set(point_values, when)
    geom.CreateNormalsAttr().Set(_array(normals, "normal3f[]"), when)
    geom.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    geom.CreateWidthsAttr().Set(width_values, when)
    geom.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    # The extent of points includes their widths (UsdGeomPoints' own rule).
    extent = UsdGeom.Points.ComputeExtent(point_values, width_values) if n else Vt.Vec3fArray(2)
    geom.CreateExtentAttr().Set(extent, when)
    api = UsdGeom.PrimvarsAPI(geom.GetPrim())
    for name, values in samples.arrays.items():
        type_name = _PRIMVAR_TYPES.get(name) or ("float3[]" if np.ndim(values) == 2 else "float[]")
        pv = api.CreatePrimvar(primvar_name(name), Sdf.ValueTypeNames.Find(type_name), UsdGeom.Tokens.vertex)
        pv.Set(_array(np.asarray(values), type_name), when)
    layer = stage.GetRootLayer()
    layer.customLayerData = {"isobarUsd": {"kind": "fe-samples", "samples": int(n)}}
    layer.documentation = "isobar high-order FE isosurface samples, written by isobar_usd"
    with _atomic.atomic_path(output) as staged:
        if not layer.Export(str(staged)):
            raise OSError(f"USD could not write {staged}")
    return output


def write_fe_samples(
    input: Union[str, Path],
    output: Union[str, Path],
    field: str,
    iso: float,
    spacing: float = 0.0,
    rho: float = 0.0,
    tolerance: Optional[float] = None,
    progress=None,
    **stage,
):
    """Samples the isosurface ``field == iso`` of the Lagrange cells in `input` (.vtu) with
    isobar's particle system and writes the samples with :func:`write_points`. Returns
    (path, samples). What the sampling warns about (an isovalue the field never crosses,
    which writes no points) is in ``samples.warnings``, not issued again through Python's
    ``warnings``: the CLI prints it."""
    import isobar

    check_output_path(Path(output))
    with isobar.quiet_warnings():
        samples = isobar.sample_fe(
            isobar.FeMesh.read(str(input)), field, iso, spacing=spacing, rho=rho, tolerance=tolerance, progress=progress
        )
    return write_points(samples, output, **stage), samples


__all__ = ["write_fe_samples", "write_points"]
