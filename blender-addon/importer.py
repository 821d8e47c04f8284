"""From a fluid-surface object's settings to its mesh at a frame.

Finds the particles of the frame (a file of the sequence, or a scene object evaluated by
the depsgraph), extracts the surface through ``extraction`` (or reads the baked frame
through ``cache`` when one matches the current parameters) and writes it into the object's
mesh through ``mesh``. No UI here: operators and the frame-change handler call
:func:`update_object`; errors end up in the object's status text (and are returned), never
raised into Blender, and the extraction's warnings beside it.
"""

from __future__ import annotations

import contextlib
import os
import re
import threading
import traceback
from typing import Dict, Iterator, List, Optional, Sequence, Tuple

import bpy
import numpy as np

from . import cache, extraction, sequence
from . import mesh as mesh_io
from .extraction import FrameMesh, Params

# -- runtime state (not saved; cleared when a file is loaded) --------------------------

#: Per object: what the mesh shows now (key, vertices, triangles, origin, warnings), so
#: that an unchanged frame is not extracted again (Cycles' motion blur and repeated
#: frame_set calls land on the same frame).
_shown: Dict[str, Tuple] = {}
#: Per object: (name, components) of the particle arrays last read, for the UI's search.
_arrays: Dict[str, List[Tuple[str, int]]] = {}
#: Objects being baked: the frame-change handler leaves them alone.
_baking: set = set()
#: Depth of suspend_updates(): property updates do nothing while > 0.
_suspended = 0
#: A render is running (set by the render handlers): a frame that fails shows nothing
#: rather than the last good frame, which would be a wrong picture.
_rendering = False
#: Names of linked fluid surfaces the console was told about (once each, not every frame).
_linked_noted = set()


def clear_runtime() -> None:
    """Forgets the runtime state (on file load)."""
    global _rendering
    _shown.clear()
    _arrays.clear()
    _baking.clear()
    _linked_noted.clear()
    _rendering = False


def set_rendering(rendering: bool) -> None:
    global _rendering
    _rendering = rendering


@contextlib.contextmanager
def suspend_updates() -> Iterator[None]:
    """Property changes inside do not re-extract (set many settings, extract once)."""
    global _suspended
    _suspended += 1
    try:
        yield
    finally:
        _suspended -= 1


@contextlib.contextmanager
def baking(obj) -> Iterator[None]:
    """The frame-change handler skips `obj` inside (the bake drives its frames)."""
    key = object_key(obj)
    _baking.add(key)
    try:
        yield
    finally:
        _baking.discard(key)


def object_key(obj) -> str:
    return obj.name_full


def is_fluid(obj) -> bool:
    """True for a mesh object that is an isobar fluid surface."""
    try:
        return obj is not None and obj.type == "MESH" and obj.isobar.enabled
    except (AttributeError, ReferenceError):
        return False


def linked_from(obj) -> str:
    """The library file `obj` or its mesh is linked from, '' when both are this file's
    own: a linked mesh cannot be written (writing it crashes Blender) nor the object's
    settings, so a linked surface keeps the mesh its library saved."""
    for block in (obj, getattr(obj, "data", None)):
        library = getattr(block, "library", None)
        if library is not None:
            return library.filepath
    return ""


def is_baking(obj) -> bool:
    return object_key(obj) in _baking


# -- errors ----------------------------------------------------------------------------


def describe_error(error: BaseException) -> str:
    """A one-line message for the user."""
    try:
        isobar = extraction.isobar_module()
        if isinstance(error, isobar.Error):
            return str(error)
    except Exception:  # noqa: BLE001 - the package itself may be what failed
        pass
    if isinstance(error, ImportError):
        return f"the isobar package could not be loaded: {error}"
    if isinstance(error, (OSError, ValueError)):
        return str(error)
    return f"{type(error).__name__}: {error}"


# -- sources ---------------------------------------------------------------------------


def source_description(settings, cache_dir: str = "") -> str:
    """What the surface is made from, for the bake fingerprint of frames baked into
    `cache_dir`."""
    if settings.source_type == "OBJECT":
        src = settings.source_object
        return f"object:{src.name_full if src else ''}:{settings.particle_system}"
    return (
        f"sequence:{_particle_folder_seen_from(settings, cache_dir)}:{settings.pattern}:{settings.file_first}:"
        f"{settings.file_last}:{settings.frame_offset}:{int(settings.hold)}"
    )


def _particle_folder_seen_from(settings, cache_dir: str) -> str:
    """The particle folder relative to the bake folder: unchanged when the .blend is
    saved elsewhere (its '//' spelling changes) or the project folder moves as a whole,
    so a bake stays valid; absolute when there is no bake folder or no relative path."""
    folder = settings.directory
    if not folder:
        return ""
    folder = os.path.normpath(bpy.path.abspath(folder))
    if not cache_dir:
        return folder
    try:
        return os.path.relpath(folder, cache_dir)
    except ValueError:  # another drive
        return folder


def fingerprint(settings, params: Optional[Params] = None, cache_dir: str = "") -> str:
    return (params or Params.from_settings(settings)).fingerprint(source_description(settings, cache_dir))


def bake_fingerprint(obj, params: Optional[Params] = None) -> str:
    """The fingerprint a baked frame of `obj` must have to be played with the current
    settings."""
    try:
        folder = cache_folder(obj)
    except ValueError:
        folder = ""
    return fingerprint(obj.isobar, params, folder)


def sequence_path(settings, frame: int) -> Optional[str]:
    """The particle file of scene `frame` (None: no file, an empty surface)."""
    if sequence.is_static(settings.pattern):
        number = 0  # one file for every frame
    else:
        number = sequence.file_number(
            frame, settings.frame_offset, settings.file_first, settings.file_last, settings.hold
        )
    if number is None:
        return None
    directory = bpy.path.abspath(settings.directory) if settings.directory else ""
    if not directory:
        raise ValueError("the fluid surface has no particle folder")
    return sequence.path_for(directory, settings.pattern, number)


def read_particles(path: str):
    """isobar.Particles of a file, with a clear message when it is missing."""
    if not os.path.isfile(path):
        raise FileNotFoundError(f"particle file not found: {path}")
    return extraction.isobar_module().Particles.read(path)


_FLOAT_TYPES = {
    "FLOAT": ("value", 1),
    "INT": ("value", 1),
    "FLOAT2": ("vector", 2),
    "FLOAT_VECTOR": ("vector", 3),
    "FLOAT_COLOR": ("color", 4),
}
_SKIP_ATTRIBUTES = {"position", "custom_normal", "sharp_face", "sharp_edge", "material_index"}


def _geometry_of(evaluated):
    """(owner, data): the evaluated point cloud or mesh of an object. Keep `owner` alive
    while reading `data` (a geometry set frees its parts with itself)."""
    geometry = None
    if hasattr(evaluated, "evaluated_geometry"):
        try:
            geometry = evaluated.evaluated_geometry()
        except Exception:  # noqa: BLE001 - fall back to the object data
            geometry = None
    if geometry is not None:
        if getattr(geometry, "pointcloud", None) is not None:
            return geometry, geometry.pointcloud
        if getattr(geometry, "mesh", None) is not None:
            return geometry, geometry.mesh
    return evaluated, evaluated.data


def _point_arrays(data) -> Tuple[np.ndarray, Dict[str, np.ndarray]]:
    """Positions and float point attributes of a mesh or point cloud (local space)."""
    attributes = data.attributes
    if "position" not in attributes:
        raise ValueError(f"'{data.name}' has no point positions")
    n = len(attributes["position"].data)
    positions = np.empty(n * 3, dtype=np.float32)
    attributes["position"].data.foreach_get("vector", positions)
    arrays = {}
    for attr in attributes:
        name = attr.name
        if (
            attr.domain != "POINT"
            or name in _SKIP_ATTRIBUTES
            or name.startswith(".")
            or attr.data_type not in _FLOAT_TYPES
        ):
            continue
        key, k = _FLOAT_TYPES[attr.data_type]
        values = np.empty(n * k, dtype=np.float32 if attr.data_type != "INT" else np.int32)
        attr.data.foreach_get(key, values)
        arrays[name] = values.astype(np.float64).reshape(n, k) if k > 1 else values.astype(np.float64)
    return positions.reshape(n, 3).astype(np.float64), arrays


def _alive_values(ps) -> List[int]:
    """alive_state values of particles that are shown."""
    items = {i.identifier: i.value for i in bpy.types.Particle.bl_rna.properties["alive_state"].enum_items}
    shown = [items["ALIVE"], items["DYING"]]
    settings = ps.settings
    if getattr(settings, "show_unborn", False):
        shown.append(items["UNBORN"])
    if getattr(settings, "use_dead", False):
        shown.append(items["DEAD"])
    return shown


def scene_arrays(settings, depsgraph) -> Tuple[np.ndarray, Dict[str, np.ndarray]]:
    """World-space particle positions and arrays from the settings' scene object."""
    src = settings.source_object
    if src is None:
        raise ValueError("choose the object whose particles make the surface")
    evaluated = src.evaluated_get(depsgraph) if depsgraph is not None else src
    if settings.particle_system:
        ps = evaluated.particle_systems.get(settings.particle_system)
        if ps is None:
            raise ValueError(f"'{src.name}' has no particle system '{settings.particle_system}'")
        particles = ps.particles
        n = len(particles)
        loc = np.empty(n * 3, dtype=np.float32)
        vel = np.empty(n * 3, dtype=np.float32)
        size = np.empty(n, dtype=np.float32)
        state = np.empty(n, dtype=np.int32)
        if n:
            particles.foreach_get("location", loc)
            particles.foreach_get("velocity", vel)
            particles.foreach_get("size", size)
            particles.foreach_get("alive_state", state)
        keep = np.isin(state, _alive_values(ps))
        arrays = {"velocity": vel.reshape(n, 3)[keep].astype(np.float64), "size": size[keep].astype(np.float64)}
        return loc.reshape(n, 3)[keep].astype(np.float64), arrays  # particles are in world space

    owner, data = _geometry_of(evaluated)
    positions, arrays = _point_arrays(data)
    del owner
    matrix = np.array(evaluated.matrix_world, dtype=np.float64)
    rotation = matrix[:3, :3]
    positions = positions @ rotation.T + matrix[:3, 3]
    for name in extraction.VELOCITY_NAMES:
        values = arrays.get(name)
        if values is not None and values.ndim == 2 and values.shape[1] == 3:
            arrays[name] = values @ rotation.T
    return positions, arrays


def scene_particles(settings, depsgraph):
    positions, arrays = scene_arrays(settings, depsgraph)
    if positions.shape[0] == 0:
        return None
    return extraction.isobar_module().Particles.from_arrays(positions, arrays)


# -- one frame -------------------------------------------------------------------------


def cache_folder(obj, settings=None, assign_name: bool = False) -> str:
    """The folder of `obj`'s baked frames.

    Raises:
        ValueError: the cache folder is relative to an unsaved .blend file.
    """
    settings = settings or obj.isobar
    base = settings.cache_directory or "//isobar_cache/"
    if base.startswith("//") and not bpy.data.filepath:
        raise ValueError("save the .blend file first, or choose an absolute cache folder")
    name = settings.cache_name or _cache_name_of(obj)
    if assign_name and (not settings.cache_name or cache_sharers(obj, name)):
        # A duplicated object (Shift+D) copies the cache name: baking it into the same
        # folder would overwrite the other object's frames.
        name = _unused_cache_name(obj, _cache_name_of(obj))
        settings.cache_name = name
    return os.path.join(bpy.path.abspath(base), name)


def _cache_name_of(obj) -> str:
    return re.sub(r"[^0-9A-Za-z_.-]", "_", obj.name) or "surface"


def _unused_cache_name(obj, name: str) -> str:
    """`name`, or `name`_2, _3, ...: the first that no other surface bakes into."""
    candidate, n = name, 1
    while cache_sharers(obj, candidate):
        n += 1
        candidate = f"{name}_{n}"
    return candidate


def cache_sharers(obj, name: Optional[str] = None) -> List[str]:
    """Names of the other fluid surfaces whose bake folder is `obj`'s (with cache name
    `name`, default its own), and the other .blend file that baked into it, if one did
    (two shots in one folder, each with an object of the same name)."""
    settings = obj.isobar
    mine = _resolved_cache_folder(settings, name if name is not None else settings.cache_name or _cache_name_of(obj))
    sharers = [
        other.name
        for other in bpy.data.objects
        if other != obj
        and is_fluid(other)
        and other.isobar.cache_name
        and _resolved_cache_folder(other.isobar, other.isobar.cache_name) == mine
    ]
    owner = cache.owner(mine)
    if owner and owner != blend_identity():
        sharers.append(owner)
    return sharers


def blend_identity() -> str:
    """The open .blend file as a bake folder's owner record names it: its file name ('' when
    unsaved, which claims nothing). The name alone, so that a project moved or copied
    elsewhere still owns its bakes; two shots baking into one folder have different names."""
    return os.path.basename(bpy.data.filepath)


def _resolved_cache_folder(settings, name: str) -> str:
    base = settings.cache_directory or "//isobar_cache/"
    return os.path.normcase(os.path.normpath(os.path.join(bpy.path.abspath(base), name)))


class OverLiveLimit(ValueError):
    """A live extraction would read more particles than the object's Live Particle Limit."""


# What asks for a live extraction (see :func:`live_limit`).
SETTING = "setting"  # a setting of the object changed (or it was imported)
FRAME = "frame"  # the scene's frame changed
REFRESH = "refresh"  # the user asked for this frame (Refresh)


def live_limit(settings, cause: str = SETTING) -> int:
    """The most particles a live extraction of `settings`' object may read (0: no limit).

    The limit keeps an interactive session responsive: a live extraction cannot be
    cancelled, a bake can. It holds back a setting change, and a frame change while the
    timeline plays or is scrubbed (see :func:`timeline_moving`; the frame shown when it
    stops is extracted then). It does not hold back a frame set any other way: a frame
    step, a script, or an exporter stepping through the frames (Blender's Alembic and
    USD export) needs that frame's surface, and the last one shown would be a wrong
    result. Nor does it hold back Refresh (the user asked for this frame), a render, or
    background mode (no UI to freeze). While a surface bakes, the frames it sets hold the
    other surfaces back as playback would (until the bake ends)."""
    if _rendering or not _interactive() or cause == REFRESH:
        return 0
    if cause == FRAME and not (timeline_moving() or _baking):
        return 0
    return max(0, int(settings.live_particle_limit))


def _interactive() -> bool:
    """True in Blender with a UI (a window manager that shows progress and could freeze)."""
    return not bpy.app.background


def timeline_moving() -> bool:
    """True while a window plays the animation or the user scrubs the timeline: frames
    then come faster than a large frame extracts. False off the main thread (a job's
    frame steps), where the UI must not be read."""
    if threading.current_thread() is not threading.main_thread():
        return False
    for window in _windows():
        screen = window.screen
        if screen is not None and (screen.is_animation_playing or screen.is_scrubbing):
            return True
    return False


def _windows():
    """The window manager's windows (none in background mode)."""
    return getattr(getattr(bpy.context, "window_manager", None), "windows", ())


# Seconds between looks at whether the timeline still moves, while frames are held back.
_SETTLE_INTERVAL = 0.25


def _hold_back_until_the_timeline_stops() -> None:
    """A frame change was held back while the timeline moved: once it stops, the frame
    it stopped on is extracted (a timer: no event says that scrubbing ended)."""
    timers = getattr(bpy.app, "timers", None)
    if timers is not None and not timers.is_registered(extract_held_back_frames):
        timers.register(extract_held_back_frames, first_interval=_SETTLE_INTERVAL)


def extract_held_back_frames() -> Optional[float]:
    """The timer of :func:`_hold_back_until_the_timeline_stops`: while the timeline
    moves, looks again later; then updates every fluid surface of the scene to the frame
    shown, no longer limited (the timeline stopped)."""
    try:
        if timeline_moving() or _baking:
            return _SETTLE_INTERVAL
        scene = getattr(bpy.context, "scene", None)
        if scene is not None:
            update_all(scene)
    except Exception:  # noqa: BLE001 - a timer must never raise into Blender
        traceback.print_exc()
    return None


def _check_live_limit(count: int, limit: int, cause: str) -> None:
    """Raises OverLiveLimit when `count` particles are more than `limit` (0: no limit)."""
    if limit and count > limit:
        when = "extracted when the timeline stops; " if cause == FRAME else ""
        raise OverLiveLimit(
            f"{count:,} particles, over the live limit of {limit:,}: {when}"
            "bake the range (Esc cancels), Refresh, or raise Live Particle Limit"
        )


class _CursorProgress:
    """An extraction's progress callback shown as the window manager's cursor progress.
    It begins at the first report, so a frame read from the bake or already shown (no
    extraction) shows none."""

    def __init__(self, wm):
        self.wm = wm
        self.begun = False

    def __call__(self, fraction: float, _phase: str = "") -> None:
        if not self.begun:
            self.wm.progress_begin(0.0, 1.0)
            self.begun = True
        self.wm.progress_update(min(max(float(fraction), 0.0), 1.0))

    def end(self) -> None:
        if self.begun:
            self.begun = False
            self.wm.progress_end()


def _progress_window_manager():
    """The window manager to show a live extraction's progress, or None: none in
    background mode, and none during a render or off the main thread (frame handlers of
    a render run on its thread, where the UI must not be touched)."""
    if _rendering or not _interactive() or threading.current_thread() is not threading.main_thread():
        return None
    return getattr(bpy.context, "window_manager", None)


@contextlib.contextmanager
def live_progress() -> Iterator:
    """A progress callback for a live extraction (None where no UI shows it); the cursor
    progress always ends on leaving, on error too, or the cursor would stay busy."""
    wm = _progress_window_manager()
    if wm is None:
        yield None
        return
    progress = _CursorProgress(wm)
    try:
        yield progress
    finally:
        progress.end()


def extract_live(
    obj,
    scene,
    depsgraph,
    frame: int,
    params: Optional[Params] = None,
    progress=None,
    limit: int = 0,
    cause: str = SETTING,
) -> Tuple[Optional[FrameMesh], str]:
    """Extracts `frame` from the particles: (mesh, or None for a frame without particles;
    where they came from).

    Raises:
        OverLiveLimit: the frame has more than `limit` particles (0: no limit); they are
            counted after reading and before the (far longer) extraction. `cause` (see
            :func:`live_limit`) words the message.
    """
    settings = obj.isobar
    params = params or Params.from_settings(settings)
    if settings.source_type == "OBJECT":
        if depsgraph is None:
            depsgraph = bpy.context.evaluated_depsgraph_get()
        particles = scene_particles(settings, depsgraph)
        origin = f"'{settings.source_object.name}'"
    else:
        path = sequence_path(settings, frame)
        if path is None:
            return None, "no file"
        particles = read_particles(path)
        origin = os.path.basename(path)
    if particles is None:
        return None, origin + ", no particles"
    if len(particles) == 0:  # an emitter before its first particle: an empty surface
        particles.close()
        return None, origin + ", 0 particles"
    try:
        _check_live_limit(len(particles), limit, cause)
        _arrays[object_key(obj)] = extraction.array_infos(particles)
        frame_mesh = extraction.extract(particles, params, progress=progress)
    finally:
        particles.close()
    return frame_mesh, origin


def empty_mesh() -> FrameMesh:
    return FrameMesh(points=np.empty((0, 3), np.float32), triangles=np.empty((0, 3), np.int32))


def _live_key(settings, frame: int, current: str) -> Optional[Tuple]:
    """Identifies the input of a live extraction (None: always extract again)."""
    if settings.source_type == "OBJECT":
        return None  # the scene may have changed in any way
    path = sequence_path(settings, frame)
    if path is None:
        return ("empty", current)
    try:
        stat = os.stat(path)
    except OSError:
        return None  # missing: the extraction reports it
    return ("file", path, stat.st_mtime_ns, stat.st_size, current)


def frame_mesh(
    obj, scene, depsgraph, frame: int, use_cache: bool = True, progress=None, limit: int = 0, cause: str = SETTING
):
    """The surface of `obj` at `frame`: (mesh, origin text, memo key); mesh None when the
    object shows that very surface already. A baked frame is used when baking is on and
    its fingerprint matches the current settings; else the particles are extracted (at
    most `limit` of them, see :func:`extract_live`)."""
    settings = obj.isobar
    params = Params.from_settings(settings)
    note = missing = ""
    if use_cache and settings.use_cache:
        try:
            folder = cache_folder(obj, settings)
        except ValueError:
            folder = ""
        current = fingerprint(settings, params, folder)
        path = cache.frame_path(folder, frame) if folder else ""
        if path and os.path.isfile(path):
            if cache.read_fingerprint(path) == current:
                stat = os.stat(path)
                key = ("cache", path, stat.st_mtime_ns, current)
                if _is_shown(obj, key):
                    return None, "bake", key
                mesh, _ = cache.read(path)
                return mesh, "bake", key
            note = ", baked frame made with other settings"
        elif settings.baked_start <= frame <= settings.baked_end and (frame - settings.baked_start) % max(1, settings.baked_step) == 0:
            # Baked, but not where the bake folder points now: say so, or the user
            # would never learn why playback is slow (or why the particles are read).
            missing = f"the baked frame {frame} is missing ({path or settings.cache_directory}): extracted again"
            note = ", baked frame missing"
    key = _live_key(settings, frame, fingerprint(settings, params) + missing)
    if _is_shown(obj, key):
        return None, "unchanged", key
    mesh, origin = extract_live(obj, scene, depsgraph, frame, params, progress, limit, cause)
    mesh = mesh if mesh is not None else empty_mesh()
    if missing:
        mesh.warnings = [missing] + list(mesh.warnings)
    return mesh, origin + note, key


def _is_shown(obj, key) -> bool:
    shown = _shown.get(object_key(obj))
    if shown is None or key is None or shown[0] != key:
        return False
    data = obj.data
    return len(data.vertices) == shown[1] and len(data.polygons) == shown[2]


def update_object(
    obj, scene=None, depsgraph=None, frame: Optional[int] = None, force: bool = False, cause: str = SETTING
) -> Tuple[bool, str]:
    """Shows the surface of `frame` (default: the scene's current frame) in `obj`'s mesh.

    Never raises: returns (ok, message) and writes the message into ``obj.isobar.status``,
    the extraction's warnings into ``obj.isobar.status_warnings`` (and, for a surface
    extracted now, the console). On failure the mesh keeps what it showed (the last good
    frame) for interactive work; during a render it is emptied (see :func:`_fail_render_frame`).
    A frame over the object's Live Particle Limit (see :func:`live_limit`; `cause` says
    what asks for the update) is such a failure: it is not extracted, and a frame change
    held back while the timeline moves is extracted once it stops. An extraction shows
    its progress in the cursor.
    """
    try:
        if linked_from(obj):
            return False, _linked_message(obj)
        settings = obj.isobar
        scene = scene or bpy.context.scene
        frame = scene.frame_current if frame is None else int(frame)
        if force:
            _shown.pop(object_key(obj), None)
        with live_progress() as progress:
            limit = live_limit(settings, cause)
            mesh, origin, key = frame_mesh(obj, scene, depsgraph, frame, progress=progress, limit=limit, cause=cause)
        if mesh is None:  # the mesh shows this surface already
            _, n, m, origin, warnings = _shown[object_key(obj)]
            message = f"Frame {frame}: {n} vertices, {m} triangles ({origin})"
            _set_status(settings, message, False, warnings)
            _set_backend_note(settings)
            return True, message
        mesh_io.write_object(obj, mesh)
        if key is not None:
            _shown[object_key(obj)] = (key, mesh.n_points, mesh.n_triangles, origin, mesh.warnings)
        else:
            _shown.pop(object_key(obj), None)
        seconds = mesh.info.get("seconds")
        timing = f", {seconds:.2f} s" if isinstance(seconds, (int, float)) and origin != "bake" else ""
        message = f"Frame {frame}: {mesh.n_points} vertices, {mesh.n_triangles} triangles ({origin}{timing})"
        _set_status(settings, message, False, mesh.warnings)
        _set_backend_note(settings)
        if origin != "bake":  # the bake's own extraction was reported then
            for text in mesh.warnings:
                print(f"isobar: {obj.name}: Frame {frame}: warning: {text}")
        return True, message
    except Exception as error:  # noqa: BLE001 - nothing may raise into Blender
        message = describe_error(error)
        if not _is_expected(error):
            traceback.print_exc()
        if isinstance(error, OverLiveLimit) and cause == FRAME:
            _hold_back_until_the_timeline_stops()
        try:
            frame_text = f"Frame {frame}: " if isinstance(frame, int) else ""
            message = frame_text + message
            if _rendering:
                message = _fail_render_frame(obj, message)
            _set_status(obj.isobar, message, True)
        except Exception:  # noqa: BLE001 - the object may be gone
            pass
        print(f"isobar: {getattr(obj, 'name', '?')}: {message}")
        return False, message


def _fail_render_frame(obj, message: str) -> str:
    """A frame failed during a render: the last good frame would render as this one
    and the render would look right, so the mesh is emptied instead (a handler cannot
    stop the render); returns the message saying so."""
    mesh_io.write_object(obj, empty_mesh())
    _shown.pop(object_key(obj), None)
    return message + " (rendering: the surface of this frame is left empty)"


def _is_expected(error: BaseException) -> bool:
    if isinstance(error, (OSError, ValueError)):
        return True
    try:
        return isinstance(error, extraction.isobar_module().Error)
    except Exception:  # noqa: BLE001
        return False


def _set_status(settings, message: str, is_error: bool, warnings: Sequence[str] = ()) -> None:
    """The panel's status line, and the warnings of the surface shown (none after an
    error: they were about a surface the update did not make)."""
    if settings.status != message:
        settings.status = message
    if settings.status_error != is_error:
        settings.status_error = is_error
    text = "\n".join(warnings)
    if settings.status_warnings != text:
        settings.status_warnings = text


def frame_warnings(found: Sequence[Tuple[int, str]]) -> List[str]:
    """One line per distinct warning of (frame, text) pairs, naming the frames it came
    from: a range of frames with no surface is one line, not one per frame."""
    frames: Dict[str, List[int]] = {}
    for frame, text in found:
        frames.setdefault(text, []).append(frame)
    lines = []
    for text, where in frames.items():
        if len(where) == 1:
            lines.append(f"frame {where[0]}: {text}")
        else:
            lines.append(f"{len(where)} frames, {min(where)} to {max(where)}: {text}")
    return lines


def _set_backend_note(settings) -> None:
    """Keeps ``settings.backend_note`` (shown in the panel, reported by the operators)
    saying why Backend Auto runs on the CPU, "" otherwise."""
    note = extraction.auto_backend_note(settings.backend)
    if settings.backend_note != note:
        settings.backend_note = note


def update_all(scene, depsgraph=None) -> None:
    """Updates every fluid surface of `scene` to its current frame (the handler's work)."""
    for obj in list(scene.objects):
        if not is_fluid(obj) or is_baking(obj):
            continue
        if linked_from(obj):
            if obj.name_full not in _linked_noted:  # once, not on every frame
                _linked_noted.add(obj.name_full)
                print(f"isobar: {_linked_message(obj)}")
            continue
        update_object(obj, scene, depsgraph, cause=FRAME)


def _linked_message(obj) -> str:
    return (
        f"'{obj.name}' is linked from {linked_from(obj)}: it shows the mesh saved there; "
        "bake it in that file, or make it local (Object > Relations > Make Local) to extract it here"
    )


# -- property updates and UI helpers ----------------------------------------------------


def on_settings_changed(settings, context, force: bool = True) -> None:
    """A property of `settings` changed: re-extract the current frame (`force` False:
    only when the mesh does not show it already)."""
    if _suspended:
        return
    try:
        obj = settings.id_data
        if not is_fluid(obj) or not settings.live_update or is_baking(obj):
            return
        scene = getattr(context, "scene", None) or bpy.context.scene
        update_object(obj, scene, force=force)
    except Exception:  # noqa: BLE001 - never raise out of a property update
        traceback.print_exc()


def known_arrays(settings) -> List[Tuple[str, int]]:
    try:
        return _arrays.get(object_key(settings.id_data), [])
    except Exception:  # noqa: BLE001
        return []


def field_suggestions(settings, text: str) -> List[str]:
    out = ["SumOfWeights"]
    for name, k in known_arrays(settings):
        out.append(name)
        if k > 1:
            out.append(f"{name}:mag")
    return [s for s in out if text.lower() in s.lower()]


def array_suggestions(settings, text: str) -> List[str]:
    return [n for n, _ in known_arrays(settings) if text.lower() in n.lower()]


__all__ = [
    "FRAME",
    "REFRESH",
    "SETTING",
    "OverLiveLimit",
    "bake_fingerprint",
    "baking",
    "cache_folder",
    "cache_sharers",
    "clear_runtime",
    "extract_held_back_frames",
    "extract_live",
    "fingerprint",
    "frame_mesh",
    "frame_warnings",
    "is_fluid",
    "linked_from",
    "live_limit",
    "live_progress",
    "scene_arrays",
    "sequence_path",
    "set_rendering",
    "suspend_updates",
    "timeline_moving",
    "update_all",
    "update_object",
]
