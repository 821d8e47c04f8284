"""Rendering with Cycles (CPU) and saving/reopening the .blend."""

import os

import bpy
import numpy as np
from conftest import assert_mesh_equals, GRID_FACTOR, H, import_sequence, mesh_arrays, reference
from mathutils import Vector


def _attribute_emission_material():
    """Emission colour = the 'sph_SumOfWeights' attribute (0.6 everywhere on the free
    surface): a render shows the attribute reached Cycles."""
    material = bpy.data.materials.new("sow")
    if bpy.app.version < (5, 0, 0):
        material.use_nodes = True
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "sph_SumOfWeights"
    emission = nodes.new("ShaderNodeEmission")
    output = nodes.new("ShaderNodeOutputMaterial")
    links.new(attr.outputs["Fac"], emission.inputs["Color"])
    links.new(emission.outputs["Emission"], output.inputs["Surface"])
    return material


def _camera_on(scene, obj):
    """A camera that sees the whole of `obj`'s mesh as it is now."""
    points, _ = mesh_arrays(obj)
    lo, hi = points.min(axis=0), points.max(axis=0)
    center, size = Vector((lo + hi) / 2), float((hi - lo).max())
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    camera.location = center + Vector((0.9, -1.6, 1.0)) * size
    camera.rotation_euler = (center - camera.location).to_track_quat("-Z", "Y").to_euler()
    scene.camera = camera


def _cycles_cpu(scene, samples=8):
    """Cycles on the CPU, 160x120, transparent film (alpha: where the fluid is)."""
    render = scene.render
    render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    render.resolution_x, render.resolution_y, render.resolution_percentage = 160, 120, 100
    render.film_transparent = True
    return render


def test_render_cycles_cpu(scene, demo_sequence, tmp_path):
    obj = import_sequence(demo_sequence[1])
    scene.frame_set(2)
    obj.data.materials.clear()
    obj.data.materials.append(_attribute_emission_material())
    _camera_on(scene, obj)
    render = _cycles_cpu(scene)
    render.use_motion_blur = True  # uses the 'velocity' attribute of the mesh
    scene.view_settings.view_transform = "Standard"
    render.image_settings.file_format = "PNG"
    render.image_settings.color_mode = "RGBA"
    render.filepath = str(tmp_path / "render.png")
    bpy.ops.render.render(write_still=True)

    assert os.path.getsize(tmp_path / "render.png") > 0
    pixels = _load_png(tmp_path / "render.png")
    covered = pixels[:, 3] > 0.99
    assert 0.05 < covered.mean() < 0.95, covered.mean()  # the fluid, and background around it
    value = np.median(pixels[covered, :3])
    # 0.6 linear is 0.797 in sRGB: the attribute reached the shader.
    assert 0.75 < value < 0.85, value

    # Without the 'velocity' attribute the same render has no motion blur: the edges
    # differ, so Cycles did blur with the vertex velocities.
    obj.isobar.motion_blur = False
    assert "velocity" not in obj.data.attributes
    render.filepath = str(tmp_path / "sharp.png")
    bpy.ops.render.render(write_still=True)
    sharp = _load_png(tmp_path / "sharp.png")
    difference = np.abs(sharp[:, 3] - pixels[:, 3])
    print("motion blur alpha difference: max", difference.max(), "pixels > 0.05:", int((difference > 0.05).sum()))
    assert difference.max() > 0.2


def test_a_frame_that_fails_during_a_render_renders_empty_not_the_last_frame(scene, demo_sequence, tmp_path):
    obj = import_sequence(demo_sequence[0])
    _camera_on(scene, obj)
    render = _cycles_cpu(scene, samples=1)
    render.image_settings.file_format = "PNG"
    render.image_settings.color_mode = "RGBA"
    render.filepath = str(tmp_path / "frame_")
    demo_sequence[1].unlink()  # frame 2 is missing
    scene.frame_start, scene.frame_end = 1, 2
    bpy.ops.render.render(animation=True)
    covered = [(_load_png(tmp_path / f"frame_000{f}.png")[:, 3] > 0.5).mean() for f in (1, 2)]
    assert covered[0] > 0.05  # frame 1: the fluid
    assert covered[1] == 0.0, covered  # frame 2: nothing, not frame 1's surface again
    # Interactive again: a failing frame keeps the last good mesh.
    scene.frame_set(1)
    scene.frame_set(2)
    assert obj.isobar.status_error and "frame_0002.vtk" in obj.isobar.status
    assert len(obj.data.polygons) > 0


def _load_png(path):
    image = bpy.data.images.load(str(path))
    assert tuple(image.size) == (160, 120)
    pixels = np.empty(160 * 120 * 4, np.float32)
    image.pixels.foreach_get(pixels)
    bpy.data.images.remove(image)
    return pixels.reshape(-1, 4)


def test_save_reopen_keeps_object_settings_and_handler(scene, isobar, demo_sequence, tmp_path):
    obj = import_sequence(demo_sequence[0])
    name = obj.name
    settings = obj.isobar
    settings.kernel = "wendland"
    settings.iso = 0.55
    settings.attributes = "velocity"
    blend = tmp_path / "fluid.blend"
    assert bpy.ops.wm.save_as_mainfile(filepath=str(blend)) == {"FINISHED"}
    saved = mesh_arrays(obj)[0]
    # A relative cache folder works once the file is saved.
    assert bpy.ops.isobar.bake() == {"FINISHED"}
    assert (tmp_path / "isobar_cache" / settings.cache_name / "frame_000003.npz").is_file()
    assert bpy.ops.wm.save_mainfile() == {"FINISHED"}

    bpy.ops.wm.read_homefile(use_empty=True)
    assert name not in bpy.data.objects
    assert bpy.ops.wm.open_mainfile(filepath=str(blend)) == {"FINISHED"}
    obj = bpy.data.objects[name]
    settings = obj.isobar
    assert settings.enabled and settings.source_type == "SEQUENCE"
    assert settings.pattern == "frame_####.vtk" and (settings.file_first, settings.file_last) == (1, 3)
    assert settings.kernel == "wendland" and abs(settings.iso - 0.55) < 1e-6
    assert abs(settings.h - H) < 1e-9 and abs(settings.grid_factor - GRID_FACTOR) < 1e-9
    assert settings.attributes == "velocity" and settings.use_cache
    np.testing.assert_array_equal(mesh_arrays(obj)[0], saved)  # the mesh was saved too
    assert "isobar_frame_change_post" in [h.__name__ for h in bpy.app.handlers.frame_change_post]

    expected = [reference(isobar, p, iso=0.55, kernel="wendland") for p in demo_sequence]
    for path in demo_sequence:
        path.unlink()  # from now on only the cache (relative to the reopened file) can serve
    bpy.context.scene.frame_set(2)
    assert not settings.status_error, settings.status
    assert_mesh_equals(obj, expected[1])
    assert set(k for k in obj.data.attributes.keys() if k.startswith("sph_")) == {"sph_SumOfWeights", "sph_speed"}
    bpy.context.scene.frame_set(3)
    assert_mesh_equals(obj, expected[2])
