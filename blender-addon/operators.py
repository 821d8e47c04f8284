"""Operators: import a particle sequence, make a surface from scene particles, refresh,
bake (modal, Esc cancels), free the bake and export to USD. Errors reach the user through
self.report."""

from __future__ import annotations

import os

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper, ImportHelper

from . import bake, extraction, fe_samples, importer, paths, sequence, usd_export, volume_slider


def _fluid_object(context, name: str = ""):
    """The object named `name`, else the active object, when it is a fluid surface."""
    obj = bpy.data.objects.get(name) if name else getattr(context, "active_object", None)
    return obj if importer.is_fluid(obj) else None


def _new_surface_object(context, name: str):
    return _link_and_select(context, bpy.data.objects.new(name, bpy.data.meshes.new(name)))


def _link_and_select(context, obj):
    """Links `obj` to the active collection and makes it the only selected, active object."""
    collection = getattr(context, "collection", None) or context.scene.collection
    collection.objects.link(obj)
    for other in context.view_layer.objects:
        other.select_set(False)
    obj.select_set(True)
    context.view_layer.objects.active = obj
    return obj


def _default_material():
    """A water-like material (created once per file, shared by the surfaces)."""
    name = "isobar Water"
    material = bpy.data.materials.get(name)
    if material is None:
        material = bpy.data.materials.new(name)
        material.diffuse_color = (0.35, 0.6, 0.9, 1.0)
        if bpy.app.version < (5, 0, 0) and not material.use_nodes:
            material.use_nodes = True  # always on (and deprecated) from 5.0
        bsdf = material.node_tree.nodes.get("Principled BSDF") if material.node_tree else None
        if bsdf is not None:
            bsdf.inputs["Base Color"].default_value = (0.35, 0.6, 0.9, 1.0)
            bsdf.inputs["Roughness"].default_value = 0.05
    return material


def _report_update_warnings(operator, settings) -> None:
    """Warnings about the update that just ran, from what it kept for the panel: Backend
    Auto ran on the CPU (in the CLI's words: the user chose Auto and may expect the GPU;
    ``backend_note``), and what the extraction warned about (``status_warnings``: the
    surface was made, but may not be the one the user meant). FE samples have no back end
    to choose, hence no ``backend_note``."""
    note = getattr(settings, "backend_note", "")
    if note:
        operator.report({"WARNING"}, f"backend auto: running on the CPU ({note})")
    for text in settings.status_warnings.splitlines():
        operator.report({"WARNING"}, text)


def _report_frame_warnings(operator, found) -> None:
    """What the extractions of a frame range warned about ((frame, text) pairs), one
    report per distinct warning."""
    for line in importer.frame_warnings(found):
        operator.report({"WARNING"}, line)


class _SurfaceParameters:
    """Parameters asked for when a surface is made (the panel has them all)."""

    iso: FloatProperty(
        name="Isovalue", default=0.6, precision=4, description="Level of the free-surface field (sum of weights)"
    )
    h: FloatProperty(
        name="Smoothing Length",
        default=0.05,
        min=1e-9,
        precision=5,
        subtype="DISTANCE",
        description="SPH smoothing length, about twice the particle radius (a per-particle h array in the files wins)",
    )
    grid_factor: FloatProperty(
        name="Grid Factor", default=0.5, min=0.01, soft_max=2.0, description="Cell size in units of h"
    )

    def apply(self, settings, names):
        settings.iso = self.iso
        settings.grid_factor = self.grid_factor
        settings.h = self.h
        h_array = extraction.h_array_name([n for n, _ in names])
        if h_array:
            settings.h_mode, settings.h_array = "ARRAY", h_array
        else:
            settings.h_mode = "CONSTANT"
        settings.velocity_array = extraction.velocity_name(names) or "velocity"


class ISOBAR_OT_import_sequence(bpy.types.Operator, ImportHelper, _SurfaceParameters):
    """Import a numbered SPH particle sequence as a fluid surface extracted on frame change"""

    bl_idname = "isobar.import_sequence"
    bl_label = "Import SPH Particle Sequence"
    bl_options = {"REGISTER", "UNDO"}

    filter_glob: StringProperty(default=";".join("*" + e for e in sequence.PARTICLE_EXTENSIONS), options={"HIDDEN"})
    frame_offset: IntProperty(name="Frame Offset", default=0, description="Scene frame = file number + offset")
    set_frame_range: BoolProperty(
        name="Set Scene Frame Range", default=True, description="Make the scene's frame range the sequence's"
    )
    y_up: BoolProperty(
        name="Y Up",
        default=False,
        description="The simulation's up axis is Y: rotate the object so it stands in Blender's Z up",
    )
    relative_path: BoolProperty(
        name="Relative Path",
        default=True,
        description="Store the folder relative to the .blend file (when it is saved)",
    )

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        for name in ("iso", "h", "grid_factor", "frame_offset", "set_frame_range", "y_up", "relative_path"):
            layout.prop(self, name)

    def execute(self, context):
        try:
            seq = sequence.detect(self.filepath)
        except ValueError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        try:
            particles = importer.read_particles(seq.path(seq.first))
            try:
                names = extraction.array_infos(particles)
            finally:
                particles.close()
        except Exception as error:  # noqa: BLE001 - reported, not raised
            self.report({"ERROR"}, importer.describe_error(error))
            return {"CANCELLED"}

        stem = sequence.name_stem(seq.pattern) or "fluid"
        obj = _new_surface_object(context, f"{stem}_surface")
        obj.data.materials.append(_default_material())
        directory = paths.for_blend(seq.directory) if self.relative_path else seq.directory
        settings = obj.isobar
        with importer.suspend_updates():
            settings.enabled = True
            settings.source_type = "SEQUENCE"
            settings.directory = directory if directory.endswith(("/", os.sep)) else directory + os.sep
            settings.pattern = seq.pattern
            settings.file_first, settings.file_last = seq.first, seq.last
            settings.frame_offset = self.frame_offset
            self.apply(settings, names)
        importer._arrays[importer.object_key(obj)] = names
        if self.y_up:
            obj.rotation_euler = (1.5707963267948966, 0.0, 0.0)
        scene = context.scene
        if self.set_frame_range and not seq.is_static:  # a static file has no range
            scene.frame_start = seq.first + self.frame_offset
            scene.frame_end = seq.last + self.frame_offset

        ok, message = importer.update_object(obj, scene, force=True)
        missing = seq.missing()
        if missing:
            self.report({"WARNING"}, f"{len(missing)} files missing in the sequence (first: {seq.path(missing[0])})")
        if not ok:
            self.report({"WARNING"}, f"Imported '{obj.name}', but the current frame failed: {message}")
        else:
            self.report({"INFO"}, f"Imported {len(seq.numbers)} files as '{obj.name}': {message}")
            _report_update_warnings(self, settings)
        return {"FINISHED"}


class ISOBAR_OT_import_volume(bpy.types.Operator, ImportHelper):
    """Import a volume for isovalue sliding: pre-encode it once, then drag the isovalue"""

    bl_idname = "isobar.import_volume"
    bl_label = "Import Volume for Isovalue Sliding"
    bl_options = {"REGISTER", "UNDO"}

    filter_glob: StringProperty(
        default=";".join("*" + e for e in volume_slider.VOLUME_EXTENSIONS + (volume_slider.STORE_EXTENSION,)),
        options={"HIDDEN"},
    )
    lod_error_bound: FloatProperty(
        name="LOD Error Bound",
        description="Level of detail, as a fraction of the value range (0: the exact surface); "
        "editable later in the Isovalue Slider panel",
        default=0.0,
        min=0.0,
        max=0.99,
        soft_max=0.1,
        step=0.1,
        precision=4,
    )
    memory_budget: FloatProperty(
        name="Memory Budget (GiB)",
        description="What pre-encoding the volume may hold besides the volume (0: the default, 4 GiB); "
        "past about 29 bytes a node it sorts on disk, beside the store, and writes the same store",
        default=4.0,
        min=0.0,
        soft_max=64.0,
    )

    def execute(self, context):
        path = paths.resolve(self.filepath)
        stem = os.path.splitext(os.path.basename(path))[0] or "volume"
        obj = None
        try:
            # The cursor shows the store build (seconds for a 256³ volume).
            with importer.live_progress() as progress:
                store, said = volume_slider.ensure_store(path, self.memory_budget, progress=progress)
            obj = _new_surface_object(context, f"{stem}_isosurface")
            # The object's own slider: opening a store checks it whole, so open it once.
            lo, hi = volume_slider.slider_for(obj, store).value_range
        except Exception as error:  # noqa: BLE001 - reported, not raised
            if obj is not None:
                volume_slider.close(obj)
                bpy.data.objects.remove(obj)
            self.report({"ERROR"}, importer.describe_error(error))
            return {"CANCELLED"}
        settings = obj.isobar_slider
        settings.volume, settings.store = paths.for_blend(path), paths.for_blend(store)
        settings.value_min, settings.value_max = lo, hi
        settings.lod_error_bound = self.lod_error_bound  # not enabled yet: no slide
        settings.enabled = True
        settings.isovalue = 0.5 * (lo + hi)  # slides: the mesh appears
        for text in said:
            self.report({"WARNING"}, text)
        if settings.status_error:
            self.report({"ERROR"}, settings.status)
        return {"FINISHED"}


class ISOBAR_OT_import_fe(bpy.types.Operator, ImportHelper):
    """Import the isosurface of a high-order finite-element field as a point cloud"""

    bl_idname = "isobar.import_fe"
    bl_label = "Import High-Order FE Isosurface"
    bl_options = {"REGISTER", "UNDO"}

    filter_glob: StringProperty(default=";".join("*" + e for e in fe_samples.FE_EXTENSIONS), options={"HIDDEN"})
    field: StringProperty(name="Field", description="Scalar point array to contour (empty: the first one)")
    isovalue: FloatProperty(name="Isovalue", description="Isovalue (NaN: the median of the field's node values)", default=float("nan"))
    spacing: FloatProperty(name="Spacing", description="Sample spacing on flat parts (0: 1/40 of the diagonal)", default=0.0, min=0.0)

    def execute(self, context):
        path = paths.resolve(self.filepath)
        stem = os.path.splitext(os.path.basename(path))[0] or "fe"
        obj = None
        try:
            # An empty point cloud that the settings below sample into; its FE mesh is read
            # once here and kept for every later isovalue change.
            obj = bpy.data.objects.new(f"{stem}_samples", bpy.data.pointclouds.new(f"{stem}_samples"))
            fields = fe_samples.scalar_fields(fe_samples.mesh_for(obj, path))
            if not fields:
                raise ValueError(f"{path}: no scalar point array to contour")
            chosen = [f for f in fields if f[0] == self.field] if self.field else fields[:1]
            if not chosen:
                raise ValueError(f"{path}: no scalar point array '{self.field}'; it has {', '.join(f[0] for f in fields)}")
            # The median node value: half the nodes on each side, so the surface cuts cells.
            name, lo, hi, median = chosen[0]
            iso = median if self.isovalue != self.isovalue else self.isovalue
        except Exception as error:  # noqa: BLE001 - reported, not raised
            if obj is not None:
                fe_samples.close(obj)
                bpy.data.objects.remove(obj)
            self.report({"ERROR"}, importer.describe_error(error))
            return {"CANCELLED"}
        _link_and_select(context, obj)
        settings = obj.isobar_fe
        settings.value_min, settings.value_max = lo, hi
        settings.filepath = paths.for_blend(path)
        settings.spacing = self.spacing
        settings.isovalue = iso
        settings.enabled = True
        settings.field = name  # samples: the points appear
        if settings.status_error:
            self.report({"ERROR"}, settings.status)
            return {"FINISHED"}
        self.report({"INFO"}, f"'{obj.name}': {settings.status}")
        _report_update_warnings(self, settings)
        return {"FINISHED"}


class ISOBAR_OT_surface_from_object(bpy.types.Operator, _SurfaceParameters):
    """Fluid surface from scene particles: a mesh's or point cloud's points and attributes, or a particle system"""

    bl_idname = "isobar.surface_from_object"
    bl_label = "Fluid Surface from Object"
    bl_options = {"REGISTER", "UNDO"}

    source: StringProperty(
        name="Source", description="Object with the particles (default: the active object)", options={"SKIP_SAVE"}
    )
    particle_system: StringProperty(
        name="Particle System",
        description="Particle system to use (default: the first one, if any; 'NONE' for the points)",
        options={"SKIP_SAVE"},
    )

    def execute(self, context):
        src = bpy.data.objects.get(self.source) if self.source else context.active_object
        if src is None:
            self.report({"ERROR"}, "select the object with the particles (a mesh, point cloud or particle emitter)")
            return {"CANCELLED"}
        if src.type not in {"MESH", "POINTCLOUD"} or importer.is_fluid(src):
            self.report({"ERROR"}, f"'{src.name}' is not a mesh, point cloud or particle emitter")
            return {"CANCELLED"}
        psys = self.particle_system
        if psys == "NONE":
            psys = ""
        elif not psys and len(src.particle_systems):
            psys = src.particle_systems[0].name
        if psys and psys not in src.particle_systems:
            self.report({"ERROR"}, f"'{src.name}' has no particle system '{psys}'")
            return {"CANCELLED"}

        obj = _new_surface_object(context, f"{src.name}_surface")
        obj.data.materials.append(_default_material())
        settings = obj.isobar
        with importer.suspend_updates():
            settings.enabled = True
            settings.source_type = "OBJECT"
            settings.source_object = src
            settings.particle_system = psys
            try:
                _, arrays = importer.scene_arrays(settings, context.evaluated_depsgraph_get())
                names = [(n, 1 if v.ndim == 1 else v.shape[1]) for n, v in arrays.items()]
            except Exception:  # noqa: BLE001 - the update below reports it
                names = []
            self.apply(settings, names)
        importer._arrays[importer.object_key(obj)] = names
        ok, message = importer.update_object(obj, context.scene, context.evaluated_depsgraph_get(), force=True)
        if not ok:
            self.report({"WARNING"}, f"Made '{obj.name}', but the current frame failed: {message}")
        else:
            self.report({"INFO"}, f"Made '{obj.name}': {message}")
            _report_update_warnings(self, settings)
        return {"FINISHED"}


class ISOBAR_OT_refresh(bpy.types.Operator):
    """Extract the current frame of the fluid surface again, whatever its particle count"""

    bl_idname = "isobar.refresh"
    bl_label = "Refresh Surface"
    bl_options = {"REGISTER"}

    object_name: StringProperty(
        name="Object", description="Fluid surface (default: the active object)", options={"SKIP_SAVE"}
    )

    def execute(self, context):
        obj = _fluid_object(context, self.object_name)
        if obj is None:
            self.report({"ERROR"}, "select an isobar fluid surface")
            return {"CANCELLED"}
        ok, message = importer.update_object(obj, context.scene, force=True, cause=importer.REFRESH)
        if not ok:
            self.report({"ERROR"}, message)
            return {"CANCELLED"}
        self.report({"INFO"}, message)
        _report_update_warnings(self, obj.isobar)
        return {"FINISHED"}


class ISOBAR_OT_bake(bpy.types.Operator):
    """Extract every frame of the range into the cache on disk (Esc cancels); playback then reads the cache"""

    bl_idname = "isobar.bake"
    bl_label = "Bake Fluid Surface"
    bl_options = {"REGISTER"}

    object_name: StringProperty(
        name="Object", description="Fluid surface (default: the active object)", options={"SKIP_SAVE"}
    )
    use_scene_range: BoolProperty(
        name="Scene Range", default=True, description="Bake the scene's frame range", options={"SKIP_SAVE"}
    )
    frame_start: IntProperty(name="Start", default=1, options={"SKIP_SAVE"})
    frame_end: IntProperty(name="End", default=250, options={"SKIP_SAVE"})

    _job = None
    _timer = None

    def _make_job(self, context):
        obj = _fluid_object(context, self.object_name)
        if obj is None:
            raise ValueError("select an isobar fluid surface to bake")
        scene = context.scene
        frames = (
            bake.scene_frames(scene)
            if self.use_scene_range
            else bake.scene_frames(scene, self.frame_start, self.frame_end)
        )
        return bake.BakeJob(obj, scene, frames)

    # -- all at once (scripts, background mode) ----------------------------------------

    def execute(self, context):
        try:
            job = self._make_job(context)
        except Exception as error:  # noqa: BLE001
            self.report({"ERROR"}, importer.describe_error(error))
            return {"CANCELLED"}
        wm = context.window_manager
        wm.progress_begin(0, job.total)
        try:
            while not job.done:
                i = job.index

                def progress(fraction, _phase, i=i):
                    wm.progress_update(i + fraction)

                job.step(progress)
                wm.progress_update(job.index)
        except Exception as error:  # noqa: BLE001
            frame = job.current_frame
            job.finish()
            _report_frame_warnings(self, job.warnings)
            self.report({"ERROR"}, f"Bake stopped at frame {frame}: {importer.describe_error(error)}")
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        job.finish()
        _report_frame_warnings(self, job.warnings)
        self.report({"INFO"}, f"Baked {len(job.baked)} frames to {job.folder}")
        return {"FINISHED"}

    # -- one frame per timer tick (interactive) ------------------------------------------

    def invoke(self, context, event):
        if context.window is None:
            return self.execute(context)
        try:
            self._job = self._make_job(context)
        except Exception as error:  # noqa: BLE001
            self.report({"ERROR"}, importer.describe_error(error))
            return {"CANCELLED"}
        wm = context.window_manager
        wm.progress_begin(0, self._job.total)
        self._timer = wm.event_timer_add(0.001, window=context.window)
        wm.modal_handler_add(self)
        self._status(context)
        return {"RUNNING_MODAL"}

    def _status(self, context, text=None):
        workspace = getattr(context, "workspace", None)
        if workspace is None:
            return
        if text is None and self._job is not None and not self._job.done:
            job = self._job
            frame, count = job.current_frame, f"{job.index + 1}/{job.total}"
            text = f"isobar: baking '{job.obj_name}' frame {frame} ({count}), Esc to cancel"
        workspace.status_text_set(text)

    def _end(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        workspace = getattr(context, "workspace", None)
        if workspace is not None:
            workspace.status_text_set(None)
        if self._job is not None:
            try:
                self._job.finish()
            except Exception as error:  # noqa: BLE001
                self.report({"WARNING"}, importer.describe_error(error))
            # Before the closing report (done, cancelled, stopped), which the status bar shows.
            _report_frame_warnings(self, self._job.warnings)
        if context.area is not None:
            context.area.tag_redraw()

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            self._end(context)
            self.report({"WARNING"}, f"Bake cancelled: {len(job.baked)} of {job.total} frames baked")
            return {"CANCELLED"}
        if event.type != "TIMER" or event.timer is not self._timer:
            return {"PASS_THROUGH"}
        try:
            job.step()
        except Exception as error:  # noqa: BLE001
            frame = job.current_frame
            self._end(context)
            self.report({"ERROR"}, f"Bake stopped at frame {frame}: {importer.describe_error(error)}")
            return {"CANCELLED"}
        context.window_manager.progress_update(job.index)
        if job.done:
            self._end(context)
            self.report({"INFO"}, f"Baked {len(job.baked)} frames to {job.folder}")
            return {"FINISHED"}
        self._status(context)
        return {"RUNNING_MODAL"}


class ISOBAR_OT_free_bake(bpy.types.Operator):
    """Delete the baked frames of the fluid surface; playback extracts from the particles again"""

    bl_idname = "isobar.free_bake"
    bl_label = "Free Bake"
    bl_options = {"REGISTER", "UNDO"}

    object_name: StringProperty(
        name="Object", description="Fluid surface (default: the active object)", options={"SKIP_SAVE"}
    )

    def execute(self, context):
        obj = _fluid_object(context, self.object_name)
        if obj is None:
            self.report({"ERROR"}, "select an isobar fluid surface")
            return {"CANCELLED"}
        try:
            removed, sharers = bake.free(obj)
        except Exception as error:  # noqa: BLE001
            self.report({"ERROR"}, importer.describe_error(error))
            return {"CANCELLED"}
        if sharers:
            names = ", ".join(f"'{n}'" for n in sharers)
            self.report({"INFO"}, f"Bake off; its frames are kept: {names} bakes into the same folder")
        else:
            self.report({"INFO"}, f"Deleted {removed} baked frames")
        return {"FINISHED"}


def _export_objects(context, name: str = ""):
    """The surfaces to export: the one named, else the selected fluid surfaces, else the
    active one."""
    if name:
        obj = bpy.data.objects.get(name)
        return [obj] if importer.is_fluid(obj) else []
    selected = [o for o in (getattr(context, "selected_objects", None) or []) if importer.is_fluid(o)]
    if selected:
        return sorted(selected, key=lambda o: o.name)
    active = _fluid_object(context)
    return [active] if active is not None else []


class ISOBAR_OT_export_usd(bpy.types.Operator, ExportHelper):
    """Export fluid surfaces over a frame range to USD: time-sampled mesh, vertex normals, sph_* primvars, velocities"""

    bl_idname = "isobar.export_usd"
    bl_label = "Export Fluid to USD"
    bl_options = {"REGISTER"}

    filename_ext = ".usd"
    filter_glob: StringProperty(default="*.usd;*.usda;*.usdc", options={"HIDDEN"})

    object_name: StringProperty(
        name="Object",
        description="Fluid surface to export (default: the selected fluid surfaces, else the active one)",
        options={"SKIP_SAVE"},
    )
    use_scene_range: BoolProperty(
        name="Scene Range", default=True, description="Export the scene's frame range (else Start to End)"
    )
    frame_start: IntProperty(name="Start", default=1, description="First frame to export")
    frame_end: IntProperty(name="End", default=250, description="Last frame to export")
    layout: EnumProperty(
        name="Layout",
        items=[
            ("AUTO", "Auto", "One file for a single frame, value clips otherwise"),
            ("CLIPS", "Value Clips", "One layer per frame in <name>.clips/, joined by value clips: any length, "
             "one frame in memory at a time"),
            ("FLAT", "Single File", "Every frame's samples in the one file (all frames in memory until written)"),
        ],
        default="AUTO",
    )
    up_axis: EnumProperty(
        name="Up Axis",
        items=[
            ("AUTO", "Auto", "Y for a surface imported with Y Up (the object rotated 90 degrees about X), else Z"),
            ("Y", "Y", "Declare the stage Y up (the data is not rotated)"),
            ("Z", "Z", "Declare the stage Z up (the data is not rotated)"),
        ],
        default="AUTO",
    )
    meters_per_unit: FloatProperty(
        name="Meters per Unit", default=1.0, min=1e-9, precision=4, description="The stage's metersPerUnit"
    )
    export_attributes: BoolProperty(
        name="Attributes", default=True, description="The sph_* attributes as vertex primvars"
    )
    export_velocities: BoolProperty(
        name="Velocities", default=True, description="The velocity attribute as the mesh's velocities (motion blur)"
    )

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "use_scene_range")
        col = layout.column(align=True)
        col.active = not self.use_scene_range
        col.prop(self, "frame_start")
        col.prop(self, "frame_end")
        for name in ("layout", "up_axis", "meters_per_unit", "export_attributes", "export_velocities"):
            layout.prop(self, name)

    def check(self, _context):
        """Keeps .usd, .usda and .usdc (the file format follows the extension); adds .usd
        to anything else."""
        filepath = self.filepath
        if os.path.basename(filepath) and os.path.splitext(filepath)[1].lower() not in (".usd", ".usda", ".usdc"):
            self.filepath = bpy.path.ensure_ext(filepath, self.filename_ext)
            return True
        return False

    def invoke(self, context, event):
        objects = _export_objects(context, self.object_name)
        if not self.filepath and objects:
            folder = os.path.dirname(bpy.data.filepath) if bpy.data.filepath else ""
            self.filepath = os.path.join(folder, usd_export.prim_name(objects[0].name) + self.filename_ext)
        scene = context.scene
        if not self.properties.is_property_set("frame_start"):
            self.frame_start = scene.frame_start
        if not self.properties.is_property_set("frame_end"):
            self.frame_end = scene.frame_end
        return ExportHelper.invoke(self, context, event)

    def execute(self, context):
        scene = context.scene
        frames = (
            bake.scene_frames(scene)
            if self.use_scene_range
            else bake.scene_frames(scene, self.frame_start, self.frame_end)
        )
        options = usd_export.Options(
            layout=self.layout,
            up_axis=self.up_axis,
            meters_per_unit=self.meters_per_unit,
            primvars=self.export_attributes,
            velocities=self.export_velocities,
        )
        try:
            job = usd_export.ExportJob(
                _export_objects(context, self.object_name), scene, frames, self.filepath, options
            )
        except ImportError as error:  # no pxr in this Blender, or the writer's wheel is missing
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        except Exception as error:  # noqa: BLE001 - reported, not raised
            self.report({"ERROR"}, importer.describe_error(error))
            return {"CANCELLED"}
        wm = context.window_manager
        wm.progress_begin(0, job.total)
        try:
            results = job.run(progress=wm.progress_update)
        except usd_export.ExportError as error:
            path = job.paths[job.obj_names.index(error.obj_name)]
            done = "".join(f"; {r.path} was written" for r in job.results)
            self.report({"ERROR"}, f"USD export stopped at {error} ({path} left as it was{done})")
            return {"CANCELLED"}
        except Exception as error:  # noqa: BLE001
            self.report({"ERROR"}, f"USD export failed: {importer.describe_error(error)}")
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        for warning in job.warnings:
            self.report({"WARNING"}, warning)
        for result in results:
            span = f"frame {frames[0]}" if len(frames) == 1 else f"frames {frames[0]}-{frames[-1]}"
            baked = sum(1 for s in result.sources if s == "bake")
            note = f", {baked} from the bake" if baked else ""
            count = len(result.frames)
            kind = "value clips" if result.layout == "clips" else "one file"
            self.report(
                {"INFO"},
                f"Exported '{result.name}' {span} ({count} frame{'s' if count != 1 else ''}{note}, "
                f"{result.up_axis} up, {kind}) to {result.path}",
            )
        return {"FINISHED"}


def menu_import(self, context):
    self.layout.operator(ISOBAR_OT_import_sequence.bl_idname, text="SPH Particle Sequence (isobar)")
    self.layout.operator(ISOBAR_OT_import_volume.bl_idname, text="Volume for Isovalue Sliding (isobar)")
    self.layout.operator(ISOBAR_OT_import_fe.bl_idname, text="High-Order FE Isosurface (isobar)")


def menu_export(self, context):
    self.layout.operator(ISOBAR_OT_export_usd.bl_idname, text="Fluid Surface to USD (isobar)")


classes = (
    ISOBAR_OT_import_volume,
    ISOBAR_OT_import_fe,
    ISOBAR_OT_import_sequence,
    ISOBAR_OT_surface_from_object,
    ISOBAR_OT_refresh,
    ISOBAR_OT_bake,
    ISOBAR_OT_free_bake,
    ISOBAR_OT_export_usd,
)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_import.append(menu_import)
    bpy.types.TOPBAR_MT_file_export.append(menu_export)


def unregister():
    bpy.types.TOPBAR_MT_file_export.remove(menu_export)
    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
