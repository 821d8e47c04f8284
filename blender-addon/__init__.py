"""isobar Fluid Surface: exact isosurfaces of SPH particle simulations in Blender.

Modules: ``sequence`` (numbered files), ``extraction`` (the isobar call, attribute names),
``cache`` (baked frames), ``mesh`` (numpy into a Blender mesh), ``importer`` (settings to
mesh at a frame), ``bake`` (frame-range jobs), ``usd_export`` (frame ranges into isobar's
USD writer), ``paths`` (blend-relative paths, rebased on Save As) -- these hold no UI --
and ``properties``, ``operators``, ``panels``, ``handlers`` for Blender's side.
"""

from __future__ import annotations

from . import handlers, operators, panels, properties

_MODULES = (properties, operators, panels, handlers)


def register():
    for module in _MODULES:
        module.register()


def unregister():
    for module in reversed(_MODULES):
        module.unregister()
