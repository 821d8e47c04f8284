"""Baking a frame range to the cache and playing it back."""

import os
from pathlib import Path

import bpy
import pytest
from conftest import assert_mesh_equals, import_sequence, ISO, reference


def test_bake_and_play_back_without_particle_files(scene, isobar, demo_sequence, tmp_path):
    obj = import_sequence(demo_sequence[0])
    settings = obj.isobar
    settings.cache_directory = str(tmp_path / "cache")
    references = [reference(isobar, p, attributes=["velocity"]) for p in demo_sequence]
    assert bpy.ops.isobar.bake() == {"FINISHED"}
    folder = tmp_path / "cache" / settings.cache_name
    assert sorted(os.listdir(folder)) == ["frame_000001.npz", "frame_000002.npz", "frame_000003.npz"]
    assert settings.use_cache and (settings.baked_start, settings.baked_end) == (1, 3)

    for path in demo_sequence:  # the particles are gone: only the cache can make the frames
        path.unlink()
    for frame in (2, 3, 1, 2):
        scene.frame_set(frame)
        assert not settings.status_error, settings.status
        assert "bake" in settings.status
        assert_mesh_equals(obj, references[frame - 1])
        assert {"sph_SumOfWeights", "sph_speed", "velocity"} <= set(obj.data.attributes.keys())
        assert obj.data.has_custom_normals

    # A parameter changed after the bake: the cached frame no longer matches and the
    # particles are gone, so the change is reported and the mesh stays.
    shown = len(obj.data.vertices)
    settings.iso = 0.55
    assert settings.status_error and "frame_0002.vtk" in settings.status
    assert len(obj.data.vertices) == shown
    settings.iso = ISO  # back to the baked parameters: the cache plays again
    assert not settings.status_error and "bake" in settings.status

    assert bpy.ops.isobar.free_bake() == {"FINISHED"}
    assert not folder.exists() and not settings.use_cache


def test_bake_range_and_partial_cache(scene, isobar, demo_sequence, tmp_path):
    obj = import_sequence(demo_sequence[0])
    obj.isobar.cache_directory = str(tmp_path / "cache")
    assert bpy.ops.isobar.bake(use_scene_range=False, frame_start=2, frame_end=2) == {"FINISHED"}
    folder = tmp_path / "cache" / obj.isobar.cache_name
    assert os.listdir(folder) == ["frame_000002.npz"]
    scene.frame_set(2)
    assert "bake" in obj.isobar.status
    scene.frame_set(3)  # not baked: extracted from the particles
    assert "frame_0003.vtk" in obj.isobar.status
    assert_mesh_equals(obj, reference(isobar, demo_sequence[2]))


def test_bake_stops_at_a_missing_file_with_a_report(scene, isobar, demo_sequence, tmp_path):
    obj = import_sequence(demo_sequence[0])
    obj.isobar.cache_directory = str(tmp_path / "cache")
    demo_sequence[1].unlink()
    with pytest.raises(RuntimeError, match="frame 2.*frame_0002.vtk"):
        bpy.ops.isobar.bake()
    folder = tmp_path / "cache" / obj.isobar.cache_name
    assert os.listdir(folder) == ["frame_000001.npz"]  # what was baked stays usable
    assert obj.isobar.use_cache and obj.isobar.baked_end == 1
    assert_mesh_equals(obj, reference(isobar, demo_sequence[0]))


def test_bake_job_one_frame_per_step_and_cancel(scene, addon, demo_sequence, tmp_path):
    """The modal operator's unit of work: one frame per timer tick; Esc ends the job with
    the frames baked so far."""
    bake = addon.bake
    obj = import_sequence(demo_sequence[0])
    obj.isobar.cache_directory = str(tmp_path / "cache")
    job = bake.BakeJob(obj, scene, bake.scene_frames(scene))
    assert job.total == 3 and job.current_frame == 1
    fractions = []
    assert job.step(lambda f, phase: fractions.append(f)) == 1
    assert fractions and all(0.0 <= f <= 1.0 for f in fractions)
    assert job.current_frame == 2
    job.finish()  # cancelled here
    assert obj.isobar.use_cache and (obj.isobar.baked_start, obj.isobar.baked_end) == (1, 1)
    assert os.listdir(job.folder) == ["frame_000001.npz"]


def test_bake_needs_a_saved_file_for_a_relative_cache(scene, demo_sequence):
    obj = import_sequence(demo_sequence[0])
    assert obj.isobar.cache_directory.startswith("//")
    with pytest.raises(RuntimeError, match="save the .blend"):
        bpy.ops.isobar.bake()


class _Modal:
    """Stands in for the running operator so that its modal() can be driven tick by tick
    (background bpy has no event loop to send timer events)."""

    def __init__(self, operator_class, job, context):
        self.cls = operator_class
        self._job = job
        self._timer = context.window_manager.event_timer_add(3600.0, window=context.window)
        self.reports = []

    def report(self, kind, message):
        self.reports.append((set(kind), message))

    def _end(self, context):
        return self.cls._end(self, context)

    def _status(self, context, text=None):
        return self.cls._status(self, context, text)

    def send(self, context, event_type):
        event = type("Event", (), {"type": event_type, "value": "PRESS", "timer": self._timer})()
        return self.cls.modal(self, context, event)


def test_modal_bake_one_frame_per_tick_and_esc(scene, addon, demo_sequence, tmp_path):
    operators, bake = addon.operators, addon.bake
    obj = import_sequence(demo_sequence[0])
    obj.isobar.cache_directory = str(tmp_path / "cache")
    context = bpy.context
    modal = _Modal(operators.ISOBAR_OT_bake, bake.BakeJob(obj, scene, bake.scene_frames(scene)), context)
    assert modal.send(context, "MOUSEMOVE") == {"PASS_THROUGH"}  # the UI stays usable
    assert modal._job.baked == []
    assert modal.send(context, "TIMER") == {"RUNNING_MODAL"}
    assert modal._job.baked == [1]
    assert modal.send(context, "ESC") == {"CANCELLED"}
    assert modal._timer is None  # removed
    assert modal.reports and "cancelled" in modal.reports[-1][1] and "WARNING" in modal.reports[-1][0]
    assert sorted(os.listdir(modal._job.folder)) == ["frame_000001.npz"]
    assert obj.isobar.use_cache and obj.isobar.baked_end == 1

    # A full run, tick by tick, and one with a missing file.
    modal = _Modal(operators.ISOBAR_OT_bake, bake.BakeJob(obj, scene, bake.scene_frames(scene)), context)
    results = [modal.send(context, "TIMER") for _ in range(3)]
    assert results == [{"RUNNING_MODAL"}, {"RUNNING_MODAL"}, {"FINISHED"}]
    assert len(os.listdir(modal._job.folder)) == 3 and "Baked 3 frames" in modal.reports[-1][1]
    demo_sequence[2].unlink()
    obj.isobar.iso = 0.55  # new parameters: the bake must read the particles again
    modal = _Modal(operators.ISOBAR_OT_bake, bake.BakeJob(obj, scene, bake.scene_frames(scene)), context)
    results = [modal.send(context, "TIMER") for _ in range(3)]
    assert results == [{"RUNNING_MODAL"}, {"RUNNING_MODAL"}, {"CANCELLED"}]
    kind, message = modal.reports[-1]
    assert "ERROR" in kind and "frame 3" in message and "frame_0003.vtk" in message


def _snapshot(folder):
    return {p.name: p.stat().st_mtime_ns for p in folder.iterdir()}


def test_a_duplicated_surface_bakes_and_frees_its_own_folder(scene, demo_sequence, tmp_path):
    obj = import_sequence(demo_sequence[0])
    obj.isobar.cache_directory = str(tmp_path / "cache")
    assert bpy.ops.isobar.bake() == {"FINISHED"}
    original = tmp_path / "cache" / obj.isobar.cache_name
    before = _snapshot(original)

    assert bpy.ops.object.duplicate() == {"FINISHED"}  # Shift+D copies the cache name
    dup = bpy.context.active_object
    assert dup != obj and dup.isobar.cache_name == obj.isobar.cache_name
    dup.isobar.iso = 0.5
    assert bpy.ops.isobar.bake(object_name=dup.name) == {"FINISHED"}
    assert dup.isobar.cache_name != obj.isobar.cache_name
    assert _snapshot(original) == before  # not overwritten
    assert bpy.ops.isobar.free_bake(object_name=dup.name) == {"FINISHED"}
    assert not (tmp_path / "cache" / dup.isobar.cache_name).exists()
    assert _snapshot(original) == before

    # A copy that never baked shares the original's folder: freeing it keeps the frames.
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    dup.select_set(False)
    assert bpy.ops.object.duplicate() == {"FINISHED"}
    copy = bpy.context.active_object
    assert copy.isobar.cache_name == obj.isobar.cache_name
    assert bpy.ops.isobar.free_bake(object_name=copy.name) == {"FINISHED"}
    assert _snapshot(original) == before and not copy.isobar.use_cache
    scene.frame_set(2)
    assert obj.isobar.use_cache and "bake" in obj.isobar.status, obj.isobar.status


def test_rebaking_a_sub_range_shows_every_frame_playback_uses(scene, demo_sequence, tmp_path):
    obj = import_sequence(demo_sequence[0])
    settings = obj.isobar
    settings.cache_directory = str(tmp_path / "cache")
    assert bpy.ops.isobar.bake() == {"FINISHED"}
    assert bpy.ops.isobar.bake(use_scene_range=False, frame_start=2, frame_end=2) == {"FINISHED"}
    assert (settings.baked_start, settings.baked_end) == (1, 3)  # 1 and 3 still play
    settings.iso = 0.5  # frames 1 and 3 no longer match
    assert bpy.ops.isobar.bake(use_scene_range=False, frame_start=2, frame_end=2) == {"FINISHED"}
    assert (settings.baked_start, settings.baked_end) == (2, 2)


def test_two_blend_files_in_one_folder_keep_their_bakes_apart(scene, addon, demo_sequence, tmp_path):
    """Two shots side by side, each with its own 'frame_surface' and the default
    //isobar_cache/: the second shot's bake overwrote the first's frames, and its Free
    deleted them."""
    shots = {}
    for shot in ("shot_010", "shot_020"):
        bpy.ops.wm.read_homefile(use_empty=True)
        obj = import_sequence(demo_sequence[0])
        assert obj.name == "frame_surface"
        bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / f"{shot}.blend"))
        assert bpy.ops.isobar.bake() == {"FINISHED"}
        folder = Path(addon.importer.cache_folder(obj))
        shots[shot] = (folder, {p.name: p.stat().st_mtime_ns for p in folder.glob("frame_*.npz")})
        bpy.ops.wm.save_mainfile()
    (first, first_files), (second, second_files) = shots["shot_010"], shots["shot_020"]
    assert first == tmp_path / "isobar_cache" / "frame_surface"
    assert second == tmp_path / "isobar_cache" / "frame_surface_2"
    assert {p.name: p.stat().st_mtime_ns for p in first.glob("frame_*.npz")} == first_files
    assert len(second_files) == 3

    assert bpy.ops.isobar.free_bake() == {"FINISHED"}  # shot 020's own folder only
    assert not second.exists()
    assert {p.name: p.stat().st_mtime_ns for p in first.glob("frame_*.npz")} == first_files
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "shot_010.blend"))
    obj = bpy.data.objects["frame_surface"]
    bpy.context.scene.frame_set(2)
    assert "bake" in obj.isobar.status and not obj.isobar.status_error, obj.isobar.status


def test_a_bake_of_every_other_frame_does_not_call_the_frames_between_missing(scene, isobar, demo_sequence, tmp_path):
    """Frame Step 2 bakes frames 1 and 3; frame 2 was never meant to be baked, and playing
    it warned 'the baked frame 2 is missing'. A baked frame that did go missing still warns."""
    obj = import_sequence(demo_sequence[0])
    settings = obj.isobar
    settings.cache_directory = str(tmp_path / "cache")
    scene.frame_step = 2
    assert bpy.ops.isobar.bake() == {"FINISHED"}
    folder = tmp_path / "cache" / settings.cache_name
    assert sorted(p.name for p in folder.iterdir()) == ["frame_000001.npz", "frame_000003.npz"]
    assert (settings.baked_start, settings.baked_end, settings.baked_step) == (1, 3, 2)
    scene.frame_set(2)  # extracted, without a warning
    assert not settings.status_error and not settings.status_warnings, (settings.status, settings.status_warnings)
    assert_mesh_equals(obj, reference(isobar, demo_sequence[1], attributes=["velocity"]))
    (folder / "frame_000003.npz").unlink()
    scene.frame_set(3)
    assert "the baked frame 3 is missing" in settings.status_warnings, settings.status_warnings
