"""Blend-relative paths of the add-on's settings (no UI).

The add-on keeps its file and folder paths (particle folder, bake folder, volume, store,
FE file) the way Blender keeps an image's: relative to the .blend file ('//') once it is
saved, so that a project folder can be moved. Blender remaps its own relative paths when
a file is saved to another folder, but not those in add-on properties: the save handlers
call :func:`before_save` and :func:`after_save`, which do that for the add-on's paths.
"""

from __future__ import annotations

import os
from typing import List, Tuple

import bpy

#: (property group, path properties) of every path the add-on stores on an object; a
#: group's paths are touched only while the group is enabled.
PATH_PROPERTIES = (
    ("isobar", ("directory", "cache_directory")),
    ("isobar_slider", ("volume", "store")),
    ("isobar_fe", ("filepath",)),
)

#: (object name, group, property, value before the save) of what before_save rewrote,
#: for after_save to put back when the open file did not move (Save Copy).
_rewritten: List[Tuple[str, str, str, str]] = []


def for_blend(path: str) -> str:
    """`path` as the add-on stores it: relative to the .blend file when that is saved,
    else (unsaved file, another drive) as given."""
    if not path or not bpy.data.filepath:
        return path
    return _relative(path, os.path.dirname(bpy.data.filepath)) or path


def resolve(value: str) -> str:
    """The absolute, normalized path of a stored path ('' stays ''): one spelling per
    file, so that an open volume or FE mesh is found again under its '//' name."""
    return os.path.normpath(bpy.path.abspath(value)) if value else ""


def rebase(value: str, old_blend: str, new_blend: str) -> str:
    """`value` rewritten for a .blend file saved from `old_blend` to `new_blend` ('' for
    an unsaved file): a '//' path keeps pointing at the same place; an absolute path is
    made relative on the first save only, as Blender does for images."""
    if not value or not new_blend:
        return value
    if value.startswith("//"):
        if not old_blend:
            return value  # relative to a file that was never saved: nothing to keep
        absolute = bpy.path.abspath(value, start=os.path.dirname(old_blend))
    elif old_blend:
        return value  # an absolute path chosen in a saved file stays absolute
    else:
        absolute = value
    return _relative(absolute, os.path.dirname(new_blend)) or value


def _relative(path: str, start: str) -> str:
    """'//' path of `path` from folder `start`, keeping a folder's trailing separator;
    '' when there is none (another drive)."""
    try:
        relative = bpy.path.relpath(os.path.normpath(path), start=start)
    except ValueError:
        return ""
    if path.endswith(("/", os.sep)) and not relative.endswith(("/", os.sep)):
        relative += "/"
    return relative


def _stored_paths():
    """(object, group name, group, property, value) of every path stored on an editable
    object (a linked object's paths are relative to its library, not to this file)."""
    for obj in bpy.data.objects:
        if obj.library is not None:
            continue
        for group_name, names in PATH_PROPERTIES:
            group = getattr(obj, group_name, None)
            if group is None or not group.enabled:
                continue
            for name in names:
                yield obj, group_name, group, name, getattr(group, name)


def before_save(target: str) -> None:
    """Rewrites the add-on's paths for the .blend file being saved to `target`."""
    from . import importer  # late: importer imports the core lazily, keep this light

    _rewritten.clear()
    old = bpy.data.filepath
    with importer.suspend_updates():  # a new spelling of the same path: nothing to redo
        for obj, group_name, group, name, value in _stored_paths():
            new = rebase(value, old, target)
            if new != value:
                _rewritten.append((obj.name_full, group_name, name, value))
                setattr(group, name, new)


def after_save(target: str) -> None:
    """Puts the paths back when the open file stays where it was (Save Copy: only the
    copy on disk lives at `target`)."""
    from . import importer

    rewritten = list(_rewritten)
    _rewritten.clear()
    if _same_file(bpy.data.filepath, target):
        return
    with importer.suspend_updates():
        for obj_name, group_name, name, value in rewritten:
            obj = bpy.data.objects.get(obj_name)
            if obj is not None:
                setattr(getattr(obj, group_name), name, value)


def _same_file(a: str, b: str) -> bool:
    return bool(a) and bool(b) and os.path.normcase(os.path.abspath(a)) == os.path.normcase(os.path.abspath(b))


__all__ = ["PATH_PROPERTIES", "after_save", "before_save", "for_blend", "rebase", "resolve"]
