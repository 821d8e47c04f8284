"""USD layers: mesh layers (one frame, or all frames of a flat file), the clip manifest,
and the root layer that joins per-frame layers by value clips."""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from . import _atomic
from ._version import __version__
from .errors import InputError, StitchError
from .mesh import FrameMesh, SchemaEntry, schema_of

#: Key of the writer's record in each layer's customLayerData.
INFO_KEY = "isobarUsd"

#: How long before a frame whose point count differs from the previous frame's the
#: previous frame's extent is authored again, in time codes (frames): 1/1024, exact in
#: binary, far shorter than any shutter interval.
HOLD_BEFORE = 1.0 / 1024.0

#: File extensions the writer produces (the file format follows the extension; ``.usd``
#: is binary crate).
OUTPUT_EXTENSIONS = (".usd", ".usda", ".usdc")


def _pxr():
    from pxr import Sdf, Usd, UsdGeom, Vt

    return Sdf, Usd, UsdGeom, Vt


@dataclass(frozen=True)
class StageSettings:
    """Stage-level choices.

    Attributes:
        fps: timeCodesPerSecond and framesPerSecond (time code = frame number).
        meters_per_unit: metersPerUnit (1: the particle data is in metres).
        up_axis: "Y" (USD's fallback; SPlisHSPlasH, splashsurf and Houdini scenes) or "Z"
            (Blender). The writer declares the axis; it never rotates the data.
        prim: name of the root prim (the defaultPrim, an Xform of kind component).
        mesh: name of the Mesh prim under it.
    """

    fps: float = 24.0
    meters_per_unit: float = 1.0
    up_axis: str = "Y"
    prim: str = "Fluid"
    mesh: str = "Surface"

    def checked(self) -> "StageSettings":
        """A normalised copy; raises InputError for a value USD would not take."""
        from pxr import Sdf

        fps = float(self.fps)
        if not (math.isfinite(fps) and fps > 0):
            raise InputError(f"fps must be a positive number, got {self.fps}")
        mpu = float(self.meters_per_unit)
        if not (math.isfinite(mpu) and mpu > 0):
            raise InputError(f"meters_per_unit must be a positive number, got {self.meters_per_unit}")
        axis = str(self.up_axis).upper()
        if axis not in ("Y", "Z"):
            raise InputError(f"up_axis must be 'Y' or 'Z' (USD allows no other), got '{self.up_axis}'")
        for what, name in (("prim", self.prim), ("mesh", self.mesh)):
            if not Sdf.Path.IsValidIdentifier(str(name)):
                raise InputError(f"{what} name '{name}' is not a valid USD prim name")
        return StageSettings(fps, mpu, axis, str(self.prim), str(self.mesh))

    @property
    def root_path(self) -> str:
        return f"/{self.prim}"

    @property
    def mesh_path(self) -> str:
        return f"/{self.prim}/{self.mesh}"


def check_output_path(path: Path, what: str = "output") -> Path:
    path = Path(path)
    if path.suffix.lower() not in OUTPUT_EXTENSIONS:
        raise InputError(
            f"{what} '{path}': give a .usd, .usda or .usdc file "
            "(package a .usdz afterwards with UsdUtils.CreateNewUsdzPackage)"
        )
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        if parent.exists() or parent.is_symlink():
            raise InputError(f"{what} '{path}': '{parent}' is not a folder")
        raise InputError(f"{what} '{path}': folder '{parent}' does not exist")
    check_writable_folder(parent, f"{what} '{path}'")
    if path.is_dir():
        raise InputError(f"{what} '{path}' is a folder")
    return path


def check_writable_folder(folder: Path, what: str) -> None:
    """Raises InputError (naming `what`, the folder and the reason) unless a file can be
    created in `folder`. It tries one, under a staging name that a later write sweeps
    should this process die in between: permission bits do not tell the whole story
    (root ignores them; an immutable folder, a read-only mount, an ACL do not show)."""
    probe = _atomic.staging_path(Path(folder) / "isobar-usd-probe")
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        # Left by this very process (pids are unique among the living): take it over.
        fd = None
    except OSError as e:
        raise InputError(f"{what}: cannot write in folder '{folder}': {e.strerror or e}") from None
    if fd is not None:
        os.close(fd)
    try:
        os.unlink(probe)
    except FileNotFoundError:
        pass
    except OSError as e:
        raise InputError(f"{what}: cannot remove files in folder '{folder}': {e.strerror or e}") from None


def _stage_metadata(stage, settings: StageSettings, start: float, end: float) -> None:
    _, _, UsdGeom, _ = _pxr()
    stage.SetTimeCodesPerSecond(settings.fps)
    stage.SetFramesPerSecond(settings.fps)
    stage.SetStartTimeCode(start)
    stage.SetEndTimeCode(end)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if settings.up_axis == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, settings.meters_per_unit)


def _define_prims(stage, settings: StageSettings):
    """The root Xform (defaultPrim, kind component) and the Mesh with its uniform
    attributes; returns the UsdGeom.Mesh."""
    _, Usd, UsdGeom, _ = _pxr()
    root = UsdGeom.Xform.Define(stage, settings.root_path)
    Usd.ModelAPI(root.GetPrim()).SetKind("component")
    stage.SetDefaultPrim(root.GetPrim())
    mesh = UsdGeom.Mesh.Define(stage, settings.mesh_path)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    # The core's triangles are counter-clockwise seen from where the normals point.
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    return mesh


def _declare(prim, entry: SchemaEntry):
    """Creates attribute `entry` (no value) with its interpolation and elementSize."""
    Sdf, _, _, _ = _pxr()
    name, type_name, interpolation, element_size = entry
    value_type = Sdf.ValueTypeNames.Find(type_name)
    if not value_type:
        raise StitchError(f"attribute '{name}': unknown USD type '{type_name}'")
    attr = prim.CreateAttribute(name, value_type, False)
    if interpolation:
        attr.SetMetadata("interpolation", interpolation)
    if element_size:
        attr.SetMetadata("elementSize", int(element_size))
    return attr


def _array(values: np.ndarray, type_name: str):
    _, _, _, Vt = _pxr()
    if type_name in ("point3f[]", "normal3f[]", "vector3f[]", "float3[]"):
        return Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(values, dtype=np.float32).reshape(-1, 3))
    if type_name == "float2[]":
        return Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(values, dtype=np.float32))
    if type_name == "float4[]":
        return Vt.Vec4fArray.FromNumpy(np.ascontiguousarray(values, dtype=np.float32))
    if type_name == "float[]":
        return Vt.FloatArray.FromNumpy(np.ascontiguousarray(values, dtype=np.float32).reshape(-1))
    if type_name == "int[]":
        return Vt.IntArray.FromNumpy(np.ascontiguousarray(values, dtype=np.int32).reshape(-1))
    raise StitchError(f"no conversion to USD type '{type_name}'")


def _values_by_name(mesh: FrameMesh) -> Dict[str, np.ndarray]:
    values = {
        "extent": mesh.extent,
        "faceVertexCounts": mesh.counts,
        "faceVertexIndices": mesh.indices,
        "points": mesh.points,
    }
    if mesh.normals is not None:
        values["normals"] = mesh.normals
    if mesh.velocities is not None:
        values["velocities"] = mesh.velocities
    for name, v in mesh.primvars.items():
        values[f"primvars:{name}"] = v
    return values


def merge_schema(into: Dict[str, SchemaEntry], entries: Iterable[SchemaEntry], where: str, seen: Dict[str, str]) -> None:
    """Adds `entries` to `into` (name -> entry), refusing an attribute whose type or
    metadata differs from what an earlier frame gave it."""
    for entry in entries:
        entry = tuple(entry)
        name = entry[0]
        known = into.get(name)
        if known is None:
            into[name] = entry  # type: ignore[assignment]
            seen[name] = where
        elif tuple(known) != entry:
            raise StitchError(
                f"attribute '{name}' is {known[1]} (interpolation '{known[2] or '-'}', elementSize {known[3]}) "
                f"in {seen[name]} but {entry[1]} (interpolation '{entry[2] or '-'}', elementSize {entry[3]}) "
                f"in {where}; rewrite the frames with the same attributes"
            )


class MeshLayer:
    """Builds one layer holding the mesh's time samples at one or more frames, in memory,
    then exports it atomically. A one-frame MeshLayer is a clip of a sequence and a
    complete stage of its own."""

    def __init__(self, settings: StageSettings, info: Optional[Mapping] = None):
        _, Usd, _, _ = _pxr()
        self.settings = settings
        self.info = dict(info or {})
        self.stage = Usd.Stage.CreateInMemory()
        self.mesh = _define_prims(self.stage, settings)
        self.schema: Dict[str, SchemaEntry] = {}
        self._where: Dict[str, str] = {}
        self.frames: List[int] = []
        self.points = 0
        self.triangles = 0
        #: (frame, points, extent) of each frame, for the extent's held samples.
        self._extents: List[Tuple[int, int, np.ndarray]] = []
        #: The attributes each frame authored, for those it lacks (see _fill_absent).
        self._authored: Dict[int, set] = {}

    def add(self, mesh: FrameMesh, frame: int) -> List[SchemaEntry]:
        """Authors `mesh` as the time samples at time code `frame`."""
        prim = self.mesh.GetPrim()
        entries = schema_of(mesh)
        merge_schema(self.schema, entries, f"frame {frame}", self._where)
        values = _values_by_name(mesh)
        for entry in entries:
            attr = _declare(prim, entry)
            attr.Set(_array(values[entry[0]], entry[1]), float(frame))
        self._authored[int(frame)] = {entry[0] for entry in entries}
        self.frames.append(int(frame))
        self.points, self.triangles = mesh.n_points, mesh.n_triangles
        self._extents.append((int(frame), mesh.n_points, np.asarray(mesh.extent)))
        return entries

    def _fill_absent(self) -> None:
        """An attribute a frame lacks (a primvar an empty frame's file does not declare)
        would show the nearest frame's samples there, as many values as that frame has
        points. It is authored empty at a frame with no points, and blocked (no value)
        at any other."""
        Sdf, _, _, _ = _pxr()
        points = {frame: n for frame, n, _ in self._extents}
        prim = self.mesh.GetPrim()
        for frame, authored in self._authored.items():
            for name, type_name, _, _ in self.schema.values():
                if name in authored:
                    continue
                empty = np.zeros((0, {"float2[]": 2, "float4[]": 4}.get(type_name, 1)))
                value = _array(empty, type_name) if points[frame] == 0 else Sdf.ValueBlock()
                prim.GetAttribute(name).Set(value, float(frame))

    def _hold_extents(self) -> None:
        """Between two frames whose point counts differ, USD cannot interpolate the points
        and holds the earlier frame's, but it interpolates the extent (always two
        corners): at frame 1.5 half the points could lie outside it, and a renderer
        sampling motion blur there would cull them. The earlier extent is authored again
        just before the later frame (see :func:`hold_times`), so the extent is held with
        the points."""
        extents = {frame: extent for frame, _, extent in self._extents}
        attr = self.mesh.GetExtentAttr()
        for frame, time in hold_times({frame: n for frame, n, _ in self._extents}).items():
            attr.Set(_array(extents[frame], "float3[]"), time)

    def export(self, path: Path, atomic: bool = True) -> None:
        """Writes the layer to `path`: through a staging file renamed into place, or (with
        `atomic` False, for a path that is itself a staging file) directly."""
        if not self.frames:
            raise InputError("no frame to write")
        self._fill_absent()
        self._hold_extents()
        start, end = min(self.frames), max(self.frames)
        _stage_metadata(self.stage, self.settings, start, end)
        record = dict(self.info)
        record.update(
            writer=f"isobar_usd {__version__}",
            frames=json.dumps(sorted(self.frames)),
            schema=json.dumps(sorted(self.schema.values())),
            settings=json.dumps(asdict(self.settings)),
        )
        if len(self.frames) == 1:
            record.update(points=int(self.points), triangles=int(self.triangles))
        layer = self.stage.GetRootLayer()
        layer.customLayerData = {INFO_KEY: record}
        layer.documentation = "isobar SPH isosurface, written by isobar_usd"
        if not atomic:
            if not layer.Export(str(path)):
                raise OSError(f"USD could not write {path}")
            return
        with _atomic.atomic_path(Path(path)) as staged:
            if not layer.Export(str(staged)):
                raise OSError(f"USD could not write {staged}")

    def release(self) -> None:
        self.stage = None
        self.mesh = None


@dataclass
class LayerRecord:
    """What a mesh layer says about itself (read from its customLayerData alone)."""

    path: Path
    frames: List[int]
    schema: List[SchemaEntry]
    settings: Optional[StageSettings]
    info: Dict


def read_record(path: Path) -> LayerRecord:
    """Reads a mesh layer's metadata only (no time samples)."""
    Sdf, _, _, _ = _pxr()
    layer = Sdf.Layer.OpenAsAnonymous(str(path), True)
    if layer is None:
        raise StitchError(f"cannot open frame layer {path}")
    data = dict(layer.customLayerData.get(INFO_KEY, {}) or {})
    if not data:
        raise StitchError(f"{path} was not written by isobar_usd (no '{INFO_KEY}' record in its customLayerData)")
    try:
        frames = [int(f) for f in json.loads(data.get("frames", "[]"))]
        schema = [tuple(e) for e in json.loads(data.get("schema", "[]"))]
        raw = json.loads(data["settings"]) if data.get("settings") else None
        settings = StageSettings(**raw) if raw else None
    except (ValueError, TypeError, KeyError) as e:
        raise StitchError(f"{path}: unreadable '{INFO_KEY}' record ({e})") from e
    return LayerRecord(Path(path), frames, schema, settings, data)  # type: ignore[arg-type]


#: Extraction options that do not change the surface: frames differing only in them are
#: not mixed (a re-run with a larger memory budget is what an over-budget error asks for).
SURFACE_NEUTRAL_OPTIONS = ("memory_budget", "backend")


def mixed_settings(
    extractions: Mapping[int, Optional[str]], defaults: Optional[Callable[[str], Mapping[str, Any]]] = None
) -> Optional[str]:
    """A sentence naming the frames extracted with other settings than most frames were
    (each frame's record's ``extraction``: isovalue and options), or None when they all
    agree. Frames with no record of it (meshes given in memory) are left out. A re-run of
    some frames with another isovalue, h or --attributes otherwise pops in the shot
    without a word. `defaults(method)` fills the options a frame left out, so a default
    spelled out and one left out agree; options that do not change the surface
    (:data:`SURFACE_NEUTRAL_OPTIONS`) are not compared."""

    def parsed(text: str) -> Dict:
        try:
            value = json.loads(text)
        except ValueError:
            return {"settings": text}
        if not isinstance(value, dict):
            return {"settings": value}
        if defaults is not None:
            value = {**defaults(str(value.get("method", "correctors"))), **value}
        return {k: v for k, v in value.items() if k not in SURFACE_NEUTRAL_OPTIONS}

    groups: Dict[str, List[int]] = {}
    for frame, text in sorted(extractions.items()):
        if text:
            groups.setdefault(json.dumps(parsed(text), sort_keys=True, default=str), []).append(frame)
    if len(groups) < 2:
        return None
    ordered = sorted(groups.items(), key=lambda kv: (-len(kv[1]), kv[1][0]))
    common_text, common_frames = ordered[0]

    def frames_of(frames: List[int]) -> str:
        shown = ", ".join(map(str, frames[:10]))
        return shown + (f" and {len(frames) - 10} more" if len(frames) > 10 else "")

    common = parsed(common_text)
    parts = []
    for text, frames in ordered[1:]:
        other = parsed(text)
        keys = sorted(k for k in set(common) | set(other) if common.get(k) != other.get(k))
        differences = ", ".join(f"{k} {other.get(k, '(not set)')!r} (not {common.get(k, '(not set)')!r})" for k in keys)
        parts.append(f"frame(s) {frames_of(frames)} with {differences}")
    return (
        f"the frames were extracted with different settings: {'; '.join(parts)}, against frame(s) "
        f"{frames_of(common_frames)}; rewrite them with the same settings if that was not meant"
    )


def write_manifest(path: Path, settings: StageSettings, schema: Sequence[SchemaEntry]) -> None:
    """The clip manifest: every attribute the clips hold samples for, with no values."""
    Sdf, _, _, _ = _pxr()
    layer = Sdf.Layer.CreateAnonymous(".usda")
    prim = Sdf.CreatePrimInLayer(layer, settings.mesh_path)
    prim.specifier = Sdf.SpecifierOver
    for name, type_name, _, _ in schema:
        Sdf.AttributeSpec(prim, name, Sdf.ValueTypeNames.Find(type_name))
    layer.documentation = "value clip manifest of an isobar_usd sequence"
    with _atomic.atomic_path(Path(path)) as staged:
        if not layer.Export(str(staged)):
            raise OSError(f"USD could not write {staged}")


def hold_times(point_counts: Mapping[int, int]) -> Dict[int, float]:
    """frame -> the time just before the next frame (HOLD_BEFORE), for each frame whose
    point count differs from the next frame's (a negative count: not known, so held).
    Between such frames USD holds the points, which it cannot interpolate; whatever the
    writer authors again at these times is held with them."""
    frames = sorted(point_counts)
    return {
        frame: float(later) - HOLD_BEFORE
        for frame, later in zip(frames, frames[1:])
        if (point_counts[frame] != point_counts[later] or point_counts[frame] < 0) and later - frame > 2 * HOLD_BEFORE
    }


def _clip_times(frames: Sequence[int], holds: Mapping[int, float]) -> List[Tuple[float, float]]:
    """(stage time, clip time) pairs: f to f, and each hold's time (see
    :func:`hold_times`) to f again."""
    times: List[Tuple[float, float]] = []
    for frame in frames:
        times.append((float(frame), float(frame)))
        if frame in holds:
            times.append((holds[frame], float(frame)))
    return times


def write_clips_root(
    path: Path,
    settings: StageSettings,
    schema: Sequence[SchemaEntry],
    clips: Sequence[Tuple[int, str]],
    manifest_asset: str,
    info: Optional[Mapping] = None,
    point_counts: Optional[Mapping[int, int]] = None,
) -> None:
    """The root layer of a sequence: stage metadata, the prims with every attribute
    declared (types, interpolation), and value clips mapping time code f to clip f.
    After each frame whose point count (`point_counts`, every frame's, or None: no
    holds) differs from the next frame's, the clip's time also maps to the time just
    before the next frame (:func:`hold_times`), so every attribute holds that frame's
    values until then: USD interpolates across clips, and would interpolate the extent
    around points it holds (see MeshLayer._hold_extents).

    Authored with the Sdf API alone: a Usd stage holding clip metadata composes the clips
    and opens every frame layer (an anonymous one resolves them against the current
    folder), which would cost time and memory in proportion to the sequence."""
    Sdf, _, _, Vt = _pxr()
    layer = Sdf.Layer.CreateAnonymous(".usda")
    frames = [f for f, _ in clips]
    layer.defaultPrim = settings.prim
    layer.timeCodesPerSecond = settings.fps
    layer.framesPerSecond = settings.fps
    layer.startTimeCode = float(min(frames))
    layer.endTimeCode = float(max(frames))
    layer.pseudoRoot.SetInfo("upAxis", settings.up_axis)
    layer.pseudoRoot.SetInfo("metersPerUnit", float(settings.meters_per_unit))

    root = Sdf.PrimSpec(layer, settings.prim, Sdf.SpecifierDef, "Xform")
    root.kind = "component"
    mesh = Sdf.PrimSpec(root, settings.mesh, Sdf.SpecifierDef, "Mesh")
    for name, value in (("orientation", "rightHanded"), ("subdivisionScheme", "none")):
        attr = Sdf.AttributeSpec(mesh, name, Sdf.ValueTypeNames.Token, Sdf.VariabilityUniform)
        attr.default = value
    for name, type_name, interpolation, element_size in schema:
        value_type = Sdf.ValueTypeNames.Find(type_name)
        if not value_type:
            raise StitchError(f"attribute '{name}': unknown USD type '{type_name}'")
        attr = Sdf.AttributeSpec(mesh, name, value_type, Sdf.VariabilityVarying)
        if interpolation:
            attr.SetInfo("interpolation", interpolation)
        if element_size:
            attr.SetInfo("elementSize", int(element_size))
    root.SetInfo(
        "clips",
        {
            "default": {
                "assetPaths": Sdf.AssetPathArray([Sdf.AssetPath(asset) for _, asset in clips]),
                "primPath": settings.root_path,
                "active": Vt.Vec2dArray([(float(f), float(i)) for i, f in enumerate(frames)]),
                "times": Vt.Vec2dArray(_clip_times(frames, hold_times(point_counts or {}))),
                "manifestAssetPath": Sdf.AssetPath(manifest_asset),
            }
        },
    )
    record = dict(info or {})
    record.update(
        writer=f"isobar_usd {__version__}",
        layout="clips",
        frames=json.dumps(frames),
        schema=json.dumps(sorted(schema)),
        settings=json.dumps(asdict(settings)),
    )
    layer.customLayerData = {INFO_KEY: record}
    layer.documentation = "isobar SPH isosurface sequence: one layer per frame joined by value clips"
    with _atomic.atomic_path(Path(path)) as staged:
        if not layer.Export(str(staged)):
            raise OSError(f"USD could not write {staged}")
