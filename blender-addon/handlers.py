"""The persistent frame-change, load, save and render handlers."""

from __future__ import annotations

import traceback

import bpy
from bpy.app.handlers import persistent

from . import importer, paths


@persistent
def isobar_frame_change_post(scene, depsgraph=None):
    """Shows every fluid surface of the scene at the new frame (errors: status text)."""
    try:
        importer.update_all(scene, depsgraph)
    except Exception:  # noqa: BLE001 - a handler must never raise into Blender
        traceback.print_exc()


@persistent
def isobar_load_post(*_args):
    """A file was loaded: forget what the meshes of the previous file showed."""
    importer.clear_runtime()


@persistent
def isobar_render_init(*_args):
    """A render starts: a frame that fails must not render as the last good one."""
    importer.set_rendering(True)


@persistent
def isobar_render_end(*_args):
    """The render completed or was cancelled: back to keeping the last good frame."""
    importer.set_rendering(False)


@persistent
def isobar_save_pre(filepath="", *_args):
    """The .blend is about to be written to `filepath`: the add-on's '//' paths are
    rewritten to point at the same files from there (Blender remaps only its own)."""
    try:
        paths.before_save(filepath)
    except Exception:  # noqa: BLE001 - a handler must never raise into Blender
        traceback.print_exc()


@persistent
def isobar_save_post(filepath="", *_args):
    """The .blend was written: after Save Copy the open file's paths go back."""
    try:
        paths.after_save(filepath)
    except Exception:  # noqa: BLE001
        traceback.print_exc()


_HANDLERS = (
    (bpy.app.handlers.frame_change_post, isobar_frame_change_post),
    (bpy.app.handlers.load_post, isobar_load_post),
    (bpy.app.handlers.save_pre, isobar_save_pre),
    (bpy.app.handlers.save_post, isobar_save_post),
    (bpy.app.handlers.render_init, isobar_render_init),
    (bpy.app.handlers.render_complete, isobar_render_end),
    (bpy.app.handlers.render_cancel, isobar_render_end),
)


def _remove(handler_list, function):
    # Also drops a stale copy left by an earlier registration of this module.
    for item in list(handler_list):
        if item is function or getattr(item, "__name__", "") == function.__name__:
            handler_list.remove(item)


def register():
    for handler_list, function in _HANDLERS:
        _remove(handler_list, function)
        handler_list.append(function)


def unregister():
    for handler_list, function in _HANDLERS:
        _remove(handler_list, function)
