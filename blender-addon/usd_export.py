"""USD export of fluid surfaces over a frame range, through isobar's USD writer.

Each frame's surface is the one the viewport shows (a baked frame while it matches the
current parameters, else extracted from the particles) and goes to ``isobar_usd``
(bundled as a wheel), which writes a UsdGeom.Mesh with time-sampled points, topology,
vertex normals, extent, velocities and ``sph_*`` primvars: one layer per frame joined by
value clips (or one flat file), staged under hidden names and renamed into place only
when every frame is written. USD comes from the ``pxr`` module Blender ships with.

No UI here: the export operator runs an :class:`ExportJob`.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import sys
from dataclasses import dataclass, field
from typing import Callable, Iterator, List, Optional, Sequence, Tuple

import bpy
import numpy as np

from . import cache, importer
from .extraction import VELOCITY_ATTRIBUTE, FrameMesh, Params

#: Name of the Mesh prim under the object's prim.
MESH_PRIM = "Surface"

LAYOUTS = ("AUTO", "CLIPS", "FLAT")
UP_AXES = ("AUTO", "Y", "Z")


# -- pxr and the writer ----------------------------------------------------------------


def _bundled_site_packages() -> Optional[str]:
    """The site-packages folder of Blender's own Python that holds its ``pxr`` (USD's
    Python bindings, built against the USD library Blender itself links), or None."""
    try:
        local = bpy.utils.resource_path("LOCAL")
    except Exception:  # noqa: BLE001
        return None
    version = f"python{sys.version_info.major}.{sys.version_info.minor}"
    for candidate in (
        os.path.join(local, "python", "lib", version, "site-packages"),  # Linux, macOS
        os.path.join(local, "python", "lib", "site-packages"),  # Windows
    ):
        if os.path.isdir(os.path.join(candidate, "pxr")):
            return candidate
    return None


def ensure_pxr():
    """Imports ``pxr``, preferring the copy Blender ships. Blender's Python has it on its
    path; the bpy module from PyPI carries the same folder but leaves it off ``sys.path``,
    so it is added (at the end, after the import) when missing.

    Raises:
        ImportError: this Blender has no USD Python bindings.
    """
    if "pxr" not in sys.modules:
        bundled = _bundled_site_packages()
        if bundled and bundled not in sys.path:
            # Blender's copy first: another pxr (usd-core) would be a second USD library
            # in the process, next to the one Blender links.
            sys.path.insert(0, bundled)
            try:
                import pxr  # noqa: F401
            except ImportError:
                pass
            finally:
                sys.path.remove(bundled)
                sys.path.append(bundled)
    try:
        import pxr  # noqa: F401
        from pxr import Usd  # noqa: F401
    except ImportError as error:
        raise ImportError(
            f"USD's Python module (pxr) is not available in this Blender ({error}); "
            "Blender 4.2+ ships it as part of its USD support"
        ) from error
    return sys.modules["pxr"]


def writer():
    """The isobar_usd package (the extension's wheel), with pxr imported first.

    Raises:
        ImportError: no pxr, or the wheel is missing.
    """
    ensure_pxr()
    try:
        import isobar_usd
    except ImportError as error:
        raise ImportError(f"isobar's USD writer (isobar_usd) could not be loaded: {error}") from error
    return isobar_usd


def usd_version() -> str:
    from pxr import Usd

    return ".".join(str(v) for v in Usd.GetVersion())


# -- errors ------------------------------------------------------------------------------


class ExportError(Exception):
    """A frame of an object failed; the message names the object, the frame and why."""

    def __init__(self, obj_name: str, frame: Optional[int], cause: BaseException):
        self.obj_name = obj_name
        self.frame = frame
        self.cause = cause
        where = f"'{obj_name}' frame {frame}" if frame is not None else f"'{obj_name}'"
        super().__init__(f"{where}: {importer.describe_error(cause)}")


# -- options and naming -----------------------------------------------------------------


@dataclass
class Options:
    """What the operator asks for (the stage settings of isobar_usd and what goes in)."""

    layout: str = "AUTO"  # AUTO (flat for one frame, clips otherwise), CLIPS, FLAT
    up_axis: str = "AUTO"  # AUTO: Y for an object rotated by the Y-up import, else Z
    meters_per_unit: float = 1.0
    primvars: bool = True  # the sph_* attributes as vertex primvars
    velocities: bool = True  # the 'velocity' attribute as the mesh's velocities
    fps: Optional[float] = None  # default: the scene's


def prim_name(name: str) -> str:
    """A valid USD prim name from an object name ('Fluid.001' -> 'Fluid_001', '2nd' ->
    '_nd'): ASCII letters, digits and '_', not starting with a digit."""
    clean = re.sub(r"[^A-Za-z0-9_]", "_", name or "") or "Fluid"
    return "_" + clean[1:] if clean[0].isdigit() else clean


def output_paths(filepath: str, names: Sequence[str]) -> List[str]:
    """One stage per object: `filepath` itself for one object, else
    ``<stem>_<object><ext>`` beside it."""
    if len(names) == 1:
        return [filepath]
    stem, ext = os.path.splitext(filepath)
    return [f"{stem}_{prim_name(n)}{ext}" for n in names]


_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # rotation X +90 degrees


def placement(obj) -> Tuple[str, bool]:
    """(up axis, transform written as is): the surface is written in the object's own
    (simulation) coordinates. An object standing in Blender's Z up through the Y-up import
    (a rotation of +90 degrees about X) is a Y-up stage; an unrotated one a Z-up stage.
    The bool is False when the object carries any other transform, which is not
    written."""
    matrix = np.array(obj.matrix_world, dtype=np.float64)
    linear, offset = matrix[:3, :3], matrix[:3, 3]
    plain = np.allclose(offset, 0.0, atol=1e-6) and np.allclose(matrix[3], (0, 0, 0, 1), atol=1e-9)
    if np.allclose(linear, _Y_UP, atol=1e-5):
        return "Y", plain
    if np.allclose(linear, np.eye(3), atol=1e-5):
        return "Z", plain
    # Another rotation or a scale: Y when local +Y points up in the scene, else Z.
    up = linear @ np.array([0.0, 1.0, 0.0])
    axis = "Y" if up[2] > 0 and abs(up[2]) >= 0.9 * np.linalg.norm(up) else "Z"
    return axis, False


def scene_fps(scene) -> float:
    render = scene.render
    return float(render.fps) / float(render.fps_base or 1.0)


# -- one frame ---------------------------------------------------------------------------


def surface_at(obj, scene, frame: int, params: Params, fingerprint: str, progress=None) -> Tuple[FrameMesh, str]:
    """The surface of `obj` at `frame`, as the viewport would show it: the baked frame
    when baking is on and its fingerprint matches, else extracted from the particles
    (object sources: from the scene as evaluated at `frame`, which the caller has set).
    Returns (mesh, origin)."""
    settings = obj.isobar
    if settings.use_cache:
        try:
            folder = importer.cache_folder(obj, settings)
        except ValueError:
            folder = ""
        path = cache.frame_path(folder, frame) if folder else ""
        if path and os.path.isfile(path) and cache.read_fingerprint(path) == fingerprint:
            mesh, _ = cache.read(path)
            return mesh, "bake"
    depsgraph = bpy.context.evaluated_depsgraph_get() if settings.source_type == "OBJECT" else None
    mesh, origin = importer.extract_live(obj, scene, depsgraph, frame, params, progress)
    return (mesh if mesh is not None else importer.empty_mesh()), origin


def usd_arrays(mesh: FrameMesh, options: Options) -> dict:
    """The arrays isobar_usd takes for one in-memory frame: the sph_* attributes as
    primvars (when asked), 'velocity' as the velocities (when asked)."""
    attributes = {}
    for name, values in mesh.attributes.items():
        if name == VELOCITY_ATTRIBUTE:
            if options.velocities and np.ndim(values) == 2 and np.shape(values)[1] == 3:
                attributes[name] = values
        elif options.primvars:
            attributes[name] = values
    return {"points": mesh.points, "triangles": mesh.triangles, "normals": mesh.normals, "attributes": attributes}


# -- the job -----------------------------------------------------------------------------


@dataclass
class ObjectResult:
    name: str
    path: str
    frames: List[int]
    layout: str
    up_axis: str
    points: int = 0  # of the last frame
    triangles: int = 0
    sources: List[str] = field(default_factory=list)


class ExportJob:
    """Exports `frames` of fluid surfaces `objects` as USD stages at `filepath` (one
    object) or beside it (several; see :func:`output_paths`).

    Each object's stage is written all or nothing (isobar_usd stages its files and
    renames them when the last frame is written); a failing frame raises
    :class:`ExportError` and leaves what was at the path before. The scene's frame is
    changed only for objects made from scene particles, and set back at the end.

    Raises (constructor):
        ValueError: no fluid surface, an empty range, a bad path or option.
        ImportError: no pxr in this Blender, or the writer is missing.
    """

    def __init__(self, objects, scene, frames: Sequence[int], filepath: str, options: Optional[Options] = None):
        self.options = options or Options()
        if self.options.layout not in LAYOUTS:
            raise ValueError(f"layout must be one of {', '.join(LAYOUTS)}, got '{self.options.layout}'")
        if self.options.up_axis not in UP_AXES:
            raise ValueError(f"up axis must be one of {', '.join(UP_AXES)}, got '{self.options.up_axis}'")
        objects = [o for o in objects if importer.is_fluid(o)]
        if not objects:
            raise ValueError("select an isobar fluid surface to export")
        self.frames = list(frames)
        if not self.frames:
            raise ValueError("the frame range to export is empty")
        if not filepath:
            raise ValueError("choose a .usd, .usda or .usdc file to export to")
        filepath = os.path.abspath(bpy.path.abspath(filepath))
        if os.path.splitext(filepath)[1].lower() not in (".usd", ".usda", ".usdc"):
            raise ValueError(f"'{filepath}': give a .usd, .usda or .usdc file")
        if not os.path.isdir(os.path.dirname(filepath)):
            raise ValueError(f"'{filepath}': the folder does not exist")
        self.usd = writer()
        self.scene = scene
        self.obj_names = [o.name for o in objects]
        self.paths = output_paths(filepath, self.obj_names)
        self.fps = float(self.options.fps) if self.options.fps else scene_fps(scene)
        if not (math.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"frames per second must be positive, got {self.fps}")
        self.original_frame = scene.frame_current
        self.original_subframe = scene.frame_subframe
        self.results: List[ObjectResult] = []
        self.warnings: List[str] = []
        self.current_obj: Optional[str] = None
        self.current_frame: Optional[int] = None

    @property
    def total(self) -> int:
        """Frames to write over all objects (the progress range)."""
        return len(self.frames) * len(self.obj_names)

    def _obj(self, name: str):
        obj = bpy.data.objects.get(name)
        if obj is None:
            raise ValueError(f"the object '{name}' was deleted during the export")
        return obj

    def run(self, progress: Optional[Callable[[float], None]] = None) -> List[ObjectResult]:
        """Writes every object's stage; `progress` gets the frames done so far (fractions
        within a frame). Sets the scene's frame back to where it was, even on error.

        Raises:
            ExportError: a frame failed (no file of that object changed).
        """
        done = 0
        try:
            with contextlib.ExitStack() as stack:
                # The frame-change handler leaves the exported surfaces alone while the
                # export steps through frames (object sources); each frame is extracted once.
                for name in self.obj_names:
                    stack.enter_context(importer.baking(self._obj(name)))
                for name, path in zip(self.obj_names, self.paths):
                    self.results.append(self._export_object(name, path, done, progress))
                    done += len(self.frames)
        finally:
            self.current_obj = self.current_frame = None
            self._restore_frame()
        return self.results

    def _restore_frame(self) -> None:
        scene = self.scene
        if scene.frame_current != self.original_frame or scene.frame_subframe != self.original_subframe:
            scene.frame_set(self.original_frame, subframe=self.original_subframe)

    def _export_object(self, name: str, path: str, done_before: int, progress) -> ObjectResult:
        obj = self._obj(name)
        settings = obj.isobar
        params = Params.from_settings(settings)
        fingerprint = importer.bake_fingerprint(obj, params)
        axis, plain = placement(obj)
        if self.options.up_axis != "AUTO":
            axis = self.options.up_axis
        if not plain:
            self.warnings.append(
                f"'{name}': the object's transform is not exported (the surface is written in its own "
                f"coordinates, {axis} up)"
            )
        is_object_source = settings.source_type == "OBJECT"
        result = ObjectResult(name, path, [], "", axis)
        usd = self.usd
        warned: List[Tuple[int, str]] = []  # (frame, text) the extractions warned about

        def frames() -> Iterator[Tuple[int, dict]]:
            for i, frame in enumerate(self.frames):
                self.current_obj, self.current_frame = name, frame
                base = done_before + i

                def within(fraction, _phase=None, base=base):
                    if progress is not None:
                        progress(base + min(max(float(fraction), 0.0), 1.0))
                    return True

                try:
                    if is_object_source:
                        self.scene.frame_set(frame)
                    mesh, origin = surface_at(self._obj(name), self.scene, frame, params, fingerprint, within)
                    arrays = usd_arrays(mesh, self.options)
                except Exception as error:  # noqa: BLE001 - raised with the frame named
                    raise ExportError(name, frame, error) from error
                result.frames.append(frame)
                result.sources.append(origin)
                warned.extend((frame, text) for text in mesh.warnings)
                result.points, result.triangles = mesh.n_points, mesh.n_triangles
                if progress is not None:
                    progress(base + 1)
                yield frame, arrays
            self.current_frame = None  # every frame made: what fails now is the commit

        layout = self.options.layout.lower()
        if layout == "auto":  # the writer cannot count a stream of frames: decide here
            layout = "flat" if len(self.frames) == 1 else "clips"
        try:
            written = usd.write_sequence(
                frames(),
                path,
                layout=layout,
                fps=self.fps,
                meters_per_unit=float(self.options.meters_per_unit),
                up_axis=axis,
                prim=prim_name(name),
                mesh=MESH_PRIM,
                velocities="auto" if self.options.velocities else None,
                primvars="auto",
            )
        except ExportError:
            raise
        except usd.FrameError as error:
            raise ExportError(name, error.frame, error.cause) from error
        except Exception as error:  # noqa: BLE001
            raise ExportError(name, self.current_frame, error) from error
        result.layout = written.layout
        self.warnings.extend(f"'{name}' {line}" for line in importer.frame_warnings(warned))
        return result


__all__ = [
    "ExportError",
    "ExportJob",
    "ObjectResult",
    "Options",
    "ensure_pxr",
    "output_paths",
    "placement",
    "prim_name",
    "surface_at",
    "usd_arrays",
    "writer",
]
