"""The sidebar panels draw (with a recording stand-in for the UI layout, as background
bpy has no regions) and name only existing properties and operators."""

import bpy
from conftest import GRID_FACTOR, ISO, H


class Layout:
    """Records prop/operator calls; every sub-layout is another recorder."""

    def __init__(self, log):
        self.log = log

    def prop(self, data, name, **_kwargs):
        assert name in data.bl_rna.properties, f"{data} has no property '{name}'"
        self.log.append(("prop", name))

    def operator(self, idname, **_kwargs):
        group, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, group), name), idname
        self.log.append(("operator", idname))

    def label(self, text="", **_kwargs):
        self.log.append(("label", text))

    def _sub(self, *_args, **_kwargs):
        return Layout(self.log)

    row = column = box = split = _sub

    def __setattr__(self, name, value):
        object.__setattr__(self, name, value)  # use_property_split, active, alert ...


def draw_all(context):
    log = []
    for cls in (
        bpy.types.ISOBAR_PT_main,
        *[getattr(bpy.types, n) for n in dir(bpy.types) if n.startswith("ISOBAR_PT_") and n != "ISOBAR_PT_main"],
    ):
        if hasattr(cls, "poll") and not cls.poll(context):
            continue
        panel = type("Panel", (), {"layout": Layout(log)})()
        cls.draw(panel, context)
    return log


def test_panels_without_and_with_a_fluid_surface(scene, demo_sequence):
    log = draw_all(bpy.context)
    assert ("operator", "isobar.import_sequence") in log and ("operator", "isobar.surface_from_object") in log
    assert not any(kind == "prop" for kind, _ in log)

    bpy.ops.isobar.import_sequence(filepath=str(demo_sequence[0]), h=H, iso=ISO, grid_factor=GRID_FACTOR)
    log = draw_all(bpy.context)
    props = {name for kind, name in log if kind == "prop"}
    assert {"field", "iso", "kernel", "h", "h_scale", "grid_factor", "method", "backend", "correct", "trim"} <= props
    assert {"directory", "pattern", "frame_offset", "cache_directory", "use_cache", "live_particle_limit"} <= props
    assert ("operator", "isobar.bake") in log and ("operator", "isobar.free_bake") in log
    assert any(kind == "label" and text.startswith("Frame 1:") for kind, text in log)  # the status
    settings = bpy.context.active_object.isobar
    settings.trim, settings.h_mode, settings.source_type = "CUSTOM", "ARRAY", "OBJECT"
    props = {name for kind, name in draw_all(bpy.context) if kind == "prop"}
    assert {"trim_node", "trim_vertex", "h_array", "source_object"} <= props
    # The adaptive method shows its own settings and not Marching Correctors'.
    settings.method = "ADAPTIVE"
    props = {name for kind, name in draw_all(bpy.context) if kind == "prop"}
    assert {"splash_threshold", "max_error", "bisection_iterations"} <= props
    assert not {"correct", "trim", "trim_node"} & props


def test_field_search_lists_the_particle_arrays(scene, addon, demo_sequence):
    bpy.ops.isobar.import_sequence(filepath=str(demo_sequence[0]), h=H, iso=ISO, grid_factor=GRID_FACTOR)
    settings = bpy.context.active_object.isobar
    suggestions = addon.importer.field_suggestions(settings, "")
    assert suggestions[0] == "SumOfWeights" and "velocity" in suggestions and "velocity:mag" in suggestions
    assert addon.importer.field_suggestions(settings, "vel") == ["velocity", "velocity:mag"]
