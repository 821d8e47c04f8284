"""The add-on's file paths (particle folder, bake folder, volume, store, FE file) are kept
relative to the .blend file, as Blender keeps an image's: saving the file to another
folder and moving the project folder keep them pointing at the same files."""

import os
import shutil
from pathlib import Path

import bpy
from conftest import assert_mesh_equals, FRAME_01, FRAME_26, import_sequence, make_sequence, reference
from test_fe_samples import _cube_vtu
from test_volume_slider import _volume


def resolved(value):
    return Path(os.path.normpath(bpy.path.abspath(value)))


def save_as(path, **kwargs):
    path.parent.mkdir(parents=True, exist_ok=True)
    assert bpy.ops.wm.save_as_mainfile(filepath=str(path), **kwargs) == {"FINISHED"}


def test_save_as_elsewhere_keeps_the_particles_and_the_bake(scene, isobar, tmp_path):
    sim = make_sequence(tmp_path / "sim", [FRAME_01, FRAME_26, FRAME_01])
    save_as(tmp_path / "shots" / "a.blend")
    obj = import_sequence(sim[0])
    name, settings = obj.name, obj.isobar
    assert settings.directory.startswith("//")
    assert bpy.ops.isobar.bake() == {"FINISHED"}
    baked = tmp_path / "shots" / "isobar_cache" / settings.cache_name
    assert (baked / "frame_000002.npz").is_file()

    save_as(tmp_path / "other" / "deeper" / "b.blend")  # relative_remap, Blender's default
    assert settings.directory.startswith("//") and settings.cache_directory.startswith("//")
    assert resolved(settings.directory) == tmp_path / "sim"
    assert resolved(settings.cache_directory) == tmp_path / "shots" / "isobar_cache"

    # The bake still plays: with the particles gone only the bake can make the frames.
    expected = [reference(isobar, p, attributes=["velocity"]) for p in sim]
    for path in sim:
        path.rename(path.with_suffix(".moved"))
    for frame in (2, 3):
        scene.frame_set(frame)
        assert not settings.status_error and "bake" in settings.status, settings.status
        assert_mesh_equals(obj, expected[frame - 1])
    for path in sim:
        path.with_suffix(".moved").rename(path)

    # Reopened from its new folder, it still reads the particles.
    assert bpy.ops.wm.save_mainfile() == {"FINISHED"}
    assert bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "other" / "deeper" / "b.blend")) == {"FINISHED"}
    settings = bpy.data.objects[name].isobar
    settings.use_cache = False
    bpy.context.scene.frame_set(2)
    assert not settings.status_error, settings.status
    assert "frame_0002.vtk" in settings.status


def test_save_copy_leaves_the_open_files_paths(scene, tmp_path):
    sim = make_sequence(tmp_path / "sim", [FRAME_01])
    save_as(tmp_path / "shots" / "a.blend")
    obj = import_sequence(sim[0])
    name, before = obj.name, obj.isobar.directory
    save_as(tmp_path / "copies" / "deeper" / "copy.blend", copy=True)
    assert obj.isobar.directory == before  # the open file did not move
    assert bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "copies" / "deeper" / "copy.blend")) == {"FINISHED"}
    assert resolved(bpy.data.objects[name].isobar.directory) == tmp_path / "sim"


def test_first_save_makes_the_particle_folder_relative(scene, tmp_path):
    sim = make_sequence(tmp_path / "sim", [FRAME_01])
    obj = import_sequence(sim[0])  # unsaved file: absolute
    assert Path(obj.isobar.directory) == tmp_path / "sim"
    save_as(tmp_path / "shots" / "a.blend")
    assert obj.isobar.directory.startswith("//"), obj.isobar.directory
    assert resolved(obj.isobar.directory) == tmp_path / "sim"


def test_a_missing_bake_is_reported_not_silently_extracted(scene, tmp_path):
    sim = make_sequence(tmp_path / "sim", [FRAME_01, FRAME_26])
    save_as(tmp_path / "a.blend")
    obj = import_sequence(sim[0])
    assert bpy.ops.isobar.bake() == {"FINISHED"}
    shutil.rmtree(tmp_path / "isobar_cache")
    scene.frame_set(2)
    settings = obj.isobar
    assert "baked frame missing" in settings.status, settings.status
    assert "baked frame 2 is missing" in settings.status_warnings, settings.status_warnings
    assert len(obj.data.polygons) > 0  # extracted again from the particles


def test_moving_the_project_keeps_volume_and_fe_files(scene, tmp_path):
    project = tmp_path / "project"
    (project / "data").mkdir(parents=True)
    save_as(project / "scene.blend")
    volume = bpy.ops.isobar.import_volume(filepath=str(_volume(project / "data" / "blobs.npy")))
    assert volume == {"FINISHED"}
    slider = bpy.context.active_object.name
    assert bpy.ops.isobar.import_fe(filepath=str(_cube_vtu(project / "data" / "cube.vtu")), isovalue=1.0) == {"FINISHED"}
    fe = bpy.context.active_object.name
    settings = bpy.data.objects[slider].isobar_slider, bpy.data.objects[fe].isobar_fe
    for value in (settings[0].volume, settings[0].store, settings[1].filepath):
        assert value.startswith("//data/"), value
    assert bpy.ops.wm.save_mainfile() == {"FINISHED"}

    shutil.move(str(project), str(tmp_path / "moved"))
    assert bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "moved" / "scene.blend")) == {"FINISHED"}
    slider = bpy.data.objects[slider].isobar_slider
    slider.isovalue = 0.5
    assert not slider.status_error and slider.triangles > 0, slider.status
    fe = bpy.data.objects[fe].isobar_fe
    fe.isovalue = 0.5
    assert not fe.status_error and fe.samples > 0, fe.status
