"""The persistent frame-change and load handlers."""

from __future__ import annotations

import traceback

import bpy
from bpy.app.handlers import persistent

from . import importer


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


_HANDLERS = (
    (bpy.app.handlers.frame_change_post, isobar_frame_change_post),
    (bpy.app.handlers.load_post, isobar_load_post),
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
