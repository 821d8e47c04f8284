"""Baking: extracting a frame range of a fluid surface into the cache, one frame per step.

The bake operator runs a :class:`BakeJob` one step per timer tick (modal, Esc cancels) or
all at once (``execute``, for scripts and background mode). No UI here.
"""

from __future__ import annotations

import math
import os
from typing import List, Optional, Tuple

import bpy

from . import cache, importer
from .extraction import Params


class BakeJob:
    """Bakes `frames` of `obj` into its cache folder.

    The parameters are read once, when the job is made: changing them during the bake
    does not mix two surfaces in one cache.

    Raises (constructor):
        ValueError: not a fluid surface, an empty range, or a cache folder relative to an
            unsaved .blend file.
    """

    def __init__(self, obj, scene, frames: List[int]):
        if not importer.is_fluid(obj):
            raise ValueError(f"'{obj.name}' is not an isobar fluid surface")
        if not frames:
            raise ValueError("the frame range to bake is empty")
        self.obj_name = obj.name
        self.scene = scene
        self.frames = list(frames)
        self.index = 0
        self.settings_params = Params.from_settings(obj.isobar)
        self.folder = importer.cache_folder(obj, obj.isobar, assign_name=True)
        self.fingerprint = importer.fingerprint(obj.isobar, self.settings_params, self.folder)
        os.makedirs(self.folder, exist_ok=True)
        self.owner = importer.blend_identity()
        self.original_frame = scene.frame_current
        self.baked: List[int] = []
        #: (frame, text) for what the extractions warned about, for the operator's report.
        self.warnings: List[Tuple[int, str]] = []
        self.is_object_source = obj.isobar.source_type == "OBJECT"

    @property
    def obj(self):
        obj = bpy.data.objects.get(self.obj_name)
        if obj is None:
            raise ValueError(f"the object '{self.obj_name}' was deleted during the bake")
        return obj

    @property
    def total(self) -> int:
        return len(self.frames)

    @property
    def done(self) -> bool:
        return self.index >= len(self.frames)

    @property
    def current_frame(self) -> Optional[int]:
        return None if self.done else self.frames[self.index]

    def step(self, progress=None) -> int:
        """Extracts and stores the next frame; returns it.

        Raises:
            isobar.Error, OSError, ValueError: the frame failed (the message names it).
        """
        frame = self.frames[self.index]
        obj = self.obj
        depsgraph = None
        with importer.baking(obj):
            if self.is_object_source:
                self.scene.frame_set(frame)
                depsgraph = bpy.context.evaluated_depsgraph_get()
            mesh, _origin = importer.extract_live(obj, self.scene, depsgraph, frame, self.settings_params, progress)
        if mesh is None:
            mesh = importer.empty_mesh()
        self.warnings.extend((frame, text) for text in mesh.warnings)
        cache.write(cache.frame_path(self.folder, frame), mesh, self.fingerprint, self.owner)
        self.baked.append(frame)
        self.index += 1
        return frame

    def finish(self) -> None:
        """Turns playback from the cache on (when a frame was baked), goes back to the
        frame the bake started on and shows it."""
        obj = bpy.data.objects.get(self.obj_name)
        if obj is None:
            return
        settings = obj.isobar
        if self.baked:
            with importer.suspend_updates():
                settings.use_cache = True
                settings.baked_start, settings.baked_end, settings.baked_step = self._playable_range()
        if self.is_object_source and self.scene.frame_current != self.original_frame:
            self.scene.frame_set(self.original_frame)  # the handler updates the surface
        importer.update_object(obj, self.scene, force=True)


    def _playable_range(self) -> Tuple[int, int, int]:
        """First and last frame in the folder that playback uses (this bake's and those an
        earlier bake with the same settings left: re-baking a sub-range keeps them), and
        their step (2 for a bake of every other frame, Frame Step 2): the frames between
        were not baked, rather than missing."""
        playable = [
            frame
            for frame in cache.frames(self.folder)
            if cache.read_fingerprint(cache.frame_path(self.folder, frame)) == self.fingerprint
        ] or self.baked
        step = 0
        for a, b in zip(playable, playable[1:]):
            step = math.gcd(step, b - a)
        return min(playable), max(playable), max(1, step)


def scene_frames(scene, start: Optional[int] = None, end: Optional[int] = None) -> List[int]:
    """Frames start..end (default: the scene's range), every frame_step-th."""
    start = scene.frame_start if start is None else start
    end = scene.frame_end if end is None else end
    return list(range(start, end + 1, max(1, scene.frame_step)))


def free(obj) -> Tuple[int, List[str]]:
    """Deletes `obj`'s baked frames and turns playback from the cache off; returns how
    many files were deleted and the other surfaces using the same folder (a duplicated
    object copies its original's cache name): their frames are kept, and `obj` only lets
    go of the folder."""
    settings = obj.isobar
    sharers = importer.cache_sharers(obj)
    try:
        folder = importer.cache_folder(obj, settings)
    except ValueError:
        folder = ""
    removed = cache.clear(folder) if folder and not sharers else 0
    with importer.suspend_updates():
        settings.use_cache = False
        settings.baked_start, settings.baked_end, settings.baked_step = 0, -1, 1
        if sharers:
            settings.cache_name = ""  # the next bake picks a folder of its own
    importer.update_object(obj, force=True)
    return removed, sharers


__all__ = ["BakeJob", "free", "scene_frames"]
