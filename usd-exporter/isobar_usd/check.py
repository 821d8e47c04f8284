"""Checking a written stage: usd-core's validators plus the per-frame mesh checks they
lack (usd-core 26.x has no topology validator)."""

from __future__ import annotations

import os
from pathlib import Path
from dataclasses import dataclass
from typing import List, Optional, Union

import numpy as np


@dataclass
class Problem:
    """One finding: `severity` is "error" or "warning"; `where` a prim path (or "/") and
    `time` the time code (None for the stage or default values)."""

    severity: str
    check: str
    where: str
    time: Optional[float]
    message: str

    def __str__(self) -> str:
        at = f" at time {self.time:g}" if self.time is not None else ""
        return f"{self.severity}: {self.check}: {self.where}{at}: {self.message}"


def _validator_problems(stage) -> List[Problem]:
    from pxr import UsdValidation

    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    problems = []
    for error in context.Validate(stage):
        kind = str(error.GetType()).rsplit(".", 1)[-1]
        severity = {"Error": "error", "Warn": "warning", "Info": "info"}.get(kind)
        if severity is None:  # ValidationErrorType.None_: nothing to report
            continue
        sites = []
        for site in error.GetSites():
            if site.IsPrim():
                sites.append(str(site.GetPrim().GetPath()))
            elif site.IsProperty():
                sites.append(str(site.GetProperty().GetPath()))
        problems.append(Problem(severity, f"validator {error.GetName()}", ", ".join(sites) or "/", None, error.GetMessage()))
    return problems


def _sample_times(attrs) -> List[float]:
    times = set()
    for attr in attrs:
        if attr and attr.HasAuthoredValue():
            times.update(attr.GetTimeSamples())
    return sorted(times)


def _mesh_problems(mesh, max_frames: Optional[int]) -> List[Problem]:
    from pxr import UsdGeom

    where = str(mesh.GetPath())
    problems: List[Problem] = []

    def add(check, time, message, severity="error"):
        problems.append(Problem(severity, check, where, time, message))

    points_attr = mesh.GetPointsAttr()
    counts_attr = mesh.GetFaceVertexCountsAttr()
    indices_attr = mesh.GetFaceVertexIndicesAttr()
    normals_attr = mesh.GetNormalsAttr()
    extent_attr = mesh.GetExtentAttr()
    velocities_attr = mesh.GetVelocitiesAttr()
    primvars = [pv for pv in UsdGeom.PrimvarsAPI(mesh).GetPrimvarsWithAuthoredValues()]
    times = _sample_times([points_attr, counts_attr, indices_attr, normals_attr, extent_attr])
    if not times:
        if points_attr.HasAuthoredValue():
            times = []
        else:
            add("mesh", None, "no points authored")
            return problems
    # The default value too, when one is authored (a frame written without time).
    check_times = list(times[:max_frames] if max_frames else times)
    for time in check_times:
        points = points_attr.Get(time)
        counts = counts_attr.Get(time)
        indices = indices_attr.Get(time)
        if points is None or counts is None or indices is None:
            missing = [n for n, v in (("points", points), ("faceVertexCounts", counts), ("faceVertexIndices", indices)) if v is None]
            add("topology", time, f"no value for {', '.join(missing)}")
            continue
        n = len(points)
        ok, reason = UsdGeom.Mesh.ValidateTopology(indices, counts, n)
        if not ok:
            add("topology", time, reason)
        if normals_attr.HasAuthoredValue():
            normals = normals_attr.Get(time)
            interpolation = mesh.GetNormalsInterpolation()
            expected = {"vertex": n, "varying": n, "faceVarying": len(indices), "uniform": len(counts), "constant": 1}.get(
                interpolation
            )
            if normals is None:
                add("normals", time, "no value")
            elif expected is not None and len(normals) != expected:
                add("normals", time, f"{len(normals)} normals for {expected} ({interpolation} interpolation, {n} points)")
        if velocities_attr.HasAuthoredValue():
            velocities = velocities_attr.Get(time)
            if velocities is not None and len(velocities) != n:
                add("velocities", time, f"{len(velocities)} velocities for {n} points")
        extent = extent_attr.Get(time)
        computed = UsdGeom.PointBased.ComputeExtent(points)
        if extent is None:
            add("extent", time, "no extent authored")
        elif computed is not None and not np.array_equal(np.asarray(extent), np.asarray(computed)):
            add("extent", time, f"extent {list(map(tuple, extent))} differs from the points' {list(map(tuple, computed))}")
        for pv in primvars:
            if pv.GetInterpolation() not in ("vertex", "varying"):
                continue
            value = pv.Get(time)
            if value is None:
                continue
            size = max(1, pv.GetElementSize())
            if len(value) != n * size:
                add("primvar", time, f"{pv.GetPrimvarName()}: {len(value)} values for {n} points x elementSize {size}")
    return problems


def _points_problems(points) -> List[Problem]:
    """Counts of normals, widths and vertex primvars against the points, finite
    positions, positive widths, the extent (with widths) against the points, at every
    time sample (or the default value)."""
    from pxr import Usd, UsdGeom

    where = str(points.GetPath())
    problems: List[Problem] = []
    times = _sample_times([points.GetPointsAttr()]) or [Usd.TimeCode.Default()]
    for time in times:
        t = None if time == Usd.TimeCode.Default() else time

        def add(what, message):
            problems.append(Problem("error", what, where, t, message))

        xyz = points.GetPointsAttr().Get(time)
        if xyz is None:
            add("points", "no value")
            continue
        xyz = np.asarray(xyz)
        n = len(xyz)
        if not np.isfinite(xyz).all():
            add("points", "non-finite positions")
        widths = points.GetWidthsAttr().Get(time)
        if widths is not None and points.GetWidthsInterpolation() == UsdGeom.Tokens.vertex:
            if len(widths) != n:
                add("widths", f"{len(widths)} widths for {n} points")
            elif n and not (np.asarray(widths) > 0).all():
                add("widths", "widths must be positive")
        normals = points.GetNormalsAttr().Get(time)
        if normals is not None and points.GetNormalsInterpolation() == UsdGeom.Tokens.vertex and len(normals) != n:
            add("normals", f"{len(normals)} normals for {n} points")
        extent = points.GetExtentAttr().Get(time)
        computed = UsdGeom.Points.ComputeExtent(xyz, widths) if widths is not None and len(widths) == n else None
        if extent is None:
            add("extent", "no extent authored")
        elif computed is not None and n and not np.allclose(np.asarray(extent), np.asarray(computed), rtol=1e-6):
            add("extent", f"extent {list(map(tuple, extent))} differs from the points' {list(map(tuple, computed))}")
        for pv in UsdGeom.PrimvarsAPI(points.GetPrim()).GetPrimvars():
            if pv.GetInterpolation() != "vertex":
                continue
            value = pv.Get(time)
            size = max(1, pv.GetElementSize())
            if value is not None and len(value) != n * size:
                add("primvar", f"{pv.GetPrimvarName()}: {len(value)} values for {n} points")
    return problems


def _clip_settings_problems(prim) -> List[Problem]:
    """A warning when the value clips of `prim` are frame layers that isobar_usd extracted
    with different settings (their records' ``extraction``): a re-run of some frames with
    another isovalue, h or attributes."""
    from pxr import Usd

    from .layers import mixed_settings, read_record
    from .sequence import extraction_defaults

    clips = Usd.ClipsAPI(prim)
    assets = clips.GetClipAssetPaths()
    if not assets:
        return []
    from .errors import StitchError

    anchor = prim.GetStage().GetRootLayer()
    where = str(prim.GetPath())
    problems = []
    extractions = {}
    for k, asset in enumerate(assets):
        path = anchor.ComputeAbsolutePath(asset.path)
        try:
            record = read_record(Path(path))
        except StitchError:  # another writer's layer: nothing to compare
            continue
        except Exception as e:  # noqa: BLE001 - Tf.ErrorException: a truncated or foreign file
            problems.append(Problem("error", "clips", where, None, f"frame layer {path} cannot be read: {_first_line(e)}"))
            continue
        frame = record.frames[0] if len(record.frames) == 1 else k
        extractions[frame] = record.info.get("extraction")
    mixed = mixed_settings(extractions, extraction_defaults)
    if mixed:
        problems.append(Problem("warning", "settings", where, None, mixed))
    return problems


def _first_line(e: Exception) -> str:
    """The first non-blank line of a USD error (Tf.ErrorException's text runs on with the
    C++ call site), or the exception's type where it says nothing."""
    return next((line.strip() for line in str(e).splitlines() if line.strip()), type(e).__name__)


def check(path: Union[str, "os.PathLike[str]"], validators: bool = True, max_frames: Optional[int] = None) -> List[Problem]:
    """Opens the stage at `path` and returns its problems (an empty list when it is sound).

    Runs every validator usd-core registers (``pxr.UsdValidation``: stage metadata,
    defaultPrim, composition errors, attribute types, ...) and, for every Mesh at every
    time sample: topology (``UsdGeom.Mesh.ValidateTopology``), normal, velocity and
    primvar counts against the points, extent against the points.

    Note: USD caches layers by path; a layer already open in this process is not read
    again from disk (reload it, or open the stage in a fresh process).
    """
    from pxr import Usd, UsdGeom

    if not os.path.isfile(path):
        return [Problem("error", "open", os.fspath(path), None, "USD could not open the stage: no such file")]
    try:
        stage = Usd.Stage.Open(os.fspath(path))
    except Exception as e:  # noqa: BLE001 - pxr.Tf.ErrorException: a corrupt or foreign file
        return [Problem("error", "open", os.fspath(path), None, f"USD could not open the stage: {e}")]
    if stage is None:
        return [Problem("error", "open", os.fspath(path), None, "USD could not open the stage")]
    problems: List[Problem] = []

    def unreadable(check: str, where: str, e: Exception) -> Problem:
        # USD raises (Tf.ErrorException) where a layer it composes cannot be read, e.g.
        # a truncated frame layer of the clips: a finding, not a crash of the check.
        return Problem("error", check, where, None, f"USD could not read a layer: {_first_line(e)}")

    if validators:
        try:
            problems += _validator_problems(stage)
        except Exception as e:  # noqa: BLE001
            problems.append(unreadable("validators", "/", e))
    if not stage.HasAuthoredTimeCodeRange():
        problems.append(Problem("warning", "stage", "/", None, "no startTimeCode/endTimeCode"))
    for prim in stage.Traverse():
        where = str(prim.GetPath())
        try:
            problems += _clip_settings_problems(prim)
            if prim.IsA(UsdGeom.Mesh):
                problems += _mesh_problems(UsdGeom.Mesh(prim), max_frames)
            elif prim.IsA(UsdGeom.Points):
                problems += _points_problems(UsdGeom.Points(prim))
        except Exception as e:  # noqa: BLE001
            problems.append(unreadable("mesh", where, e))
    return problems


__all__ = ["Problem", "check"]
