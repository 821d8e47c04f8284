"""The sidebar panel: View3D > Sidebar > isobar."""

from __future__ import annotations

import bpy

from . import importer


class _Sidebar:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "isobar"


def _fluid(context):
    obj = getattr(context, "active_object", None)
    return obj if importer.is_fluid(obj) else None


class _FluidPart(_Sidebar):
    """A sub-panel of the fluid surface panel, shown while a fluid surface is active."""

    bl_parent_id = "ISOBAR_PT_main"

    @classmethod
    def poll(cls, context):
        return _fluid(context) is not None


class ISOBAR_PT_main(_Sidebar, bpy.types.Panel):
    bl_label = "Fluid Surface"
    bl_idname = "ISOBAR_PT_main"

    def draw(self, context):
        layout = self.layout
        col = layout.column(align=True)
        col.operator("isobar.import_sequence", text="Import Particle Sequence", icon="IMPORT")
        col.operator("isobar.surface_from_object", text="Surface from Active Object", icon="MOD_FLUIDSIM")
        obj = _fluid(context)
        if obj is None:
            layout.label(text="Select a fluid surface to edit it", icon="INFO")
            return
        settings = obj.isobar
        box = layout.box()
        box.label(text=obj.name, icon="MOD_FLUIDSIM")
        if settings.status:
            row = box.row()
            row.alert = settings.status_error
            row.label(text=settings.status, icon="ERROR" if settings.status_error else "CHECKMARK")
        for warning in settings.status_warnings.splitlines():
            box.label(text=warning, icon="ERROR")
        row = box.row(align=True)
        row.operator("isobar.refresh", text="Refresh", icon="FILE_REFRESH")
        row.prop(settings, "live_update", text="Live", toggle=True)
        box.operator("isobar.export_usd", text="Export USD", icon="EXPORT")


class ISOBAR_PT_source(_FluidPart, bpy.types.Panel):
    bl_label = "Particles"

    def draw(self, context):
        settings = _fluid(context).isobar
        layout = self.layout
        layout.use_property_split = True
        layout.prop(settings, "source_type")
        if settings.source_type == "SEQUENCE":
            layout.prop(settings, "directory")
            layout.prop(settings, "pattern")
            col = layout.column(align=True)
            col.prop(settings, "file_first", text="Files")
            col.prop(settings, "file_last", text="To")
            layout.prop(settings, "frame_offset")
            layout.prop(settings, "hold")
        else:
            layout.prop(settings, "source_object")
            if settings.source_object is not None and len(settings.source_object.particle_systems):
                layout.prop(settings, "particle_system")


class ISOBAR_PT_surface(_FluidPart, bpy.types.Panel):
    bl_label = "Surface"

    def draw(self, context):
        settings = _fluid(context).isobar
        layout = self.layout
        layout.use_property_split = True
        layout.prop(settings, "field")
        layout.prop(settings, "iso")
        layout.prop(settings, "kernel")
        layout.prop(settings, "h_mode")
        if settings.h_mode == "ARRAY":
            layout.prop(settings, "h_array")
        else:
            layout.prop(settings, "h")
        layout.prop(settings, "h_scale")
        layout.prop(settings, "grid_factor")
        layout.prop(settings, "method")
        layout.prop(settings, "backend")
        if settings.backend == "AUTO" and settings.backend_note:
            layout.label(text=f"Running on the CPU: {settings.backend_note}", icon="INFO")
        if settings.method == "ADAPTIVE":
            layout.prop(settings, "splash_threshold")
            layout.prop(settings, "max_error")
            layout.prop(settings, "bisection_iterations")
            return
        layout.prop(settings, "correct")
        layout.prop(settings, "trim")
        if settings.trim == "CUSTOM":
            col = layout.column(align=True)
            col.prop(settings, "trim_node")
            col.prop(settings, "trim_vertex")


class ISOBAR_PT_attributes(_FluidPart, bpy.types.Panel):
    bl_label = "Attributes"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        settings = _fluid(context).isobar
        layout = self.layout
        layout.use_property_split = True
        layout.prop(settings, "attributes")
        layout.prop(settings, "speed")
        layout.prop(settings, "velocity_array")
        layout.prop(settings, "motion_blur")
        sub = layout.column()
        sub.active = settings.motion_blur
        sub.prop(settings, "velocity_scale")
        layout.label(text="Shader: Attribute node, name sph_<array>", icon="NODE")


class ISOBAR_PT_cache(_FluidPart, bpy.types.Panel):
    bl_label = "Bake"

    def draw(self, context):
        settings = _fluid(context).isobar
        layout = self.layout
        layout.use_property_split = True
        layout.prop(settings, "cache_directory")
        layout.prop(settings, "use_cache")
        layout.prop(settings, "live_particle_limit")
        if settings.baked_end >= settings.baked_start:
            every = f", every {settings.baked_step}" if settings.baked_step > 1 else ""
            layout.label(text=f"Baked frames {settings.baked_start} to {settings.baked_end}{every}", icon="INFO")
        row = layout.row(align=True)
        row.operator("isobar.bake", text="Bake", icon="REC")
        row.operator("isobar.free_bake", text="Free", icon="TRASH")


def _draw_isovalue_object(layout, context, import_op: str, import_text: str, group: str, draw_settings):
    """An import button, then the active object's isovalue settings (property group
    `group`): what `draw_settings(layout, settings)` shows, the value range, the status."""
    layout.operator(import_op, text=import_text, icon="IMPORT")
    obj = getattr(context, "active_object", None)
    settings = getattr(obj, group, None) if obj is not None else None
    if settings is None or not settings.enabled:
        return
    draw_settings(layout, settings)
    layout.label(text=f"Range {settings.value_min:.6g} .. {settings.value_max:.6g}")
    if settings.status:
        row = layout.row()
        row.alert = settings.status_error
        row.label(text=settings.status, icon="ERROR" if settings.status_error else "CHECKMARK")
    for warning in getattr(settings, "status_warnings", "").splitlines():
        layout.label(text=warning, icon="ERROR")


class ISOBAR_PT_slider(_Sidebar, bpy.types.Panel):
    bl_label = "Isovalue Slider"
    bl_idname = "ISOBAR_PT_slider"

    def draw(self, context):
        def settings(layout, s):
            layout.prop(s, "isovalue", slider=True)
            layout.prop(s, "lod_error_bound")

        _draw_isovalue_object(self.layout, context, "isobar.import_volume", "Import Volume", "isobar_slider", settings)


class ISOBAR_PT_fe(_Sidebar, bpy.types.Panel):
    bl_label = "High-Order FE Isosurface"
    bl_idname = "ISOBAR_PT_fe"

    def draw(self, context):
        def settings(layout, s):
            for name in ("field", "isovalue", "spacing", "curvature_adaptivity"):
                layout.prop(s, name, slider=name == "isovalue")

        _draw_isovalue_object(self.layout, context, "isobar.import_fe", "Import FE Field", "isobar_fe", settings)


classes = (ISOBAR_PT_main, ISOBAR_PT_source, ISOBAR_PT_surface, ISOBAR_PT_attributes, ISOBAR_PT_cache, ISOBAR_PT_slider, ISOBAR_PT_fe)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
