"""Export Fluid to USD: the fluid surface over a frame range through isobar's USD writer
(isobar_usd, bundled as a wheel, on the pxr Blender ships), read back with pxr and
compared with the core's own surfaces frame by frame."""

import os

import bpy
import numpy as np
import pytest
from conftest import FRAME_01, FRAME_26, GRID_FACTOR, H, import_sequence, ISO, MODULE, reference


def open_stage(pxr, path):
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    assert stage is not None, path
    return stage


def listing(folder):
    """Every file under `folder` (hidden staging files included), relative."""
    out = []
    for base, _dirs, files in os.walk(folder):
        out += [os.path.relpath(os.path.join(base, f), folder) for f in files]
    return sorted(out)


def assert_frame_is_core_surface(mesh, frame, surface, velocities=True):
    """The time samples of `frame` are the core's surface: float32 of its points (the
    writer applies no axis conversion: the data is the simulation's, the stage's upAxis
    says which way is up), its triangles, vertex normals, extent, sph_* primvars and
    velocities."""
    from pxr import UsdGeom

    points = np.asarray(mesh.GetPointsAttr().Get(frame), dtype=np.float32)
    np.testing.assert_array_equal(points, surface.points.astype(np.float32))
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(frame))
    assert counts.shape == (surface.n_triangles,) and (counts == 3).all()
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(frame))
    np.testing.assert_array_equal(indices, surface.triangles.astype(np.int32).ravel())
    normals = np.asarray(mesh.GetNormalsAttr().Get(frame), dtype=np.float32)
    assert normals.shape == points.shape  # one normal per point
    assert mesh.GetNormalsInterpolation() == UsdGeom.Tokens.vertex
    np.testing.assert_array_equal(normals, surface.normals.astype(np.float32))
    extent = np.asarray(mesh.GetExtentAttr().Get(frame), dtype=np.float32)
    np.testing.assert_array_equal(extent, np.stack([points.min(axis=0), points.max(axis=0)]))
    primvars = UsdGeom.PrimvarsAPI(mesh.GetPrim())
    sow = primvars.GetPrimvar("sph_SumOfWeights")
    assert sow and sow.GetInterpolation() == UsdGeom.Tokens.vertex
    np.testing.assert_array_equal(np.asarray(sow.Get(frame)), surface.attributes["SumOfWeights"].astype(np.float32))
    speed = primvars.GetPrimvar("sph_speed")
    assert speed and len(speed.Get(frame)) == len(points)
    if velocities:
        v = np.asarray(mesh.GetVelocitiesAttr().Get(frame), dtype=np.float32)
        np.testing.assert_array_equal(v, surface.attributes["velocity"].astype(np.float32))
    assert mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.rightHanded
    assert mesh.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none


def test_export_frames_1_to_3_match_the_core(scene, isobar, pxr, demo_sequence, tmp_path):
    from pxr import UsdGeom

    obj = import_sequence(demo_sequence[0])
    scene.frame_set(2)
    out = tmp_path / "export" / "fluid.usd"
    out.parent.mkdir()
    assert bpy.ops.isobar.export_usd(filepath=str(out)) == {"FINISHED"}
    assert scene.frame_current == 2  # the scene's frame is left as it was
    assert not obj.isobar.status_error and obj.isobar.status.startswith("Frame 2:")
    # Value clips: a root, one layer per frame, a manifest; no staging files left.
    assert listing(out.parent) == [
        "fluid.clips/.lock",
        "fluid.clips/fluid.0001.usdc",
        "fluid.clips/fluid.0002.usdc",
        "fluid.clips/fluid.0003.usdc",
        "fluid.clips/manifest.usda",
        "fluid.usd",
    ]

    stage = open_stage(pxr, out)
    assert stage.GetDefaultPrim().GetPath() == "/frame_surface"
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z  # Blender's Z up, data unrotated
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (1.0, 3.0)
    assert stage.GetTimeCodesPerSecond() == scene.render.fps / scene.render.fps_base
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/frame_surface/Surface"))
    assert mesh
    # Topology changes every frame: counts and indices are time-sampled like the points,
    # and each frame's values hold until just before the next (its point count differs).
    from isobar_usd.layers import HOLD_BEFORE

    samples = [1.0, 2.0 - HOLD_BEFORE, 2.0, 3.0 - HOLD_BEFORE, 3.0]
    for attr in (mesh.GetPointsAttr(), mesh.GetFaceVertexCountsAttr(), mesh.GetFaceVertexIndicesAttr()):
        assert list(attr.GetTimeSamples()) == samples, attr.GetName()
    assert list(mesh.GetNormalsAttr().GetTimeSamples()) == samples
    references = [reference(isobar, p, attributes=["velocity"]) for p in demo_sequence]
    assert references[0].n_points != references[1].n_points  # the topology does change
    for frame, surface in zip((1, 2, 3), references):
        assert_frame_is_core_surface(mesh, frame, surface)

    import isobar_usd  # the bundled writer's own checker: validators + per-frame mesh checks

    assert isobar_usd.check(str(out)) == []


def test_y_up_chosen_range_flat_usda(scene, isobar, pxr, demo_sequence, tmp_path):
    from pxr import UsdGeom

    obj = import_sequence(demo_sequence[0], y_up=True)
    result = bpy.ops.isobar.export_usd(
        filepath=str(tmp_path / "fluid.usda"), use_scene_range=False, frame_start=2, frame_end=3, layout="FLAT"
    )
    assert result == {"FINISHED"}
    assert listing(tmp_path) == ["fluid.usda"] + [f"sim/frame_000{i}.vtk" for i in (1, 2, 3)]
    assert (tmp_path / "fluid.usda").read_text().startswith("#usda 1.0")
    stage = open_stage(pxr, tmp_path / "fluid.usda")
    # The Y-up import rotates the object by +90 degrees about X; the stage says Y up
    # instead and keeps the simulation's coordinates (nothing to undo).
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert tuple(obj.rotation_euler) == pytest.approx((np.pi / 2, 0.0, 0.0))
    mesh = UsdGeom.Mesh(stage.GetDefaultPrim().GetChild("Surface"))
    assert list(mesh.GetPointsAttr().GetTimeSamples()) == [2.0, 3.0]
    for frame in (2, 3):
        assert_frame_is_core_surface(mesh, frame, reference(isobar, demo_sequence[frame - 1], attributes=["velocity"]))


def test_export_plays_the_bake_without_particle_files(scene, isobar, pxr, demo_sequence, tmp_path):
    from pxr import UsdGeom

    obj = import_sequence(demo_sequence[0])
    obj.isobar.cache_directory = str(tmp_path / "cache")
    references = [reference(isobar, p, attributes=["velocity"]) for p in demo_sequence]
    assert bpy.ops.isobar.bake() == {"FINISHED"}
    for path in demo_sequence:
        path.unlink()  # only the bake can make the frames now
    out = tmp_path / "baked.usd"
    assert bpy.ops.isobar.export_usd(filepath=str(out)) == {"FINISHED"}
    stage = open_stage(pxr, out)  # held: its prims expire with it
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/frame_surface/Surface"))
    for frame, surface in zip((1, 2, 3), references):
        assert_frame_is_core_surface(mesh, frame, surface)
    # Changed parameters no longer match the bake, and the particles are gone: an error.
    obj.isobar.iso = 0.55
    with pytest.raises(RuntimeError, match="frame 1.*frame_0001.vtk"):
        bpy.ops.isobar.export_usd(filepath=str(tmp_path / "other.usd"))


def test_a_failing_frame_is_reported_and_writes_nothing(scene, isobar, pxr, demo_sequence, tmp_path):
    import_sequence(demo_sequence[0])
    out = tmp_path / "export" / "fluid.usd"
    out.parent.mkdir()
    demo_sequence[1].unlink()
    scene.frame_set(3)
    with pytest.raises(RuntimeError, match="frame 2.*particle file not found.*frame_0002.vtk"):
        bpy.ops.isobar.export_usd(filepath=str(out))
    assert listing(out.parent) == []  # no root, no clips, no staging file
    assert scene.frame_current == 3

    # Over an earlier export: a failure leaves it exactly as it was.
    demo_sequence[1].write_bytes(FRAME_26.read_bytes())  # the file is back
    assert bpy.ops.isobar.export_usd(filepath=str(out)) == {"FINISHED"}
    before = {name: (out.parent / name).read_bytes() for name in listing(out.parent)}
    demo_sequence[2].unlink()
    with pytest.raises(RuntimeError, match="frame 3.*frame_0003.vtk"):
        bpy.ops.isobar.export_usd(filepath=str(out))
    after = {name: (out.parent / name).read_bytes() for name in listing(out.parent)}
    assert after == before
    with pytest.raises(RuntimeError, match="frame 3.*frame_0003.vtk"):
        bpy.ops.isobar.export_usd(filepath=str(tmp_path / "flat.usd"), layout="FLAT")
    assert not (tmp_path / "flat.usd").exists()
    assert not [n for n in os.listdir(tmp_path) if n.startswith(".")]


def test_export_of_scene_particles_steps_frames_and_restores_the_frame(scene, isobar, pxr, tmp_path):
    from pxr import UsdGeom

    particles = isobar.Particles.read(str(FRAME_01))
    pos = particles.positions.astype(np.float32)
    mesh = bpy.data.meshes.new("particles")
    mesh.vertices.add(len(pos))
    mesh.vertices.foreach_set("co", pos.ravel())
    mesh.update()
    source = bpy.data.objects.new("particles", mesh)
    scene.collection.objects.link(source)
    source.location = (0.0, 0.0, 0.0)
    source.keyframe_insert("location", frame=1)
    source.location = (0.5, 0.0, 0.25)
    source.keyframe_insert("location", frame=2)
    scene.frame_set(5)
    result = bpy.ops.isobar.surface_from_object(source=source.name, h=H, iso=ISO, grid_factor=GRID_FACTOR)
    assert result == {"FINISHED"}
    obj = bpy.context.active_object
    shown = len(obj.data.vertices)
    out = tmp_path / "scene.usd"
    result = bpy.ops.isobar.export_usd(filepath=str(out), use_scene_range=False, frame_start=1, frame_end=2)
    assert result == {"FINISHED"}
    assert scene.frame_current == 5 and len(obj.data.vertices) == shown
    stage = open_stage(pxr, out)
    usd_mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/{obj.name}/Surface"))
    for frame, offset in ((1, (0.0, 0.0, 0.0)), (2, (0.5, 0.0, 0.25))):
        moved = pos.astype(np.float64) + np.asarray(offset, np.float32)
        surface = isobar.extract(isobar.Particles.from_arrays(moved), ISO, h=H, grid_factor=GRID_FACTOR)
        points = np.asarray(usd_mesh.GetPointsAttr().Get(frame), dtype=np.float32)
        np.testing.assert_allclose(points, surface.points.astype(np.float32), atol=2e-6)
        indices = np.asarray(usd_mesh.GetFaceVertexIndicesAttr().Get(frame))
        np.testing.assert_array_equal(indices, surface.triangles.ravel())


def test_several_surfaces_one_stage_each(scene, isobar, pxr, demo_sequence, tmp_path):
    from pxr import UsdGeom

    first = import_sequence(demo_sequence[0])
    second = import_sequence(demo_sequence[0], iso=0.5)
    first.select_set(True)
    second.select_set(True)
    result = bpy.ops.isobar.export_usd(
        filepath=str(tmp_path / "fluids.usd"), use_scene_range=False, frame_start=1, frame_end=1
    )
    assert result == {"FINISHED"}
    for obj, iso in ((first, ISO), (second, 0.5)):
        name = obj.name.replace(".", "_")
        stage = open_stage(pxr, tmp_path / f"fluids_{name}.usd")
        assert stage.GetDefaultPrim().GetName() == name
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/{name}/Surface"))
        surface = reference(isobar, demo_sequence[0], iso=iso, attributes=["velocity"])
        assert_frame_is_core_surface(mesh, 1, surface)


def test_options_attributes_velocities_units(scene, isobar, pxr, demo_sequence, tmp_path):
    from pxr import UsdGeom

    import_sequence(demo_sequence[0])
    out = tmp_path / "bare.usd"
    assert bpy.ops.isobar.export_usd(
        filepath=str(out),
        use_scene_range=False,
        frame_start=1,
        frame_end=1,
        export_attributes=False,
        export_velocities=False,
        meters_per_unit=0.01,
        up_axis="Y",
    ) == {"FINISHED"}
    assert not (tmp_path / "bare.clips").exists()  # one frame: one file
    stage = open_stage(pxr, out)
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/frame_surface/Surface"))
    assert not UsdGeom.PrimvarsAPI(mesh.GetPrim()).GetAuthoredPrimvars()
    assert not mesh.GetVelocitiesAttr().HasValue()
    assert len(mesh.GetNormalsAttr().Get(1)) == len(mesh.GetPointsAttr().Get(1))


def test_errors_are_reported(scene, pxr, demo_sequence, tmp_path):
    with pytest.raises(RuntimeError, match="select an isobar fluid surface"):
        bpy.ops.isobar.export_usd(filepath=str(tmp_path / "none.usd"))
    import_sequence(demo_sequence[0])
    with pytest.raises(RuntimeError, match=r"\.usd, \.usda or \.usdc"):
        bpy.ops.isobar.export_usd(filepath=str(tmp_path / "fluid.abc"))
    with pytest.raises(RuntimeError, match="does not exist"):
        bpy.ops.isobar.export_usd(filepath=str(tmp_path / "missing" / "fluid.usd"))
    with pytest.raises(RuntimeError, match="empty"):
        bpy.ops.isobar.export_usd(
            filepath=str(tmp_path / "fluid.usd"), use_scene_range=False, frame_start=3, frame_end=2
        )
    assert listing(tmp_path) == [f"sim/frame_000{i}.vtk" for i in (1, 2, 3)]


def test_placement_and_pxr(scene, addon, pxr, demo_sequence):
    usd_export = addon.usd_export
    obj = import_sequence(demo_sequence[0])
    assert usd_export.placement(obj) == ("Z", True)
    obj.rotation_euler = (np.pi / 2, 0.0, 0.0)
    bpy.context.view_layer.update()
    assert usd_export.placement(obj) == ("Y", True)
    obj.location = (1.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    assert usd_export.placement(obj) == ("Y", False)  # a transform the export does not write
    assert usd_export.prim_name("Fluid.001") == "Fluid_001" and usd_export.prim_name("2nd") == "_nd"
    # The writer runs on the USD that Blender links (bpy's own pxr), not a second copy.
    module = usd_export.ensure_pxr()
    if usd_export._bundled_site_packages():
        assert module.__file__.startswith(bpy.utils.resource_path("LOCAL")), module.__file__


def test_export_job_reports_progress(scene, addon, pxr, demo_sequence, tmp_path):
    """The operator's unit of work: window_manager.progress_update gets the frames done
    (with fractions inside a frame's extraction), ending at the total."""
    usd_export = addon.usd_export
    obj = import_sequence(demo_sequence[0])
    job = usd_export.ExportJob([obj], scene, [1, 2, 3], str(tmp_path / "job.usd"))
    assert job.total == 3 and job.paths == [str(tmp_path / "job.usd")]
    seen = []
    results = job.run(seen.append)
    assert seen == sorted(seen) and seen[-1] == 3 and 0 <= seen[0] < 1
    assert any(0 < v < 1 for v in seen)  # fractions from the core's progress callback
    (result,) = results
    assert result.frames == [1, 2, 3] and result.layout == "clips" and result.up_axis == "Z"
    assert result.sources == ["frame_0001.vtk", "frame_0002.vtk", "frame_0003.vtk"]


def test_export_menu_and_panel_button(addon, scene, demo_sequence):
    draw_funcs = bpy.types.TOPBAR_MT_file_export._dyn_ui_initialize()
    assert any(getattr(f, "__module__", "").startswith(MODULE) for f in draw_funcs)
    from test_panels import draw_all

    import_sequence(demo_sequence[0])
    assert ("operator", "isobar.export_usd") in draw_all(bpy.context)


def test_why_not_blenders_own_usd_export(scene, isobar, pxr, demo_sequence, tmp_path):
    """The evidence for writing through isobar_usd rather than bpy.ops.wm.usd_export
    (bpy 5.0.1). Should this start failing, Blender's exporter changed: look again.

    1. Blender's exporter decides once whether an object is animated (animation data on
       its mesh, shape keys, or a modifier other than Subdivision Surface). A mesh that a
       frame_change_post handler rewrites is none of these: it is written once, as static
       values, and frames 2 and 3 are lost.
    2. With a modifier it samples every frame (the handler does run, the topology is
       time-sampled and exact), but the normals are faceVarying: one per triangle corner,
       not one per point.
    3. A frame whose particles are missing is not an error for it: the handler keeps the
       last good mesh and the export succeeds, with frame 1's surface at frame 2.
    """
    from pxr import UsdGeom

    obj = import_sequence(demo_sequence[0])
    obj.select_set(True)
    common = dict(selected_objects_only=True, export_animation=True, export_materials=False)

    def surface_mesh(path):
        stage = open_stage(pxr, path)
        mesh = next(UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
        return stage, mesh

    assert bpy.ops.wm.usd_export(filepath=str(tmp_path / "static.usdc"), **common) == {"FINISHED"}
    stage, mesh = surface_mesh(tmp_path / "static.usdc")
    assert mesh.GetPointsAttr().GetTimeSamples() == []  # static: one surface for all frames
    assert mesh.GetFaceVertexIndicesAttr().GetTimeSamples() == []

    obj.modifiers.new("animated", "DISPLACE").strength = 0.0
    assert bpy.ops.wm.usd_export(filepath=str(tmp_path / "modifier.usdc"), **common) == {"FINISHED"}
    stage, mesh = surface_mesh(tmp_path / "modifier.usdc")
    assert list(mesh.GetFaceVertexIndicesAttr().GetTimeSamples()) == [1.0, 2.0, 3.0]
    surface = reference(isobar, demo_sequence[1])
    np.testing.assert_array_equal(np.asarray(mesh.GetPointsAttr().Get(2)), surface.points.astype(np.float32))
    assert mesh.GetNormalsInterpolation() == UsdGeom.Tokens.faceVarying
    assert len(mesh.GetNormalsAttr().Get(2)) == 3 * surface.n_triangles != surface.n_points

    demo_sequence[1].unlink()
    assert bpy.ops.wm.usd_export(filepath=str(tmp_path / "stale.usdc"), **common) == {"FINISHED"}
    stage, mesh = surface_mesh(tmp_path / "stale.usdc")
    first = reference(isobar, demo_sequence[0])
    assert len(mesh.GetPointsAttr().Get(2)) == first.n_points  # frame 1's surface, silently
