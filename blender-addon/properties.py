"""The settings of a fluid-surface object (``object.isobar``), saved in the .blend."""

from __future__ import annotations

import bpy
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)


#: Options of a path property: '//' paths are relative to the .blend file (the add-on
#: resolves them with bpy.path.abspath; without this Blender warns about the prefix).
_BLEND_RELATIVE = {"PATH_SUPPORTS_BLEND_RELATIVE"}


def _changed(self, context):
    """A parameter changed: re-extract the current frame (errors go to the status)."""
    from . import importer  # late: avoids an import cycle

    importer.on_settings_changed(self, context)


def _limit_changed(self, context):
    """Live Particle Limit changed: a frame it held back is extracted now; a frame the
    mesh shows already is not extracted again."""
    from . import importer

    importer.on_settings_changed(self, context, force=False)


def _field_search(self, context, edit_text):
    from . import importer

    return importer.field_suggestions(self, edit_text)


def _array_search(self, context, edit_text):
    from . import importer

    return importer.array_suggestions(self, edit_text)


def _particle_system_search(self, context, edit_text):
    source = self.source_object
    if source is None:
        return []
    return [ps.name for ps in source.particle_systems if edit_text.lower() in ps.name.lower()]


def _source_poll(self, obj):
    return obj.type in {"MESH", "POINTCLOUD"} and obj is not self.id_data and not obj.isobar.enabled


KERNELS = [
    ("cubic", "Cubic Spline", "Monaghan's cubic spline, support 2h"),
    ("wendland", "Wendland C2", "Wendland C2, support 2h"),
    ("quintic", "Quintic Spline", "Quintic spline, support 3h"),
    ("quadratic", "Quadratic", "Quadratic kernel, support 2h"),
]

METHODS = [
    ("CORRECTORS", "Marching Correctors", "Every vertex on the SPH level set; trimming, sph_SumOfWeights"),
    ("ADAPTIVE", "Adaptive", "Crack-free 3-level grid: far fewer triangles, splashes kept fine; no sph_SumOfWeights"),
]

BACKENDS = [
    ("CPU", "CPU", "All cores of this machine, double precision"),
    ("GPU", "GPU", "wgpu compute shaders (single precision); an error when there is no GPU adapter"),
    ("AUTO", "Auto", "A hardware GPU when there is one, else the CPU"),
]

TRIM_MODES = [
    ("AUTO", "Auto", "Trim at the free surface except when extracting the free surface itself"),
    ("OFF", "Off", "No free-surface trimming"),
    ("ON", "On", "Trim at the free surface with the core's thresholds"),
    ("CUSTOM", "Custom", "Trim with the thresholds below"),
]


class IsobarSettings(bpy.types.PropertyGroup):
    """isobar fluid-surface settings of an object."""

    enabled: BoolProperty(
        name="Fluid Surface", description="This object's mesh is an isobar fluid surface", default=False
    )

    # -- source ---------------------------------------------------------------------
    source_type: EnumProperty(
        name="Source",
        items=[
            ("SEQUENCE", "File Sequence", "Numbered particle files on disk"),
            ("OBJECT", "Scene Object", "Points of a mesh or point cloud, or a particle system, in this scene"),
        ],
        default="SEQUENCE",
        update=_changed,
    )
    directory: StringProperty(
        name="Folder",
        subtype="DIR_PATH",
        options=_BLEND_RELATIVE,
        description="Folder of the particle files ('//' is the folder of the .blend file)",
        update=_changed,
    )
    pattern: StringProperty(
        name="Files",
        description="File name pattern; a run of # is the frame number, zero padded (frame_####.vtk; "
        "frame_#.vtk: unpadded); without #, one file for every frame",
        default="frame_####.vtk",
        update=_changed,
    )
    file_first: IntProperty(
        name="First File", description="Number of the first file of the sequence", default=1, update=_changed
    )
    file_last: IntProperty(
        name="Last File", description="Number of the last file of the sequence", default=1, update=_changed
    )
    frame_offset: IntProperty(
        name="Frame Offset",
        description="Scene frame = file number + offset",
        default=0,
        update=_changed,
    )
    hold: BoolProperty(
        name="Hold Ends",
        description="Before the first and after the last file show those files (else an empty mesh)",
        default=True,
        update=_changed,
    )
    source_object: PointerProperty(
        name="Object",
        type=bpy.types.Object,
        poll=_source_poll,
        description="Mesh or point cloud whose points (and attributes) are the particles, or a particle emitter",
        update=_changed,
    )
    particle_system: StringProperty(
        name="Particle System",
        description="Particle system of the object to use (empty: the mesh or point cloud points themselves)",
        search=_particle_system_search,
        update=_changed,
    )

    # -- extraction -----------------------------------------------------------------
    field: StringProperty(
        name="Field",
        description="Particle array to contour ('NAME', 'NAME:mag', 'NAME:K'), or SumOfWeights for the free surface",
        default="SumOfWeights",
        search=_field_search,
        search_options={"SUGGESTION"},
        update=_changed,
    )
    iso: FloatProperty(
        name="Isovalue",
        description="Level of the field the surface is drawn at",
        default=0.6,
        precision=4,
        update=_changed,
    )
    kernel: EnumProperty(name="Kernel", items=KERNELS, default="cubic", update=_changed)
    h_mode: EnumProperty(
        name="Smoothing Length",
        items=[
            ("CONSTANT", "Constant", "One smoothing length for every particle"),
            ("ARRAY", "Per Particle", "A per-particle array holds the smoothing lengths"),
        ],
        default="CONSTANT",
        update=_changed,
    )
    h: FloatProperty(
        name="h",
        description="Smoothing length (about twice the particle radius)",
        default=0.05,
        min=1e-9,
        soft_min=1e-4,
        precision=5,
        subtype="DISTANCE",
        update=_changed,
    )
    h_array: StringProperty(
        name="h Array",
        description="Per-particle smoothing length array",
        default="h",
        search=_array_search,
        update=_changed,
    )
    h_scale: FloatProperty(
        name="h Scale",
        description="Multiplies every smoothing length (0.75 or 0.5 for quick previews)",
        default=1.0,
        min=1e-3,
        soft_max=4.0,
        update=_changed,
    )
    grid_factor: FloatProperty(
        name="Grid Factor",
        description="Cell size of the virtual grid in units of the smallest h (smaller: finer mesh)",
        default=0.5,
        min=0.01,
        soft_min=0.1,
        soft_max=2.0,
        update=_changed,
    )
    method: EnumProperty(name="Method", items=METHODS, default="CORRECTORS", update=_changed)
    splash_threshold: IntProperty(
        name="Splash Threshold",
        description="Adaptive: coarse cells holding 1 to this many particles are refined to the finest level "
        "(the paper's splash rule is 1; 0: none, the error criterion alone, far fewer triangles)",
        default=0,
        min=0,
        soft_max=8,
        update=_changed,
    )
    max_error: FloatProperty(
        name="Max Error",
        description="Adaptive: each cell at the surface takes the lowest level whose surface lies within this many "
        "finest cells of the finest level's there (0: off, splash criterion alone)",
        default=0.4,
        min=0.0,
        soft_max=2.0,
        update=_changed,
    )
    bisection_iterations: IntProperty(
        name="Bisection Iterations",
        description="Adaptive: halvings of a finest-level edge when placing its surface point (one more per coarser "
        "level, so shared points coincide); 0 places them linearly between the finest nodes, as marching cubes does",
        default=5,
        min=0,
        max=16,
        update=_changed,
    )
    backend: EnumProperty(
        name="Backend",
        description="Where the work runs: Marching Correctors' seed search (same surface on every back end) or the adaptive grids",
        items=BACKENDS,
        default="CPU",
        update=_changed,
    )
    correct: BoolProperty(
        name="Correction",
        description="Move every vertex onto the level set (off: a faster linear preview)",
        default=True,
        update=_changed,
    )
    trim: EnumProperty(name="Trimming", items=TRIM_MODES, default="AUTO", update=_changed)
    trim_node: FloatProperty(
        name="Node Threshold",
        description="Sum-of-weights threshold at the grid nodes",
        default=0.1,
        min=0.0,
        update=_changed,
    )
    trim_vertex: FloatProperty(
        name="Vertex Threshold",
        description="Sum-of-weights level of the trimming surface",
        default=0.5,
        min=0.0,
        update=_changed,
    )

    # -- attributes -----------------------------------------------------------------
    attributes: StringProperty(
        name="Attributes",
        description="Particle arrays to interpolate onto the vertices, separated by commas ('*': all, 'none': none); "
        "stored as sph_<name> point attributes",
        default="*",
        update=_changed,
    )
    speed: BoolProperty(
        name="Speed",
        description="Add sph_speed, the SPH-interpolated particle speed |velocity|",
        default=True,
        update=_changed,
    )
    velocity_array: StringProperty(
        name="Velocity",
        description="Particle velocity array",
        default="velocity",
        search=_array_search,
        update=_changed,
    )
    motion_blur: BoolProperty(
        name="Motion Blur Velocities",
        description="Write the interpolated velocity as the 'velocity' vertex attribute Cycles uses for motion blur",
        default=True,
        update=_changed,
    )
    velocity_scale: FloatProperty(
        name="Velocity Scale",
        description="Multiplies the velocities (units per second of scene time)",
        default=1.0,
        update=_changed,
    )

    # -- cache ----------------------------------------------------------------------
    cache_directory: StringProperty(
        name="Cache Folder",
        subtype="DIR_PATH",
        options=_BLEND_RELATIVE,
        description="Folder of baked frames ('//' is the folder of the .blend file)",
        default="//isobar_cache/",
    )
    cache_name: StringProperty(
        name="Cache Name", description="Subfolder of this object's baked frames (set on the first bake)"
    )
    use_cache: BoolProperty(
        name="Use Bake",
        description="Play baked frames back (a frame baked with other parameters is extracted again)",
        default=False,
        update=_changed,
    )
    live_particle_limit: IntProperty(
        name="Live Particle Limit",
        description="A setting change, or a frame change while the timeline plays or is scrubbed, that "
        "would extract more particles than this keeps the mesh shown and says so, as it cannot be "
        "cancelled (a frame held back is extracted when the timeline stops). Frame steps, exporters, "
        "Refresh, baking and rendering are never limited (0: no limit)",
        default=500_000,
        min=0,
        soft_max=10_000_000,
        update=_limit_changed,
    )
    baked_start: IntProperty(name="Baked From", default=0)
    baked_end: IntProperty(name="Baked To", default=-1)
    baked_step: IntProperty(name="Baked Every", default=1, min=1)

    # -- runtime feedback (saved, harmless) -----------------------------------------
    live_update: BoolProperty(
        name="Live Update", description="Re-extract the current frame when a parameter changes", default=True
    )
    status: StringProperty(name="Status", description="Result of the last update of this surface")
    status_error: BoolProperty(name="Status Is Error", default=False)
    status_warnings: StringProperty(
        name="Warnings",
        description="What the extraction of the surface shown warned about, one a line "
        "(an isovalue the field never crosses, a kernel wider than the particles)",
    )
    backend_note: StringProperty(
        name="Backend Note",
        description="Why Backend Auto runs on the CPU on this machine (empty: Backend is not Auto, or it runs on a GPU)",
    )


def _slide(self, context):
    from . import paths, volume_slider  # late: keeps this module free of the core

    obj = self.id_data
    if not self.enabled or not self.store:
        return
    store = paths.resolve(self.store)
    note = ""
    try:
        # The import checked the store against the volume; the volume may have been
        # written since (a new simulation step): slide on its surface, not the old one.
        if volume_slider.rebuild_if_stale(obj, paths.resolve(self.volume), store):
            self.value_min, self.value_max = volume_slider.slider_for(obj, store).value_range
            note = "; store rebuilt, the volume changed"
        shown = volume_slider.show(obj, store, self.isovalue, self.lod_error_bound)
    except Exception as error:  # noqa: BLE001 - shown in the panel, never raised into Blender
        self.status, self.status_error = str(error), True
        return
    self.triangles = shown.triangles
    if shown.slid:
        self.update_ms = 1e3 * shown.seconds
    detail = f" (level of detail {self.lod_error_bound:g})" if self.lod_error_bound > 0 else ""
    self.status = f"{self.triangles:,} triangles{detail}, update {self.update_ms:.2f} ms{note}"
    self.status_error = False


class IsobarSliderSettings(bpy.types.PropertyGroup):
    """Isovalue sliding on a volume (an object whose mesh follows its isovalue)."""

    enabled: BoolProperty(name="Volume Slider", description="This object's mesh is an isobar volume isosurface", default=False)
    volume: StringProperty(
        name="Volume",
        description="The volume file the store was built from",
        subtype="FILE_PATH",
        options=_BLEND_RELATIVE,
    )
    store: StringProperty(
        name="Store",
        description="The pre-encoded isovalue store (.isoslider)",
        subtype="FILE_PATH",
        options=_BLEND_RELATIVE,
    )
    isovalue: FloatProperty(
        name="Isovalue",
        description="Drag to slide the isosurface: each change updates the mesh from the store",
        default=0.0,
        precision=4,
        update=_slide,
    )
    lod_error_bound: FloatProperty(
        name="LOD Error Bound",
        description=(
            "Level of detail, as a fraction of the volume's value range (0: off, the exact surface). "
            "Blocks of cells merge where the coarser cell's trilinear interpolant stays within this "
            "fraction of every sample it drops and the topology is kept; the mesh stays closed and every "
            "vertex lies on the exact surface. 0.001 is the paper's setting; larger gives fewer triangles. "
            "Changing it does not slide the isovalue"
        ),
        default=0.0,
        min=0.0,
        max=0.99,
        soft_max=0.1,
        step=0.1,
        precision=4,
        update=_slide,
    )
    value_min: FloatProperty(name="Minimum", description="Smallest value in the volume")
    value_max: FloatProperty(name="Maximum", description="Largest value in the volume")
    triangles: IntProperty(name="Triangles", description="Triangles of the mesh shown (of the level of detail when on)")
    update_ms: FloatProperty(name="Update (ms)", description="Core time of the last isovalue change")
    status: StringProperty(name="Status", description="Result of the last isovalue change")
    status_error: BoolProperty(name="Status Is Error", default=False)


def _resample(self, context):
    from . import fe_samples, paths  # late: keeps this module free of the core

    if not self.enabled or not self.filepath or not self.field:
        return
    import time

    obj = self.id_data
    start = time.perf_counter()
    try:
        samples = fe_samples.resample(
            obj, paths.resolve(self.filepath), self.field, self.isovalue, self.spacing, self.curvature_adaptivity
        )
    except Exception as error:  # noqa: BLE001 - shown in the panel, never raised into Blender
        self.status, self.status_error, self.status_warnings = str(error), True, ""
        return
    self.status_warnings = "\n".join(samples.warnings)
    self.samples = len(samples)
    seconds = time.perf_counter() - start
    self.status = f"{self.samples:,} samples, max |F - C| {samples.stats['max_residual']:.1e}, {seconds:.2f} s"
    self.status_error = False


class IsobarFESettings(bpy.types.PropertyGroup):
    """Isosurface samples of a high-order FE field (a point-cloud object that follows its
    isovalue)."""

    enabled: BoolProperty(name="FE Samples", description="This object is an isobar high-order FE isosurface", default=False)
    filepath: StringProperty(
        name="File",
        description="The .vtu of Lagrange cells or Gmsh .msh v4 file",
        subtype="FILE_PATH",
        options=_BLEND_RELATIVE,
    )
    field: StringProperty(name="Field", description="The scalar point array to contour", update=_resample)
    isovalue: FloatProperty(name="Isovalue", description="The isovalue C", default=0.0, precision=4, update=_resample)
    spacing: FloatProperty(
        name="Spacing",
        description="Distance between samples on flat parts (0: 1/40 of the mesh's diagonal)",
        default=0.0,
        min=0.0,
        precision=4,
        update=_resample,
    )
    curvature_adaptivity: FloatProperty(
        name="Curvature Adaptivity",
        description="Extra sample density on curved parts (0: uniform)",
        default=0.0,
        min=0.0,
        update=_resample,
    )
    value_min: FloatProperty(name="Minimum", description="Smallest value of the field")
    value_max: FloatProperty(name="Maximum", description="Largest value of the field")
    samples: IntProperty(name="Samples", description="Points of the current isosurface")
    status: StringProperty(name="Status", description="Result of the last sampling")
    status_error: BoolProperty(name="Status Is Error", default=False)
    status_warnings: StringProperty(
        name="Warnings",
        description="What the last sampling warned about, one a line (an isovalue the field never crosses)",
    )


def register():
    bpy.utils.register_class(IsobarSettings)
    bpy.utils.register_class(IsobarSliderSettings)
    bpy.utils.register_class(IsobarFESettings)
    bpy.types.Object.isobar = PointerProperty(type=IsobarSettings)
    bpy.types.Object.isobar_slider = PointerProperty(type=IsobarSliderSettings)
    bpy.types.Object.isobar_fe = PointerProperty(type=IsobarFESettings)


def unregister():
    from . import fe_samples, volume_slider

    volume_slider.close_all()
    fe_samples.close_all()
    del bpy.types.Object.isobar_fe
    del bpy.types.Object.isobar_slider
    del bpy.types.Object.isobar
    bpy.utils.unregister_class(IsobarFESettings)
    bpy.utils.unregister_class(IsobarSliderSettings)
    bpy.utils.unregister_class(IsobarSettings)
